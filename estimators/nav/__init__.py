"""Navigation math: the WGS-84 Earth, rotations, the geomagnetic field and magnetic heading."""
