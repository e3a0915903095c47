"""Drive simulator: roads, vehicle dynamics, a rendered camera, IMU and CAN, with ground truth."""
