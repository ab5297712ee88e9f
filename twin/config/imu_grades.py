"""Named IMU error budgets (grades) for the twin's inertial sensors, in SI units.

A grade says how large each error of a strapdown IMU is; twin.sensors.imu_errors draws one realization of those
errors per run and applies it to ideal increments. Every figure below is converted once from the unit the
source writes (deg/h, deg/sqrt(h), mg, ug, mg/sqrt(Hz), deg/s/sqrt(Hz)) into SI; each axis is identical.

Presets (the names a scenario's `[sensors.imu] grade` or `[sensors.support_imu] grade` may use):

    mti-g-700        Xsens MTi-G-700 of 001_db251ef7ffe38041.txt, Table 1 (bias repeatability, random walk),
                     plus in-run bias stability, alignment error and range from the Xsens datasheet
    par1 .. par12    the degraded MIMUs of 001 Table 2: each one constant bias or one random walk, nothing else
    nav-004          the navigation-grade INS simulated in 004_3a7d5c375301370c.txt, Table 1
    mti-30           Xsens MTi-30 of 003_4323b291bfead1c8.txt (003 names the unit only; datasheet values)
    icm-42605        TDK InvenSense ICM-42605 of 002_5cc0b59ad045ffaa.txt (ranges from 002, noise from the
                     datasheet)
    ideal            no error at all, unlimited range

Bias instability is modelled as a first-order Gauss-Markov (GM) process. A datasheet's "in-run bias stability"
is the floor of the Allan deviation (ADEV), so where a preset takes it from a datasheet the GM sigma is set so
that the GM's ADEV maximum equals that figure: sigma = floor / GM_ADEV_PEAK (see `gm_adev`). Where a paper
gives a "bias" for a simulation, the figure is used as the standard deviation directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

G0 = 9.80665
"""Standard gravity [m/s^2], the g of mg and ug."""

DEG = math.pi / 180.0
DEG_PER_H = DEG / 3600.0  # deg/h -> rad/s
DEG_PER_SQRT_H = DEG / 60.0  # deg/sqrt(h) -> rad/sqrt(s)
DEG_PER_S_PER_SQRT_HZ = DEG  # deg/s/sqrt(Hz) -> rad/sqrt(s)
MG = 1e-3 * G0  # mg -> m/s^2
UG = 1e-6 * G0  # ug -> m/s^2
MG_PER_SQRT_HZ = MG  # mg/sqrt(Hz) -> m/s/sqrt(s)
UG_PER_SQRT_HZ = UG  # ug/sqrt(Hz) -> m/s/sqrt(s)

GM_ADEV_PEAK = 0.6173642831
"""Maximum of the Allan deviation of a first-order Gauss-Markov process, as a fraction of its sigma.

With autocovariance sigma^2 exp(-|t| / T) the Allan variance at averaging time tau (u = tau / T) is

    AVAR(tau) = Var(mean over tau) - Cov(adjacent means)
              = sigma^2 [2 / u - (3 - 4 exp(-u) + exp(-2 u)) / u^2],

whose maximum over u is 0.61736 sigma at u = 1.89262 (found numerically; tests/twin/sensors/test_imu_errors.py
re-derives both numbers and checks them on a simulated record)."""
GM_ADEV_PEAK_TAU = 1.8926169811
"""Averaging time of that maximum in units of the correlation time T."""


def gm_adev(tau, sigma: float, tc: float):
    """Closed-form Allan deviation of a stationary first-order Gauss-Markov process (sigma, correlation time tc)."""
    u = np.asarray(tau, dtype=float) / tc
    small = u < 1e-3
    us = np.where(small, 1.0, u)
    # 3 - 4 e^-u + e^-2u written with expm1 to keep the digits for moderate u.
    full = 2.0 / us - (-4.0 * np.expm1(-us) + np.expm1(-2.0 * us)) / us ** 2
    series = 2.0 * u / 3.0 - u ** 2 / 2.0
    return sigma * np.sqrt(np.where(small, series, full))


def gm_sigma_from_adev_floor(floor: float) -> float:
    """GM sigma whose Allan-deviation maximum equals a datasheet's in-run bias stability `floor`."""
    return floor / GM_ADEV_PEAK


@dataclass(frozen=True)
class ImuGrade:
    """Error budget of a three-axis IMU, SI units, identical on each axis. All figures are 1-sigma.

    Gyroscope (angle increments dtheta [rad] over each sample interval):
      gyro_bias               turn-on (repeatability) bias, drawn once per run [rad/s]
      gyro_bias_instability   sigma of the first-order Gauss-Markov in-run bias [rad/s]
      gyro_bias_tau           its correlation time [s] (> 0 when gyro_bias_instability > 0)
      gyro_arw                angle random walk (white rate noise density) [rad/sqrt(s)]
      gyro_scale              scale-factor error [-], drawn once per run
      gyro_nonorth            non-orthogonality: each off-diagonal element of the sensor matrix [rad]
      gyro_quant              quantization step of the angle increment [rad] (0: none)
      gyro_range              measurement range (saturation) of the rate [rad/s] (inf: none)
    Accelerometer (velocity increments dv [m/s]), the same in its units:
      accel_bias [m/s^2], accel_bias_instability [m/s^2], accel_bias_tau [s], accel_vrw [m/s/sqrt(s)],
      accel_scale [-], accel_nonorth [rad], accel_quant [m/s], accel_range [m/s^2].
    """

    gyro_bias: float = 0.0
    gyro_bias_instability: float = 0.0
    gyro_bias_tau: float = 0.0
    gyro_arw: float = 0.0
    gyro_scale: float = 0.0
    gyro_nonorth: float = 0.0
    gyro_quant: float = 0.0
    gyro_range: float = math.inf
    accel_bias: float = 0.0
    accel_bias_instability: float = 0.0
    accel_bias_tau: float = 0.0
    accel_vrw: float = 0.0
    accel_scale: float = 0.0
    accel_nonorth: float = 0.0
    accel_quant: float = 0.0
    accel_range: float = math.inf

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f"ImuGrade.{f.name} must be a number, got {value!r}")
            if math.isnan(value) or value < 0:
                raise ValueError(f"ImuGrade.{f.name} must be >= 0, got {value!r}")
            if math.isinf(value) and not f.name.endswith("_range"):
                raise ValueError(f"ImuGrade.{f.name} must be finite, got {value!r}")
        for sensor in ("gyro", "accel"):
            if getattr(self, f"{sensor}_range") == 0:
                raise ValueError(f"ImuGrade.{sensor}_range must be > 0 (use inf for no saturation)")
            if getattr(self, f"{sensor}_bias_instability") > 0 and getattr(self, f"{sensor}_bias_tau") <= 0:
                raise ValueError(f"ImuGrade.{sensor}_bias_tau must be > 0 when {sensor}_bias_instability > 0")

    @property
    def gyro_bias_psd(self) -> float:
        """Random-walk density [rad^2/s^3] of a filter's gyro bias state matching the Gauss-Markov in-run bias:
        2 sigma^2 / tau (0 without one)."""
        return 2 * self.gyro_bias_instability ** 2 / self.gyro_bias_tau if self.gyro_bias_instability > 0 else 0.0

    @property
    def accel_bias_psd(self) -> float:
        """The same for the accelerometer bias [m^2/s^5]."""
        return 2 * self.accel_bias_instability ** 2 / self.accel_bias_tau if self.accel_bias_instability > 0 else 0.0


def _par(gyro_bias_deg_h=0.0, gyro_rw_deg_sqrt_h=0.0, accel_bias_mg=0.0, accel_rw_mg_sqrt_hz=0.0) -> ImuGrade:
    """A row of 001 Table 2 ("Error parameters to be accumulated"): constant bias and random walk only."""
    return ImuGrade(gyro_bias=gyro_bias_deg_h * DEG_PER_H, gyro_arw=gyro_rw_deg_sqrt_h * DEG_PER_SQRT_H,
                    accel_bias=accel_bias_mg * MG, accel_vrw=accel_rw_mg_sqrt_hz * MG_PER_SQRT_HZ)


GRADES: dict[str, ImuGrade] = {
    # 001 Table 1 "Specifications of the MIMU" (Xsens MTi-G-700): gyro bias repeatability 720 deg/h and random
    # walk 0.6 deg/sqrt(h); accelerometer bias repeatability 3 mg and random walk 0.08 mg/sqrt(Hz).
    # Not in 001, from the Xsens MTi 100-series datasheet (MTi User Manual MT0605P, typical): in-run bias
    # stability 10 deg/h and 15 ug (ADEV floors, converted to GM sigma), alignment (non-orthogonality) error
    # 0.05 deg, standard full range 450 deg/s and 50 m/s^2. Assumed, stated nowhere: GM correlation time 200 s
    # (puts the ADEV floor near 400 s, where MEMS datasheets place it). Xsens states no residual scale-factor
    # error and outputs the increments as floats, so neither scale error nor quantization is modelled.
    "mti-g-700": ImuGrade(
        gyro_bias=720.0 * DEG_PER_H,
        gyro_bias_instability=gm_sigma_from_adev_floor(10.0 * DEG_PER_H),
        gyro_bias_tau=200.0,
        gyro_arw=0.6 * DEG_PER_SQRT_H,
        gyro_nonorth=0.05 * DEG,
        gyro_range=450.0 * DEG,
        accel_bias=3.0 * MG,
        accel_bias_instability=gm_sigma_from_adev_floor(15.0 * UG),
        accel_bias_tau=200.0,
        accel_vrw=0.08 * MG_PER_SQRT_HZ,
        accel_nonorth=0.05 * DEG,
        accel_range=50.0,
    ),
    # 001 Table 2: Par 1-3 gyro constant bias 100/200/300 deg/h, Par 4-6 gyro random walk 1/2/3 deg/sqrt(h),
    # Par 7-9 accelerometer constant bias 1/2/3 mg, Par 10-12 accelerometer random walk 1/2/3 mg/sqrt(Hz).
    # 001 (eq. 32) treats the constant bias as a random constant; it is the turn-on bias sigma here.
    "par1": _par(gyro_bias_deg_h=100.0),
    "par2": _par(gyro_bias_deg_h=200.0),
    "par3": _par(gyro_bias_deg_h=300.0),
    "par4": _par(gyro_rw_deg_sqrt_h=1.0),
    "par5": _par(gyro_rw_deg_sqrt_h=2.0),
    "par6": _par(gyro_rw_deg_sqrt_h=3.0),
    "par7": _par(accel_bias_mg=1.0),
    "par8": _par(accel_bias_mg=2.0),
    "par9": _par(accel_bias_mg=3.0),
    "par10": _par(accel_rw_mg_sqrt_hz=1.0),
    "par11": _par(accel_rw_mg_sqrt_hz=2.0),
    "par12": _par(accel_rw_mg_sqrt_hz=3.0),
    # 004 Table 1 "Simulation setting of main sensors" (also its Table 3): gyro zero-bias stability 0.001 deg/h,
    # angle random walk 0.0001 deg/sqrt(h), accelerometer zero-bias stability 30 ug. 004 gives one bias figure
    # per sensor and no time constant, so each is a turn-on (random-constant) bias, the reading that is
    # conservative over its 6.4 h run; nothing else is stated, so nothing else is modelled.
    "nav-004": ImuGrade(
        gyro_bias=0.001 * DEG_PER_H,
        gyro_arw=0.0001 * DEG_PER_SQRT_H,
        accel_bias=30.0 * UG,
    ),
    # 003 section 5.1 names the unit (Xsens MTi-30 AHRS: three-axis gyroscope, accelerometer, magnetometer) but
    # its specification table is not in the text, so every figure is datasheet-typical for the MTi 10-series
    # (MTi User Manual MT0605P, 4th generation): gyro bias repeatability 0.2 deg/s, in-run bias stability
    # 18 deg/h, noise density 0.03 deg/s/sqrt(Hz), alignment error 0.05 deg, range 450 deg/s; accelerometer
    # bias repeatability 0.03 m/s^2, in-run bias stability 40 ug, noise density 80 ug/sqrt(Hz), alignment error
    # 0.05 deg, range 50 m/s^2. Assumed: GM correlation time 200 s; no scale error or quantization (as mti-g-700).
    "mti-30": ImuGrade(
        gyro_bias=0.2 * DEG,
        gyro_bias_instability=gm_sigma_from_adev_floor(18.0 * DEG_PER_H),
        gyro_bias_tau=200.0,
        gyro_arw=0.03 * DEG_PER_S_PER_SQRT_HZ,
        gyro_nonorth=0.05 * DEG,
        gyro_range=450.0 * DEG,
        accel_bias=0.03,
        accel_bias_instability=gm_sigma_from_adev_floor(40.0 * UG),
        accel_bias_tau=200.0,
        accel_vrw=80.0 * UG_PER_SQRT_HZ,
        accel_nonorth=0.05 * DEG,
        accel_range=50.0,
    ),
    # 002 section 2.2: ICM-42605 gyroscopes and accelerometers with measuring range +-125 deg/s and +-16 g.
    # From the ICM-42605 datasheet (DS-000292, typical): noise 3.8 mdps/sqrt(Hz) and 70 ug/sqrt(Hz);
    # datasheet-typical for the ICM-426xx family: initial zero-rate offset 0.5 deg/s, zero-g offset 20 mg,
    # sensitivity error 0.5 %, cross-axis sensitivity 1 %. The datasheet gives no in-run bias stability;
    # assumed for this consumer MEMS class: ADEV floors 5 deg/h and 60 ug, GM correlation time 100 s. The
    # 16-bit rate LSB (7.6 mdps at +-125 deg/s) is below the per-sample noise, so no quantization is modelled.
    "icm-42605": ImuGrade(
        gyro_bias=0.5 * DEG,
        gyro_bias_instability=gm_sigma_from_adev_floor(5.0 * DEG_PER_H),
        gyro_bias_tau=100.0,
        gyro_arw=3.8e-3 * DEG_PER_S_PER_SQRT_HZ,
        gyro_scale=0.005,
        gyro_nonorth=0.01,
        gyro_range=125.0 * DEG,
        accel_bias=20.0 * MG,
        accel_bias_instability=gm_sigma_from_adev_floor(60.0 * UG),
        accel_bias_tau=100.0,
        accel_vrw=70.0 * UG_PER_SQRT_HZ,
        accel_scale=0.005,
        accel_nonorth=0.01,
        accel_range=16.0 * G0,
    ),
    # The error-free IMU: the round-trip reference (an exact mechanization reproduces the truth).
    "ideal": ImuGrade(),
}


def grade(name: str) -> ImuGrade:
    """The preset called `name`; KeyError with the list of valid names otherwise."""
    try:
        return GRADES[name]
    except (KeyError, TypeError):
        raise KeyError(f"unknown IMU grade {name!r}; valid grades: {', '.join(GRADES)}") from None
