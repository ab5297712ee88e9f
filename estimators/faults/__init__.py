"""Fault detection: chi-square and SPRT detectors on innovations, push-ram levels and per-support ram checks."""
