"""Strapdown inertial navigation (000): mechanization, coning/sculling, coarse and fine alignment, installation errors
and the closed-loop alignment at rest, the linear error model."""
