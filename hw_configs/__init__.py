"""Sensor descriptions as YAML data, read by ``rollcam.sim.hwconfig``."""
