"""Scenario files of every kind: the section base and the TOML reader, face scenarios and the one loader, the
instrument sections, 000's SINS experiments, 002's turntable, IMU grades."""
