"""One picture, every door: for each transport and each pixel format it offers, the frame decoded as a real client
decodes it equals the emulator's reference frame of the same sequence number, per channel (DESIGN: "One picture
on every door").

**The reference** is made by a second in-process ``FirmwareCamera`` of the device's settings: a frame is a function
of the spec, its sequence number and its start of exposure (``rollcam.firmware.imaging``), so frame ``seq``
exposed from ``start_ns`` of the same spec is byte-identical whichever door it left by. Doors that say which frame
they sent (the in-process ``Frame``, UVC's frame index and PTS, the HTTP part's ``X-Sequence`` and
``X-Timestamp-Ns``) stream a moving street with sensor noise, so a frame of another sequence number or time fails.
A program under ``rollcam run`` does not tell which buffer it kept, so its device shows a still street without
temporal noise (``STILL``): every frame of it is the same picture, which a test checks first. The picamera2
stand-in's arrays are read as a script reads them (its metadata names the frame), in each layout picamera2 gives.
Linux's own USB/IP client needs the vhci-hcd kernel module to attach, so USB/IP is read by rollcam's client here.

**Tolerances**, per channel of the 8-bit BGR picture:

- Wire data (the bytes in the buffer: YUV, RGB, grey, Bayer samples, the JPEG itself) wherever a client hands them
  over unconverted (ffmpeg's ``rawvideo``/``-c copy``, GStreamer caps without a converter, a source's ``Frame``):
  exact.
- A client's own conversion of an uncompressed format: RGB, BGRX and grey exact; YUV (BT.601 limited range, as
  G_FMT says) within ``YUV`` of the reference picture, which is OpenCV's conversion (chroma repeated). OpenCV's
  V4L2 backend converts with that same code: exact. Measured on 640x480 street frames: ffmpeg's swscale rounds
  differently (<= 3 levels, mean |d| <= 1.4) and interpolates NV12's chroma (p99 <= 12 near colour edges);
  GStreamer's videoconvert uses an integer matrix (<= 6 levels, 2-3 darker on average) and interpolates 4:2:2 and
  NV12 chroma (p99 <= 13). A lost chroma plane is off by ~100 (the green picture), swapped U/V by tens.
- MJPEG: a client's decode against the picture before compression, within ``JPEG`` (quality 85: measured mean |d|
  <= 3, p99 <= 22 on the still street; more on the noisy one).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from programs import need
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.preload import LIBRARY_NAME
from rollcam.emu.preload import __file__ as preload_init
from rollcam.emu.usbip import USBIPServer
from rollcam.emu.uvc import FirmwareProducer, UVCFunction
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.imaging import encode
from rollcam.firmware.spec import CameraSpec
from rollcam.host import open_camera, standin_env
from rollcam.host.servers.devnodes import build_camera, program_environment, serving
from rollcam.sim.codecs import JPEG_QUALITY, Levels, codec, preview_frame
from rollcam.sim.frame import Frame

STILL = "emu:imx219?size=640x480&scene=street&speed=static&lamps=off&noise=off&exposure_us=5000"
"""Every frame the same picture (nothing moves, no flicker, no temporal noise); a short exposure, so a client that
raises the frame rate (GStreamer asks for the fastest) leaves it as it is."""
MOVING = "scene=street&speed=fast&seed=3"
"""Walkers at speed and the sensor's noise: frames of other sequence numbers or times differ."""
SIZE = (640, 480)
PROCESSED = ["YUYV", "UYVY", "NV12", "YU12", "BGR3", "RGB3", "XR24", "GREY", "MJPG"]
IMX219_RAW = ["RGGB", "RG10", "pRAA"]
YUV = {"mean": 4.0, "p99": 16.0}
JPEG = {"mean": 4.0, "p99": 32.0}
LIB = Path(preload_init).with_name(LIBRARY_NAME)


@dataclass(frozen=True)
class Tolerance:
    """How far a client's picture may be from the reference, per channel: mean |difference| and 99th percentile."""

    mean: float = 0.0
    p99: float = 0.0


EXACT = Tolerance()


def conversion_tolerance(fourcc: str) -> Tolerance:
    """What a client's own conversion of ``fourcc`` may differ by (see the module docstring)."""
    if fourcc == "MJPG":
        return Tolerance(**JPEG)
    if codec(fourcc).layout is not None and codec(fourcc).layout.packing in ("yuyv", "uyvy", "nv12", "yu12"):
        return Tolerance(**YUV)
    return EXACT


class Reference:
    """The emulator's frames of one spec, made by a second in-process camera."""

    def __init__(self, spec: CameraSpec) -> None:
        self.spec = spec
        self.camera = FirmwareCamera(spec, clock=lambda: 0)

    def frame(self, seq: int, start_ns: int) -> Frame:
        """The render of frame ``seq`` exposed from ``start_ns``: a BGR picture before any wire encoding (MJPG's
        picture before compression), or a raw format's samples."""
        return self.camera.render(FramePlan(seq, self.camera.schedule(start_ns, seq)))

    def wire(self, seq: int, start_ns: int, fourcc: str | None = None) -> np.ndarray:
        """Frame ``seq``'s wire bytes in the spec's format, or in ``fourcc`` for a door that encodes the camera's
        picture in a wire format of its own (HTTP's JPEG, UVC's)."""
        data = encode(self.frame(seq, start_ns), self.spec).data if fourcc is None else \
            codec(fourcc).encode(self.rendered(seq, start_ns))
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)

    def picture(self, seq: int, start_ns: int) -> np.ndarray:
        """The BGR picture a client of the spec's format should show: the wire decoded by the codec table, except
        MJPG's, which is the picture before compression."""
        f = self.frame(seq, start_ns)
        return f.data if self.spec.pixel_format == "MJPG" else preview_frame(encode(f, self.spec))

    def rendered(self, seq: int, start_ns: int) -> np.ndarray:
        """The camera's BGR picture of frame ``seq``, before any wire format (a raw camera's through the preview
        ISP at the sensor's levels): what HTTP and UVC encode."""
        return preview_frame(self.frame(seq, start_ns), Levels.of_sensor(self.spec.sensor))


def assert_same_bytes(got: np.ndarray | bytes, want: np.ndarray, what: str) -> None:
    g = np.frombuffer(got, np.uint8) if isinstance(got, (bytes, bytearray)) else \
        np.ascontiguousarray(got).reshape(-1).view(np.uint8)
    assert g.size == want.size, f"{what}: {g.size} bytes, the reference has {want.size}"
    diff = np.flatnonzero(g != want)
    assert diff.size == 0, f"{what}: {diff.size} bytes differ, first at {diff[0]} ({g[diff[0]]} != {want[diff[0]]})"


def assert_close(got: np.ndarray, want: np.ndarray, tol: Tolerance, what: str) -> None:
    """``got`` within ``tol`` of ``want``, per channel of the BGR picture."""
    assert got.shape == want.shape, f"{what}: shape {got.shape}, the reference's {want.shape}"
    d = np.abs(got.astype(np.int16) - want.astype(np.int16)).reshape(-1, 3)
    mean, p99 = d.mean(axis=0), np.percentile(d, 99, axis=0)
    report = (f"{what}: per channel (B, G, R) mean |d| {mean.round(2).tolist()}, p99 {p99.tolist()}, "
              f"max {d.max(axis=0).tolist()}; signed mean {(got.astype(float) - want).reshape(-1, 3).mean(0).round(2)}")
    assert (mean <= tol.mean).all() and (p99 <= tol.p99).all(), report


def case(fourcc: str, fast: set[str]) -> pytest.param:
    """A format of a door's matrix: in the default suite when ``fast`` names it, else marked slow."""
    return pytest.param(fourcc, id=fourcc.strip(), marks=() if fourcc in fast else pytest.mark.slow)


# ------------------------------------------------------------------------------------------- in-process emu:
@pytest.mark.parametrize("fourcc", [case(f, {"NV12", "YU12", "MJPG", "RG10"}) for f in [*PROCESSED, *IMX219_RAW]])
def test_in_process_emu_frames_are_the_reference(fourcc):
    with open_camera(f"emu:imx219?size=640x480&{MOVING}&format={fourcc}&frames=3&start_ns=123456789") as src:
        frames = list(src)
        ref = Reference(src.device.spec)
    assert [f.sequence for f in frames] == [0, 1, 2]
    f = frames[-1]
    assert f.format == fourcc
    assert_same_bytes(f.data, ref.wire(f.sequence, f.timestamp_ns), f"emu: {fourcc}")
    if fourcc == "MJPG":  # what a client shows: the JPEG decoded, within the JPEG tolerance of the picture
        assert_close(preview_frame(f), ref.picture(f.sequence, f.timestamp_ns), Tolerance(**JPEG), "emu: MJPG")


# ---------------------------------------------------------------------------------- rollcam run /dev/videoN
FFMPEG = {"YUYV": "yuyv422", "UYVY": "uyvy422", "NV12": "nv12", "YU12": "yuv420p", "BGR3": "bgr24",
          "RGB3": "rgb24", "XR24": "bgr0", "GREY": "gray", "MJPG": "mjpeg", "RGGB": "bayer_rggb8"}
GSTREAMER = {"YUYV": "YUY2", "UYVY": "UYVY", "NV12": "NV12", "YU12": "I420", "BGR3": "BGR", "RGB3": "RGB",
             "XR24": "BGRx", "GREY": "GRAY8", "MJPG": None}


@pytest.fixture(scope="module")
def device() -> Iterator:
    if not LIB.is_file():
        pytest.skip(f"{LIB} not built (pip install -e . with a C compiler)")
    with serving([("/dev/video0", STILL), ("/dev/video1", "emu:imx477?size=640x480&scene=chart")]) as server:
        yield server


def run_program(server, argv: list[str], timeout: float = 120) -> subprocess.CompletedProcess:
    p = subprocess.run(argv, env=program_environment(server), capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, (argv[0], p.returncode, p.stdout[-2000:], p.stderr[-2000:])
    return p


def still_reference(server, fourcc: str) -> Reference:
    """The reference of the still device as the program left it (the format it asked for, the rate it set)."""
    spec = server.nodes["/dev/video0"].driver.camera.spec
    assert spec.pixel_format == fourcc, (spec.pixel_format, fourcc)
    return Reference(spec)


def test_the_still_device_shows_the_same_picture_at_every_sequence_and_time():
    ref = Reference(build_camera(STILL + "&format=NV12")[0].spec)
    assert np.array_equal(ref.wire(0, 0), ref.wire(7, 1_234_567_891))


@pytest.mark.parametrize("fourcc", [case(f, {"NV12", "YU12", "YUYV", "MJPG"}) for f in FFMPEG])
def test_ffmpeg_under_rollcam_run(device, tmp_path, fourcc):
    need("ffmpeg")
    native, bgr = tmp_path / "native", tmp_path / "bgr"
    wire = ["-c:v", "copy", "-f", "mjpeg"] if fourcc == "MJPG" else ["-f", "rawvideo"]
    convert = [] if codec(fourcc).raw else ["-map", "0", "-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "bgr24",
                                            str(bgr)]
    run_program(device, ["ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-f", "v4l2", "-input_format",
                         FFMPEG[fourcc], "-video_size", "640x480", "-i", "/dev/video0",
                         "-map", "0", "-frames:v", "1", *wire, str(native), *convert])
    ref = still_reference(device, fourcc)
    assert_same_bytes(native.read_bytes(), ref.wire(0, 0), f"ffmpeg {FFMPEG[fourcc]}")
    if convert:
        got = np.fromfile(bgr, np.uint8).reshape(480, 640, 3)
        assert_close(got, ref.picture(0, 0), conversion_tolerance(fourcc), f"ffmpeg {FFMPEG[fourcc]} -> bgr24")


def test_ffmpeg_default_format_and_the_docs_example_show_colour(device, tmp_path):
    """ffmpeg's own choice of format (the docs' example gives no -input_format) decodes to the colours."""
    need("ffmpeg")
    out = tmp_path / "bgr"
    run_program(device, ["ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-f", "v4l2", "-i", "/dev/video0",
                         "-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "bgr24", str(out)])
    fourcc = device.nodes["/dev/video0"].driver.camera.spec.pixel_format
    got = np.fromfile(out, np.uint8).reshape(480, 640, 3)
    assert_close(got, still_reference(device, fourcc).picture(0, 0), conversion_tolerance(fourcc),
                 f"ffmpeg's default ({fourcc})")


def test_ffmpeg_gets_a_size_no_mode_has_at_its_rate(device, tmp_path):
    """``emu:imx477?size=640x480``: ffmpeg asking for the current 640x480 gets it at the default mode's 30 fps."""
    need("ffmpeg")
    p = run_program(device, ["ffprobe", "-hide_banner", "-f", "v4l2", "-video_size", "640x480", "-i",
                             "/dev/video1", "-show_streams", "-of", "json"])
    (stream,) = json.loads(p.stdout)["streams"]
    assert (stream["width"], stream["height"]) == (640, 480)
    num, den = map(int, stream["r_frame_rate"].split("/"))
    assert abs(num / den - 30.01) < 0.05, stream["r_frame_rate"]


@pytest.mark.parametrize("fourcc", [case(f, {"pRAA"}) for f in [*IMX219_RAW, "NV12"]])
def test_v4l2_ctl_under_rollcam_run(device, tmp_path, fourcc):
    """v4l2-ctl writes the buffers as they are: the raw formats no converting client reads (CSI-2 packed, 10-bit)
    and a 4:2:0 one, exact."""
    need("v4l2-ctl")
    out = tmp_path / "frame"
    run_program(device, ["v4l2-ctl", "-d", "/dev/video0", f"--set-fmt-video=width=640,height=480,pixelformat={fourcc}",
                         "--stream-mmap", "--stream-count=1", f"--stream-to={out}"])
    assert_same_bytes(out.read_bytes(), still_reference(device, fourcc).wire(0, 0), f"v4l2-ctl {fourcc}")


@pytest.mark.parametrize("fourcc", [case(f, {"NV12", "GREY"}) for f in GSTREAMER])
def test_gstreamer_under_rollcam_run(device, tmp_path, fourcc):
    need("gst-launch-1.0")
    native, bgr = tmp_path / "native", tmp_path / "bgr"
    fmt = GSTREAMER[fourcc]
    caps, decode = ("image/jpeg,width=640,height=480", "jpegdec !") if fmt is None else \
        (f"video/x-raw,format={fmt},width=640,height=480", "")
    pipeline = (f"v4l2src device=/dev/video0 num-buffers=1 ! {caps} ! tee name=t t. ! queue ! filesink "
                f"location={native} t. ! queue ! {decode} videoconvert ! video/x-raw,format=BGR ! filesink "
                f"location={bgr}")
    run_program(device, ["gst-launch-1.0", "-q", *pipeline.split()])
    ref = still_reference(device, fourcc)
    assert_same_bytes(native.read_bytes(), ref.wire(0, 0), f"GStreamer {fmt or 'image/jpeg'}")
    got = np.fromfile(bgr, np.uint8).reshape(480, 640, 3)
    assert_close(got, ref.picture(0, 0), conversion_tolerance(fourcc), f"GStreamer {fmt or 'jpegdec'} -> BGR")


@pytest.mark.parametrize("fourcc", [case(f, {"YU12"}) for f in PROCESSED])
def test_opencv_under_rollcam_run(device, tmp_path, fourcc):
    """OpenCV's V4L2 backend converts every format to BGR itself, with the code the reference uses: exact (MJPG:
    libjpeg's decode of the same JPEG, so within the JPEG tolerance of the picture before compression)."""
    out = tmp_path / "bgr.npy"
    code = f"""
        import cv2, numpy as np
        cap = cv2.VideoCapture("/dev/video0", cv2.CAP_V4L2)
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*{fourcc!r}))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, 640)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, 480)
        ok, img = cap.read()
        assert ok
        np.save({str(out)!r}, img)
    """
    run_program(device, [sys.executable, "-c", textwrap.dedent(code)])
    got = np.load(out)
    if got.ndim == 2:  # GREY comes back as one channel
        got = np.repeat(got[..., None], 3, axis=2)
    tol = Tolerance(**JPEG) if fourcc == "MJPG" else EXACT
    assert_close(got, still_reference(device, fourcc).picture(0, 0), tol, f"OpenCV {fourcc}")


# --------------------------------------------------------------------------------------------- MJPEG over HTTP
def _parts(url: str, n: int) -> list[tuple[dict[str, str], bytes]]:
    """The first ``n`` parts of a multipart MJPEG stream: headers and JPEG, read as a browser reads them."""
    parts = []
    with urllib.request.urlopen(url, timeout=30) as r:
        while len(parts) < n:
            if r.readline().strip() != b"--rollcamframe":
                continue
            head = {}
            while line := r.readline().strip():
                k, v = line.decode().split(": ", 1)
                head[k] = v
            parts.append((head, r.read(int(head["Content-Length"]))))
    return parts


@pytest.mark.parametrize("fourcc", [case("YUYV", {"YUYV"}), case("RG10", set())])
def test_mjpeg_over_http(fourcc):
    """The server encodes each frame's picture (a raw camera's through the preview ISP) as JPEG: the bytes are the
    reference's, and the decoded picture is within the JPEG tolerance of the picture."""
    cam = FirmwareCamera(CameraSpec.create("imx219", size=SIZE, pixel_format=fourcc,
                                           scene={"scene": "street", "speed": "fast", "seed": 3}))
    with MjpegServer(cam) as srv:
        parts = _parts(srv.url, 2)
        ref = Reference(cam.spec)
        assert srv.quality == JPEG_QUALITY
    for head, jpeg in parts:
        seq, start = int(head["X-Sequence"]), int(head["X-Timestamp-Ns"])
        picture = ref.rendered(seq, start)
        assert_same_bytes(jpeg, ref.wire(seq, start, "MJPG"), f"HTTP part {seq}")
        got = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        assert_close(got, picture, Tolerance(**JPEG), f"HTTP part {seq} decoded")


@pytest.mark.parametrize("client", [pytest.param("opencv", id="opencv"),
                                    pytest.param("ffmpeg", id="ffmpeg", marks=pytest.mark.slow)])
def test_mjpeg_over_http_read_by_a_video_client(tmp_path, client):
    """OpenCV's VideoCapture (its ffmpeg backend) and ffmpeg itself on the multipart stream of the still camera
    (they do not say which part they kept): ffmpeg's copy is the reference's JPEG, and both decodes are within the
    JPEG tolerance of the picture."""
    cam, _ = build_camera(STILL)
    with MjpegServer(cam) as srv:
        if client == "opencv":
            cap = cv2.VideoCapture(srv.url)
            ok, got = cap.read()
            cap.release()
            assert ok
        else:
            need("ffmpeg")
            jpeg, bgr = tmp_path / "frame.jpg", tmp_path / "bgr"
            p = subprocess.run(["ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-i", srv.url,
                                "-map", "0", "-frames:v", "1", "-c:v", "copy", "-f", "mjpeg", str(jpeg),
                                "-map", "0", "-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "bgr24", str(bgr)],
                               capture_output=True, text=True, timeout=120)
            assert p.returncode == 0, p.stderr[-2000:]
            got = np.fromfile(bgr, np.uint8).reshape(480, 640, 3)
        ref = Reference(cam.spec)
    if client == "ffmpeg":
        assert_same_bytes(jpeg.read_bytes(), ref.wire(0, 0, "MJPG"), "ffmpeg's copy of an HTTP part")
    assert_close(got, ref.rendered(0, 0), Tolerance(**JPEG), f"{client} on the HTTP MJPEG stream")


# ------------------------------------------------------------------------------------- UVC: pyusb and USB/IP
UVC_FORMATS = {"YUYV": "yuyv", "NV12": "nv12", "MJPG": "mjpeg"}


def _uvc_check(frames: list[Frame], wire: list[Frame], spec: CameraSpec, fourcc: str, what: str) -> None:
    """Frames of a fresh camera's first stream (UVC frame index ``i`` is sequence ``i``, the PTS its start): the
    wire ones (``decode=0``) exact, the decoded ones as the codec table decodes the reference's wire."""
    ref = Reference(spec)
    for w in wire:
        assert w.format == fourcc
        assert_same_bytes(w.data, ref.wire(w.sequence, w.timestamp_ns, fourcc), f"{what} {fourcc} frame {w.sequence}")
    for f in frames:  # decoded by the source, as its client code decodes them
        assert f.format == "BGR3"
        if fourcc == "MJPG":
            assert_close(f.data, ref.rendered(f.sequence, f.timestamp_ns), Tolerance(**JPEG), f"{what} MJPG")
        else:
            want = codec(fourcc).decode(ref.wire(f.sequence, f.timestamp_ns, fourcc), *SIZE)
            assert_close(f.data, want, EXACT, f"{what} {fourcc} decoded")


@pytest.mark.parametrize("fourcc", [case(f, {"NV12"}) for f in UVC_FORMATS])
def test_uvc_through_pyusb(fourcc):
    uri = (f"uvc:1209:0001?backend=emu&sensor=imx219&size=640x480&scene=street&seed=3&realtime=off&frames=2"
           f"&format={UVC_FORMATS[fourcc]}")
    with open_camera(uri) as src:
        frames = list(src)
        spec = src.function.producer.camera.spec
    with open_camera(uri + "&decode=0") as src:
        wire = list(src)
    assert [f.sequence for f in frames] == [w.sequence for w in wire] == [0, 1]
    _uvc_check(frames, wire, spec, fourcc, "UVC/pyusb")


@pytest.mark.parametrize("fourcc", [case(f, {"MJPG"}) for f in UVC_FORMATS])
def test_uvc_through_usbip_with_rollcams_client(fourcc):
    """Linux's own USB/IP client needs the vhci-hcd kernel module to attach (the kernel path is the real-kernel
    tests'); here rollcam's client imports the device over TCP and decodes as it would."""
    got = {}
    for decode in (1, 0):
        cam = FirmwareCamera("imx219", size=SIZE, scene={"scene": "street", "speed": "fast", "seed": 3})
        with USBIPServer([UVCFunction(FirmwareProducer(cam), transfer="bulk")], port=0) as srv:
            host, port = srv.address
            with open_camera(f"uvc:1209:0001?backend=usbip&usbip={host}:{port}&busid=1-1&frames=2&size=640x480"
                             f"&format={UVC_FORMATS[fourcc]}&decode={decode}") as src:
                got[decode] = list(src)
        cam.stream_off()
    _uvc_check(got[1], got[0], cam.spec, fourcc, "UVC/USB-IP")


# ------------------------------------------------------------------------------- the picamera2 stand-in (read)
PICAMERA2 = ["RGB888", "BGR888", "XRGB8888", "XBGR8888", "YUV420", "YVU420"]
PICAMERA2_SCRIPT = """
    import json, sys
    import numpy as np
    from picamera2 import Picamera2

    out = {}
    with Picamera2() as picam2:
        for fmt in sys.argv[2:]:
            picam2.configure(picam2.create_preview_configuration(main={"format": fmt, "size": (640, 480)}))
            picam2.start()
            request = picam2.capture_request()
            np.save(f"{sys.argv[1]}/{fmt}.npy", request.make_array("main"))
            md = request.get_metadata()
            request.release()
            picam2.stop()
            out[fmt] = [md["RollcamSequence"], md["RollcamDeviceTimestamp"]]
    print(json.dumps(out))
"""


def _as_picamera2(fmt: str, bgr: np.ndarray) -> np.ndarray:
    """The reference picture laid out as picamera2 gives ``fmt``'s array: RGB888 is B, G, R in memory (OpenCV's
    BGR), BGR888 R, G, B; the X formats add a fourth byte of 255; YUV420 is I420 and YVU420 has V before U."""
    if fmt in ("RGB888", "XRGB8888"):
        out = bgr
    elif fmt in ("BGR888", "XBGR8888"):
        out = bgr[..., ::-1]
    else:
        i420 = codec("YU12").encode(bgr)
        if fmt == "YVU420":
            y, quarter = 640 * 480, 640 * 480 // 4
            flat = i420.reshape(-1)
            i420 = np.concatenate([flat[:y], flat[y + quarter:], flat[y:y + quarter]]).reshape(i420.shape)
        return i420
    if fmt.startswith("X"):
        out = np.concatenate([out, np.full((*out.shape[:2], 1), 255, np.uint8)], axis=2)
    return np.ascontiguousarray(out)


@pytest.mark.parametrize("formats", [pytest.param(["RGB888", "YUV420"], id="fast"),
                                     pytest.param(PICAMERA2, id="all", marks=pytest.mark.slow)])
def test_picamera2_stand_in_arrays(tmp_path, formats):
    """The stand-in's main stream at the sensor mode's size (no scaling) is the firmware camera's processed
    picture: the preview ISP of the same raw frame, so exact in every layout."""
    source = f"emu:imx219?size=640x480&{MOVING}"
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(PICAMERA2_SCRIPT), str(tmp_path), *formats],
                       env=standin_env([source]), capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    frames = json.loads(p.stdout.strip().splitlines()[-1])
    ref = Reference(build_camera(source + "&format=YUYV")[0].spec)
    for fmt, (seq, start) in frames.items():
        got = np.load(tmp_path / f"{fmt}.npy")
        want = _as_picamera2(fmt, ref.frame(seq, start).data)
        assert_same_bytes(got, want.reshape(-1), f"picamera2 {fmt} frame {seq}")
