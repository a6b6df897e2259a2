"""Device-side logic (register map, control protocol, frame scheduler); grows with the device issue."""
