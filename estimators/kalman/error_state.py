"""The state layout of the SINS/odometer error-state filters (001 section 3; estimators.shearer.odometer_filter
and federated_filter, the measurement models of estimators.kalman.measurements): the error state and the three
vectors of the kernels it is fed back into and linearized at. Named indices only; numba reads the slices as
constants (a block's first element is its .start).

Error state (001 eq. 12, this order, then the non-orthogonality; errors are estimate - truth):

    x = [dv_n (ENU, m/s), phi (attitude error, C_b^n' = (I - [phi x]) C_b^n, rad), dp (ENU, m),
         eps (gyro bias, b, rad/s), nabla (accelerometer bias, b, m/s^2), dalpha (odometer mounting, rad),
         dk_D (odometer scale-factor error), da (accelerometer non-orthogonality a_xy, a_xz, a_yz, rad)]

dp is in metres east/north/up instead of 001's (longitude, latitude, height): the same state through the
diagonal matrix C of 001 eq. 7, and better conditioned. (estimators.sins.error_model is the 9-state navigation
error alone, attitude first and position geodetic, for the check of the mechanization against it.)
"""

from __future__ import annotations

DV = slice(0, 3)
PHI = slice(3, 6)
DP = slice(6, 9)
GYRO_BIAS = slice(9, 12)
ACCEL_BIAS = slice(12, 15)
ODO_MOUNT = slice(15, 18)
ODO_SCALE = 18
ACCEL_NONORTH = slice(19, 22)
N_STATES = 22

# Navigation vector: geodetic position, ENU velocity, attitude q_nb.
LAT, LON, HGT = 0, 1, 2
VEL = slice(3, 6)
QUAT = slice(6, 10)
N_NAV = 10

# Calibration vector: gyro and accelerometer corrections (subtracted from the increments), odometer mounting as
# the rotation vector of C_m^b, odometer scale k (distance = nominal / (1 + k)).
CAL_GYRO = slice(0, 3)
CAL_ACCEL = slice(3, 6)
CAL_MOUNT = slice(6, 9)
CAL_SCALE = 9
CAL_NONORTH = slice(10, 13)  # (a_xy, a_xz, a_yz): dv_b <- dv_b - A dv_b
N_CAL = 13

# Nominal vector, the running means the models are linearized at (carried across the kernels' calls): the
# odometer speed H is evaluated at and the last epoch's odometer speed (measurements.odometer_velocity), the
# specific force in n low-passed by two stages, F taking the second (odometer_filter.transition).
NOM_SPEED = 0
NOM_FORCE_1 = slice(1, 4)
NOM_SPEED_LAST = 4
NOM_FORCE_2 = slice(5, 8)
N_NOMINAL = 8
