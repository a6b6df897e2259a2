"""Lens and ISP picture steps: each does what it says, off is the frame as before, the same through every door,
and blurring the composed rolling-shutter frame stays within its stated bound of the per-row truth."""

from __future__ import annotations

import math
import re

import cv2
import numpy as np
import pytest
from rollcam.common.errors import ConfigError, SourceError
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.imaging import encode
from rollcam.firmware.protocol import ProtocolSession
from rollcam.firmware.spec import CameraSpec
from rollcam.host.sources import open_camera
from rollcam.sim.codecs import codec
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.isp import sharpen
from rollcam.sim.optics import LensOptics, gaussian_kernel, vignette_map
from rollcam.sim.picture import PictureSteps
from rollcam.sim.render.renderer import encode_linear
from rollcam.sim.scenegen import make_chart_scene
from rollcam.sim.synthetic import SyntheticCamera

SMALL = "size=320x240"
EFFECTS = "vignette=0.3&lens_blur_px=1.2&defocus_px=1&sharpen=1&jpeg_quality=80"


def _frame(query: str, sensor: str = "imx219"):
    with open_camera(f"emu:{sensor}?{query}&frames=1") as cam:
        return cam.read()


def test_vignette_corner_over_centre_is_the_configured_fraction():
    m = vignette_map(0.3, 240, 320)
    assert m[0, 0] == m[-1, -1] == m[0, -1] == pytest.approx(0.7, rel=1e-6)
    assert m.max() <= 1 and m[119:121, 159:161].min() > 0.9999
    # On the sensor, noise off: raw samples over the black level, the corner against the centre (same CFA site).
    f = _frame(f"scene=flat&level=0.5&format=RG10&noise=off&{SMALL}&vignette=0.3")
    black = f.meta["black_level_dn"]
    dn = f.data.astype(np.float64) - black
    assert dn[0, 0] / dn[120, 160] == pytest.approx(0.7, rel=0.01)
    assert dn[-2, -2] / dn[120, 160] == pytest.approx(m[-2, -2], rel=0.01)
    assert f.meta["optics"] == {"vignette": 0.3}
    # The clean path dims the linear radiance too (sRGB decoded back to linear).
    bgr = _frame(f"scene=flat&level=0.5&{SMALL}&vignette=0.3").data.astype(np.float64) / 255
    lin = np.where(bgr <= 0.04045, bgr / 12.92, ((bgr + 0.055) / 1.055) ** 2.4)
    assert lin[0, 0, 1] / lin[120, 160, 1] == pytest.approx(0.7, rel=0.02)


@pytest.mark.parametrize("sigma", [0.6, 1.5, 3.0])
def test_lens_blur_spreads_an_edge_by_the_configured_sigma(sigma):
    step = np.zeros((40, 64, 3), np.float32)
    step[:, 32:] = 1.0
    out = LensOptics(lens_blur_px=sigma).apply(step)
    lsf = np.diff(out[20, :, 1].astype(np.float64))  # the line-spread function
    x = np.arange(lsf.size) - 31.0  # the edge lies between pixels 31 and 32
    var = (lsf * x * x).sum() / lsf.sum() - ((lsf * x).sum() / lsf.sum()) ** 2
    assert math.sqrt(var - 1 / 12) == pytest.approx(sigma, rel=0.02)  # Sheppard: the pixel adds 1/12
    assert gaussian_kernel(sigma).sum() == pytest.approx(1.0, abs=1e-6)


def test_lens_blur_of_a_rendered_edge_adds_the_configured_variance():
    # A mono sensor, noise off: the chart's anti-aliased bar edges, with and without the lens.
    q = "scene=chart&vx=0&format=Y10&noise=off&size=320x200&exposure_us=5000"
    plain, blurred = (_frame(q + extra, "ov9281").data.astype(np.float64) for extra in ("", "&lens_blur_px=1.5"))

    def spread(row: np.ndarray) -> float:
        d = np.diff(row)
        i = int(np.argmin(d))  # the steepest falling edge
        w = np.clip(-d[i - 8:i + 9], 0, None)
        x = np.arange(-8, 9)
        mean = (w * x).sum() / w.sum()
        return float((w * (x - mean) ** 2).sum() / w.sum())

    sigma = math.sqrt(spread(blurred[100]) - spread(plain[100]))
    assert sigma == pytest.approx(1.5, rel=0.04)


def test_defocus_disc_keeps_light_and_reaches_its_radius():
    point = np.zeros((41, 41, 3), np.float32)
    point[20, 20] = 1.0
    out = LensOptics(defocus_px=5.0).apply(point)[..., 0]
    assert out.sum() == pytest.approx(1.0, rel=1e-5)
    assert out[20, 20 + 4] == pytest.approx(out[20, 20], rel=1e-3) and abs(out[20, 20 + 7]) < 1e-7
    assert out[20, 20] == pytest.approx(1 / (math.pi * 25), rel=0.05)


def test_sharpen_raises_edge_contrast_and_leaves_flat_areas():
    img = np.full((32, 64, 3), 60, np.uint8)
    img[:, 32:] = 180
    img = cv2.GaussianBlur(img, (0, 0), 1.2)  # a soft edge, as a lens leaves it
    out = sharpen(img, 1.0)
    grad = lambda a: np.abs(np.diff(a[16, :, 1].astype(int))).max()  # noqa: E731
    assert grad(out) > 1.2 * grad(img)
    assert out[16, 31, 1] < img[16, 31, 1] and out[16, 32, 1] > img[16, 32, 1]
    assert np.array_equal(out[:, :20], img[:, :20]) and np.array_equal(out[:, 44:], img[:, 44:])
    f0, f1 = (_frame(f"scene=chart&vx=0&{SMALL}{q}") for q in ("", "&sharpen=1"))
    contrast = [np.abs(np.diff(f.data.astype(int), axis=1)).mean() for f in (f0, f1)]
    assert contrast[1] > 1.1 * contrast[0]
    assert f1.meta["isp"] == {"sharpen": 1.0}


@pytest.mark.parametrize(("quality", "low", "high"), [(90, 33.0, 60.0), (30, 26.0, 45.0)])
def test_jpeg_leaves_bounded_artifacts_and_decodes(quality, low, high):
    plain = _frame(f"seed=3&{SMALL}").data
    f = _frame(f"seed=3&{SMALL}&jpeg_quality={quality}")
    mse = np.mean((f.data.astype(np.float64) - plain) ** 2)
    psnr = 10 * math.log10(255**2 / mse)
    assert low < psnr < high, psnr
    jpg = codec("MJPG")
    assert np.array_equal(f.data, jpg.decode(jpg.encode(plain, quality=quality)))  # libjpeg's round trip
    # MJPG is the encoder: one encoding at that quality, not two.
    m = _frame(f"seed=3&{SMALL}&format=MJPG&physics=off&jpeg_quality={quality}")
    assert m.format == "MJPG" and np.array_equal(m.data, jpg.encode(plain, quality=quality))
    assert np.array_equal(_frame(f"seed=3&{SMALL}&format=MJPG&physics=off").data, jpg.encode(plain))  # 0: 85


@pytest.mark.parametrize("fmt", ["BGR3", "YUYV", "RG10"])
def test_off_is_the_frame_as_before(fmt):
    zeros = "vignette=0&lens_blur_px=0&defocus_px=0&sharpen=0&jpeg_quality=0"
    a, b = _frame(f"seed=1&{SMALL}&format={fmt}"), _frame(f"seed=1&{SMALL}&format={fmt}&{zeros}")
    assert np.array_equal(a.data, b.data) and a.meta == b.meta and a.objects == b.objects
    assert "optics" not in a.meta and "isp" not in a.meta
    c = _frame(f"seed=1&{SMALL}&format={fmt}&{EFFECTS}")
    assert not np.array_equal(a.data, c.data)
    assert c.objects == a.objects  # ground truth is the scene's, whatever the lens and the ISP do


def test_raw_formats_bypass_the_isp_steps_and_keep_the_lens():
    raw = _frame(f"seed=1&{SMALL}&format=RG10&sharpen=2&jpeg_quality=20")
    assert np.array_equal(raw.data, _frame(f"seed=1&{SMALL}&format=RG10").data) and "isp" not in raw.meta
    lensed = _frame(f"seed=1&{SMALL}&format=RG10&vignette=0.3")
    assert lensed.data.mean() < raw.data.mean()


@pytest.mark.parametrize(("name", "value", "bound"), [
    ("vignette", "1", "0..0.95"), ("vignette", "-0.1", ">= 0"), ("lens_blur_px", "1e6", "0..32"),
    ("defocus_px", "33", "0..32"), ("sharpen", "5", "0..4"), ("jpeg_quality", "101", "0..100"),
    ("jpeg_quality", "1.5", "invalid"),
])
def test_out_of_range_values_are_refused_naming_the_bound(name, value, bound):
    with pytest.raises(SourceError, match=f"{re.escape(f'{name}={value!r}')}.*{re.escape(bound)}"):
        open_camera(f"emu:imx219?{name}={value}")
    with pytest.raises(ConfigError, match=name):  # a typed door: the grouped field refuses it alike
        kind = PictureSteps if name in ("sharpen", "jpeg_quality") else LensOptics
        CameraSpec.create("imx219", **{"picture" if kind is PictureSteps else "lens": kind(**{
            name: float(value) if name != "jpeg_quality" else 1000})})


def test_the_uri_and_the_serial_line_give_the_same_spec_and_bytes():
    with open_camera(f"emu:imx219?size=640x480&seed=2&format=YUYV&{EFFECTS}&frames=1") as src:
        want, spec = src.read(), src.spec
    cam = FirmwareCamera("imx219", clock=lambda: 0)
    lines = ["SIZE 640x480", "SCENE seed 2", "FMT YUYV", *(f"OPT {kv.replace('=', ' ')}" for kv in EFFECTS.split("&"))]
    replies = ProtocolSession(cam).feed("".join(f"{x}\n" for x in lines).encode()).decode().split()
    assert all(not r.startswith("ERR") for r in replies), replies
    assert cam.spec == spec
    got = encode(cam.render(FramePlan(0, cam.schedule(0))), cam.spec)
    assert got.format == want.format == "YUYV" and np.array_equal(got.data, want.data)
    assert spec.option_values()["sharpen"] == 1.0 and spec.lens == LensOptics(0.3, 1.2, 1.0)
    assert spec.with_options({"vignette": "0.1"}).lens == LensOptics(0.1, 1.2, 1.0)  # the others stay


def test_blurring_the_composed_rs_frame_stays_within_the_stated_bound():
    """Each output pixel mixes rows read up to the PSF's reach apart; against the physical order (row r of the
    lens image of the whole scene at row r's own time) the error is at most contrast x peak tap x speed x line
    time x E|k| (see docs/optics.md)."""
    sigma, vx = 2.0, 1000.0
    sensor = load_sensor("imx219")
    cam = SyntheticCamera(sensor, make_chart_scene(0, vx_px_s=vx, width=160, height=120), size=(160, 120))
    lens = LensOptics(lens_blur_px=sigma)
    times = cam.line_times_ns(0)
    r = cam.renderer
    lin = r.render_lines(times, linear=True).linear
    fast = lens.apply(lin)
    brute = np.empty_like(fast)
    for row, t in enumerate(times):
        gs = r.render_lines(np.full(times.size, t), linear=True).linear
        brute[row] = lens.apply(gs)[row]
    line_time_s = float(times[1] - times[0]) * 1e-9
    taps = gaussian_kernel(sigma).astype(np.float64)
    k = np.arange(taps.size) - taps.size // 2
    contrast = float(lin.max() - lin.min())
    bound = contrast * taps.max() * vx * line_time_s * float((np.abs(k) * taps).sum())
    err = float(np.abs(fast - brute).max())
    assert 0 < err <= bound * 1.01, (err, bound)
    assert bound < 0.1 * contrast  # here ~0.3 px of motion a line: still a small error


@pytest.mark.parametrize(("fmt", "readout"), [("BGR3", "tb"), ("RG10", "tb"), ("BGR3", "lr")])
def test_only_the_lines_a_walker_touches_are_refiltered_and_they_equal_the_whole_frame_through_the_lens(fmt, readout):
    sensor = load_sensor("imx219")
    from rollcam.sim.scenegen import make_street_scene

    scene = make_street_scene(0, speed="fast", width=320, height=180)
    lens = LensOptics(vignette=0.2, lens_blur_px=0.7, defocus_px=1.5)
    kw = {"size": (320, 180), "pixel_format": fmt, "readout": readout, "noise": frozenset(), "blur_px": None}
    cam, ref = SyntheticCamera(sensor, scene, optics=lens, **kw), SyntheticCamera(sensor, scene, **kw)
    by_col = ref.settings.readout.by_column
    for i in range(3):
        got = cam.frame(i).data.astype(int)
        if fmt == "BGR3":
            lin = ref.renderer.render_lines(ref.line_times_ns(i), by_column=by_col, linear=True).linear
            want = encode_linear(lens.apply(lin), ref.renderer.gain)
        else:
            whole = lens.apply(ref.renderer.render_linear(ref.line_times_ns(i)).radiance)
            want = ref.pipeline.samples(whole, ref.settings.exposure_ns, i)
        assert np.abs(got - want).max() <= 1  # the same filter; a transposed frame may round differently


def test_picture_steps_refuse_bad_values():
    with pytest.raises(ConfigError, match="sharpen"):
        PictureSteps(sharpen=-1)
    with pytest.raises(ConfigError, match="jpeg_quality"):
        PictureSteps(jpeg_quality=True)
    with pytest.raises(ConfigError, match="vignette"):
        LensOptics(vignette=float("nan"))
