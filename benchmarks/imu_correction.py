"""The correction half of `rollcam bench imu`: gyro and flow RS correction against the GS frame of the same instant.

For ego-motion cases (camera panning, a drone's rotation and vibration, a vehicle) and one of object motion
only (a static camera, fast walkers), consecutive frame pairs of the same instants are rendered under both
shutters; each RS frame is corrected from the device's gyro (``rollcam.sim.rscorrect``) and, the optional
method, from its dense optical flow to the previous RS frame (``rollcam.host.correction.flow``), and compared
with the GS frame: mean absolute error (8-bit, over pixels whose source lies inside the frame for both
corrections), box error (mean absolute edge offset from the GS box, px: the RS box as rendered, and as each
correction maps it; objects whose GS or RS box meets the frame's edge are left out and counted, since a clipped
box is not the object's extent and the flow has no pixels beyond the edge), each correction's time per frame
(median), and optionally the recall of a detector against the GS boxes on GS, RS and both corrections (the
study's two pipelines side by side).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

CASES = {"pan": "ego=pan&pedestrians=12", "drone": "ego=drone&pedestrians=12",
         "vehicle": "ego=vehicle&pedestrians=12", "objects": "ego=none&speed=fast&pedestrians=12"}
"""Case name -> emu: options: camera motion in the first three, object motion only in the last."""
METHODS = ("rs", "gyro", "flow")


def _box_error(a: Any, b: Any) -> float:
    return float(np.mean(np.abs(np.subtract(a, b))))


def _at_edge(box: Any, w: int, h: int) -> bool:
    x0, y0, x1, y1 = box
    return x0 <= 0 or y0 <= 0 or x1 >= w or y1 >= h


def _gyro_box(box: Any, rot: np.ndarray, k: tuple, w: int, h: int) -> tuple[float, float, float, float]:
    """An RS box as the gyro correction maps it (its edges' points through the per-line rotations)."""
    from rollcam.sim.rscorrect import forward_points

    x0, y0, x1, y1 = box
    s = np.linspace(0.0, 1.0, 16)
    # x extents are continuous (pixel i spans [i, i + 1)), y whole rows: both to OpenCV's pixel-centre coordinates
    xa, xb, ya, yb = x0 - 0.5, x1 - 0.5, y0, y1 - 1
    pts = np.concatenate([np.stack([xa + (xb - xa) * s, np.full_like(s, ya)], 1),
                          np.stack([xa + (xb - xa) * s, np.full_like(s, yb)], 1),
                          np.stack([np.full_like(s, xa), ya + (yb - ya) * s], 1),
                          np.stack([np.full_like(s, xb), ya + (yb - ya) * s], 1)])
    m = forward_points(pts, rot, k)
    return (max(m[:, 0].min() + 0.5, 0.0), max(m[:, 1].min(), 0.0), min(m[:, 0].max() + 0.5, w),
            min(m[:, 1].max() + 1, h))


def _flow_box(left: np.ndarray, right: np.ndarray, shift: np.ndarray, w: int, h: int
              ) -> tuple[float, float, float, float] | None:
    """An object's RS extent (per row ``left``..``right``, NaN where absent) moved by the flow correction: each
    row by the median displacement (``shift``, (h, w, 2) px) of the object's own pixels on it."""
    rows = np.flatnonzero(~np.isnan(left))
    if rows.size == 0:
        return None
    xs0, xs1, ys = [], [], []
    for r in rows:
        a, b = int(np.floor(left[r])), int(np.ceil(right[r]))
        d = np.median(shift[r, max(a, 0):max(min(b, w), a + 1)], axis=0)
        xs0.append(left[r] + d[0])
        xs1.append(right[r] + d[0])
        ys.append(r + d[1])
    return (max(min(xs0), 0.0), max(min(ys), 0.0), min(max(xs1), w), min(max(ys) + 1, h))


def correction_case(options: str, size: tuple[int, int], frames: int, detector: Any = None) -> dict[str, Any]:
    """One case of the correction study (see the module docstring): ``frames`` corrected frames."""
    from rollcam.host import open_camera
    from rollcam.host.correction.flow import dense_flow, image_velocity, unwarp_flow
    from rollcam.host.evaluation.truthmatch import RunningPR
    from rollcam.sim.rscorrect import gyro_line_rotations, unwarp

    w, h = size
    uri = f"emu:imx219?size={w}x{h}&imu=on&{options}"
    src = open_camera(uri)
    mae: dict[str, list[float]] = {m: [] for m in METHODS}
    box: dict[str, list[float]] = {m: [] for m in METHODS}
    ms: dict[str, list[float]] = {"gyro": [], "flow": []}
    pr = {k: RunningPR() for k in ("gs", *METHODS)}
    prev = None
    edge = 0
    for _ in range(frames + 1):  # the first pair only gives the flow its previous frame
        gs, rs = src.read_pair()
        if prev is None:
            prev = rs
            continue
        p = rs.imu.params
        times = rs.row_times_ns
        ref = int(times.min())
        imu = src.device.imager.imu.imu(src.spec, src.camera.camera)
        cover = imu.samples(int(times.min()) + p.time_offset_ns - 10**7, int(times.max()) + p.time_offset_ns + 10**7)
        k = tuple(rs.meta["intrinsics"])
        t0 = time.perf_counter()
        rot = gyro_line_rotations(cover, times, ref)
        out_g, valid_g = unwarp(rs.data, rot, k)
        t1 = time.perf_counter()
        velocity = image_velocity(dense_flow(rs.data, prev.data), times, prev.row_times_ns)
        out_f, valid_f = unwarp_flow(rs.data, velocity, times, ref)
        t2 = time.perf_counter()
        ms["gyro"].append((t1 - t0) * 1e3)
        ms["flow"].append((t2 - t1) * 1e3)
        valid = valid_g & valid_f
        g = gs.data.astype(np.int16)
        for m, img in zip(METHODS, (rs.data, out_g, out_f), strict=True):
            mae[m].append(float(np.abs(g - img.astype(np.int16))[valid].mean()))
        truth = src.camera.renderer.render_lines(times, truth_only=True).truth
        index = {int(a): i for i, a in enumerate(src.camera.renderer.actor_ids)}
        tau = (times - ref).astype(np.float64)[:, None, None]
        shift = -velocity.astype(np.float64) * tau  # each RS pixel's displacement to the reference instant
        for o in rs.objects or ():
            if o.box_gs is None or o.box_rs is None or o.visible <= 0.5 or o.id not in index:
                continue
            fb = _flow_box(truth.left[index[o.id]], truth.right[index[o.id]], shift, w, h)
            if fb is None:
                continue
            if _at_edge(o.box_gs, w, h) or _at_edge(o.box_rs, w, h):
                edge += 1
                continue
            box["rs"].append(_box_error(o.box_rs, o.box_gs))
            box["gyro"].append(_box_error(_gyro_box(o.box_rs, rot, k, w, h), o.box_gs))
            box["flow"].append(_box_error(fb, o.box_gs))
        if detector is not None:
            for name, img in (("gs", gs.data), ("rs", rs.data), ("gyro", out_g), ("flow", out_f)):
                pr[name].update(rs if name != "gs" else gs, detector.detect(img))
        prev = rs
    src.close()
    doc: dict[str, Any] = {
        "uri": uri, "frames": frames, "boxes": len(box["rs"]), "edge_boxes": edge,
        "mae_vs_gs": {m: float(np.mean(v)) for m, v in mae.items()},
        "box_error_px": {m: float(np.mean(v)) if v else None for m, v in box.items()},
        "correct_ms": {m: float(np.median(v)) for m, v in ms.items()}}
    if detector is not None:  # recall against the GS boxes: what each pipeline's detector sees
        doc["recall_vs_gs"] = {k: v.totals["gs"].recall for k, v in pr.items()}
    return doc
