"""The sensor models' numba kernels with the argument types of their calls, for estimators.precompile: a first run
compiles them in the background while the face is simulated, so the run finds them in the cache when it draws the
sensors (it compiled them itself before, on the run's own path: about 8 s of CPU).

The order is the one they are reached in. A change of a listed call's argument types must be made here too, or
the call compiles again (tests/twin/sensors/test_precompiled.py fails). The IMU error kernel is left out: numba's
signature syntax has no name for the numpy Generator it takes.
"""

from __future__ import annotations

from estimators.precompile import Kernel

_C1, _C2 = "f8[::1]", "f8[:, ::1]"
SENSOR_KERNELS = (
    Kernel("twin.sensors.vibration", "_envelope_kernel", f"i8[::1], i8, {_C2}"),
    Kernel("twin.sensors.imu", "_gravity_kernel", f"{_C2}, {_C1}, {_C1}, {_C1}, {_C2}"),
    Kernel("twin.sensors.imu", "_derivative_kernel", f"{_C2}, {_C1}, i8, {_C2}"),
    Kernel("twin.sensors.imu", "_increments_kernel",
           f"{_C1}, {_C2}, {_C2}, {_C2}, {_C2}, {_C2}, {_C2}, {_C2}, f8[:, :, ::1], f8[:, :, ::1], {_C2}, {_C2}, "
           f"{_C1}, {_C2}, {_C1}, {_C1}, {_C2}, {_C2}"),
    Kernel("twin.sensors.odometer", "_speed_kernel", f"{_C1}, {_C1}, {_C1}, {_C1}, {_C1}, {_C1}, {_C1}, f8, f8, f8, {_C1}"),
)
"""The shearer's sensor kernels (twin.sensors.vibration, imu, odometer)."""
