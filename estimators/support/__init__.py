"""Roof-support canopy attitude from 9-axis units: 002's models (`unit_model`), KF and UKF (`filters_002`) and the
GD-UKF's tuning of Q (`tuning`), our error-state filter (`error_state`), the batch of units they run on (`batch`)
and what their numba kernels share (`kernel_math`; rotations: estimators.nav.rotations_scalar)."""
