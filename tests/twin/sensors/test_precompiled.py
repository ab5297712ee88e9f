"""The sensor kernels a first run compiles ahead (twin.sensors.precompiled) are listed with the argument types of
their calls: a listed type that no longer matches would compile them twice, once in the background and once on the
run's own path."""

from __future__ import annotations

from twin.sensors.precompiled import SENSOR_KERNELS


def test_each_listed_sensor_kernel_is_called_with_the_listed_argument_types(short_default_run):
    # The fixture drew every stream of the default scenario in this process.
    for kernel in SENSOR_KERNELS:
        assert kernel.signature() in kernel.dispatcher().signatures, kernel
