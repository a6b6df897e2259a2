"""``rollcam gadget`` without a kernel: the configfs tree it writes (into a temporary folder) and its answers to
the UVC class requests the kernel passes up (pure functions of the request bytes).

The kernel test (``test_kernel_gadget.py``) runs the same code against Linux's usb_f_uvc in a guest."""

from __future__ import annotations

import ctypes
import errno
import json
import logging
import os
import struct
from pathlib import Path
from typing import ClassVar

import pytest
from helpers import wait_for
from rollcam.emu.gadget import Gadget, GadgetError, SetupHandler, Tree, find_udc, layout, uapi
from rollcam.emu.gadget.server import CLOCK_HZ
from rollcam.emu.uvc import (
    FirmwareProducer,
    Probe,
    UVCFunction,
    iso_payload_size,
    offered_formats,
    parse_streaming,
)
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.descriptors import split_descriptors
from rollcam.emu.uvc.requests import VideoControls
from rollcam.emu.v4l2.abi import REQUESTS, Event
from rollcam.firmware.camera import FirmwareCamera
from uvc_fakes import FakeProducer

FOURCCS = ("YUYV", "NV12", "MJPG")


class ConfigfsTree(Tree):
    """A temporary folder that behaves as configfs where it matters: a folder comes with its default groups
    (the folders configfs makes with it) and goes with them and with the attribute files in it; a step whose
    path ends with ``fail_on`` fails with ``error``. ``calls`` records what was done."""

    DEFAULTS: ClassVar[dict[str, tuple[str, ...]]] = {
        "c.1": ("strings",), "uvc.0": ("control/class/fs", "control/class/ss", "control/header",
                                       "streaming/class/fs", "streaming/class/hs", "streaming/class/ss",
                                       "streaming/header", "streaming/mjpeg", "streaming/uncompressed")}
    GADGET_DEFAULTS = ("configs", "functions", "strings")

    def __init__(self, fail_on: str | None = None, error: int = errno.EBUSY) -> None:
        self.fail_on, self.error = fail_on, error
        self.calls: list[tuple[str, str]] = []

    def _defaults(self, path: Path) -> tuple[str, ...]:
        top = path.parent.name not in ("functions", "configs", "strings", "uncompressed", "mjpeg") and \
            path.parent.parent.name not in ("strings", "uncompressed", "mjpeg", "header", "class")
        return self.DEFAULTS.get(path.name, self.GADGET_DEFAULTS if top and path.name != "h" else ())

    def _maybe_fail(self, what: str, path: Path) -> None:
        self.calls.append((what, str(path)))
        if self.fail_on is not None and str(path).endswith(self.fail_on):
            raise OSError(self.error, os.strerror(self.error), str(path))

    def mkdir(self, path: Path) -> None:
        self._maybe_fail("mkdir", path)
        super().mkdir(path)
        for sub in self._defaults(path):
            (path / sub).mkdir(parents=True)

    def write(self, path: Path, data: str | bytes) -> None:
        self._maybe_fail("write", path)
        super().write(path, data)

    def symlink(self, target: Path, path: Path) -> None:
        self._maybe_fail("link", path)
        super().symlink(target, path)

    def rmdir(self, path: Path) -> None:
        self.calls.append(("rmdir", str(path)))
        for p in path.iterdir():
            if p.is_file() and not p.is_symlink():
                p.unlink()
        subs = {"/".join(sub.split("/")[:n]) for sub in self._defaults(path) for n in range(1, sub.count("/") + 2)}
        for sub in sorted(subs, key=lambda s: s.count("/"), reverse=True):
            (path / sub).rmdir()  # not empty (a link, a format left in it): configfs refuses too
        super().rmdir(path)


@pytest.fixture
def producer() -> FakeProducer:
    return FakeProducer(sizes=((640, 480), (320, 240)), intervals_ns=(33_333_333, 66_666_667))


def test_the_configfs_tree_says_what_the_emulated_cameras_descriptors_say(tmp_path, producer):
    """Formats, frame sizes, intervals, bit rates and buffer sizes written to configfs equal the descriptors
    rollcam's own USB camera sends for the same producer: one table behind both."""
    formats, _ = offered_formats(producer, FOURCCS)
    with Gadget(layout(formats, udc="usbip-vudc.0"), tmp_path, ConfigfsTree()) as g:
        fn = tmp_path / "rollcam" / "functions" / "uvc.0"
        assert (tmp_path / "rollcam" / "idVendor").read_text() == "0x1209\n"
        assert (tmp_path / "rollcam" / "idProduct").read_text() == "0x0001\n"
        assert (tmp_path / "rollcam" / "strings" / "0x409" / "product").read_text() == "rollcam emulated UVC camera\n"
        assert (tmp_path / "rollcam" / "UDC").read_text() == "usbip-vudc.0\n"
        assert (fn / "streaming_maxpacket").read_text() == "3072\n"
        assert len("rollcam emulated UVC camera: " + (fn / "function_name").read_text().strip()) <= 31
        assert (fn / "streaming" / "uncompressed" / "nv12" / "guidFormat").read_bytes()[:4] == b"NV12"
        assert (fn / "streaming" / "uncompressed" / "nv12" / "bBitsPerPixel").read_text() == "12\n"
        for speed in ("fs", "hs", "ss"):
            assert os.readlink(fn / "streaming" / "class" / speed / "h") == str(fn / "streaming" / "header" / "h")
        assert os.readlink(tmp_path / "rollcam" / "configs" / "c.1" / "uvc.0") == str(fn)
        assert sorted(p.name for p in (fn / "streaming" / "header" / "h").iterdir()) == ["mjpg", "nv12", "yuyv"]
        # The emulated camera's descriptors, frame by frame (FrameSize, bit rates, buffer size).
        config = UVCFunction(producer).descriptors.configuration
        want = {}
        fourcc, streaming = None, False
        for d in split_descriptors(config):
            if d[1] == C.DT_INTERFACE:
                streaming = d[6] == C.SC_VIDEOSTREAMING
            if not streaming or d[1] != C.CS_INTERFACE:
                continue
            if d[2] in (C.VS_FORMAT_UNCOMPRESSED, C.VS_FORMAT_MJPEG):
                fourcc = "MJPG" if d[2] == C.VS_FORMAT_MJPEG else {b"YUY2": "YUYV"}.get(d[5:9], d[5:9].decode())
            if d[2] in (C.VS_FRAME_UNCOMPRESSED, C.VS_FRAME_MJPEG):
                w, h, lo, hi, buf, default, n = struct.unpack_from("<HHIIIIB", d, 5)
                want[(fourcc, w, h)] = (lo, hi, buf, default, struct.unpack_from(f"<{n}I", d, 26))
        assert len(want) == 6
        for (fourcc, w, h), (lo, hi, buf, default, intervals) in want.items():
            kind = "mjpeg" if fourcc == "MJPG" else "uncompressed"
            f = fn / "streaming" / kind / fourcc.lower() / f"{w}x{h}"
            got = {name: (f / name).read_text() for name in ("wWidth", "wHeight", "dwMinBitRate", "dwMaxBitRate",
                                                            "dwMaxVideoFrameBufferSize", "dwDefaultFrameInterval",
                                                            "dwFrameInterval")}
            assert got == {"wWidth": f"{w}\n", "wHeight": f"{h}\n", "dwMinBitRate": f"{lo}\n",
                           "dwMaxBitRate": f"{hi}\n", "dwMaxVideoFrameBufferSize": f"{buf}\n",
                           "dwDefaultFrameInterval": f"{default}\n",
                           "dwFrameInterval": "".join(f"{i}\n" for i in intervals)}
        assert parse_streaming(config).formats == formats
        assert g.bound
    assert list(tmp_path.iterdir()) == []  # closed: every step undone


def test_usb_ids_and_strings_follow_the_identity(tmp_path, producer):
    from rollcam.emu.uvc import DeviceIdentity

    formats, _ = offered_formats(producer, ("MJPG",))
    steps = layout(formats, DeviceIdentity(vendor_id=0x046D, product_id=0x0825, serial="42"), gadget="cam2")
    with Gadget(steps, tmp_path, ConfigfsTree()):
        assert (tmp_path / "cam2" / "idVendor").read_text() == "0x046d\n"
        assert (tmp_path / "cam2" / "idProduct").read_text() == "0x0825\n"
        assert (tmp_path / "cam2" / "strings" / "0x409" / "serialnumber").read_text() == "42\n"
        assert not (tmp_path / "cam2" / "UDC").exists()  # no UDC given: configured, not bound
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("fail_on", "error", "message"), [
    ("/UDC", errno.EBUSY, "USB device controller 'usbip-vudc.0' refused the gadget"),
    ("functions/uvc.0", errno.ENOENT, "modprobe usb_f_uvc"),
    ("streaming/class/hs/h", errno.EINVAL, "streaming/class/hs/h: Invalid argument"),
])
def test_an_error_half_way_leaves_nothing_behind_and_names_the_step(tmp_path, producer, fail_on, error, message):
    formats, _ = offered_formats(producer, FOURCCS)
    tree = ConfigfsTree(fail_on, error)
    with pytest.raises(GadgetError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Gadget(layout(formats, udc="usbip-vudc.0"), tmp_path, tree).open()
    assert list(tmp_path.iterdir()) == []
    made = [c for c in tree.calls if c[0] in ("mkdir", "link")]
    assert made  # it got some way before failing


def test_teardown_runs_in_reverse_order_unbinding_first(tmp_path, producer):
    formats, _ = offered_formats(producer, ("YUYV",))
    tree = ConfigfsTree()
    g = Gadget(layout(formats, udc="dwc2"), tmp_path, tree).open()
    tree.calls.clear()
    g.close()
    g.close()  # twice is harmless
    assert tree.calls[0] == ("write", str(tmp_path / "rollcam" / "UDC"))
    assert (tmp_path / "rollcam" / "UDC").exists() is False
    assert list(tmp_path.iterdir()) == []


def test_missing_configfs_an_existing_gadget_and_udcs_are_named(tmp_path, producer):
    formats, _ = offered_formats(producer, ("YUYV",))
    with pytest.raises(GadgetError, match="modprobe libcomposite"):
        Gadget(layout(formats), tmp_path / "nope").open()
    (tmp_path / "rollcam").mkdir()
    with pytest.raises(GadgetError, match="exists already"):
        Gadget(layout(formats), tmp_path).open()
    assert (tmp_path / "rollcam").is_dir()  # someone else's: left alone
    udcs = tmp_path / "udc"
    udcs.mkdir()
    with pytest.raises(GadgetError, match=r"no USB device controller in .*dtoverlay=dwc2"):
        find_udc(None, udcs)
    (udcs / "fe980000.usb").mkdir()
    assert find_udc(None, udcs) == "fe980000.usb"
    (udcs / "usbip-vudc.0").mkdir()
    with pytest.raises(GadgetError, match=r"several USB device controllers \(fe980000.usb, usbip-vudc.0\)"):
        find_udc(None, udcs)
    with pytest.raises(GadgetError, match="no USB device controller 'dwc2'"):
        find_udc("dwc2", udcs)
    with pytest.raises(GadgetError, match=r"outside 1\.\.3072"):
        layout(formats, max_packet=4096)


# ------------------------------------------------------------------------------------------ SETUP / DATA
def _controls(producer, max_packet: int = 3072) -> VideoControls:
    formats, intervals = offered_formats(producer, FOURCCS)
    return VideoControls(producer, formats, intervals, CLOCK_HZ,
                         lambda frame_bytes, ns: iso_payload_size(frame_bytes, ns, max_packet))


def setup(request_type: int, request: int, selector: int, entity: int, interface: int, length: int) -> bytes:
    """The 8 bytes of a SETUP as the kernel passes it up (struct usb_ctrlrequest)."""
    return struct.pack("<BBHHH", request_type, request, selector << 8, (entity << 8) | interface, length)


GET, SET = 0xA1, 0x21  # class, interface, IN / OUT


def test_probe_and_commit_negotiate_and_program_the_camera(producer):
    handler = SetupHandler(_controls(producer))
    cur = handler.setup(setup(GET, C.GET_CUR, C.VS_PROBE_CONTROL, 0, 1, 48))
    probe = Probe.unpack(cur)
    assert (probe.bFormatIndex, probe.bFrameIndex, probe.dwMaxVideoFrameSize) == (1, 1, 640 * 480 * 2)
    assert probe.dwMaxPayloadTransferSize == 640 * 480 * 2 * 30 // 8000 + 12 + 1  # a frame over 267 microframes
    assert iso_payload_size(640 * 480 * 2, 8_333_333, 3072) == 3072  # capped at the packet: uvcvideo finds an alt
    assert probe.dwClockFrequency == CLOCK_HZ
    assert Probe.unpack(handler.setup(setup(GET, C.GET_MAX, C.VS_PROBE_CONTROL, 0, 1, 34)) + bytes(14))
    assert handler.setup(setup(GET, C.GET_LEN, C.VS_PROBE_CONTROL, 0, 1, 2)) == b"\x30\x00"
    assert handler.setup(setup(GET, C.GET_INFO, C.VS_COMMIT_CONTROL, 0, 1, 1)) == b"\x03"
    # SET_CUR: the SETUP is answered with the length to receive; the DATA event carries the probe.
    want = Probe(bmHint=1, bFormatIndex=2, bFrameIndex=2, dwFrameInterval=666667)
    assert handler.setup(setup(SET, C.SET_CUR, C.VS_PROBE_CONTROL, 0, 1, 26)) == bytes(26)
    handler.data(want.pack(26))
    got = Probe.unpack(handler.setup(setup(GET, C.GET_CUR, C.VS_PROBE_CONTROL, 0, 1, 26)))
    assert (got.bFormatIndex, got.bFrameIndex, got.dwFrameInterval) == (2, 2, 666667)
    assert got.dwMaxVideoFrameSize == 320 * 240 * 3 // 2  # NV12
    assert handler.setup(setup(SET, C.SET_CUR, C.VS_COMMIT_CONTROL, 0, 1, 26)) == bytes(26)
    handler.data(got.pack(26))
    committed = handler.controls.committed
    assert (committed.fourcc, committed.width, committed.height) == ("NV12", 320, 240)
    assert producer.configured[-1] == (320, 240, 66_666_667)
    assert handler.stalls == 0


def test_unknown_requests_are_stalled_and_logged_once(producer, caplog):
    handler = SetupHandler(_controls(producer))
    contrast = setup(GET, C.GET_INFO, 0x03, C.UNIT_PROCESSING, 0, 1)
    with caplog.at_level(logging.WARNING, logger="rollcam.gadget"):
        assert handler.setup(contrast) is None
        assert handler.setup(contrast) is None
    assert len([r for r in caplog.records if "refused" in r.getMessage()]) == 1
    assert handler.stalls == 2
    # The request error code control says why (UVC 1.5 4.2.1.2).
    code = handler.setup(setup(GET, C.GET_CUR, C.VC_REQUEST_ERROR_CODE_CONTROL, 0, 0, 1))
    assert code == bytes((C.ERR_INVALID_CONTROL,))
    assert handler.setup(setup(SET, C.SET_CUR, 0x03, C.UNIT_PROCESSING, 0, 2)) is None  # before any data stage
    brightness = (C.PU_BRIGHTNESS_CONTROL, C.UNIT_PROCESSING, 0)  # Linux 6.1's function always advertises it
    assert handler.setup(setup(GET, C.GET_INFO, *brightness, 1)) == bytes((C.INFO_GET,))  # read-only
    assert [handler.setup(setup(GET, r, *brightness, 2)) for r in (C.GET_MIN, C.GET_MAX, C.GET_DEF, C.GET_RES)] \
        == [b"\0\0", b"\0\0", b"\0\0", b"\1\0"]
    assert handler.setup(setup(SET, C.SET_CUR, *brightness, 2)) is None
    assert handler.pending is None
    assert handler.setup(setup(0x80, C.REQ_GET_DESCRIPTOR, 1, 0, 0, 18)) is None  # not a class request
    assert handler.setup(setup(GET, C.SET_CUR, C.VS_PROBE_CONTROL, 0, 1, 26)) is None  # SET_CUR with IN bit
    assert handler.setup(setup(GET, C.GET_CUR, C.VS_PROBE_CONTROL, 0, 7, 26)) is None  # no such interface
    assert handler.setup(setup(GET, 0x99, C.VS_PROBE_CONTROL, 0, 1, 26)) is None  # no such request


def test_a_refused_data_stage_sets_the_error_code(producer):
    handler = SetupHandler(_controls(producer))
    assert handler.setup(setup(SET, C.SET_CUR, C.VS_COMMIT_CONTROL, 0, 1, 26)) == bytes(26)
    handler.data(Probe(bFormatIndex=9, bFrameIndex=1, dwFrameInterval=333333).pack(26))
    assert handler.controls.committed is None
    assert handler.setup(setup(GET, C.GET_CUR, C.VC_REQUEST_ERROR_CODE_CONTROL, 0, 0, 1)) == \
        bytes((C.ERR_OUT_OF_RANGE,))
    handler.data(b"\x00")  # a DATA with no SET_CUR pending is ignored
    assert handler.stalls == 1


def test_interfaces_are_the_functions_own_numbers(producer):
    handler = SetupHandler(_controls(producer), interfaces=(2, 3))
    assert handler.setup(setup(GET, C.GET_CUR, C.VS_PROBE_CONTROL, 0, 3, 48)) is not None
    assert handler.setup(setup(GET, C.GET_CUR, C.VS_PROBE_CONTROL, 0, 1, 48)) is None


def test_exposure_and_gain_requests_reach_the_firmware_controls():
    camera = FirmwareCamera("imx219", size=(640, 480))
    handler = SetupHandler(_controls(FirmwareProducer(camera)))
    exposure = (C.CT_EXPOSURE_TIME_ABSOLUTE_CONTROL, C.TERMINAL_CAMERA, 0)
    assert handler.setup(setup(GET, C.GET_INFO, *exposure, 1)) == bytes((C.INFO_GET | C.INFO_SET,))
    assert handler.setup(setup(SET, C.SET_CUR, *exposure, 4)) == bytes(4)
    handler.data((50).to_bytes(4, "little"))  # 5 ms in 100 us units
    assert abs(camera.spec.settings.exposure_ns - 5_000_000) < camera.spec.settings.timing.line_offset_ns(1)
    gain = (C.PU_GAIN_CONTROL, C.UNIT_PROCESSING, 0)
    assert handler.setup(setup(SET, C.SET_CUR, *gain, 2)) == bytes(2)
    handler.data((400).to_bytes(2, "little"))
    assert camera.spec.gain == pytest.approx(4.0, rel=0.05)
    assert int.from_bytes(handler.setup(setup(GET, C.GET_CUR, *gain, 2)), "little") == round(camera.spec.gain * 100)
    assert handler.stalls == 0


def test_the_kernel_interface_layouts_are_linux_6_1s():
    assert uapi.UVCIOC_SEND_RESPONSE == 0x40405501  # _IOW('U', 1, struct uvc_request_data)
    assert REQUESTS["DQEVENT"][0] == 0x80885659 and ctypes.sizeof(Event) == 136
    assert REQUESTS["SUBSCRIBE_EVENT"][0] == 0x4020565A
    assert uapi.UVC_EVENT_SETUP == 0x08000004  # what KERNEL.md saw arrive on the node
    assert uapi.response(None).length == -1
    r = uapi.response(b"\x01\x02")
    assert r.length == 2 and bytes(r.data[:2]) == b"\x01\x02"
    event = Event(type=uapi.UVC_EVENT_DATA)
    ctypes.memmove(event.u.data, struct.pack("<i", 3) + b"abc", 7)
    assert uapi.event_data(event) == b"abc"
    ctypes.memmove(event.u.data, setup(GET, C.GET_CUR, 1, 0, 1, 26), 8)
    assert uapi.event_request(event) == setup(GET, C.GET_CUR, 1, 0, 1, 26)


# ------------------------------------------------------------------------------------------ serve()
class _Door:
    """A transport with no fault statistics (as the gadget is), whose loop may have died."""

    def __init__(self, error: Exception | None = None) -> None:
        self.error, self.closed = error, False

    def check(self) -> None:
        if self.error is not None:
            raise self.error

    def close(self) -> None:
        self.closed = True


def test_serve_runs_a_transport_without_fault_stats_and_ends_when_its_loop_dies(capsys):
    """`rollcam gadget` used to end every run with AttributeError: 'GadgetServer' object has no attribute
    'fault_stats' (serve() asked every transport for it, faults or not)."""
    import argparse

    from rollcam.common.errors import DeviceError
    from rollcam.common.faults import FaultPlan
    from rollcam.host.servers.emulate import Running, serve

    def run(door: _Door) -> int:
        args = argparse.Namespace(sensor="imx219", json=False, duration=0.0, faults=FaultPlan())
        starter = lambda *_: Running("door", door, ["door: here"], {}, uses_pump=False)  # noqa: E731
        return serve(args, {"size": "640x480"}, [("door", starter)], "rollcam gadget")

    quiet = _Door()
    assert run(quiet) == 0 and quiet.closed
    assert "door: here" in capsys.readouterr().out
    dead = _Door(DeviceError("the gadget's loop died"))
    with pytest.raises(DeviceError, match="loop died"):
        run(dead)
    assert dead.closed


# ------------------------------------------------------------------------------------------ the command line
@pytest.mark.parametrize(("argv", "words"), [
    (["gadget", "imx219", "--usb-id", "logitech"], "gadget: argument --usb-id: 'logitech' is not VID:PID in hex"),
    (["gadget", "imx219", "--fps", "fast"], "gadget: argument --fps: 'fast' is invalid: expected a number > 0"),
    (["gadget", "imx219", "--http", "host"], "gadget: argument --http: expected HOST:PORT, got 'host'"),
    (["gadget"], "the following arguments are required: SENSOR"),
])
def test_gadget_usage_errors_are_one_line_and_exit_2(capsys, argv, words):
    from rollcam.host.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("rollcam: error: ") and words in err[0], err


def test_a_missing_usb_device_controller_is_named_and_exit_1(capsys):
    from rollcam.host.cli import main

    assert main(["gadget", "imx219", "--udc", "no-such-udc.0", "--size", "640x480"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "no USB device controller 'no-such-udc.0' in /sys/class/udc" in err[0], err


def test_gadget_takes_emulates_camera_and_door_flags():
    from rollcam.host.cli import build_parser
    from rollcam.host.commands.emulate import camera_options

    parser, _ = build_parser()
    args = parser.parse_args(["gadget", "imx219", "--fps", "15", "--scene", "flat", "--serial", "--http", ":0",
                              "--udc", "fe980000.usb", "--usb-id", "046d:0825"])
    assert args.run.__module__ == "rollcam.host.commands.gadget"
    assert camera_options(args) == {"fps": "15", "scene": "flat"}
    assert (args.udc, args.usb_id, args.serial, args.http) == ("fe980000.usb", (0x046D, 0x0825), True,
                                                               ("127.0.0.1", 0))


def test_the_functions_node_is_found_under_its_controller_without_opening_any(tmp_path):
    """Opening a UVC function's node connects its gadget (closing disconnects it): the node is found in sysfs."""
    from rollcam.emu.gadget.device import udc_nodes

    devices, video = tmp_path / "devices", tmp_path / "video4linux"
    for name, parent in (("video0", "pci0000:00/usb1/1-1/1-1:1.0"), ("video2", "platform/usbip-vudc.0/gadget.0"),
                         ("video3", "platform/soc/fe980000.usb/gadget.0")):
        (devices / parent).mkdir(parents=True)
        (video / name).mkdir(parents=True)
        (video / name / "device").symlink_to(devices / parent)
    (video / "video9").mkdir()  # no device link (being removed): skipped
    assert udc_nodes("usbip-vudc.0", video) == ["/dev/video2"]
    assert udc_nodes("fe980000.usb", video) == ["/dev/video3"]
    assert udc_nodes("dwc2", video) == []


# ------------------------------------------------------------------------------------------ the stream loop
class FakeFunction:
    """Linux 6.1's UVC function node as ``GadgetStream`` uses it, in ioctls over a plain file (``path``) that
    stands in for the buffers' memory. ``host_left()`` does what a host's SET_INTERFACE 0 does: the function
    gives its requests back with -ESHUTDOWN, after which QBUF fails with ENODEV until the queue is stopped
    (``uvcg_queue_enable(0)`` clears UVC_QUEUE_DISCONNECTED)."""

    def __init__(self, path: Path, buffer_bytes: int) -> None:
        self.path, self.size = path, -(-buffer_bytes // 4096) * 4096
        self.disconnected = False
        self.calls: list[str] = []
        self.queued: list[int] = []

    def host_left(self) -> None:
        self.disconnected = True

    def __call__(self, fd: int, name: str, arg):
        self.calls.append(name)
        if name == "REQBUFS" and arg.count:
            arg.count = 4
            os.truncate(self.path, 4 * self.size)
        elif name == "QUERYBUF":
            arg.length, arg.m.offset = self.size, arg.index * self.size
        elif name == "QBUF":
            if self.disconnected:
                raise OSError(errno.ENODEV, os.strerror(errno.ENODEV))
            self.queued.append(arg.bytesused)
        elif name == "DQBUF":
            raise OSError(errno.EAGAIN, os.strerror(errno.EAGAIN))
        elif name == "STREAMOFF":
            self.disconnected = False
        return arg


def test_a_host_that_leaves_the_stream_before_its_streamoff_event_stops_it_and_the_next_stream_runs(
        tmp_path, producer):
    """In the kernel suite the gadget died with OSError(19) at a stream-off: the host's SET_INTERFACE 0 made the
    function refuse QBUF (ENODEV) before the STREAMOFF event reached the loop, which queued the next frame."""
    from rollcam.emu.gadget.device import GadgetStream

    node = tmp_path / "video0"
    node.write_bytes(b"")
    fake = FakeFunction(node, 640 * 480 * 2)
    log = tmp_path / "frames.jsonl"
    stream = GadgetStream(str(node), producer, _controls(producer), frame_log=log, ioctl=fake)
    try:
        stream._event(Event(type=uapi.UVC_EVENT_STREAMON))
        assert stream.queue is not None
        producer.clock.t += 10**9  # frames are due: the renderer makes the newest
        fake.host_left()
        wait_for(lambda: stream.queue is None or (stream._feed() and stream.queue is None),
                 what="the loop to stop the stream the host left")
        assert fake.calls[-2:] == ["STREAMOFF", "REQBUFS"] and fake.queued == []
        assert not log.read_text()  # a frame the function refused is no frame sent
        stream._event(Event(type=uapi.UVC_EVENT_STREAMOFF))  # the event arrives late: nothing more to stop
        stream._event(Event(type=uapi.UVC_EVENT_STREAMON))
        producer.clock.t += 10**9
        wait_for(lambda: stream._feed() and fake.queued, what="the next stream's first frame")
        assert fake.queued[0] == 640 * 480 * 2 and stream.stats.streams == 2
    finally:
        stream.run(lambda: True)  # stops the stream and closes the node
    assert fake.calls[-2:] == ["STREAMOFF", "REQBUFS"]
    assert [json.loads(line)["bytes"] for line in log.read_text().splitlines()] == fake.queued
