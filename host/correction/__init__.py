"""Rolling-shutter correction on the host (``gyro`` from the IMU's samples, ``flow`` from optical flow) and the
calibration it needs (``calibrate``: line time and camera-IMU time offset from a capture)."""
