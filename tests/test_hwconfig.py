"""Sensor descriptions: every shipped YAML loads, timing figures match the drivers, bad files are rejected
with messages that name the file, the key and the expected form."""

from __future__ import annotations

import dataclasses
import functools
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rollcam.common.errors import ConfigError
from rollcam.sim.hwconfig import (
    ExposureLimits,
    GainLimits,
    NoiseParams,
    Optics,
    Register,
    SensorConfig,
    SensorMode,
    list_sensors,
    load_sensor,
)
from rollcam.sim.timing import LineTiming, Readout

REQUIRED_SENSORS = {"imx219", "imx477", "imx708", "imx378", "ov9281", "ar0234", "letsroll"}


_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_Dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


@functools.cache
def _raw_text(name: str) -> str:
    return (resources.files("rollcam.hw_configs") / f"{name}.yaml").read_text()


def _raw(name: str = "imx219") -> dict[str, Any]:
    """A fresh, editable copy of a shipped description as plain YAML data."""
    return yaml.load(_raw_text(name), Loader=_Loader)


def _write(tmp_path: Path, data: Any, name: str = "broken_cam.yaml") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.dump(data, Dumper=_Dumper, sort_keys=False))
    return path


def _error(tmp_path: Path, data: Any) -> str:
    with pytest.raises(ConfigError) as info:
        load_sensor(_write(tmp_path, data))
    return str(info.value)


# --- shipped configs --------------------------------------------------------------------------------------


def test_required_sensors_are_shipped() -> None:
    assert set(list_sensors()) >= REQUIRED_SENSORS


@pytest.mark.parametrize("name", list_sensors())
def test_every_shipped_config_loads(name: str) -> None:
    cfg = load_sensor(name)
    assert isinstance(cfg, SensorConfig)
    assert cfg.name == name
    assert cfg.mode().name == cfg.default_mode
    assert isinstance(cfg.readout, Readout)
    for mode in cfg.modes:
        timing = cfg.timing(mode)
        assert isinstance(timing, LineTiming) and isinstance(timing.line_time_ns, int)
        assert 1 <= timing.fps <= 1000
        assert cfg.focal_px(mode) > 0
    assert cfg.rolling == (cfg.shutter == "rolling")
    assert name in repr(cfg)


def test_global_shutter_sensors() -> None:
    for name in ("ov9281", "ar0234"):
        cfg = load_sensor(name)
        assert cfg.shutter == "global" and not cfg.rolling
        assert cfg.timing().line_time_ns > 0  # frame timing still comes from the pixel clock
    assert load_sensor("ov9281").bayer_order == "mono"


def test_imx219_1080p_timing() -> None:
    cfg = load_sensor("imx219")
    timing = cfg.timing("1920x1080")
    assert (timing.pixel_rate_hz, timing.line_length_pck, timing.frame_length_lines) == (182_400_000, 3448, 1763)
    assert timing.line_time_ns == 18904  # 18,903.5 ns rounded
    assert timing.fps == pytest.approx(30.0, abs=0.01)
    assert cfg.timing("3280x2464").fps == pytest.approx(15.0, abs=0.01)
    assert cfg.register("CHIP_ID").reset == 0x0219
    assert cfg.register(0x0160).role == "frame_length"
    assert cfg.register("exposure").address == 0x015A


def test_letsroll_line_offsets_are_exact() -> None:
    cfg = load_sensor("letsroll")
    timing = cfg.timing()
    assert cfg.rolling and cfg.readout is Readout.TOP_TO_BOTTOM
    assert timing.fps == 30.0
    rows = np.arange(1080, dtype=np.int64)
    np.testing.assert_array_equal(timing.line_offset_ns(rows), rows * 10**9 // 32_400)
    far = 77_000_000 * 1080 + 17  # a row a month into a stream
    assert timing.line_offset_ns(far) == far * 10**9 // 32_400
    assert cfg.focal_px() == pytest.approx(35 / 36 * 1920)
    assert cfg.noise.ideal


def test_modes_binning_crop_and_focal_px() -> None:
    cfg = load_sensor("imx219")
    full, binned = cfg.focal_px("3280x2464"), cfg.focal_px("1640x1232")
    assert binned == pytest.approx(full / 2)
    assert cfg.focal_px("1920x1080") == pytest.approx(full)  # a crop keeps the pixel pitch
    assert cfg.crop("1640x1232") == cfg.crop("3280x2464")  # no crop given: the centred read area
    assert cfg.mode("640x480").crop is not None
    assert cfg.with_mode("640x480").timing().frame_length_lines == 1763
    assert load_sensor("imx708").timing("1536x864").pixel_rate_hz == 566_400_000
    with pytest.raises(ConfigError, match="no mode"):
        cfg.mode("1x1")


def test_configs_are_frozen_and_replace_revalidates() -> None:
    cfg = load_sensor("imx219")
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.pixel_rate_hz = 1  # type: ignore[misc]
    mode = cfg.mode()
    assert dataclasses.replace(mode, frame_length_lines=2000).frame_length_lines == 2000
    with pytest.raises(ConfigError, match="line_length_pck"):
        dataclasses.replace(mode, width=4000)
    with pytest.raises(ConfigError, match="default_mode"):
        dataclasses.replace(cfg, default_mode="nope")


def test_schema_accepts_path_objects_and_strings(tmp_path: Path) -> None:
    path = _write(tmp_path, _raw(), name="copy.yaml")
    assert load_sensor(path).name == "imx219"
    assert load_sensor(str(path)).timing().line_time_ns == 18904


# --- rejected configs -------------------------------------------------------------------------------------


def test_unknown_top_level_key(tmp_path: Path) -> None:
    data = _raw()
    data["frame_rate"] = 30
    msg = _error(tmp_path, data)
    assert "broken_cam.yaml" in msg and "frame_rate" in msg and "unknown key" in msg


def test_unknown_nested_key_gets_dotted_path_and_hint(tmp_path: Path) -> None:
    data = _raw()
    data["modes"][1]["line_lenght_pck"] = data["modes"][1].pop("line_length_pck")
    msg = _error(tmp_path, data)
    assert "broken_cam.yaml" in msg and "modes[1].line_lenght_pck" in msg
    assert "did you mean 'line_length_pck'" in msg
    data = _raw()
    data["optics"]["f_number"] = 2.0
    assert "optics.f_number" in _error(tmp_path, data)


def test_line_shorter_than_its_pixels_is_rejected(tmp_path: Path) -> None:
    data = _raw()
    data["modes"][1]["line_length_pck"] = 1000
    msg = _error(tmp_path, data)
    assert "broken_cam.yaml: modes[1].line_length_pck" in msg
    assert ">= width (1920)" in msg and "got 1000" in msg


def test_frame_shorter_than_its_lines_is_rejected(tmp_path: Path) -> None:
    data = _raw()
    data["modes"][0]["frame_length_lines"] = 2000
    msg = _error(tmp_path, data)
    assert "modes[0].frame_length_lines" in msg and ">= height (2464)" in msg and "got 2000" in msg


@pytest.mark.parametrize(
    ("edit", "key", "shown"),
    [
        (lambda d: d["modes"][0].__setitem__("width", "3280"), "modes[0].width", "'3280'"),
        (lambda d: d.__setitem__("pixel_rate_hz", 182.4), "pixel_rate_hz", "182.4"),
        (lambda d: d.__setitem__("pixel_rate_hz", 0), "pixel_rate_hz", "got 0"),
        (lambda d: d["noise"].__setitem__("full_well_e", "lots"), "noise.full_well_e", "'lots'"),
        (lambda d: d.__setitem__("modes", {"a": 1}), "modes", "expected a list"),
        (lambda d: d.__setitem__("optics", [3.04]), "optics", "expected a mapping"),
        (lambda d: d["gain"].__setitem__("analog_min", True), "gain.analog_min", "True"),
    ],
)
def test_wrong_types(tmp_path: Path, edit: Any, key: str, shown: str) -> None:
    data = _raw()
    edit(data)
    msg = _error(tmp_path, data)
    assert "broken_cam.yaml" in msg and f"{key}:" in msg and shown in msg and "expected" in msg


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda d: d.__setitem__("default_mode", "4k"), "default_mode"),
        (lambda d: d["noise"].__setitem__("full_well_e", 0), "noise.full_well_e"),
        (lambda d: d["noise"].__setitem__("quantum_efficiency", 1.2), "noise.quantum_efficiency"),
        (lambda d: d["gain"].__setitem__("analog_min", 20.0), "gain.analog_min"),
        (lambda d: d.__setitem__("bayer_order", "RGBG"), "bayer_order"),
        (lambda d: d.__setitem__("readout", "sideways"), "readout"),
        (lambda d: d.__setitem__("bit_depth", 17), "bit_depth"),
        (lambda d: d.__setitem__("shutter", "electronic"), "shutter"),
        (lambda d: d.pop("optics"), "optics"),
        (lambda d: d["registers"][0].__setitem__("reset", 0x10000), "registers[0].reset"),
        (lambda d: d["registers"][1].__setitem__("name", "CHIP_ID"), "registers[1].name"),
        (lambda d: d["registers"][1].__setitem__("access", "wo"), "registers[1].access"),
        (lambda d: d.__setitem__("formats", ["BG10"]), "formats[0]"),
        (lambda d: d.__setitem__("formats", ["RG12"]), "formats[0]"),
        (lambda d: d.__setitem__("formats", ["XXXX"]), "formats[0]"),
        (lambda d: d["optics"].__setitem__("sensor_width_mm", 5.0), "optics.sensor_width_mm"),
        (lambda d: d["modes"][1].__setitem__("crop", {"left": 2000, "top": 0, "width": 1920, "height": 1080}),
         "modes[1].crop"),
        (lambda d: d["modes"][1].__setitem__("binning", [2, 2]), "modes[1].crop"),
        (lambda d: d["modes"][2].__setitem__("name", "1920x1080"), "modes[2].name"),
        (lambda d: d["exposure"].__setitem__("max_margin_lines", 5000), "modes[0].frame_length_lines"),
    ],
)
def test_impossible_or_contradictory_values(tmp_path: Path, edit: Any, key: str) -> None:
    data = _raw()
    edit(data)
    msg = _error(tmp_path, data)
    assert msg.startswith(str(tmp_path / "broken_cam.yaml")) and f": {key}:" in msg and "expected" in msg


def test_duplicate_and_overlapping_register_addresses(tmp_path: Path) -> None:
    data = _raw()
    data["registers"].append({"address": 0x0160, "width_bits": 8, "name": "FRM_LENGTH_HI", "access": "rw",
                              "meaning": "high byte"})
    msg = _error(tmp_path, data)
    assert f"registers[{len(data['registers']) - 1}].address" in msg and "FRM_LENGTH_A" in msg
    data["registers"][-1]["address"] = 0x0161  # inside the 16-bit FRM_LENGTH_A
    assert "clear of registers[" in _error(tmp_path, data)


def test_bad_yaml_and_non_mapping_top_level(tmp_path: Path) -> None:
    msg = _error(tmp_path, "name: imx219\nmodes: [1, 2\n")
    assert "broken_cam.yaml" in msg and "not valid YAML" in msg
    msg = _error(tmp_path, "- just\n- a list\n")
    assert "broken_cam.yaml" in msg and "top level" in msg and "mapping" in msg
    msg = _error(tmp_path, "")
    assert "broken_cam.yaml" in msg and "None" in msg
    msg = _error(tmp_path, "name: a\nname: b\n")
    assert "duplicate key 'name'" in msg


def test_missing_files_and_names(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no sensor named 'imx999'"):
        load_sensor("imx999")
    with pytest.raises(ConfigError, match=r"nothere\.yaml"):
        load_sensor(tmp_path / "nothere.yaml")


def test_schema_rows_match_dataclass_fields() -> None:
    from rollcam.sim.configschema import schema

    for cls in (SensorConfig, SensorMode, Optics, NoiseParams, ExposureLimits, GainLimits, Register):
        assert set(schema(cls)) == {f.name for f in dataclasses.fields(cls)}
