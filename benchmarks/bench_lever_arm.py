"""Benchmark: lever-arm compensation on the sway of 000 eq. 54 (reproduction of the paper's Tables 2-3).

The experiment is the scenario file scenarios/seed000_lever_arm.toml (every parameter there); twin.papers.sins_experiments
runs it (`longwall run scenarios/seed000_lever_arm.toml` also writes the error time series and a Rerun recording).

The body's reference point rests at the paper's site (34.27 N, 117.18 E, 36 m) while it sways in pitch, roll
and yaw with 10 deg amplitudes and periods 6, 8, 10 s; an error-free IMU at the lever arm r_p (twin.sensors.imu's exact
increments at 200 Hz) is mechanized for 400 s (estimators.sins.strapdown.mechanize, two-sample updates, height
held) once with its raw increments and once with the lever arm removed by the two-sample compensation
(estimators.sins.installation.compensate_lever_arm, eqs. 48-53). The metric is the paper's: the maximum attitude
error (E, N, U; at yaw near 0 these are the pitch, roll and yaw errors) over the run.

The paper's numbers come from its fine-alignment filter (sensor biases, initial attitude errors, velocity
observations), where the lever-arm acceleration is mistaken for tilt; here the sensors are error-free so the
attitude errors are those of the lever arm alone (through the velocity error and the transport rate), and
their absolute size is not comparable with the paper's -- the reductions are.

The closed-loop rows run the paper's own setting as far as it is specified: a closed-loop fine alignment of 400 s
(15-state error-state Kalman filter on estimators.sins.error_model: attitude, velocity, position, gyro drift,
accelerometer bias; zero-velocity observations of the resting reference point at 10 Hz), the paper's sensor
errors (gyro bias 0.01 deg/h and random drift 0.005 deg/h, accelerometer bias 1e-4 g and random 1e-5 g) and
initial attitude error [0.1, 0.1, 0.5] deg. Uncompensated, the sensor's lever-arm velocity enters the
zero-velocity observations and is taken for tilt. The paper gives no filter tuning; here R = (0.05 m/s)^2,
and the absolute errors depend on that choice (a larger R hides more of the lever arm). The metric is the
maximum error over the second half (200-400 s, the steady state the paper describes), since the initial
0.5 deg heading error would otherwise dominate both columns.
Run: python benchmarks/bench_lever_arm.py
"""

from twin.papers.sins_experiments import benchmark

if __name__ == "__main__":
    benchmark(["seed000_lever_arm"])
