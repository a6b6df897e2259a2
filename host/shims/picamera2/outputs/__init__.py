"""picamera2's outputs are not part of rollcam's stand-in: importing them says so (docs/picamera2.md)."""

raise ImportError("rollcam's picamera2 stand-in has no outputs (FileOutput, FfmpegOutput, CircularOutput: "
                  "recording is not emulated); see rollcam's docs/picamera2.md")
