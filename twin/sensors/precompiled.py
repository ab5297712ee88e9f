"""The sensor models' numba kernels with the argument types of their calls, for estimators.precompile: a first run
compiles them in the background while the face is simulated, so the run finds them in the cache when it draws the
sensors (it compiled them itself before, on the run's own path: about 8 s of CPU).

The order is the one they are reached in. A change of a listed call's argument types must be made here too, or
the call compiles again (tests/twin/sensors/test_precompiled.py fails). The IMU error kernel is left out: numba's
signature syntax has no name for the numpy Generator it takes.
"""

from __future__ import annotations

from estimators.precompile import F8_1D, F8_2D, Kernel

SENSOR_KERNELS = (
    Kernel("twin.sensors.vibration", "_envelope_kernel", f"i8[::1], i8, {F8_2D}"),
    Kernel("twin.sensors.imu", "_gravity_kernel", f"{F8_2D}, {F8_1D}, {F8_1D}, {F8_1D}, {F8_2D}"),
    Kernel("twin.sensors.imu", "_derivative_kernel", f"{F8_2D}, {F8_1D}, i8, {F8_2D}"),
    Kernel("twin.sensors.imu", "_increments_kernel",
           f"{F8_1D}, {F8_2D}, {F8_2D}, {F8_2D}, {F8_2D}, {F8_2D}, {F8_2D}, {F8_2D}, f8[:, :, ::1], f8[:, :, ::1], "
           f"{F8_2D}, {F8_2D}, {F8_1D}, {F8_2D}, {F8_1D}, {F8_1D}, {F8_2D}, {F8_2D}"),
    Kernel("twin.sensors.odometer", "_speed_kernel",
           f"{F8_1D}, {F8_1D}, {F8_1D}, {F8_1D}, {F8_1D}, {F8_1D}, {F8_1D}, f8, f8, f8, {F8_1D}"),
)
"""The shearer's sensor kernels (twin.sensors.vibration, imu, odometer)."""
