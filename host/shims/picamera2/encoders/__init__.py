"""picamera2's encoders are not part of rollcam's stand-in: importing them says so (docs/picamera2.md)."""

raise ImportError("rollcam's picamera2 stand-in has no encoders (H.264, MJPEG, JPEG recording is not emulated); "
                  "capture frames with capture_array/capture_request and encode them yourself "
                  "(see rollcam's docs/picamera2.md)")
