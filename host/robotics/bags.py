"""A capture as one MCAP file, ROS 2 bag or ROS 1 bag, written whole or not at all, with no ROS install.

``BagWriter(out_dir, fmt)`` takes a capture's instants (``write(frames)``) and, on ``close()``, moves the finished
recording into place: ``capture.mcap`` (``mcap``: ROS 2 messages through ``mcap_ros2``'s writer), ``capture_ros2/``
(``ros2bag``: ``rosbags``' rosbag2 writer, sqlite3 storage, or MCAP storage with ``storage='mcap'``),
``capture.bag`` (``rosbag1``: ``rosbags``' rosbag1 writer), ``kalibr.bag`` (``kalibr``: a ROS 1 bag with exactly
the topics and types ``kalibr_bagcreater`` writes, ``/cam0/image_raw`` mono8 ``sensor_msgs/Image`` and ``/imu0``
``sensor_msgs/Imu``). The recording is built in a temporary folder beside its final name and renamed into place
only when finished (``rollcam.common.files.commit_tree``); ``abort()`` removes it. So after a Ctrl-C the capture
closes what it has and the file is there, whole; after an error in the middle of an instant, or a kill, it is
absent. With an IMU, Kalibr's ``imu.yaml`` and ``camchain.yaml`` (``rollcam.host.recording.imu_export``) go beside it,
written atomically at the first instant. The messages and their fields are ``rollcam.host.robotics.messages``';
docs/robotics.md documents them.

Topics (Kalibr's names): ``/cam0/image_raw`` (or ``/cam0/image_raw/compressed``), ``/cam0/camera_info``,
``/cam0/rolling_shutter``, ``/cam0/truth``, ``/cam0/line_poses``, ``/imu0``; a GS/RS pair's global-shutter frame
goes under ``/cam0_gs``. Each message's log time is its header stamp (device clock, integer ns).
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, require
from rollcam.common.files import commit_tree, part_path, write_atomic
from rollcam.sim.frame import Frame

from ..recording.imu_export import CAMCHAIN_YAML, IMU_YAML, camchain_yaml, imu_yaml
from .messages import (
    IMU_TOPIC,
    ROLLCAM_MSGS,
    TOPICS,
    camera_info_msg,
    image_encoding,
    image_msg,
    imu_msgs,
    line_poses_msg,
    rolling_shutter_msg,
    truth_msg,
)

BAG_FORMATS = ("mcap", "ros2bag", "rosbag1", "kalibr")
OUTPUT = {"mcap": "capture.mcap", "ros2bag": "capture_ros2", "rosbag1": "capture.bag", "kalibr": "kalibr.bag"}
"""The file (folder, for a ROS 2 bag) each format writes in the capture folder."""
KALIBR_TOPICS = {"/cam0/image_raw": "sensor_msgs/msg/Image", "/imu0": "sensor_msgs/msg/Imu"}
"""The topics and types ``kalibr_bagcreater`` writes for one camera and one IMU, and nothing else."""
TYPES = {"image": "sensor_msgs/msg/Image", "compressed": "sensor_msgs/msg/CompressedImage",
         "camera_info": "sensor_msgs/msg/CameraInfo", "rolling_shutter": "rollcam_msgs/msg/RollingShutter",
         "truth": "rollcam_msgs/msg/FrameTruth", "line_poses": "rollcam_msgs/msg/LinePoses"}
IMU_TYPE = "sensor_msgs/msg/Imu"
ROS2_STORAGES = ("sqlite3", "mcap")
"""Storage plugins of a ROS 2 bag (rosbag2's default first)."""


def require_libraries(fmt: str) -> None:
    """Import what ``fmt`` needs, or raise the missing-dependency error naming the ``robotics`` extra."""
    if fmt not in BAG_FORMATS:
        raise ConfigError(f"recording format {fmt!r} is not one of {list(BAG_FORMATS)}")
    feature = f"rollcam capture --format {fmt}"
    require("rosbags.typesys", "rosbags", "robotics", feature)
    if fmt == "mcap":
        require("mcap_ros2.writer", "mcap-ros2-support", "robotics", feature)


@lru_cache(maxsize=2)
def typestore(ros_version: int) -> Any:
    """A ``rosbags`` type store of ROS ``ros_version`` (Noetic or Humble messages) with rollcam_msgs added."""
    typesys = require("rosbags.typesys", "rosbags", "robotics", "ROS messages")
    store = typesys.get_typestore(typesys.Stores.ROS1_NOETIC if ros_version == 1 else typesys.Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in ROLLCAM_MSGS.items():
        types.update(typesys.get_types_from_msg(text, name))
    store.register(types)
    return store


_NP = {"float64": np.float64, "float32": np.float32, "int64": np.int64, "uint64": np.uint64, "int32": np.int32,
       "uint32": np.uint32, "int16": np.int16, "uint16": np.uint16, "int8": np.int8, "uint8": np.uint8,
       "byte": np.uint8, "char": np.uint8, "bool": np.bool_}


def _default(store: Any, node: Any) -> Any:
    """The zero value of a field (rosbags' node kinds: 1 base type, 2 message, 3 array, 4 sequence)."""
    kind, desc = node
    if kind == 1:  # BASE
        t = desc[0]
        return "" if t == "string" else False if t == "bool" else 0.0 if t.startswith("float") else 0
    if kind == 2:  # NAME
        return to_store(store, desc, {})
    count = 0 if kind == 4 else desc[1]  # SEQUENCE or ARRAY
    sub_kind, sub = desc[0]
    if sub_kind == 1 and sub[0] in _NP:
        return np.zeros(count, _NP[sub[0]])
    return [_default(store, desc[0]) for _ in range(count)]


def _value(store: Any, node: Any, value: Any) -> Any:
    kind, desc = node
    if value is None:
        return _default(store, node)
    if kind == 1:
        return value
    if kind == 2:
        return to_store(store, desc, value)
    sub_kind, sub = desc[0]
    if sub_kind == 1 and sub[0] in _NP:
        if isinstance(value, bytes):
            return np.frombuffer(value, np.uint8)
        return np.asarray(value, dtype=_NP[sub[0]])
    return [_value(store, desc[0], v) for v in value]


def to_store(store: Any, typename: str, msg: dict[str, Any]) -> Any:
    """``msg`` (ROS 2 field names, ``rollcam.host.robotics.messages``) as the store's message class: fields
    matched without regard to case (ROS 1's CameraInfo spells ``K``), absent ones (ROS 1's ``Header.seq``) zero."""
    lower = {k.lower(): v for k, v in msg.items()}
    _, fields = store.fielddefs[typename]
    return store.types[typename](**{name: _value(store, node, lower.get(name.lower())) for name, node in fields})


Message = tuple[str, str, int, dict[str, Any]]
"""(topic, type name, log time ns, message)."""


def stamp_ns(msg: dict[str, Any]) -> int:
    """A message's header stamp in ns: its log time in every recording."""
    t = msg["header"]["stamp"]
    return int(t["sec"]) * 1_000_000_000 + int(t["nanosec"])


def frame_messages(frames: Sequence[Frame]) -> list[Message]:
    """Every message of one instant: per frame its image, camera info, timing, truth and line poses; the IMU
    samples once (a GS/RS pair carries the same block)."""
    pair = len(frames) > 1
    out: list[Message] = []
    for frame in frames:
        cam = "/cam0_gs" if pair and frame.shutter == "global" else "/cam0"
        t = int(frame.timestamp_ns)
        kind, img = image_msg(frame)
        out.append((f"{cam}/{TOPICS[kind]}", TYPES[kind], t, img))
        for kind, msg in (("camera_info", camera_info_msg(frame)), ("rolling_shutter", rolling_shutter_msg(frame)),
                          ("truth", truth_msg(frame)), ("line_poses", line_poses_msg(frame))):
            if msg is not None:
                out.append((f"{cam}/{TOPICS[kind]}", TYPES[kind], stamp_ns(msg), msg))
    imu = next((f.imu for f in frames if f.imu is not None), None)
    if imu is not None:
        out.extend((IMU_TOPIC, IMU_TYPE, t, msg) for t, msg in imu_msgs(imu))
    return out


def kalibr_messages(frames: Sequence[Frame]) -> list[Message]:
    """The instant in Kalibr's layout: the RS image as mono8 (``kalibr_bagcreater`` reads its images in grey) on
    ``/cam0/image_raw``, the IMU on ``/imu0``."""
    from rollcam.sim.codecs import codec  # lazily, as cv2 behind it: importing the bag writer stays light

    out: list[Message] = []
    for frame in frames:
        enc = image_encoding(frame)
        if enc is None or enc[0] not in ("bgr8", "mono8"):
            raise ConfigError(f"--format kalibr takes 8-bit picture frames (BGR3, RGB3, GREY), not {frame.format!r}")
        img = enc[1] if enc[0] == "mono8" else codec("GREY").encode(enc[1])
        kind, msg = image_msg(Frame(img, "GREY", frame.sequence, frame.timestamp_ns, frame.line_time_ns,
                                    frame.readout, frame.exposure_ns))
        out.append(("/cam0/image_raw", TYPES[kind], int(frame.timestamp_ns), msg))
        if frame.imu is not None:
            out.extend((IMU_TOPIC, IMU_TYPE, t, m) for t, m in imu_msgs(frame.imu))
    return out


def check_frames(frames: Sequence[Frame], fmt: str) -> None:
    """Refuse, before anything is written, frames that ``fmt`` cannot hold (raises ``ConfigError``)."""
    if fmt == "kalibr":
        if len(frames) > 1 or any(f.shutter == "global" for f in frames):
            raise ConfigError("--format kalibr records one rolling-shutter camera (kalibr_calibrate_rs_cameras); "
                              "leave out --shutter both/global")
        kalibr_messages(frames)
    else:
        for frame in frames:
            image_encoding(frame)


class _Mcap:
    """ROS 2 messages (CDR) in an MCAP file, through mcap_ros2's writer; schemas are ROS 2 ``.msg`` text."""

    def __init__(self, path: Path) -> None:
        writer = require("mcap_ros2.writer", "mcap-ros2-support", "robotics", "rollcam capture --format mcap")
        self._file = open(path, "wb")  # noqa: SIM115 (closed by close)
        self._writer = writer.Writer(self._file)
        self._store = typestore(2)
        self._schemas: dict[str, Any] = {}

    def write(self, topic: str, typename: str, t_ns: int, msg: dict[str, Any]) -> None:
        schema = self._schemas.get(typename)
        if schema is None:
            text = self._store.generate_msgdef(typename, ros_version=2)[0]
            schema = self._schemas[typename] = self._writer.register_msgdef(typename, text)
        self._writer.write_message(topic, schema, msg, log_time=t_ns, publish_time=t_ns)

    def close(self) -> None:
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def abort(self) -> None:
        self._file.close()


class _Rosbags:
    """A ROS 2 bag (sqlite3 or MCAP storage) or a ROS 1 bag, through rosbags' writers."""

    def __init__(self, path: Path, ros_version: int, storage: str = "sqlite3") -> None:
        self._store = typestore(ros_version)
        self._ros1 = ros_version == 1
        if self._ros1:
            self._writer = require("rosbags.rosbag1", "rosbags", "robotics", "ROS 1 bags").Writer(path)
        else:
            rosbag2 = require("rosbags.rosbag2", "rosbags", "robotics", "ROS 2 bags")
            if storage not in ROS2_STORAGES:
                raise ConfigError(f"ROS 2 bag storage {storage!r} is not one of {list(ROS2_STORAGES)}")
            plugin = rosbag2.StoragePlugin.SQLITE3 if storage == "sqlite3" else rosbag2.StoragePlugin.MCAP
            self._writer = rosbag2.Writer(path, version=9, storage_plugin=plugin)
        self._writer.open()
        self._connections: dict[str, Any] = {}

    def write(self, topic: str, typename: str, t_ns: int, msg: dict[str, Any]) -> None:
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._connections[topic] = self._writer.add_connection(topic, typename, typestore=self._store)
        obj = to_store(self._store, typename, msg)
        data = self._store.serialize_ros1(obj, typename) if self._ros1 else self._store.serialize_cdr(obj, typename)
        self._writer.write(conn, t_ns, data)

    def close(self) -> None:
        self._writer.close()

    def abort(self) -> None:
        with contextlib.suppress(Exception):
            self._writer.close()


class BagWriter:
    """One capture's recording in ``fmt`` (see the module docstring): ``write`` an instant's frames, then
    ``close`` (rename the finished recording into place) or ``abort`` (remove it). ``storage`` picks a ROS 2
    bag's storage (``sqlite3``, ``mcap``)."""

    def __init__(self, out_dir: str | Path, fmt: str, *, storage: str = "sqlite3") -> None:
        require_libraries(fmt)
        self.fmt = fmt
        self.out_dir = Path(out_dir)
        self.path = self.out_dir / OUTPUT[fmt]
        self.frames = self.images = 0
        self._stage = part_path(self.path)
        self._stage.mkdir()
        staged = self._stage / self.path.name
        try:
            self._backend: _Mcap | _Rosbags | None = (
                _Mcap(staged) if fmt == "mcap" else _Rosbags(staged, 2, storage) if fmt == "ros2bag"
                else _Rosbags(staged, 1))
        except BaseException:
            shutil.rmtree(self._stage, ignore_errors=True)
            raise
        self._broken = False

    def __repr__(self) -> str:
        return f"BagWriter({str(self.path)!r}, {self.fmt}, {self.frames} instants)"

    def write(self, frames: Sequence[Frame]) -> None:
        """Record one instant (a frame, or a GS/RS pair); an error or interrupt part-way makes ``close`` abort."""
        if self._backend is None:
            raise ValueError("recording is closed")
        messages = kalibr_messages(frames) if self.fmt == "kalibr" else frame_messages(frames)
        if self.frames == 0:
            self._write_kalibr_yaml(frames)
        self._broken = True  # until every message of the instant is in
        for topic, typename, t_ns, msg in messages:
            self._backend.write(topic, typename, t_ns, msg)
        self._broken = False
        self.frames += 1
        self.images += len(frames)

    def _write_kalibr_yaml(self, frames: Sequence[Frame]) -> None:
        """Kalibr's ``imu.yaml`` and ``camchain.yaml`` beside the recording (its topics, the true line delay and
        time shift), as a capture to image files writes them, when the camera has an IMU."""
        frame = next((f for f in frames if f.imu is not None and f.shutter == "rolling"), None) or \
            next((f for f in frames if f.imu is not None), None)
        if frame is None or frame.imu is None:
            return
        write_atomic(self.out_dir / IMU_YAML, imu_yaml(frame.imu.params).encode())
        if "intrinsics" in frame.meta:
            write_atomic(self.out_dir / CAMCHAIN_YAML, camchain_yaml(frame, frame.imu.params).encode())

    def close(self) -> None:
        """Finish the recording and move it into place (removed instead when an instant was cut short or no
        instant was recorded); safe to call twice."""
        backend, self._backend = self._backend, None
        if backend is None:
            return
        if self._broken or self.frames == 0:
            backend.abort()
            shutil.rmtree(self._stage, ignore_errors=True)
            return
        try:
            backend.close()
            if self.path.is_dir():
                shutil.rmtree(self.path)
            commit_tree(self._stage / self.path.name, self.path)
        finally:
            shutil.rmtree(self._stage, ignore_errors=True)

    def abort(self) -> None:
        """Stop and remove the unfinished recording; safe to call twice and after ``close``."""
        backend, self._backend = self._backend, None
        if backend is not None:
            backend.abort()
        shutil.rmtree(self._stage, ignore_errors=True)
