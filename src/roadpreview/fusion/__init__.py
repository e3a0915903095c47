"""Pitch fusion: visual pitch + IMU gyro; back ends chosen by name, modes and fallback."""
