"""Roof-support canopy attitude: 002's KF, UKF and GD-UKF and our error-state filter."""
