"""Emulated device interfaces (V4L2-like, UVC, USB/IP, serial, HTTP); grows with the device issue."""
