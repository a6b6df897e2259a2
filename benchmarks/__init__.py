"""Speed-versus-error studies behind ``rollcam bench``."""
