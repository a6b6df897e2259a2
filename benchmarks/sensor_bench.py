"""Costs of the sensor model: ``rollcam bench sensor``.

Measurements on a seeded street of the study's pedestrians (20 walkers, static camera; "fast" unless said):

- ``sensor_overhead``: on an IMX219 1920x1080 rolling-shutter stream, the time of one clean BGR3 frame
  (``SyntheticCamera.frame``, the study's render), of the linear-radiance render the sensor path needs
  (``Renderer.render_linear``: painted lines over the cached composite), and of the sensor stages on it:
  EMVA noise with mosaic (one kernel, reading the composite in place), then CSI-2 RAW10 packing (pRAA).
  Overhead = (noise + mosaic + packing) / RS frame time (target <= 25 %), and the whole raw frame
  (``SyntheticCamera.frame`` in pRAA, blur off) against half the 1080p30 frame period (target). Beside them,
  for processed formats, the preview ISP on the same samples (demosaic, levels, gamma: what YUYV adds). Medians
  over frames at different indices, all in one run.
- ``raw_streams``: whole pRAA frames (``SyntheticCamera.frame``: truth, exposure integration, noise, packing)
  on the study's "normal" and "fast" pedestrians, with motion blur at the default 0.5 px bound and off.
- ``adaptive_blur``: on the study's camera (letsroll, 10 ms exposure), the adaptive plan (bound 0.5 px)
  against fixed dense sampling (every line at one sample per 0.05 px of the fastest motion): scene
  evaluations (line renders), wall time, and the error of the adaptive and of the mid-exposure point-sampled
  frame against the dense one, in 8-bit sRGB DN over every pixel and channel.
- ``optics``: each lens effect (``rollcam.sim.optics``: vignetting, Gaussian PSF, defocus disc) on the linear
  radiance of one IMX219 1920x1080 street frame, and each ISP picture step (``rollcam.sim.picture.PictureSteps``:
  sharpening, a JPEG round trip) on its 8-bit picture; then whole clean BGR3 frames with every effect off (the
  path with no lens work), with a phone-like lens (vignette 0.3, 1 px PSF: the linear render and its encoding
  added) and with the lens and both ISP steps, and whole raw pRAA frames (blur bound 0.5 px) without and with
  that lens. Medians, ms per frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rollcam.sim.codecs import codec
from rollcam.sim.exposure import DEFAULT_BOUND_PX, dense_plan, integrate, plan_samples
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.isp import preview
from rollcam.sim.optics import LensOptics
from rollcam.sim.picture import PictureSteps
from rollcam.sim.render.renderer import srgb_lut

from .cameras import camera

_LUT = srgb_lut()


def _median_ms(fn: Callable[[int], Any], n: int) -> float:
    fn(0)  # warm-up (numba dispatch, first allocations)
    out = []
    for i in range(1, n + 1):
        t = time.perf_counter()
        fn(i)
        out.append(time.perf_counter() - t)
    return float(np.median(out) * 1e3)


def _srgb(lin: np.ndarray) -> np.ndarray:
    idx = np.clip(lin, 0.0, 1.0) * (_LUT.size - 1) + 0.5
    return _LUT[idx.astype(np.int64)].astype(np.float64)


def sensor_overhead(size: tuple[int, int] = (1920, 1080), frames: int = 5, seed: int = 0) -> dict[str, Any]:
    """Noise + mosaic + packing time against the RS frame time (see the module docstring)."""
    sensor = load_sensor("imx219")
    street = {"scene": "street", "seed": seed, "speed": "fast"}
    clean = camera(sensor, street, size=size)
    raw = camera(sensor, street, size=size, pixel_format="pRAA", blur_px=0.0)
    pipe = raw.pipeline
    assert pipe is not None
    frame_ms = _median_ms(lambda i: clean.frame(i), frames)
    exp_ns = raw.settings.exposure_ns
    buf = np.empty((size[1], size[0], 3), np.float32)  # reused, as the stream does
    stages: dict[str, list[float]] = {"render": [], "noise": [], "pack": [], "isp": []}
    for i in range(frames + 1):  # the first round warms up
        t0 = time.perf_counter()
        radiance = raw.renderer.render_linear(raw.line_times_ns(i), out=buf).radiance
        t1 = time.perf_counter()
        dn = pipe.samples(radiance, exp_ns, i)
        t2 = time.perf_counter()
        codec("pRAA").encode(dn, sample_bits=10)
        t3 = time.perf_counter()
        preview(dn, sensor.bayer_order, pipe.isp)
        t4 = time.perf_counter()
        if i:
            for key, dt in (("render", t1 - t0), ("noise", t2 - t1), ("pack", t3 - t2), ("isp", t4 - t3)):
                stages[key].append(dt)
    linear_ms, noise_ms, pack_ms, isp_ms = (float(np.median(stages[k]) * 1e3)
                                            for k in ("render", "noise", "pack", "isp"))
    raw_frame_ms = _median_ms(lambda i: raw.frame(i), frames)
    period_ms = raw.settings.timing.frame_period_ns / 1e6
    return {"sensor": "imx219", "size": f"{size[0]}x{size[1]}", "format": "pRAA",
            "rs_frame_ms": round(frame_ms, 3), "linear_render_ms": round(linear_ms, 3),
            "noise_mosaic_ms": round(noise_ms, 3), "pack_ms": round(pack_ms, 3),
            "raw_frame_ms": round(raw_frame_ms, 3), "isp_preview_ms": round(isp_ms, 3),
            "frame_period_ms": round(period_ms, 3), "raw_frame_target_ms": round(period_ms / 2, 3),
            "overhead_vs_rs_frame": round((noise_ms + pack_ms) / frame_ms, 4),
            "overhead_vs_linear_render": round((noise_ms + pack_ms) / linear_ms, 4), "target": 0.25}


def raw_streams(size: tuple[int, int] = (1920, 1080), frames: int = 3, seed: int = 0) -> dict[str, Any]:
    """Median whole raw-frame times per walker speed, blur at the default bound and off (module docstring)."""
    sensor = load_sensor("imx219")
    out: dict[str, Any] = {"sensor": "imx219", "size": f"{size[0]}x{size[1]}", "format": "pRAA"}
    for speed in ("normal", "fast"):
        street = {"scene": "street", "seed": seed, "speed": speed}
        for key, blur in (("blur", DEFAULT_BOUND_PX), ("noblur", 0.0)):
            cam = camera(sensor, street, size=size, pixel_format="pRAA", blur_px=blur)
            out[f"{speed}_{key}_ms"] = round(_median_ms(lambda i, c=cam: c.frame(i + 2), frames), 3)
    return out


def adaptive_blur(size: tuple[int, int] = (1920, 1080), frame: int = 3, seed: int = 0,
                  bound_px: float = DEFAULT_BOUND_PX, dense_step_px: float = 0.05) -> dict[str, Any]:
    """Adaptive against dense exposure sampling on the fast pedestrians (see the module docstring)."""
    sensor = load_sensor("letsroll")
    cam = camera(sensor, {"scene": "street", "seed": seed, "speed": "fast"}, size=size, exposure_ns=10_000_000)
    r, s = cam.renderer, cam.settings
    mid = cam.line_times_ns(frame)
    starts = mid - s.exposure_ns // 2
    t = time.perf_counter()
    plan = plan_samples(r, starts, s.exposure_ns, bound_px=bound_px)
    adaptive = integrate(r, plan)
    adaptive_s = time.perf_counter() - t
    dense = dense_plan(plan, dense_step_px)
    t = time.perf_counter()
    ref = integrate(r, dense)
    dense_s = time.perf_counter() - t
    point = r.render_lines(mid, linear=True).linear
    assert point is not None
    ref8 = _srgb(ref.linear)
    err = np.abs(_srgb(adaptive.linear) - ref8)
    err_point = np.abs(_srgb(point) - ref8)
    moving = plan.n > 1
    return {"sensor": "letsroll", "size": f"{size[0]}x{size[1]}", "exposure_ns": s.exposure_ns,
            "bound_px": bound_px, "dense_step_px": dense_step_px,
            "max_speed_px_s": round(float(plan.speed_px_s.max()), 1),
            "lines_moving": int(moving.sum()), "adaptive_samples_max": int(plan.n.max()),
            "dense_samples_per_line": int(dense.n[0]),
            "adaptive_evaluations": adaptive.evaluations, "dense_evaluations": ref.evaluations,
            "evaluation_ratio": round(ref.evaluations / max(adaptive.evaluations, 1), 2),
            "adaptive_lines_painted": adaptive.lines_painted, "dense_lines_painted": ref.lines_painted,
            "adaptive_s": round(adaptive_s, 3), "dense_s": round(dense_s, 3),
            "mean_abs_err_dn": round(float(err.mean()), 4), "max_abs_err_dn": round(float(err.max()), 2),
            "point_sampled_mean_abs_err_dn": round(float(err_point.mean()), 4),
            "point_sampled_max_abs_err_dn": round(float(err_point.max()), 2), "target_ratio": 5.0}


PHONE_LENS = LensOptics(vignette=0.3, lens_blur_px=1.0)
"""The lens of the ``optics`` measurement's whole frames: a phone camera's light fall-off and softness."""
PHONE_ISP = PictureSteps(sharpen=1.0, jpeg_quality=85)


def optics_costs(size: tuple[int, int] = (1920, 1080), frames: int = 5, seed: int = 0) -> dict[str, Any]:
    """Milliseconds per frame of each lens effect and ISP picture step, and of whole clean frames with them
    (see the module docstring)."""
    sensor = load_sensor("imx219")
    street = {"scene": "street", "seed": seed, "speed": "normal"}
    plain = camera(sensor, street, size=size)
    lin = plain.renderer.render_lines(plain.line_times_ns(0), linear=True).linear
    assert lin is not None
    picture = plain.frame(0).data
    buf = np.empty(lin.shape, np.float32)
    lens = {"vignette_0.3": LensOptics(vignette=0.3), "lens_blur_1px": LensOptics(lens_blur_px=1.0),
            "lens_blur_2px": LensOptics(lens_blur_px=2.0), "defocus_2px": LensOptics(defocus_px=2.0),
            "defocus_8px": LensOptics(defocus_px=8.0)}
    steps = {"sharpen_1": PictureSteps(sharpen=1.0), "jpeg_85": PictureSteps(jpeg_quality=85),
             "jpeg_50": PictureSteps(jpeg_quality=50)}
    out: dict[str, Any] = {"sensor": "imx219", "size": f"{size[0]}x{size[1]}"}
    for name, optics in lens.items():
        out[f"{name}_ms"] = round(_median_ms(lambda i, o=optics: o.apply(lin, buf), frames), 3)
    for name, step in steps.items():
        out[f"{name}_ms"] = round(_median_ms(lambda i, st=step: st.apply(picture), frames), 3)
    lensed = camera(sensor, street, size=size, lens=PHONE_LENS)
    out["frame_off_ms"] = round(_median_ms(lambda i: plain.frame(i), frames), 3)
    out["frame_lens_ms"] = round(_median_ms(lambda i: lensed.frame(i), frames), 3)
    out["frame_lens_isp_ms"] = round(_median_ms(lambda i: PHONE_ISP.apply(lensed.frame(i).data), frames), 3)
    raw, raw_lens = (camera(sensor, street, size=size, pixel_format="pRAA", lens=o)
                     for o in (LensOptics(), PHONE_LENS))
    out["raw_frame_off_ms"] = round(_median_ms(lambda i: raw.frame(i), frames), 3)
    out["raw_frame_lens_ms"] = round(_median_ms(lambda i: raw_lens.frame(i), frames), 3)
    return out


def run_sensor_bench(quick: bool = False) -> dict[str, Any]:
    """All four measurements; ``quick`` runs them at 480x270."""
    size = (480, 270) if quick else (1920, 1080)
    return {"sensor_overhead": sensor_overhead(size), "raw_streams": raw_streams(size),
            "adaptive_blur": adaptive_blur(size), "optics": optics_costs(size)}


def format_sensor_bench(doc: dict[str, Any]) -> str:
    """The rows ``rollcam bench sensor`` prints."""
    o, a = doc["sensor_overhead"], doc["adaptive_blur"]
    verdict = "PASS" if o["overhead_vs_rs_frame"] <= o["target"] else "MISS"
    lines = [f"sensor_overhead {o['sensor']} {o['size']} {o['format']}: RS frame {o['rs_frame_ms']} ms, linear render "
             f"{o['linear_render_ms']} ms, noise+mosaic {o['noise_mosaic_ms']} ms, packing {o['pack_ms']} ms, "
             f"raw frame {o['raw_frame_ms']} ms; preview ISP {o['isp_preview_ms']} ms",
             f"  {verdict} overhead {o['overhead_vs_rs_frame']:.1%} of the RS frame (target <= {o['target']:.0%}); "
             f"{o['overhead_vs_linear_render']:.1%} of the linear render",
             f"  {'PASS' if o['raw_frame_ms'] <= o['raw_frame_target_ms'] else 'MISS'} raw frame {o['raw_frame_ms']} ms"
             f" "
             f"(target <= half the {o['frame_period_ms']} ms frame period: {o['raw_frame_target_ms']} ms)"]
    r = doc.get("raw_streams")
    if r:
        lines.append(f"raw_streams {r['sensor']} {r['size']} {r['format']} frame: normal walkers "
                     f"{r['normal_blur_ms']} ms (blur off {r['normal_noblur_ms']} ms), fast walkers "
                     f"{r['fast_blur_ms']} ms (blur off {r['fast_noblur_ms']} ms), blur bound {DEFAULT_BOUND_PX} px")
    verdict = "PASS" if a["evaluation_ratio"] >= a["target_ratio"] else "MISS"
    lines += [f"adaptive_blur {a['sensor']} {a['size']} exposure {a['exposure_ns']} ns, fastest "
              f"{a['max_speed_px_s']} px/s, {a['lines_moving']} lines moving: adaptive {a['adaptive_evaluations']} "
              f"line evaluations (max {a['adaptive_samples_max']}/line, {a['adaptive_s']} s), dense "
              f"{a['dense_evaluations']} ({a['dense_samples_per_line']}/line, {a['dense_s']} s)",
              f"  {verdict} {a['evaluation_ratio']}x fewer evaluations (target >= {a['target_ratio']}x); error vs "
              f"dense: mean {a['mean_abs_err_dn']} DN, max {a['max_abs_err_dn']} DN (point-sampled: mean "
              f"{a['point_sampled_mean_abs_err_dn']}, max {a['point_sampled_max_abs_err_dn']} DN)"]
    p = doc.get("optics")
    if p:
        effects = ", ".join(f"{k[:-3]} {v} ms" for k, v in p.items() if k.endswith("_ms") and "frame_" not in k)
        lines += [f"optics {p['sensor']} {p['size']} per frame: {effects}",
                  f"  clean BGR3 frame: effects off {p['frame_off_ms']} ms, phone lens {p['frame_lens_ms']} ms, "
                  f"lens + sharpen + JPEG {p['frame_lens_isp_ms']} ms; raw pRAA frame: off {p['raw_frame_off_ms']} "
                  f"ms, phone lens {p['raw_frame_lens_ms']} ms"]
    return "\n".join(lines)
