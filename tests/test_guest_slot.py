"""The kernel suite's guest keeping (``guest.GuestSlot``, ``guest.find_oops``), without booting a kernel: one guest
kernel bug must cost the test that met it, not every kernel test after it."""

from __future__ import annotations

from pathlib import Path

import guest

# the lines 6.1's uvcvideo printed on the CI guest when it broke at a detach while streaming (trimmed)
BROKEN = """\
[   91.203110] usb 1-1: USB disconnect, device number 3
[   91.231877] ------------[ cut here ]------------
[   91.232001] refcount_t: underflow; use-after-free.
[   91.232410] WARNING: CPU: 1 PID: 57 at lib/refcount.c:28 refcount_warn_saturate+0xba/0x110
[   91.240100] Workqueue: uvcvideo uvc_video_copy_data_work [uvcvideo]
[   91.240500] Call Trace:
[   91.240600]  uvc_video_copy_data_work+0x8f/0xd0 [uvcvideo]
"""
SOUND = """\
[    1.000000] Linux version 6.1.0-57-amd64
[    2.100000] usbcore: registered new interface driver uvcvideo
[   12.300000] uvcvideo 1-1:1.0: Found UVC 1.10 device rollcam (1209:0001)
[   30.000000] usb 1-1: USB disconnect, device number 2
rollcam-guest: ready
"""


def test_find_oops_quotes_a_broken_kernel_with_its_trace_and_passes_a_sound_one():
    crash = guest.find_oops(SOUND + BROKEN)
    assert crash is not None
    assert "refcount_t: underflow" in crash and "uvc_video_copy_data_work" in crash
    assert "Linux version" not in crash  # the lines around it, not the whole boot
    assert guest.find_oops(SOUND) is None
    assert guest.find_oops("[ 5.0] kernel BUG at lib/list_debug.c:62!\ninvalid opcode: 0000 [#1]") is not None


class FakeGuest:
    def __init__(self, workdir: Path) -> None:
        self.workdir = workdir
        self.broken = False
        self.closed = False

    def sound(self) -> bool:
        return not (self.broken or self.closed)

    def close(self) -> None:
        self.closed = True


def test_the_slot_keeps_a_sound_guest_and_boots_a_fresh_one_after_a_broken_one(tmp_path):
    folders = iter(tmp_path / str(n) for n in range(10))
    slot = guest.GuestSlot(lambda: next(folders), boot=FakeGuest)
    first = slot.get()
    assert slot.get() is first and slot.boots == 1
    first.broken = True
    second = slot.get()
    assert second is not first and first.closed and slot.boots == 2
    assert second.workdir != first.workdir  # a folder of its own: the broken guest's console stays readable
    slot.close()
    assert second.closed
