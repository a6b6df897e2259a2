"""Camera-IMU calibration acceptance: from rollcam's own captures alone (images + imu.csv), the estimator
recovers the configured line time within 1 % and the camera-IMU time offset within 0.1 ms."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main
from rollcam.host.correction.calibrate import RESULT_YAML, GyroOrientation, calibrate
from rollcam.host.recording.capture import capture
from rollcam.host.sources import open_camera
from rollcam.sim.pose import rotation_vector_to_matrix


def _capture(tmp: Path, query: str, frames: int) -> tuple[Path, int]:
    """A capture of the calibration excitation; returns its folder and the configured line time (ns)."""
    uri = f"emu:imx219?ego=calib&pedestrians=0&exposure_us=2000&{query}"
    with open_camera(uri) as src:
        capture(src, tmp / "cap", frames, progress=False)
    rec = json.loads((tmp / "cap" / "frames.jsonl").read_text().splitlines()[0])
    return tmp / "cap", int(rec["line_time_ns"])


def test_cli_recovers_line_time_and_offset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cap, line_ns = _capture(tmp_path, "size=320x240&imu_offset_us=-1700", 16)
    assert main(["calibrate", str(cap), "--json", "--max-offset-ms", "5"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert abs(got["line_time_ns"] - line_ns) < 0.01 * line_ns, (got, line_ns)
    assert abs(got["timeshift_cam_imu_ns"] - -1_700_000) < 100_000, got
    # the stated uncertainty is small enough to make the claim, and honest (the error within 4 sigma)
    assert got["line_time_std_ns"] < 0.005 * line_ns and got["timeshift_cam_imu_std_ns"] < 50_000, got
    assert abs(got["timeshift_cam_imu_ns"] + 1_700_000) < 4 * got["timeshift_cam_imu_std_ns"] + 5_000, got
    result = yaml.safe_load((cap / RESULT_YAML).read_text())["cam0"]
    assert result["line_delay"] == pytest.approx(got["line_time_ns"] * 1e-9, rel=1e-9)
    assert result["timeshift_cam_imu"] == pytest.approx(got["timeshift_cam_imu_ns"] * 1e-9, rel=1e-9)
    assert result["resolution"] == [320, 240] and len(result["T_cam_imu"]) == 4


@pytest.mark.slow
@pytest.mark.parametrize("query", ["size=640x480&imu_offset_us=250", "size=640x480&imu_offset_us=-3000&imu_rate=1000",
                                   "size=320x240&imu_offset_us=8000&imu_rotation_deg=0,90,0"])
def test_recovers_at_other_settings(tmp_path: Path, query: str) -> None:
    cap, line_ns = _capture(tmp_path, query, 30)
    offset_ns = float(query.split("imu_offset_us=")[1].split("&")[0]) * 1e3
    cal = calibrate(cap)
    assert abs(cal.line_time_s * 1e9 - line_ns) < 0.01 * line_ns, (cal, line_ns)
    assert abs(cal.offset_s * 1e9 - offset_ns) < 100_000, (cal, offset_ns)


def test_gyro_orientation_integrates_a_rate_linear_in_time() -> None:
    # omega(t) = a + b t about a fixed axis: the angle is a t + b t^2 / 2 exactly, between and at samples
    t_ns = np.arange(0, 100_000_001, 2_500_000, dtype=np.int64)
    axis = np.array([0.6, 0.0, 0.8])
    rate = (0.3 + 4.0 * t_ns * 1e-9)[:, None] * axis
    g = GyroOrientation(t_ns, rate, np.eye(3), 0)
    t = np.array([0.0, 0.0123, 0.05, 0.0999])
    want = rotation_vector_to_matrix((0.3 * t + 2.0 * t * t)[:, None] * axis)
    np.testing.assert_allclose(g.at(t), want, atol=1e-12)


def test_refuses_a_capture_without_imu(tmp_path: Path) -> None:
    with open_camera("emu:imx219?size=160x120&scene=flat") as src:
        capture(src, tmp_path / "cap", 3, progress=False)
    with pytest.raises(ConfigError, match=r"imu\.csv"):
        calibrate(tmp_path / "cap")
