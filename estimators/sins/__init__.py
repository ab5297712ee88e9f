"""Strapdown inertial navigation: mechanization, coning/sculling, coarse and fine alignment, installation errors, the linear error model (000)."""
