"""Shearer positioning: 001's SINS/odometer filter with CPOEM and RTS, 003's federated magnetometer filter, 004's rail kinematics model."""
