"""Camera sources, one module per URI scheme."""
