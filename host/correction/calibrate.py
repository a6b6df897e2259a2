"""Camera-IMU calibration from a capture alone: the rolling shutter's line time and the camera-IMU time offset.

Gyro-image alignment of feature tracks, the approach of the rolling-shutter calibrations that use a gyro
(Karpenko et al. 2011, Kalibr's rolling-shutter camera-IMU model): corners are tracked between consecutive
rolling-shutter images (``cv2.goodFeaturesToTrack`` and pyramidal Lucas-Kanade, kept only when the backward
track returns within ``FB_MAX_PX``), and a track from pixel ``p1`` of frame i to ``p2`` of frame i+1 is
predicted by the rotation the gyro integrates between the two lines' instants:

    t(line v) = timestamp + exposure / 2 + v * line_time        (camera clock; the line's mid-exposure)
    Q(t)      = orientation integrated from the gyro at IMU time t + offset   (Kalibr: t_imu = t_cam + shift)
    p2'       = K proj(Q(t2)^T Q(t1) K^-1 p1)

``line_time`` and ``offset`` are fitted to minimise ``|p2' - p2|`` by a coarse grid search (robust truncated
cost) and then Levenberg-Marquardt with Huber weights (numpy only); their standard errors are the larger of
the Gauss-Newton covariance scaled by the residual variance and the covariance clustered by first image
(tracks from one image share its stretch of gyro noise). The model is rotation only: the capture should
rotate without translating (``ego=calib``), or translate little against the scene's depth.

Inputs, all files ``rollcam capture`` writes: the images and their ``frames.jsonl`` records (timestamp,
exposure, readout: the stamping convention, not the answer), ``imu.csv`` and ``camera.yaml`` (intrinsics and
``T_BS``, the camera-IMU rotation a calibration would also have estimated). The configured answer in
``camchain.yaml``'s ``line_delay`` / ``timeshift_cam_imu`` and the records' ``line_time_ns`` is never read.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.pose import rotation_vector_to_matrix

from ..recording.capture import read_capture
from ..recording.imu_export import CAMERA_YAML, IMU_CSV

RESULT_YAML = "camchain-imucam.yaml"
"""The result file, named as Kalibr names its camera-IMU result (``camchain-imucam-<bag>.yaml``)."""
FB_MAX_PX = 0.3
MAX_CORNERS = 400
GAPS = (1, 2, 3)
HUBER_K = 1.345  # Huber's 95 %-efficiency constant, in units of the residuals' robust sigma
GRID_OFFSET_STEP_S = 0.5e-3
GRID_LINE_STEPS = 16


@dataclass(frozen=True)
class CaptureInputs:
    """What the estimator reads from a capture: RS images with their stamps, the gyro, intrinsics, mounting."""

    images: tuple[Path, ...]
    timestamp_ns: np.ndarray  # (n,) int64, start of exposure of each image's first line
    exposure_ns: np.ndarray  # (n,) int64
    height: int
    bottom_up: bool
    intrinsics: tuple[float, float, float, float]
    R_cam_imu: np.ndarray
    imu_t_ns: np.ndarray  # (m,) int64
    gyro: np.ndarray  # (m, 3) rad/s, IMU axes


@dataclass(frozen=True)
class Tracks:
    """Feature tracks between pairs of images: the index of each image, the pixel in each."""

    frame: np.ndarray  # (n,) index of the first image of the pair
    frame2: np.ndarray  # (n,) index of the second
    p1: np.ndarray  # (n, 2) x, y in the first image
    p2: np.ndarray  # (n, 2) x, y in the second

    def __len__(self) -> int:
        return int(self.frame.shape[0])


@dataclass(frozen=True)
class Calibration:
    """The estimate: line time and camera-IMU offset (s) with their standard errors, and how well it fits."""

    line_time_s: float
    line_time_std_s: float
    offset_s: float
    offset_std_s: float
    rms_px: float
    tracks: int
    inliers: int
    images: int

    def to_json(self) -> dict[str, Any]:
        """The figures ``rollcam calibrate --json`` prints (ns for times, as the device clock counts)."""
        return {"line_time_ns": self.line_time_s * 1e9, "line_time_std_ns": self.line_time_std_s * 1e9,
                "timeshift_cam_imu_ns": self.offset_s * 1e9, "timeshift_cam_imu_std_ns": self.offset_std_s * 1e9,
                "rms_px": self.rms_px, "tracks": self.tracks, "inliers": self.inliers, "images": self.images}

    def __str__(self) -> str:
        return (f"line time {self.line_time_s * 1e9:.1f} +- {self.line_time_std_s * 1e9:.1f} ns, "
                f"timeshift_cam_imu {self.offset_s * 1e6:.2f} +- {self.offset_std_s * 1e6:.2f} us "
                f"({self.inliers} of {self.tracks} tracks in {self.images} images, rms {self.rms_px:.3f} px)")


def load_capture(capture_dir: str | os.PathLike[str]) -> CaptureInputs:
    """Read a capture's RS images, stamps, gyro, intrinsics and camera-IMU rotation (see the module docstring)."""
    from rollcam.sim.yamlsafe import read_yaml

    out = Path(capture_dir)
    for name in (IMU_CSV, CAMERA_YAML):
        if not (out / name).is_file():
            raise ConfigError(f"capture {str(out)!r} has no {name}: capture from a camera with imu=on")
    _, records = read_capture(out)
    rs = [r for r in records if r.get("shutter") == "rolling"]
    if len(rs) < 3:
        raise ConfigError(f"capture {str(out)!r} holds {len(rs)} rolling-shutter image(s); calibration needs >= 3")
    readouts = {r.get("readout") for r in rs}
    if not readouts <= {"top_to_bottom", "bottom_to_top"} or len(readouts) != 1:
        raise ConfigError(f"calibration needs one row readout (top_to_bottom or bottom_to_top), got {readouts!r}")
    cam = read_yaml((out / CAMERA_YAML).read_text(encoding="utf-8"), str(out / CAMERA_YAML))
    t_bs = np.asarray(cam["T_BS"]["data"], np.float64).reshape(4, 4)
    imu = np.loadtxt(out / IMU_CSV, delimiter=",", comments="#", ndmin=2)
    if imu.shape[0] < 2 or imu.shape[1] != 7:
        raise SourceError(f"{str(out / IMU_CSV)!r}: expected rows of 7 columns, got shape {imu.shape!r}")
    with open(out / IMU_CSV, encoding="utf-8") as f:  # stamps exactly (float64 would round ns past 104 days)
        stamps = np.array([int(line.split(",", 1)[0]) for line in f if line[:1].isdigit()], np.int64)
    rs.sort(key=lambda r: int(r["timestamp_ns"]))
    return CaptureInputs(
        images=tuple(out / str(r["file"]) for r in rs),
        timestamp_ns=np.array([int(r["timestamp_ns"]) for r in rs], np.int64),
        exposure_ns=np.array([int(r["exposure_ns"]) for r in rs], np.int64),
        height=int(rs[0]["height"]), bottom_up=readouts == {"bottom_to_top"},
        intrinsics=tuple(float(v) for v in cam["intrinsics"]),  # type: ignore[arg-type]
        R_cam_imu=np.linalg.inv(t_bs)[:3, :3], imu_t_ns=stamps, gyro=imu[:, 1:4])


def track_features(images: tuple[Path, ...], max_corners: int = MAX_CORNERS, gaps: tuple[int, ...] = GAPS) -> Tracks:
    """Corners of each image tracked into the images ``gaps`` later (forward-backward checked, sub-pixel).

    A longer gap sees more change of angular velocity, which is what makes the offset observable."""
    import cv2

    lk = {"winSize": (21, 21), "maxLevel": 4,
          "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 0.003)}
    imgs = []
    for path in images:
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise SourceError(f"cannot read image {str(path)!r}")
        imgs.append(img)
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for i, prev in enumerate(imgs):
        if not any(i + g < len(imgs) for g in gaps):
            break
        pts = cv2.goodFeaturesToTrack(prev, max_corners, 0.01, 7, blockSize=7)
        if pts is None or not len(pts):
            continue
        pts = cv2.cornerSubPix(prev, pts.astype(np.float32), (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 40, 0.001))
        for g in gaps:
            if i + g >= len(imgs):
                continue
            img = imgs[i + g]
            fwd, ok1, _ = cv2.calcOpticalFlowPyrLK(prev, img, pts, None, **lk)
            back, ok2, _ = cv2.calcOpticalFlowPyrLK(img, prev, fwd, None, **lk)
            h, w = img.shape
            good = ((ok1[:, 0] == 1) & (ok2[:, 0] == 1) & (np.linalg.norm((back - pts)[:, 0], axis=1) < FB_MAX_PX)
                    & np.all((fwd[:, 0] >= 2) & (fwd[:, 0] <= (w - 3, h - 3)), axis=1))
            n = int(good.sum())
            parts.append((np.full(n, i, np.int64), np.full(n, i + g, np.int64),
                          pts[good, 0].astype(np.float64), fwd[good, 0].astype(np.float64)))
    if sum(len(p[0]) for p in parts) < 20:
        raise SourceError("fewer than 20 feature tracks: the images show too little texture to calibrate from")
    return Tracks(*(np.concatenate([p[k] for p in parts]) for k in range(4)))


class GyroOrientation:
    """The camera's orientation integrated from the gyro, at any IMU-clock instant (rate linear between samples,
    as ``rollcam.sim.rscorrect`` integrates it). Times are float seconds from ``origin_ns``."""

    def __init__(self, t_ns: np.ndarray, gyro: np.ndarray, r_cam_imu: np.ndarray, origin_ns: int) -> None:
        self.tau = (np.asarray(t_ns, np.int64) - int(origin_ns)).astype(np.float64) * 1e-9
        self.omega = np.asarray(gyro, np.float64) @ np.asarray(r_cam_imu).T  # camera-axis rates
        dt = np.diff(self.tau)
        steps = rotation_vector_to_matrix(0.5 * (self.omega[1:] + self.omega[:-1]) * dt[:, None])
        q = np.empty((len(self.tau), 3, 3))
        q[0] = np.eye(3)
        for k in range(steps.shape[0]):
            q[k + 1] = q[k] @ steps[k]
        self.q = q
        self.slope = np.diff(self.omega, axis=0) / dt[:, None]

    def at(self, t_s: np.ndarray) -> np.ndarray:
        """Orientations (camera to the first sample's camera) at IMU-clock times ``t_s`` (n, 3, 3)."""
        k = np.clip(np.searchsorted(self.tau, t_s, side="right") - 1, 0, len(self.tau) - 2)
        h = t_s - self.tau[k]
        rotvec = self.omega[k] * h[:, None] + 0.5 * self.slope[k] * (h * h)[:, None]
        return self.q[k] @ rotation_vector_to_matrix(rotvec)


class TrackModel:
    """Residuals (px) of the tracks against the gyro's prediction, as a function of (line time, offset) in s."""

    def __init__(self, data: CaptureInputs, tracks: Tracks) -> None:
        origin = int(data.timestamp_ns[0])
        self.gyro = GyroOrientation(data.imu_t_ns, data.gyro, data.R_cam_imu, origin)
        mid = (data.timestamp_ns - origin).astype(np.float64) * 1e-9 + data.exposure_ns * 0.5e-9
        self.t1, self.t2 = mid[tracks.frame], mid[tracks.frame2]
        line = (lambda y: data.height - 1 - y) if data.bottom_up else (lambda y: y)
        self.v1, self.v2 = line(tracks.p1[:, 1]), line(tracks.p2[:, 1])
        fx, fy, cx, cy = data.intrinsics
        self.k = (fx, fy, cx, cy)
        self.ray1 = np.stack([(tracks.p1[:, 0] - cx) / fx, (tracks.p1[:, 1] - cy) / fy, np.ones(len(tracks))], 1)
        self.p2 = tracks.p2
        self.frame = tracks.frame

    def covered(self, max_line_s: float, max_offset_s: float) -> np.ndarray:
        """Tracks whose instants the gyro covers for every line time and offset up to the bounds."""
        lo, hi = self.gyro.tau[0], self.gyro.tau[-1]
        return (self.t1 - max_offset_s >= lo) & (self.t2 + self.v2.clip(0) * max_line_s + max_offset_s <= hi)

    def residuals(self, line_s: float, offset_s: float, sel: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Predicted minus tracked positions in the second image (n, 2) px."""
        q1 = self.gyro.at(self.t1[sel] + self.v1[sel] * line_s + offset_s)
        q2 = self.gyro.at(self.t2[sel] + self.v2[sel] * line_s + offset_s)
        ray = np.einsum("nji,njk,nk->ni", q2, q1, self.ray1[sel])  # Q2^T Q1 ray1
        fx, fy, cx, cy = self.k
        z = np.where(np.abs(ray[:, 2]) < 1e-9, 1e-9, ray[:, 2])
        return np.stack([fx * ray[:, 0] / z + cx, fy * ray[:, 1] / z + cy], 1) - self.p2[sel]


def fit(model: TrackModel, frame_period_s: float, height: int, max_offset_s: float = 0.02,
        n_images: int = 0) -> Calibration:
    """Fit line time and offset: a grid over ``[0, frame period / height] x [-max_offset_s, max_offset_s]``
    on a robust truncated cost, then Levenberg-Marquardt with Huber weights from the best grid point."""
    if not (math.isfinite(max_offset_s) and max_offset_s > 0):
        raise ConfigError(f"max offset must be a positive number of seconds, got {max_offset_s!r}")
    max_line_s = frame_period_s / height
    sel = np.flatnonzero(model.covered(max_line_s, max_offset_s))
    if sel.size < 20:
        raise ConfigError(f"only {sel.size} tracks lie where the IMU stream covers every offset up to "
                          f"{max_offset_s * 1e3:g} ms: capture more frames or search a smaller offset range")
    sub = sel[:: max(1, sel.size // 1500)]
    lines = np.linspace(max_line_s / GRID_LINE_STEPS, max_line_s, GRID_LINE_STEPS)
    offsets = np.arange(-max_offset_s, max_offset_s + 0.5 * GRID_OFFSET_STEP_S, GRID_OFFSET_STEP_S)
    best = (math.inf, 0.0, 0.0)
    for line_s in lines:
        for off in offsets:
            r = model.residuals(line_s, off, sub)
            cost = float(np.minimum((r * r).sum(1), 4.0).sum())
            best = min(best, (cost, line_s, off))
    x, cov, r = _refine(model, np.array([best[1], best[2]]) * 1e6, sel)
    err = np.hypot(r[:, 0], r[:, 1])
    inlier = err < 3.0 * max(float(np.median(err)), 1e-6)  # ~3.5 sigma of a 2-D normal's radius
    return Calibration(line_time_s=x[0] * 1e-6, line_time_std_s=math.sqrt(cov[0, 0]) * 1e-6,
                       offset_s=x[1] * 1e-6, offset_std_s=math.sqrt(cov[1, 1]) * 1e-6,
                       rms_px=float(np.sqrt(np.mean(err[inlier] ** 2))), tracks=len(model.p2),
                       inliers=int(inlier.sum()), images=n_images)


def _refine(model: TrackModel, x_us: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on (line time, offset) in us with Huber weights per track (IRLS); returns the
    estimate, its covariance (us^2) and the final residuals."""
    steps = np.array([1e-3, 0.5])  # central differences: 1 ns of line time, 0.5 us of offset

    def resid(x: np.ndarray) -> np.ndarray:
        return model.residuals(x[0] * 1e-6, x[1] * 1e-6, sel)

    lam = 1e-3
    for _ in range(60):
        r = resid(x_us)
        err = np.hypot(r[:, 0], r[:, 1])
        scale = HUBER_K * max(1.4826 * float(np.median(err)), 1e-6)
        w = np.repeat(np.where(err <= scale, 1.0, scale / np.maximum(err, 1e-12)), 2)
        jac = np.stack([(resid(x_us + d) - resid(x_us - d)).ravel() / (2 * h)
                        for d, h in ((np.array([steps[0], 0.0]), steps[0]), (np.array([0.0, steps[1]]), steps[1]))], 1)
        rv = r.ravel()
        jtj, jtr = jac.T @ (w[:, None] * jac), jac.T @ (w * rv)
        cost = float(w @ rv**2)
        while True:
            delta = -np.linalg.solve(jtj + lam * np.diag(np.diag(jtj)), jtr)
            rn = resid(x_us + delta).ravel()
            if float(w @ rn**2) <= cost or lam > 1e8:
                break
            lam *= 10.0
        if lam > 1e8:
            break
        x_us, lam = x_us + delta, max(lam / 10.0, 1e-9)
        if abs(delta[0]) < 1e-5 and abs(delta[1]) < 1e-3:
            break
    r = resid(x_us)
    rv = r.ravel()
    dof = max(rv.size - 2, 1)
    inv = np.linalg.inv(jtj)
    cov = float(w @ rv**2) / dof * inv
    # Tracks that start in one image share its gyro noise and its rendering: a covariance clustered by that
    # image (the sandwich estimator) counts what they share; the larger of the two is stated.
    score = (jac * (w * rv)[:, None]).reshape(-1, 2, 2).sum(1)  # per track
    labels = np.unique(model.frame[sel], return_inverse=True)[1]
    per_image = np.zeros((int(labels.max()) + 1, 2))
    np.add.at(per_image, labels, score)
    n_c = per_image.shape[0]
    clustered = inv @ (per_image.T @ per_image) @ inv * (n_c / max(n_c - 1, 1))
    return x_us, np.maximum(cov, clustered), r


def calibrate(capture_dir: str | os.PathLike[str], *, max_offset_s: float = 0.02,
              max_corners: int = MAX_CORNERS, gaps: tuple[int, ...] = GAPS) -> Calibration:
    """Line time and camera-IMU offset of a capture's camera (see the module docstring)."""
    data = load_capture(capture_dir)
    tracks = track_features(data.images, max_corners, gaps)
    period = float(np.median(np.diff(data.timestamp_ns))) * 1e-9
    return fit(TrackModel(data, tracks), period, data.height, max_offset_s, len(data.images))


def result_yaml(capture_dir: str | os.PathLike[str], cal: Calibration) -> str:
    """Kalibr's camera-IMU result (``camchain-imucam``): the capture's ``camchain.yaml`` with the estimated
    ``line_delay`` and ``timeshift_cam_imu`` (their standard errors as comments)."""
    from ..recording.imu_export import CAMCHAIN_YAML

    src = Path(capture_dir) / CAMCHAIN_YAML
    lines = src.read_text(encoding="utf-8").splitlines() if src.is_file() else ["cam0:"]
    values = {"line_delay": (cal.line_time_s, cal.line_time_std_s),
              "timeshift_cam_imu": (cal.offset_s, cal.offset_std_s)}
    out = [f"# rollcam calibrate: {cal}"]
    for line in lines:
        key = line.strip().split(":", 1)[0]
        if key in values and line.startswith("  "):
            continue
        out.append(line)
        if line == "cam0:":
            out += [f"  {k}: {v:.12g}  # +- {s:.3g}" for k, (v, s) in values.items()]
    return "\n".join(out) + "\n"
