"""Test-session set-up shared by every test module."""

from __future__ import annotations

import contextlib

import pytest

# depthai must be loaded before faster_coco_eval in one process (a pybind11 clash breaks depthai host-node
# subclasses otherwise; see rollcam.host.integrations.oaknode). The evaluation tests import faster_coco_eval first.
with contextlib.suppress(Exception):
    from rollcam.host.sources.oak import import_depthai

    import_depthai()


@pytest.fixture(scope="session")
def kernel_guest(tmp_path_factory):
    """One booted guest kernel (``guest.Guest``) for every kernel test of the session; skips, naming what is
    missing, on a machine without QEMU, busybox-static, the USB/IP and V4L2 tools or the kernel cache."""
    import guest

    why = guest.missing()
    if why:
        pytest.skip(f"the kernel tests need: {why}")
    g = guest.Guest(tmp_path_factory.mktemp("guest"))
    yield g
    g.close()
