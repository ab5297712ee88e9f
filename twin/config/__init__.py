"""Scenario files: the TOML reader, validated sections, IMU grades."""
