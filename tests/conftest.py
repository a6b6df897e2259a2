"""Test-session set-up shared by every test module."""

from __future__ import annotations

import contextlib

# depthai must be loaded before faster_coco_eval in one process (a pybind11 clash breaks depthai host-node
# subclasses otherwise; see rollcam.host.oaknode). The evaluation tests import faster_coco_eval first.
with contextlib.suppress(Exception):
    from rollcam.host.sources.oak import import_depthai

    import_depthai()
