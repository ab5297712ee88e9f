"""The S-shaped snake of the AFC between pushed and unpushed pans.

The pans of a snake of n pans turn by equal bends: their yaws ramp up one step per pan over the first half
and back down over the second (1, 2, ..., n/2, n/2, ..., 2, 1 steps), so no joint bends by more than one
step. The lateral offset of the joints is the running sum of pan_length * sin(yaw).
"""

import numpy as np


def yaw_steps(snake_pans: int) -> np.ndarray:
    """Yaw of each snake pan in units of one bend step (snake_pans values)."""
    half = snake_pans // 2
    return np.concatenate([np.arange(1, half + 1), np.arange(snake_pans - half, 0, -1)]).astype(float)


def joint_offsets(snake_pans: int, pan_length_m: float, step_rad: float) -> np.ndarray:
    """Lateral offset of the snake's joints 0..snake_pans [m] for a bend step of step_rad."""
    return np.concatenate([[0.0], np.cumsum(pan_length_m * np.sin(step_rad * yaw_steps(snake_pans)))])


BEND_FRACTION = 0.75
"""Share of the bend limit a snake may use; the rest is left for the face's own bends (see
twin.face.layout.INITIAL_BEND_FRACTION), so the two together stay within the limit."""


def capacity_m(snake_pans: int, pan_length_m: float, bend_limit_rad: float) -> float:
    """Largest push the snake (fractions) takes up with no bend over BEND_FRACTION of the limit.

    Bisected below the offset of equal bends of that size: the small bends' shape stretched to it bends its steepest
    joint more (0.2 % on the default face), as sin(yaw), not yaw, grows by equal steps towards the snake's middle.
    """
    step = BEND_FRACTION * bend_limit_rad
    rise = np.diff(fractions(snake_pans)) / pan_length_m  # sin(yaw) per metre of push
    low, high = 0.0, float(joint_offsets(snake_pans, pan_length_m, step)[-1])
    for _ in range(40):
        push = 0.5 * (low + high)
        yaw = np.arcsin(np.minimum(push * rise, 1.0))
        low, high = (push, high) if np.abs(np.diff(yaw, prepend=0.0, append=0.0)).max() <= step else (low, push)
    return low


def fractions(snake_pans: int) -> np.ndarray:
    """Normalised push of the joints 0..snake_pans (0 at the snake head, 1 at its tail), small bends."""
    offsets = joint_offsets(snake_pans, 1.0, 1e-3)
    return offsets / offsets[-1]
