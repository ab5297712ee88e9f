"""Shearer positioning on a sensor log, the methods by name in methods (METHODS, estimate):

* 001, SINS/odometer filter with CPOEM fixes and RTS smoothing: positioning (kernel odometer_filter; cpoem,
  position_fixes);
* 003, adaptive federated SINS/odometer/magnetometer filter and its centralized baseline: adaptive_federated_mag
  (kernel federated_filter);
* 004, federated SINS/odometer + SINS/rail-kinematics-model filter with fault detection and isolation:
  rail_kinematics (kernel rail_fix_update; face_line for the face survey's points).

Shared: config (Config and what it holds), prepare (the log resampled for the filters), federated (the 003/004
kernel run pass by pass), solution (a method's output and its columns).
"""
