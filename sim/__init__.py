"""Simulation: scenes, per-row rendering, sensor timing, ground truth."""
