"""rollcam inside other frameworks: a labgrid resource and driver (``labgrid``), a depthai host node
(``oaknode``)."""
