"""Self-calibration from a drive (``roadpreview calibrate``): the forward direction t and the
horizon, the IMU-to-camera rotation and the camera-IMU time offset.

The estimation math is in pure modules over arrays (`motion`, `forward`, `timing`,
`rotation`); `drive` reads a drive's sources into those arrays and `result` writes and
prints what was found (``docs/calibration.md``).
"""
