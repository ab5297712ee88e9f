"""The shearer's vibration as the IMU feels it: sums of sines (a drum tone and a pick tone per machine state, random
phases per axis) whose amplitudes follow the machine's state (idle, cutting coal, cutting rock) through a smooth
envelope. twin.sensors.imu integrates them into the increments.

The envelope of a sample reads the machine states up to ENVELOPE_S to either side, and is computed in integers,
so a chunk of the run (with that halo) gives the whole run's values bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from twin.config.imu_grades import G0
from twin.config.scenario import Scenario
from twin.config.sensors import VibrationState
from twin.face.haulage import STOPPED

# Machine states of the vibration model.
IDLE, COAL, ROCK = range(3)

VIBRATION_STREAM = 1000
"""Key of the run's vibration generator, np.random.default_rng([scn.seed, VIBRATION_STREAM]): the vibration's
phases belong to the machine's motion, drawn once per run, not per Monte Carlo trial."""
ENVELOPE_S = 0.5
"""Length [s] of each of the two boxcars that smooth the machine state into the vibration envelope."""


@dataclass(frozen=True)
class VibrationTones:
    """Sines of the sensor's angle phi_i = sum a sin(2 pi f t + p) and displacement u_i, per machine state.

    Shapes: freq_hz (n_states, n_tones); ang_amp and lin_amp (n_states, n_tones, 3) per axis [rad], [m];
    phase_ang and phase_lin (3, n_tones) [rad]."""

    freq_hz: np.ndarray
    ang_amp: np.ndarray
    lin_amp: np.ndarray
    phase_ang: np.ndarray
    phase_lin: np.ndarray


def vibration_tones(states: list[VibrationState], rng: np.random.Generator) -> VibrationTones:
    """Tone amplitudes per state: the drum tone from its displacement and angle amplitudes, the pick tone from
    the band's RMS (a sine of RMS s has amplitude sqrt(2) s: rate amplitude sqrt(2) s is angle amplitude
    sqrt(2) s / (2 pi f), acceleration likewise over (2 pi f)^2)."""
    freq = np.array([[max(st.drum_hz, 1e-3), max(st.pick_hz, 1e-3)] for st in states])
    omega_pick = 2 * np.pi * freq[:, 1]
    ang = np.column_stack([[np.radians(st.drum_angle_deg) for st in states],
                           [np.sqrt(2) * np.radians(st.angular_rms_deg_s) for st in states] / omega_pick])
    lin = np.column_stack([[st.drum_displacement_mm * 1e-3 for st in states],
                           [np.sqrt(2) * st.accel_rms_g * G0 for st in states] / omega_pick ** 2])
    per_axis = np.ones((1, 1, 3))
    return VibrationTones(freq, ang[..., None] * per_axis, lin[..., None] * per_axis,
                          rng.uniform(0, 2 * np.pi, (3, 2)), rng.uniform(0, 2 * np.pi, (3, 2)))


def machine_state(scn: Scenario, phase: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Idle while stopped, cutting coal while moving, cutting rock inside the scenario's rock zones."""
    state = np.where(phase == STOPPED, IDLE, COAL)
    for lo, hi in scn.sensors.vibration.rock_zones_m:
        state = np.where((state == COAL) & (s >= min(lo, hi)) & (s <= max(lo, hi)), ROCK, state)
    return state


def state_envelope(state: np.ndarray, rate_hz: float, n_states: int = 3) -> np.ndarray:
    """Weights (K, n_states) of each machine state's tones for the states (K,) of samples at rate_hz: one-hot per
    sample, smoothed by a boxcar of ENVELOPE_S twice (a triangle reaching width - 1 samples to each side, so the
    envelope's slope is continuous and its curvature bounded).

    The convolution is done in integers (two running sums of the boxcar) and divided once at the end, so a sample's
    weight does not depend on how far the array extends beyond the triangle's reach (a chunk of the run gives the
    whole run's values)."""
    width = max(1, int(ENVELOPE_S * rate_hz))  # 100 samples at 200 Hz
    out = np.empty((len(state), n_states))
    _envelope_kernel(np.ascontiguousarray(state, np.int64), width, out)
    return out


@nb.njit(cache=True)
def _envelope_kernel(state, width, out):
    """state_envelope into out (K, n_states), per state in integers (exact): the one-hot column's boxcar b(j) (the
    full convolution with `width` ones), the same lagging by width, and their difference's running sum, the second
    boxcar; rows width - 1 .. width + K - 2 of the full convolution (np.convolve's mode="same"), over width^2."""
    n_rows, n_states = out.shape
    for i in range(n_states):
        box = lag = tri = 0  # b(j), b(j - width), and the triangle at j
        for j in range(n_rows + width - 1):
            box += (j < n_rows and state[j] == i) - (0 <= j - width and state[j - width] == i)
            lag += (0 <= j - width < n_rows and state[j - width] == i) - (0 <= j - 2 * width and
                                                                          state[j - 2 * width] == i)
            tri += box - lag
            if j >= width - 1:
                out[j - width + 1, i] = tri / (width * width)
