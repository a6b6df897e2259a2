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
def kernel_guests(tmp_path_factory):
    """The session's guest kernel (``guest.GuestSlot``), booted on first use and again after a test broke it;
    skips, naming what is missing, on a machine without QEMU, busybox-static, the USB/IP and V4L2 tools or the
    kernel cache."""
    import guest

    why = guest.missing()
    if why:
        pytest.skip(f"the kernel tests need: {why}")
    slot = guest.GuestSlot(lambda: tmp_path_factory.mktemp("guest"))
    yield slot
    slot.close()


@pytest.fixture
def kernel_guest(kernel_guests):
    """A booted guest kernel (``guest.Guest``), shared by the kernel tests while it stays sound; a test during
    which its kernel oopses fails with the oops, and the next test gets a fresh guest."""
    g = kernel_guests.get()
    yield g
    crash = g.oops()
    if crash is not None:
        pytest.fail(f"the guest kernel broke during this test (the next test boots a fresh guest):\n{crash}",
                    pytrace=False)
