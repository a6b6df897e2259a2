"""ROS messages of a captured frame, as plain dicts that every writer serialises (no ROS library needed here).

One frame becomes, on the camera's topics (``TOPICS``): ``sensor_msgs/Image`` (``CompressedImage`` for MJPG
frames), ``sensor_msgs/CameraInfo`` (the pinhole lens; with an IMU the frame carries its intrinsics),
``rollcam_msgs/RollingShutter`` (first-line time, line time, readout direction and every line's sample time),
``rollcam_msgs/FrameTruth`` (GS and RS boxes of every object) and ``rollcam_msgs/LinePoses`` (the true
camera pose at every line's sample time); its IMU samples become ``sensor_msgs/Imu``. Every stamp is the
device clock's integer ns split exactly into ``builtin_interfaces/Time`` (``sec = ns // 10**9``,
``nanosec = ns % 10**9``). Field names are ROS 2's (``k``, ``d``); ``to_store`` fills a ``rosbags`` message
class of either ROS version from them (ROS 1 spells them ``K``, ``D`` and has ``Header.seq``).
``ROLLCAM_MSGS`` holds the ``.msg`` text of rollcam's own types, documented in docs/robotics.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.sim.formats import BAYER_ORDERS, FORMATS, bayer_fourcc
from rollcam.sim.frame import Frame
from rollcam.sim.imu import ImuSamples

from ..recording.imagefiles import image_array

NS_PER_S = 1_000_000_000
CAMERA_FRAME, IMU_FRAME, WORLD_FRAME = "cam0", "imu0", "world"

ROLLCAM_MSGS: dict[str, str] = {
    "rollcam_msgs/msg/RollingShutter": """\
# When each line of one frame was sampled, on the device clock (integer ns).
std_msgs/Header header      # stamp: first_line_ns; frame_id: the camera frame
uint32 sequence             # the frame's sequence number
string shutter              # rolling | global
int64 first_line_ns         # start of exposure of the first line read
int64 exposure_ns           # exposure of every line
int64 line_time_ns          # nominal line time, rounded to ns; 0 for a global shutter
string readout              # top_to_bottom | bottom_to_top | left_to_right | right_to_left
uint32 lines                # lines read: rows, or columns when the readout is by column
int64 readout_ns            # active readout, lines x line_time_ns (no blanking)
int64[] line_times_ns       # sample (mid-exposure) time of every image line, by image row/column index
""",
    "rollcam_msgs/msg/ObjectTruth": """\
# Exact ground truth of one object in one frame; boxes x0 y0 x1 y1 in pixels, x1 and y1 exclusive.
uint32 id
string cls                  # object class, e.g. person
bool has_box_gs             # false: no pixel of the object in the image at the reference time
float64[4] box_gs           # every line at the frame's reference time (its first line's sample time)
bool has_box_rs             # false: no pixel of the object under the rolling shutter
float64[4] box_rs           # union of the per-line extents, each line at its own sample time
float64 visible             # fraction of its in-image pixels that no nearer object hides
float64 speed_mps
""",
    "rollcam_msgs/msg/FrameTruth": """\
# Ground truth of the objects of one frame.
std_msgs/Header header      # stamp: first_line_ns of the frame; frame_id: the camera frame
uint32 sequence
string shutter              # rolling | global: which frame these boxes belong to
rollcam_msgs/ObjectTruth[] objects
""",
    "rollcam_msgs/msg/LinePoses": """\
# The camera's true motion at every line's sample time of one frame.
std_msgs/Header header      # stamp: the first line's sample time; frame_id: world (X east, Y north, Z up)
uint32 sequence
int64[] t_ns                # sample time of each line (device clock), by image line index
geometry_msgs/Pose[] poses  # camera-to-world: camera centre (m) and orientation (camera x right, y down, z forward)
geometry_msgs/Vector3[] velocity          # world axes, m/s
geometry_msgs/Vector3[] angular_velocity  # camera axes, rad/s
""",
}

TOPICS = {
    "image": "image_raw", "compressed": "image_raw/compressed", "camera_info": "camera_info",
    "rolling_shutter": "rolling_shutter", "truth": "truth", "line_poses": "line_poses",
}
"""Topic names under a camera's prefix (``/cam0/image_raw``, ...), as ROS camera drivers and Kalibr name them."""
IMU_TOPIC = "/imu0"

_MONO = {"GREY": "mono8", "Y10 ": "mono16", "Y12 ": "mono16", "Y16 ": "mono16"}
_BAYER8 = {bayer_fourcc(o, 8): f"bayer_{o.lower()}8" for o in BAYER_ORDERS}
_BAYER16 = {bayer_fourcc(o, b): f"bayer_{o.lower()}16" for o in BAYER_ORDERS for b in (10, 12, 16)}
"""ROS encodings of V4L2's unpacked Bayer fourccs (samples in the low bits of 16, as V4L2 delivers them)."""


def stamp(t_ns: int) -> dict[str, int]:
    """``builtin_interfaces/Time`` of a device time in integer ns (exact; negative times borrow a second)."""
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    return {"sec": sec, "nanosec": nanosec}


def header(t_ns: int, frame_id: str) -> dict[str, Any]:
    """``std_msgs/Header`` (ROS 1's ``seq`` is left 0: rosbag1 readers ignore it)."""
    return {"stamp": stamp(t_ns), "frame_id": frame_id}


def image_encoding(frame: Frame) -> tuple[str, np.ndarray] | None:
    """The ``sensor_msgs/Image`` encoding and 2-D or 3-D pixel array of ``frame``; None for MJPG (compressed).

    Pictures go as ``bgr8`` / ``mono8`` (RGB3 is stored as BGR, as the image files are), 8-bit Bayer as
    ``bayer_*8``, unpacked 10-16-bit Bayer as ``bayer_*16`` and mono as ``mono16`` (samples in the low bits,
    as V4L2 delivers them). Packed CSI-2 and YUV layouts are refused: capture them as npy.
    """
    fmt = frame.format
    if fmt == "MJPG":
        return None
    if fmt in _BAYER8 and frame.data.dtype == np.uint8:
        return _BAYER8[fmt], frame.data
    if fmt in _BAYER16 and frame.data.dtype == np.uint16:
        return _BAYER16[fmt], frame.data
    if fmt in _MONO and fmt != "GREY" and frame.data.dtype == np.uint16:
        return "mono16", frame.data
    if fmt in ("BGR3", "RGB3", "GREY") or fmt not in FORMATS:
        img = image_array(frame, "png")
        if img.ndim == 3:
            return "bgr8", img
        return ("mono16" if img.dtype == np.uint16 else "mono8"), img
    raise ConfigError(f"{fmt.strip()!r} frames have no sensor_msgs/Image encoding here; capture BGR3, RGB3, GREY, "
                      "MJPG, 8-bit or unpacked Bayer, or Y10/Y12/Y16 (or use --format npy)")


def image_msg(frame: Frame, frame_id: str = CAMERA_FRAME) -> tuple[str, dict[str, Any]]:
    """(``'image'`` or ``'compressed'``, the message) of a frame, stamped at its first line's exposure start."""
    enc = image_encoding(frame)
    if enc is None:
        return "compressed", {"header": header(frame.timestamp_ns, frame_id), "format": "jpeg",
                              "data": np.ascontiguousarray(frame.data, np.uint8).tobytes()}
    encoding, img = enc
    img = np.ascontiguousarray(img)
    return "image", {"header": header(frame.timestamp_ns, frame_id), "height": int(img.shape[0]),
                     "width": int(img.shape[1]), "encoding": encoding, "is_bigendian": 0,
                     "step": int(img.strides[0]), "data": img.tobytes()}


def camera_info_msg(frame: Frame, frame_id: str = CAMERA_FRAME) -> dict[str, Any] | None:
    """``sensor_msgs/CameraInfo`` of the frame's pinhole lens, or None when the frame does not carry intrinsics.

    rollcam's lens has no geometric distortion (docs/optics.md: vignetting and blur only), so the model is
    ``plumb_bob`` with its five coefficients zero; K and P hold fx, fy, cx, cy (OpenCV's convention, pixel
    centres at integers), R is the identity (a monocular camera).
    """
    k = frame.meta.get("intrinsics")
    if k is None:
        return None
    fx, fy, cx, cy = (float(v) for v in k)
    return {"header": header(frame.timestamp_ns, frame_id), "height": frame.height, "width": frame.width,
            "distortion_model": "plumb_bob", "d": [0.0] * 5,
            "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0], "binning_x": 0, "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}}


def readout_lines(frame: Frame) -> int:
    """Lines a frame's readout walks: rows, or columns for column readout."""
    return frame.width if frame.readout.by_column else frame.height


def rolling_shutter_msg(frame: Frame, frame_id: str = CAMERA_FRAME) -> dict[str, Any]:
    """``rollcam_msgs/RollingShutter`` of a frame (see ``ROLLCAM_MSGS``)."""
    lines = readout_lines(frame)
    times = frame.row_times_ns
    return {"header": header(frame.timestamp_ns, frame_id), "sequence": int(frame.sequence),
            "shutter": frame.shutter, "first_line_ns": int(frame.timestamp_ns), "exposure_ns": int(frame.exposure_ns),
            "line_time_ns": int(frame.line_time_ns), "readout": frame.readout.value, "lines": lines,
            "readout_ns": lines * int(frame.line_time_ns),
            "line_times_ns": [] if times is None else np.asarray(times, np.int64).tolist()}


def _box(b: Any) -> list[float]:
    return [0.0] * 4 if b is None else [float(v) for v in b]


def truth_msg(frame: Frame, frame_id: str = CAMERA_FRAME) -> dict[str, Any] | None:
    """``rollcam_msgs/FrameTruth`` of a synthetic frame; None for a frame without ground truth."""
    if frame.objects is None:
        return None
    objects = [{"id": int(o.id), "cls": o.cls, "has_box_gs": o.box_gs is not None, "box_gs": _box(o.box_gs),
                "has_box_rs": o.box_rs is not None, "box_rs": _box(o.box_rs), "visible": float(o.visible),
                "speed_mps": float(o.speed_mps)} for o in frame.objects]
    return {"header": header(frame.timestamp_ns, frame_id), "sequence": int(frame.sequence),
            "shutter": frame.shutter, "objects": objects}


def _vec(v: np.ndarray) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def line_poses_msg(frame: Frame) -> dict[str, Any] | None:
    """``rollcam_msgs/LinePoses`` of a frame with per-line truth (``Frame.poses``); None without."""
    k = frame.poses
    if k is None:
        return None
    q = k.quaternion_wxyz
    poses = [{"position": _vec(p), "orientation": {"x": float(r[1]), "y": float(r[2]), "z": float(r[3]),
                                                   "w": float(r[0])}} for p, r in zip(k.position, q, strict=True)]
    t = np.asarray(k.t_ns, np.int64).tolist()
    return {"header": header(min(t) if t else frame.timestamp_ns, WORLD_FRAME),
            "sequence": int(frame.sequence), "t_ns": t, "poses": poses,
            "velocity": [_vec(v) for v in k.velocity], "angular_velocity": [_vec(w) for w in k.angular_velocity]}


def imu_msgs(samples: ImuSamples, frame_id: str = IMU_FRAME) -> list[tuple[int, dict[str, Any]]]:
    """(stamp ns, ``sensor_msgs/Imu``) of each sample: rates in rad/s and specific force in m/s^2, IMU axes.

    No orientation estimate (``orientation_covariance[0] = -1``, as sensor_msgs/Imu defines it); the rate and
    acceleration covariances are the white noise's per-sample variance (density^2 x rate), on the diagonal.
    """
    p = samples.params
    var_g = p.gyroscope_noise_density ** 2 * p.rate_hz
    var_a = p.accelerometer_noise_density ** 2 * p.rate_hz
    no_orientation = [-1.0] + [0.0] * 8
    out = []
    for t, g, a in zip(samples.t_ns.tolist(), samples.gyro, samples.accel, strict=True):
        out.append((t, {"header": header(t, frame_id), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0},
                        "orientation_covariance": no_orientation, "angular_velocity": _vec(g),
                        "angular_velocity_covariance": [var_g, 0.0, 0.0, 0.0, var_g, 0.0, 0.0, 0.0, var_g],
                        "linear_acceleration": _vec(a),
                        "linear_acceleration_covariance": [var_a, 0.0, 0.0, 0.0, var_a, 0.0, 0.0, 0.0, var_a]}))
    return out
