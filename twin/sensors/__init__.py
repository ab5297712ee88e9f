"""Sensor models: every stream of the sensor log drawn from the truth, with injected faults."""
