"""Running a scenario: simulation, Monte Carlo trials, run directories, estimator wiring."""
