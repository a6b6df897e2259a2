"""The studies behind ``rollcam bench STUDY``: one entry each, with its options, run, report and targets.

Each study's code lives in its own module of ``rollcam.benchmarks`` (``bench`` renders, ``realism``,
``detect``, ``ptc``, ``sensor_bench``, ``uvc``, ``soak``, ``mjpeg``, ``dataset``, ``imu``, ``view``,
``preload``, ``personnet``, ``flicker``, ``device``, ``insensor``);
an entry here is the thin layer the command line needs.
``run(args, progress)`` does the work, writes its files under ``args.out`` and returns the JSON document with
its plain-text report; ``targets(doc)`` reads the document's targets as ``{name: {"value", "op", "limit",
"pass"}}`` (``pass`` None when a target did not apply). This module imports only the standard library at the
top, so ``rollcam --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rollcam.common.errors import ConfigError, RollcamError, require
from rollcam.common.values import name_list, parse_bool, parse_size, positive_float, positive_int
from rollcam.host.commands import value_type

Doc = dict[str, Any]
Targets = dict[str, dict[str, Any]]
PTC_TOLERANCE = 0.05
"""Largest relative error of a figure the PTC measures against the sensor's configuration."""

_COUNT = value_type(positive_int, "an integer >= 1")


class TargetMissed(RollcamError):
    """``--check``: a study's number missed its target (exit status 1); the message names each one."""


@dataclass(frozen=True)
class Study:
    """One ``rollcam bench`` subcommand."""

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, Any], tuple[Doc, str]]
    targets: Callable[[Doc], Targets]


def write_json(out: str | Path, name: str, doc: Doc) -> Path:
    """``doc`` as ``out/name``, written atomically (the folder is created)."""
    from rollcam.common.files import write_atomic

    path = Path(out) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, (json.dumps(doc, indent=1) + "\n").encode())
    return path


def missed(targets: Targets) -> list[str]:
    """``name (value op limit)`` of every target that failed."""
    return [f"{name} ({t['value']} {t['op']} {t['limit']} failed)" for name, t in targets.items() if t["pass"] is False]


def _target(value: Any, op: str, limit: float, ok: bool | None) -> dict[str, Any]:
    return {"value": value, "op": op, "limit": limit, "pass": ok}


def _no_arguments(p: argparse.ArgumentParser) -> None:
    pass


# --------------------------------------------------------------------------------------------- render
def _render_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="static scene and every ego preset, fewer methods and frames")
    p.add_argument("--size", type=value_type(parse_size), default=(1920, 1080), metavar="WxH",
                   help="frame size (default: the study's 1920x1080)")
    p.add_argument("--scenes", type=value_type(name_list), default=None,
                   help="comma-separated subset of normal,fast,normal_ego,fast_ego,pan_ego,walk_ego,drone_ego")
    p.add_argument("--props", action="store_true", help="street props in the scenes (parked cars, trees, poles, ...)")


def _render(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .bench import run_bench
    from .render_report import format_table

    overrides = {"scenes": args.scenes} if args.scenes else {}
    if args.props:
        overrides["props"] = True
    doc = run_bench(*args.size, quick=args.quick, out_dir=args.out, progress=progress.status, **overrides)
    return doc, format_table(doc)


def _render_targets(doc: Doc) -> Targets:
    return {name: _target(t["value"], t["op"], t["limit"], t["pass"]) for name, t in doc["targets"].items()}


# -------------------------------------------------------------------------------------------- realism
def _realism_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenes", type=_COUNT, default=10, help="street scenes (default: %(default)s)")
    p.add_argument("--seed", type=value_type(int, "an integer"), default=0, help="first scene's seed (default: 0)")
    p.add_argument("--detector", action="append", metavar="SPEC",
                   help="a detector spec to score (repeatable; default: ssdlite on 3x2 tiles, and hog)")
    p.add_argument("--times", default="daylight", metavar="LIST",
                   help="times of day, comma list, 'daylight' (morning, noon, afternoon: the targets') or 'all'")
    p.add_argument("--gallery", metavar="DIR", help="also write a contact sheet per time of day into DIR")
    p.add_argument("--lens", metavar="K=V,...", default="",
                   help="the lens in front of the sensor, e.g. vignette=0.3,lens_blur_px=1 (docs/optics.md)")
    p.add_argument("--picture", metavar="K=V,...", default="",
                   help="the ISP's last steps, e.g. sharpen=0.5,jpeg_quality=85 (docs/optics.md)")
    p.add_argument("--no-shadows", dest="shadows", action="store_false",
                   help="the walkers without their shadows on the ground (emu: shadows=off)")


def _steps(kind: type, flag: str, text: str) -> Any:
    """A ``LensOptics`` / ``PictureSteps`` from ``--lens`` / ``--picture`` text (``name=value`` pairs)."""
    import dataclasses

    fields = {f.name: f.type for f in dataclasses.fields(kind)}
    values: dict[str, Any] = {}
    for item in filter(None, text.split(",")):
        name, sep, raw = item.partition("=")
        if not sep or name not in fields:
            raise ConfigError(f"{flag}: {item!r} is not NAME=VALUE with NAME one of {sorted(fields)}")
        try:
            values[name] = int(raw) if name == "jpeg_quality" else float(raw)
        except ValueError:
            raise ConfigError(f"{flag}: {name}={raw!r} is not a number") from None
    return kind(**values)


def _realism(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from rollcam.sim.scenegen import DAYLIGHT, TIMES_OF_DAY

    from .realism import DETECTORS, format_realism, realism, write_gallery

    times = {"daylight": DAYLIGHT, "all": tuple(TIMES_OF_DAY)}.get(args.times) or tuple(args.times.split(","))
    bad = [t for t in times if t not in TIMES_OF_DAY]
    if bad:
        raise ConfigError(f"--times: {bad[0]!r} is not one of {list(TIMES_OF_DAY)}, 'daylight' or 'all'")
    from rollcam.sim.optics import LensOptics
    from rollcam.sim.picture import PictureSteps

    doc = realism(detectors=args.detector or DETECTORS, n_scenes=args.scenes, seed=args.seed, times=times,
                  lens=_steps(LensOptics, "--lens", args.lens), picture=_steps(PictureSteps, "--picture", args.picture),
                  shadows=args.shadows, progress=lambda done, total: progress.status(f"frame {done}/{total}"))
    write_json(args.out, "realism.json", doc)
    if args.gallery:
        doc["gallery"] = [str(p) for p in write_gallery(args.gallery, seed=args.seed)]
    return doc, format_realism(doc)


REALISM_RECALL_TARGET = 0.7
"""Recall the detectors must reach on the fair daylight walkers: ssdlite at precision >= 0.8, hog at its default."""


def _realism_targets(doc: Doc) -> Targets:
    out: Targets = {}
    for spec, rep in doc["detectors"].items():
        name = spec.split("?")[0]
        if name == "ssdlite":
            point = rep.get("at_precision_0.8")
            recall = None if point is None else point["recall"]
            out[f"{name} recall at P>=0.8"] = _target(recall, ">=", REALISM_RECALL_TARGET,
                                                      None if recall is None else recall >= REALISM_RECALL_TARGET)
        elif name == "hog":
            recall = rep["at_default"]["recall"]
            out["hog recall"] = _target(recall, ">=", REALISM_RECALL_TARGET,
                                        None if recall is None else recall >= REALISM_RECALL_TARGET)
    return out


# --------------------------------------------------------------------------------------------- detect
def _detect_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    p.add_argument("--onnx", action="append", metavar="MODEL", help="also time onnx:MODEL (repeatable)")


def _detect(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .detect import detect_bench, format_detect_bench

    doc = detect_bench(quick=args.quick, onnx=args.onnx or (), say=progress.status)
    write_json(args.out, "detect_bench.json", doc)
    return doc, format_detect_bench(doc)


def _detect_targets(doc: Doc) -> Targets:
    o = doc["loop_overhead"]
    return {"bookkeeping_ms": _target(o["bookkeeping_ms_median"], "<=", o["target_bookkeeping_ms"],
                                      o["meets_target"])}


# ------------------------------------------------------------------------------------------------ ptc
def _ptc_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sensor", nargs="?", default="imx219", metavar="SENSOR",
                   help="emulated sensor to measure (default: %(default)s)")


def _ptc(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .ptc import format_ptc, run_ptc

    progress.status(f"flat-field pairs of emu:{args.sensor}")
    result = run_ptc(args.sensor, args.out)  # writes ptc.json and ptc.png
    return result.to_json(), f"{format_ptc(result)}\nwrote {Path(args.out) / 'ptc.png'}"


def _ptc_targets(doc: Doc) -> Targets:
    return {f"{name}_error": _target(round(err, 5), "|x| <=", PTC_TOLERANCE, abs(err) <= PTC_TOLERANCE)
            for name, err in doc["errors"].items()}


# --------------------------------------------------------------------------------------------- sensor
def _quick_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="at 480x270 instead of 1920x1080")


def _sensor(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .sensor_bench import format_sensor_bench, run_sensor_bench

    progress.status("noise, mosaic, packing and adaptive blur")
    doc = run_sensor_bench(quick=args.quick)
    write_json(args.out, "sensor_bench.json", doc)
    return doc, format_sensor_bench(doc)


def _sensor_targets(doc: Doc) -> Targets:
    o, a = doc["sensor_overhead"], doc["adaptive_blur"]
    return {"sensor_overhead_vs_rs_frame": _target(o["overhead_vs_rs_frame"], "<=", o["target"],
                                                   o["overhead_vs_rs_frame"] <= o["target"]),
            "raw_frame_ms": _target(o["raw_frame_ms"], "<=", o["raw_frame_target_ms"],
                                    o["raw_frame_ms"] <= o["raw_frame_target_ms"]),
            "adaptive_blur_evaluation_ratio": _target(a["evaluation_ratio"], ">=", a["target_ratio"],
                                                      a["evaluation_ratio"] >= a["target_ratio"])}


# ------------------------------------------------------------------------------------------------ uvc
def _uvc(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    require("usb.core", "pyusb", feature="rollcam bench uvc")  # before the codec half, not after it
    from .uvc import format_uvc, run_uvc_bench

    progress.status("UVC payload packing and parsing")
    doc = run_uvc_bench()
    write_json(args.out, "uvc.json", doc)
    return doc, format_uvc(doc)


def _uvc_targets(doc: Doc) -> Targets:
    t = doc["target"]
    return {"pack_parse_iso_3072_mb_s": _target(t["value_mb_s"], t["op"], t["limit_mb_s"], t["pass"])}


# ----------------------------------------------------------------------------------------------- soak
def _soak_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--minutes", type=value_type(positive_float, "a number of minutes > 0"), default=None,
                   help="how long to stream (default: 10, or 5 with --cameras N)")
    p.add_argument("--size", type=value_type(parse_size), default=None, metavar="WxH",
                   help="frame size (default: 1920x1080, or 1280x720 with --cameras N)")
    p.add_argument("--scene", default="street", choices=("street", "chart", "flat"),
                   help="scene (default: street; flat isolates pacing from rendering cost)")
    p.add_argument("--rt-priority", type=value_type(positive_int, "an integer >= 1"), default=None, metavar="N",
                   help="run the pump's waits and the reader under SCHED_FIFO priority N")
    p.add_argument("--hog", action="store_true",
                   help="run a CPU hog (yes > /dev/null) for the whole run; target: 0 dropped at 720p or less, "
                        "<= 1 %% dropped above")
    p.add_argument("--memory", action="store_true",
                   help="instead: the RSS curve of 'rollcam emulate' at 1080p with one MJPEG reader (<= 500 MB)")
    p.add_argument("--cameras", type=_COUNT, default=1, metavar="N",
                   help="N >= 2: one 'rollcam emulate --rig' serving N cameras, every MJPEG stream read over HTTP; "
                        "target: 0 dropped per camera (default: 1, the in-process V4L2 device)")
    p.add_argument("--sync", default=None, metavar="free|hw",
                   help="with --cameras N: the rig's sync, free-running or one hardware trigger (default: free)")
    p.add_argument("--physics", type=value_type(parse_bool), default=None, metavar="on|off",
                   help="with --cameras N: the cameras' sensor model (default: on, the default blur bound; off: the "
                        "clean picture 'rollcam emulate' serves by default)")


def _soak(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .soak import format_memory_report, format_report, format_rig_report, run_memory_soak, run_rig_soak, run_soak

    rig = args.cameras > 1
    for flag, given in (("--memory", args.memory), ("--hog", args.hog), ("--rt-priority", args.rt_priority)):
        if rig and given:
            raise ConfigError(f"bench soak: {flag} applies to the one-camera soak, not to --cameras {args.cameras}")
    for flag, given in (("--sync", args.sync), ("--physics", args.physics)):
        if not rig and given is not None:
            raise ConfigError(f"bench soak: {flag} needs --cameras N (N >= 2)")
    minutes = args.minutes or (5.0 if rig else 10.0)
    if args.memory:
        doc = run_memory_soak(minutes, size=args.size or (1920, 1080), progress=progress.status)
        write_json(args.out, "soak_memory.json", doc)
        return doc, format_memory_report(doc)
    if rig:
        size = args.size or (1280, 720)
        physics = args.physics is not False
        doc = run_rig_soak(minutes, cameras=args.cameras, size=size, scene=args.scene, sync=args.sync or "free",
                           physics=physics, progress=progress.status)
        tail = "" if physics else "_clean"
        write_json(args.out, f"soak_rig{args.cameras}_{args.scene}_{size[0]}x{size[1]}{tail}.json", doc)
        return doc, format_rig_report(doc)
    size = args.size or (1920, 1080)
    doc = run_soak(minutes, size=size, scene=args.scene, rt_priority=args.rt_priority, progress=progress.status,
                   hog=args.hog)
    c = doc["config"]
    tail = ("" if size == (1920, 1080) else f"_{size[0]}x{size[1]}") + ("_rt" if c["rt_priority"] is not None
                                                                      else "") + ("_hog" if args.hog else "")
    write_json(args.out, f"soak_{c['scene']}{tail}.json", doc)
    return doc, format_report(doc)


def _doc_targets(doc: Doc) -> Targets:
    return {name: _target(t["value"], t.get("op", "=="), t["limit"], t["pass"]) for name, t in doc["targets"].items()}


# ---------------------------------------------------------------------------------------------- mjpeg
def _mjpeg(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .mjpeg import format_mjpeg_bench, run_mjpeg_bench

    progress.status("JPEG encode and 8 clients of one MJPEG server")
    doc = run_mjpeg_bench(quick=args.quick)
    write_json(args.out, "mjpeg.json", doc)
    return doc, format_mjpeg_bench(doc)


# -------------------------------------------------------------------------------------------- dataset
def _dataset_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--size", type=value_type(parse_size), default=(1920, 1080), metavar="WxH",
                   help="image size (default: 1920x1080)")


def _dataset(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .dataset import bench_dataset, format_report

    doc = bench_dataset(args.size, say=progress.status)
    write_json(args.out, "dataset_bench.json", doc)
    return doc, format_report(doc)


# ------------------------------------------------------------------------------------------------ imu
def _imu_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="half an hour of IMU, 640x480 frames (< 1 min)")
    p.add_argument("--detector", default=None, metavar="NAME",
                   help="also compare this detector's recall on GS, RS and gyro/flow-corrected RS (e.g. personnet)")


def _imu(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .imu import format_report, run_imu_bench

    doc = run_imu_bench(quick=args.quick, detector=args.detector, say=progress.status)
    write_json(args.out, "imu_bench.json", doc)
    return doc, format_report(doc)


# ----------------------------------------------------------------------------------------------- view
def _view_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=value_type(positive_float, "a number of seconds > 0"), default=10.0,
                   help="length of each phase (default: %(default)s)")
    p.add_argument("--size", type=value_type(parse_size), default=(1920, 1080), metavar="WxH",
                   help="frame size (default: 1920x1080)")
    p.add_argument("--no-browser", action="store_true", help="a Python WebSocket client instead of Chromium")


def _view(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .view import format_report, run_view_bench

    doc = run_view_bench(args.seconds, args.size, browser=False if args.no_browser else None, out_dir=args.out,
                         say=progress.status)
    write_json(args.out, "view_bench.json", doc)
    return doc, format_report(doc)


# -------------------------------------------------------------------------------------------- preload
def _preload(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .preload import format_report, run_preload_bench

    doc = run_preload_bench(frames=args.frames, say=progress.status)
    write_json(args.out, "preload.json", doc)
    return doc, format_report(doc)


def _preload_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--frames", type=_COUNT, default=30, help="frames per round (default: %(default)s)")


# ------------------------------------------------------------------------------------------ personnet
def _personnet_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", default=None, metavar="ONNX", help="a rollcam train model.onnx (default: the packaged "
                   "personnet)")
    p.add_argument("--dataset", default=None, metavar="DIR", help="rollcam dataset whose val and test splits to "
                   "score (without it the mAP targets do not apply)")
    p.add_argument("--empty-scenes", type=_COUNT, default=10,
                   help="scenes of empty street frames, x 5 cameras x 3 times (default: %(default)s)")


def _personnet(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .personnet import format_report, personnet_bench

    doc = personnet_bench(args.model, args.dataset, args.empty_scenes, say=progress.status)
    write_json(args.out, "personnet.json", doc)
    return doc, format_report(doc)


# -------------------------------------------------------------------------------------------- flicker
def _flicker_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--size", type=value_type(parse_size), default=(1920, 1080), metavar="WxH",
                   help="frame size of the cost runs (default: 1920x1080)")
    p.add_argument("--frames", type=_COUNT, default=10, help="frames per case (default: %(default)s)")


def _flicker(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .flicker import format_report, run_flicker_bench

    doc = run_flicker_bench(args.size, args.frames, say=progress.status)
    write_json(args.out, "flicker.json", doc)
    return doc, format_report(doc)


# --------------------------------------------------------------------------------------------- device
def _device_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="3 reads after 1 warm-up per row instead of 8 after 2")
    p.add_argument("--frames", type=_COUNT, default=None, help="timed reads per row (default: 8, quick 3)")
    p.add_argument("--size", type=value_type(parse_size), default=(1920, 1080), metavar="WxH",
                   help="frame size (default: the issue's 1920x1080)")
    p.add_argument("--rows", type=value_type(name_list), default=None,
                   help="comma-separated subset of static_bgr3,static_yuyv,static_raw10,static_yuyv_noblur,"
                        "ego_walk,ego_pan,ego_drone,ego_vehicle,night_steady,night_lights")


def _device(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .device import format_report, row_uris, run_device_bench

    bad = [r for r in args.rows or () if r not in row_uris(args.size)]
    if bad:
        raise ConfigError(f"--rows: {bad[0]!r} is not one of {list(row_uris(args.size))}")
    frames = args.frames or (3 if args.quick else 8)
    doc = run_device_bench(args.size, frames=frames, warmup=1 if args.quick else 2,
                           only=tuple(args.rows) if args.rows else None, say=progress.status)
    write_json(args.out, "device.json", doc)
    return doc, format_report(doc)


# ------------------------------------------------------------------------------------------- insensor
def _insensor_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenes", type=_COUNT, default=4, help="street scenes, x 3 cameras (default: %(default)s)")
    p.add_argument("--frames", type=_COUNT, default=8, help="frames per camera (default: %(default)s)")
    p.add_argument("--host-detector", default="personnet", metavar="SPEC",
                   help="the host pipeline's detector, on the ISP picture (default: %(default)s)")
    p.add_argument("--network", default="personnet-raw", metavar="SPEC",
                   help="the in-sensor network, on the raw mosaic (default: %(default)s)")


def _insensor(args: argparse.Namespace, progress: Any) -> tuple[Doc, str]:
    from .insensor import format_report, run_insensor_bench

    doc = run_insensor_bench(scenes=args.scenes, frames=args.frames, host=args.host_detector, net=args.network,
                             say=progress.status)
    write_json(args.out, "insensor.json", doc)
    return doc, format_report(doc)


STUDIES: dict[str, Study] = {s.name: s for s in (
    Study("render", "speed versus error of the ways to make an RS frame (bench.json, bench.png)",
          _render_arguments, _render, _render_targets),
    Study("realism", "do detectors trained on photographs (ssdlite, hog) find the rendered walkers? (~5 min)",
          _realism_arguments, _realism, _realism_targets),
    Study("detect", "detect-loop overhead and each built-in detector's time per frame",
          _detect_arguments, _detect, _detect_targets),
    Study("ptc", "photon transfer curve of an emulated sensor, measured from its frames (ptc.png)",
          _ptc_arguments, _ptc, _ptc_targets),
    Study("sensor", "cost of the sensor model (noise, mosaic, packing) and of adaptive motion blur",
          _quick_argument, _sensor, _sensor_targets),
    Study("uvc", "UVC payload packing and parsing throughput (a few seconds)", _no_arguments, _uvc, _uvc_targets),
    Study("soak", "stream an emulated 1080p30 RS V4L2 device in real time (or N cameras of one 'rollcam emulate "
          "--rig' over HTTP): drops, jitter, latency",
          _soak_arguments, _soak, _doc_targets),
    Study("mjpeg", "MJPEG serving: one 1080p JPEG encode per frame, and 8 clients of one 1080p30 stream",
          _quick_argument, _mjpeg, _doc_targets),
    Study("dataset", "dataset generation (vs render+encode, 1 vs 2 workers) and evaluation metric speed",
          _dataset_arguments, _dataset, _doc_targets),
    Study("imu", "IMU noise (Allan fit against the config), calibration (line time, offset), gyro and flow RS "
          "correction (error vs GS, time per frame)",
          _imu_arguments, _imu, _doc_targets),
    Study("view", "the live view at 1080p30: the device's frame rate with a page watching, the page's update rate, "
          "cost per frame", _view_arguments, _view, _doc_targets),
    Study("preload", "per-frame cost of rollcam run's preload path beyond making the frame (1920x1080 YUYV)",
          _preload_arguments, _preload, _doc_targets),
    Study("personnet", "the packaged personnet detector: size, ms per 640x360 frame on one core, mAP, empty-frame FP",
          _personnet_arguments, _personnet, _doc_targets),
    Study("flicker", "modulated light: cost of flicker on vs off (night street RS) and the bands vs analytic",
          _flicker_arguments, _flicker, _doc_targets),
    Study("device", "frames through open_camera(uri).read() as users stream them: sensor model, ego presets, "
          "static RS vs a frame copy, night lights (issue 42's targets)", _device_arguments, _device, _doc_targets),
    Study("insensor", "ISP + host detector against the in-sensor detector on raw: accuracy, latency, bytes, energy",
          _insensor_arguments, _insensor, _doc_targets),
)}
"""Study name -> study, in the order ``rollcam bench --help`` lists them."""
