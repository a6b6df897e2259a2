"""Frames to files: ``rollcam capture`` (images, ``frames.jsonl``, recordings), ``rollcam demo``, the one video
writer, image files and a capture's IMU and calibration files."""
