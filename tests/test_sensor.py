"""Sensor model: EMVA noise stages, fixed patterns, gains, exposure windows, adaptive blur, emu: and capture."""

from __future__ import annotations

import dataclasses
import json
import math
from statistics import NormalDist

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host import SourceError, open_camera
from rollcam.host.recording.capture import capture
from rollcam.sim.codecs import codec
from rollcam.sim.exposure import dense_plan, integrate, plan_samples
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.noise import STAGES, SensorModel, parse_stages, split_gain
from rollcam.sim.scenegen import make_chart_scene, make_flat_scene
from rollcam.sim.synthetic import SyntheticCamera

IMX219 = load_sensor("imx219")
N = IMX219.noise


def model(stages=STAGES, serial="A", seed=0) -> SensorModel:
    return SensorModel(N, 10, "RGGB", serial=serial, seed=seed, stages=frozenset(stages))


def flat(level: float, h: int = 64, w: int = 64) -> np.ndarray:
    return np.full((h, w, 3), level, np.float32)


def test_noiseless_output_is_the_closed_form():
    m = model(("saturation", "quantization"))
    dn = m.expose(flat(0.25), 10_000_000, 0)
    expected = round(0.25 * N.full_well_e * N.system_gain_dn_per_e + N.black_level_dn)
    assert dn.dtype == np.uint16 and np.all(dn == expected)
    assert np.all(m.expose(flat(0.25), 10_000_000, 0, analog_gain=2.0) == round(0.5 * 958.5 + 64))


def test_saturation_at_full_well_and_adc_top():
    m = model(("saturation", "quantization"))
    assert np.all(m.expose(flat(5.0), 10_000_000, 0) == math.floor(N.full_well_e * N.system_gain_dn_per_e + 64.5))
    assert np.all(m.expose(flat(5.0), 10_000_000, 0, analog_gain=4.0) == 1023)  # the ADC clips first
    assert np.all(model(("quantization",)).expose(flat(0.0), 0, 0) == 64)


def test_temporal_noise_reproducible_per_seed_and_frame():
    m = model()
    a, b = m.expose(flat(0.3), 10_000_000, 5), m.expose(flat(0.3), 10_000_000, 5)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, m.expose(flat(0.3), 10_000_000, 6))
    assert not np.array_equal(a, model(seed=1).expose(flat(0.3), 10_000_000, 5))


def test_fixed_patterns_follow_the_serial_and_the_array_position():
    fixed = ("dsnu", "prnu", "saturation", "quantization")
    m = model(fixed, serial="S1")
    a = m.expose(flat(0.3), 10_000_000, 0)
    assert np.array_equal(a, model(fixed, serial="S1", seed=9).expose(flat(0.3), 10_000_000, 77))
    assert not np.array_equal(a, model(fixed, serial="S2").expose(flat(0.3), 10_000_000, 0))
    crop = m.expose(flat(0.3, 32, 32), 10_000_000, 0, origin=(16, 8), array_width=64)
    assert np.array_equal(crop, a[16:48, 8:40])
    f = m.expose(flat(0.3), 10_000_000, 0, array_width=64).astype(float) - 64
    assert 0.005 < f.std() / f.mean() < 0.02  # PRNU 1% (+ DSNU, 1 e-)


def test_each_stage_adds_its_variance():
    exp_ns, mu_e = 10_000_000, 0.3 * N.full_well_e

    def var(stages):
        d = [model(stages).expose(flat(0.3, 128, 128), exp_ns, i, array_width=128).astype(float) for i in (0, 1)]
        return np.var(d[0] - d[1]) / 2

    k = N.system_gain_dn_per_e
    assert var(("shot", "quantization")) == pytest.approx(k * k * mu_e + 1 / 12, rel=0.05)
    assert var(("read", "quantization")) == pytest.approx((k * N.dark_noise_e) ** 2 + 1 / 12, rel=0.08)
    assert var(("dsnu", "prnu", "quantization")) == 0.0  # fixed patterns are not temporal noise


def test_dark_current_grows_with_exposure_and_poisson_at_low_signal():
    m = SensorModel(N, 16, "mono", stages=frozenset({"dark", "shot"}), flux_photons_per_s=0.0)
    for t_s in (0.01, 1.0):
        e = m.expose(flat(0.0, 128, 128), int(t_s * 1e9), 0)
        e_el = (e - 64) / N.system_gain_dn_per_e
        assert e_el.mean() == pytest.approx(N.dark_current_e_per_s * t_s, rel=0.05, abs=0.02)
    # Exact Poisson at 0.1 e-: most pixels hold no electron at all.
    assert np.mean(m.expose(flat(0.0, 128, 128), 10_000_000, 0) == 64) == pytest.approx(math.exp(-0.1), abs=0.01)


def test_dark_frames_keep_negative_dsnu_offsets_above_the_adc_floor():
    """Regression: charge was clipped at 0 e- after the DSNU offset, so every negative offset was lost (a
    dark frame's DSNU read 0.6 e- for 1 e- configured). Only the well and the ADC clip."""
    for stages in (("dsnu", "saturation"), ("dsnu", "dark", "shot", "saturation")):
        dn = model(stages).expose(flat(0.0, 256, 256), 10_000_000, 0, array_width=256)  # float DN, no rounding
        e = (dn - N.black_level_dn) / N.system_gain_dn_per_e - N.dark_current_e_per_s * 0.01 * ("dark" in stages)
        assert np.mean(e < 0) == pytest.approx(0.5, abs=0.03 if "shot" not in stages else 0.1)
        assert e.std() == pytest.approx(math.hypot(N.dsnu_e, math.sqrt(0.1) * ("shot" in stages)), rel=0.02)
    # Quantised, the black level keeps them in the output (mean at the black level, not above it); with no
    # black level the ADC clips them at 0 DN. DSNU at 8x gain spans 1.7 DN, so rounding moves the fractions.
    k8 = 8.0 * N.system_gain_dn_per_e
    below = NormalDist(0.0, N.dsnu_e * k8).cdf(-0.5)
    q = model(("dsnu", "saturation", "quantization")).expose(flat(0.0, 256, 256), 0, 0, analog_gain=8.0)
    assert q.mean() == pytest.approx(N.black_level_dn, abs=0.03)
    assert np.mean(q < N.black_level_dn) == pytest.approx(below, abs=0.01)
    no_black = SensorModel(dataclasses.replace(N, black_level_dn=0), 10, "RGGB", serial="A",
                           stages=frozenset(("dsnu", "saturation", "quantization")))
    z = no_black.expose(flat(0.0, 256, 256), 0, 0, analog_gain=8.0)
    assert np.mean(z == 0) == pytest.approx(1 - below, abs=0.01)


def test_quantization_off_gives_float_dn():
    out = model(("saturation",)).expose(flat(0.25), 10_000_000, 0)
    assert out.dtype == np.float64 and out[0, 0] == pytest.approx(0.25 * 4500 * 0.213 + 64)


def test_ideal_sensor_has_no_random_stages():
    s = load_sensor("letsroll")
    m = SensorModel(s.noise, s.bit_depth, s.bayer_order)
    assert m.stages == frozenset({"saturation", "quantization"})


def test_stage_parsing_and_gain_split():
    assert parse_stages("off") == frozenset({"saturation", "quantization"})
    assert parse_stages("shot,read") == frozenset({"shot", "read", "quantization"})
    with pytest.raises(ConfigError, match="'blur'"):
        parse_stages("shot,blur")
    g = IMX219.gain
    assert split_gain(4.0, (g.analog_min, g.analog_max), (g.digital_min, g.digital_max)) == (4.0, 1.0, False)
    a, d, clamped = split_gain(20.0, (1.0, 10.66), (1.0, 16.0))
    assert (a, clamped) == (10.66, False) and a * d == pytest.approx(20.0)
    assert split_gain(1000.0, (1.0, 10.0), (1.0, 16.0))[2] is True
    with pytest.raises(ConfigError):
        split_gain(float("nan"), (1.0, 10.0), (1.0, 16.0))


# --------------------------------------------------------------------------- exposure windows, blur
def test_static_scene_needs_one_sample_per_line():
    cam = SyntheticCamera(IMX219, make_flat_scene(0, level=0.3, width=64, height=48), size=(64, 48),
                          pixel_format="RG10")
    s = cam.settings
    plan = plan_samples(cam.renderer, cam.line_times_ns(0) - s.exposure_ns // 2, s.exposure_ns)
    assert plan.n.tolist() == [1] * 48 and plan.evaluations == 48


def test_chart_bar_blur_follows_the_speed_rule_and_the_dense_reference():
    vx = 3000.0
    scene = make_chart_scene(0, vx_px_s=vx, width=160, height=40)
    cam = SyntheticCamera(load_sensor("letsroll"), scene, size=(160, 40), exposure_ns=2_000_000)
    r, s = cam.renderer, cam.settings
    starts = cam.line_times_ns(0) - s.exposure_ns // 2
    plan = plan_samples(r, starts, s.exposure_ns, bound_px=0.5)
    want = math.ceil(vx * s.exposure_ns * 1e-9 / 0.5)
    assert plan.n.max() == want and plan.n.min() >= 1
    adaptive, dense = integrate(r, plan), integrate(r, dense_plan(plan, 0.05))
    assert dense.evaluations >= 5 * adaptive.evaluations
    assert np.abs(adaptive.linear - dense.linear).mean() < 0.01 * max(dense.linear.mean(), 1e-6)
    # Blur widens edges: fewer distinct-from-neighbour steps than the sharp frame, values in between.
    sharp = r.render_lines(cam.line_times_ns(0), linear=True).linear
    assert np.unique(np.round(adaptive.linear[20, :, 1], 4)).size > np.unique(np.round(sharp[20, :, 1], 4)).size


def test_global_shutter_windows_are_common_and_rolling_ones_staggered():
    cam = SyntheticCamera(IMX219, make_flat_scene(0, width=64, height=48), size=(64, 48), pixel_format="RG10",
                          shutter="global")
    f = cam.frame(0)
    assert np.unique(f.row_times_ns).size == 1
    rs = SyntheticCamera(IMX219, make_flat_scene(0, width=64, height=48), size=(64, 48), pixel_format="RG10")
    assert np.all(np.diff(rs.frame(0).row_times_ns) > 0)


# --------------------------------------------------------------------------- emu: end to end
@pytest.mark.parametrize(("uri", "fmt", "shape", "dtype"), [
    ("emu:imx219?format=pRAA&size=64x48", "pRAA", (48, 80), np.uint8),
    ("emu:imx219?format=RG10&size=64x48", "RG10", (48, 64), np.uint16),
    ("emu:imx219?format=RGGB&size=64x48", "RGGB", (48, 64), np.uint8),
    ("emu:imx219?format=YUYV&size=64x48", "YUYV", (48, 64, 2), np.uint8),
    ("emu:imx219?format=NV12&size=64x48", "NV12", (72, 64), np.uint8),
    ("emu:imx477?format=pRCC&size=64x48", "pRCC", (48, 96), np.uint8),
    ("emu:ov9281?format=Y10&size=64x40", "Y10 ", (40, 64), np.uint16),
    ("emu:imx219?size=64x48&physics=on&noise=off", "BGR3", (48, 64, 3), np.uint8),
])
def test_emu_formats(uri, fmt, shape, dtype):
    with open_camera(uri + "&speed=fast&frames=1") as cam:
        f = cam.read()
        info = cam.info()
    assert (f.format, f.data.shape, f.data.dtype, f.width) == (fmt, shape, dtype, 64)
    assert info["format"] == fmt and info["physics"] is True
    assert f.meta["noise_stages"] and f.objects is not None


def test_emu_bgr3_default_is_the_clean_render():
    with open_camera("emu:imx219?size=64x48&speed=fast") as cam:
        f = cam.read()
        r = cam.camera.renderer.render_lines(cam.camera.line_times_ns(0)).image
    assert f.format == "BGR3" and "noise_stages" not in f.meta and np.array_equal(f.data, r)


def test_emu_rejects_formats_the_sensor_cannot_deliver():
    with pytest.raises(SourceError, match="GRBG"):
        open_camera("emu:imx219?format=GRBG&size=64x48")
    with pytest.raises(SourceError, match="12 bits"):
        open_camera("emu:imx219?format=RG12&size=64x48")
    with pytest.raises(SourceError, match="physics"):
        open_camera("emu:imx219?format=RG10&physics=off")
    with pytest.raises(SourceError, match="noise"):
        open_camera("emu:imx219?format=RG10&noise=loud")


def test_exposure_longer_than_the_frame_is_clamped_and_said_so():
    with open_camera("emu:imx219?format=RG10&size=64x48&scene=flat&exposure_us=1e6") as cam:
        f = cam.read()
        assert cam.info()["exposure_clamped"] is True
    assert f.meta["exposure_clamped"] is True
    assert f.exposure_ns < cam.camera.settings.timing.frame_period_ns


def test_flat_field_brightness_scales_with_exposure_and_gain():
    def mean(q: str) -> float:
        with open_camera(f"emu:imx219?format=RG10&size=64x48&scene=flat&level=0.1&noise=off&{q}") as cam:
            return float(cam.read().data.mean()) - 64

    base = mean("exposure_us=5000")
    assert mean("exposure_us=10000") == pytest.approx(2 * base, rel=0.02)
    assert mean("exposure_us=5000&gain=2") == pytest.approx(2 * base, rel=0.02)


def test_capture_writes_raw_frames_losslessly(tmp_path):
    uri = "emu:imx219?format=pRAA&size=64x48&speed=fast&frames=2"
    with open_camera(uri) as src:
        capture(src, tmp_path / "png", 2, progress=False)
    with open_camera(uri) as src:
        capture(src, tmp_path / "npy", 2, fmt="npy", progress=False)
    with open_camera(uri) as src:
        first = src.read()
    recs = [json.loads(line) for line in (tmp_path / "png" / "frames.jsonl").read_text().splitlines()]
    assert recs[0]["format"] == "pRAA" and recs[0]["bytesperline"] == 80 and recs[0]["width"] == 64
    import cv2

    png = cv2.imread(str(tmp_path / "png" / recs[0]["file"]), cv2.IMREAD_UNCHANGED)
    npy = np.load(tmp_path / "npy" / "000000_rs.npy")
    assert np.array_equal(png, first.data) and np.array_equal(npy, first.data)
    raa = codec("pRAA")
    assert np.array_equal(raa.decode(png, 64, png.shape[0]), raa.decode(first.data, 64, first.height))
    with open_camera(uri) as src, pytest.raises(ConfigError, match="jpg"):
        capture(src, tmp_path / "jpg", 1, fmt="jpg", progress=False)


def test_flips_mirror_the_image_the_truth_and_the_bayer_order():
    base = "emu:imx219?format=RG10&size=64x48&speed=fast&noise=off&seed=2"
    with open_camera(base) as cam:
        plain = cam.read()
    with open_camera(base + "&hflip=on") as cam:
        h = cam.read()
    assert h.format == "BA10" and np.array_equal(h.data, plain.data[:, ::-1])  # RGGB read mirrored: GRBG
    assert np.array_equal(h.row_times_ns, plain.row_times_ns)
    for a, b in zip(plain.objects, h.objects, strict=True):
        if a.box_rs is not None:
            assert b.box_rs == pytest.approx((64 - a.box_rs[2], a.box_rs[1], 64 - a.box_rs[0], a.box_rs[3]))
    with open_camera(base + "&vflip=on&hflip=on") as cam:
        hv = cam.read()
    assert hv.format == "BG10" and np.all(np.diff(hv.row_times_ns) > 0)
    flat = "emu:imx219?format=pRAA&size=64x48&scene=flat&level=0.3&noise=prnu,dsnu"
    with open_camera(flat) as a, open_camera(flat.replace("pRAA", "pGAA") + "&vflip=on") as b:
        fa, fb = a.read(), b.read()
    assert fb.format == "pGAA"  # the flipped order's fourcc may be asked for directly
    # The fixed pattern belongs to the pixel: a vertical flip reads the same array bottom-up.
    flipped, plain = codec("pGAA").decode(fb.data, 64, fb.height), codec("pRAA").decode(fa.data, 64, fa.height)
    assert np.array_equal(flipped, plain[::-1])


def test_vflip_scans_the_scene_bottom_up():
    with open_camera("emu:imx219?format=RG10&size=64x48&speed=fast&noise=off&vflip=on") as cam:
        f = cam.read()
        scene_times = cam.camera.line_times_ns(0)
    assert np.all(np.diff(scene_times) < 0)  # the scene's bottom line is read first
    assert np.array_equal(f.row_times_ns, scene_times[::-1])


def test_photon_flux_from_the_sensor_description():
    noise = dataclasses.replace(N, flux_photons_per_s=1e5)
    m = SensorModel(noise, 10, "RGGB", stages=frozenset({"quantization"}))
    assert m.flux == 1e5
    assert np.all(m.expose(flat(1.0), 10_000_000, 0) == math.floor(0.65 * 1e3 * 0.213 + 64.5))
    with pytest.raises(ConfigError, match="flux_photons_per_s"):
        dataclasses.replace(N, flux_photons_per_s=-1.0)
