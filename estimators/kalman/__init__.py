"""Generic Kalman machinery: the RTS smoother, federated fusion, innovation-based noise estimation."""
