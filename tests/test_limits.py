"""Bounds on every user-supplied value, at every door, with the limit in one clear error; external triggers as a
sensor's trigger input (one latched, the rest ignored); scene changes that never hold up frames; a dead frame
pump ends ``rollcam emulate``; sensor descriptions that cannot blow up the loader."""

from __future__ import annotations

import re
import threading
import time
from importlib import resources

import pytest
from helpers import FakeClock
from rollcam.common.errors import ConfigError, DeviceError, SourceError, exit_code
from rollcam.firmware import options as O
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import handle_line
from rollcam.firmware.spec import CameraSpec
from rollcam.host import open_camera
from rollcam.host.cli import main
from rollcam.sim.hwconfig import load_sensor

NS_PER_S = 1_000_000_000

# option, a value past its limit, the limit as the error names it
PAST_LIMITS = [
    ("size", "100000x100000", "8192"),
    ("pedestrians", "1000000", "0..1000"),
    ("seed", str(2**64), "18446744073709551615"),
    ("noise_seed", "-1", ">= 0"),
    ("speed", "1e300", "0..100"),
    ("exposure_us", "1e300", "0..1e+09"),
    ("blur_px", "1e6", "0..256"),
    ("vignette", "1", "0..0.95"),
    ("lens_blur_px", "1e6", "0..32"),
    ("jpeg_quality", "101", "0..100"),
    ("gain", "1e300", "170.6"),
    ("gain", "nan", "finite"),
    ("gain", "-1", "greater than 0"),
    ("fps", "1e9", "maximum"),
    ("serial", "x" * 40, "1..32"),
]


@pytest.mark.parametrize(("name", "value", "limit"), PAST_LIMITS)
def test_every_text_door_refuses_a_value_past_its_limit_naming_it(name, value, limit, capsys):
    with pytest.raises(ConfigError, match=re.escape(limit)):
        CameraSpec.from_options("imx219", {name: value})
    with pytest.raises(SourceError, match=re.escape(limit)):
        open_camera(f"emu:imx219?{name}={value}")
    cam = FirmwareCamera("imx219")
    reply = handle_line(cam, f"OPT {name} {value}")
    assert reply.startswith("ERR 102") and limit in reply, reply
    if name in O.SCENE_OPTIONS:
        assert limit in handle_line(cam, f"SCENE {name} {value}")
    flag = "--" + O.OPTIONS[name].name.replace("_", "-") if name != "serial" else "--serial-number"
    assert main(["emulate", "imx219", flag, value, "--http", "127.0.0.1:0", "--duration", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rollcam: error:") and limit in err[0], err


def test_scene_options_of_other_kinds_are_bounded_too():
    with pytest.raises(ConfigError, match=r"-1e\+06\.\.1e\+06"):
        CameraSpec.from_options("imx219", {"scene": "chart", "vx": "1e300"})
    with pytest.raises(ConfigError, match=r"0\.\.100"):
        CameraSpec.from_options("imx219", {"scene": "flat", "level": "1e300"})


def test_typed_doors_meet_the_same_limits():
    with pytest.raises(ConfigError, match="at most 8192 a side"):
        CameraSpec.create("imx219", size=(100_000, 100_000))
    with pytest.raises(ConfigError, match="longer than the longest frame"):
        CameraSpec.create("imx219", frame_length_lines=10**38)
    with pytest.raises(ConfigError, match="exposure"):
        CameraSpec.create("imx219", exposure_ns=10**30)
    with pytest.raises(ConfigError, match="gain"):
        CameraSpec.create("imx219", gain=1e300)
    cam = FirmwareCamera("imx219")
    assert "8192" in handle_line(cam, "SIZE 100000x100000")


def test_an_emu_start_past_the_device_clock_range_is_refused():
    with pytest.raises(SourceError, match=r"start_ns.*0\.\.4611686018427387904"):
        open_camera("emu:imx219?start_ns=9223372036854775807")
    with open_camera(f"emu:imx219?start_ns={2**62}&size=64x48&scene=flat") as cam:
        assert cam.read().timestamp_ns == 2**62


def test_a_trigger_storm_latches_one_frame_and_ignores_the_rest():
    clock = FakeClock()
    c = FirmwareCamera("imx219", clock=clock)
    c.set_trigger_mode("external")
    c.stream_on()
    first = c.trigger()
    frame_ns = c.schedule(first).frame_due_ns(0) - first
    clock.t += 1_000_000  # during the first frame's exposure: latched for when its readout ends
    latched = c.trigger()
    assert latched == first + frame_ns
    replies = {handle_line(c, "TRIGGER") for _ in range(3000)}  # while one is latched: ignored
    assert replies == {"OK IGNORED"}
    assert (c.stats.triggers, c.stats.triggers_ignored) == (2, 3000)
    plans = [c.plan_next(), c.plan_next(), c.plan_next()]
    assert [p.start_ns for p in plans[:2]] == [first, latched] and plans[2] is None
    clock.t = c.host_ns(latched + 10 * frame_ns)  # long idle: the next trigger starts a frame at once
    assert c.trigger() == c.clock_ns()
    assert "triggers_ignored=3000" in handle_line(c, "STATS?")


def test_an_unread_trigger_queue_stays_bounded():
    clock = FakeClock()
    c = FirmwareCamera("imx219", clock=clock)
    c.set_trigger_mode("external")
    c.stream_on()
    for _ in range(50):  # triggers spaced a second apart that nobody turns into frames
        c.trigger()
        clock.t += NS_PER_S
    assert c.stats.triggers == 50 and c.stats.skipped == 48
    assert c.plan_next() is not None and c.plan_next() is not None and c.plan_next() is None


def test_a_scene_change_is_built_without_holding_the_camera(monkeypatch):
    c = FirmwareCamera("imx219", size=(64, 48))
    c.stream_on()
    building, release = threading.Event(), threading.Event()
    real = CameraSpec.with_options

    def slow_build(spec, options, owner="camera"):
        building.set()
        assert release.wait(10)
        return real(spec, options, owner)

    monkeypatch.setattr(CameraSpec, "with_options", slow_build)
    t = threading.Thread(target=c.set_options, args=({"pedestrians": "5"},))
    t.start()
    try:
        assert building.wait(10)
        assert c.lock.acquire(timeout=2)  # frames and other controls go on while the scene is built
        c.lock.release()
        assert c.next_frame() is not None
    finally:
        release.set()
        t.join(10)
    assert c.scene_options["pedestrians"] == 5


def test_emulate_ends_with_the_error_of_a_dead_pump():
    from rollcam.emu.pump import FramePump
    from rollcam.host.servers.emulate import wait_until_stopped

    class Broken:
        def on_band(self, *args):
            pass

        def on_frame(self, *args):
            raise RuntimeError("sink exploded")

    cam = FirmwareCamera("imx219", size=(64, 48))
    cam.stream_on()
    with FramePump(cam, bands=1) as pump:
        pump.add_sink(Broken())
        started = time.monotonic()
        with pytest.raises(DeviceError, match="sink exploded") as err:
            wait_until_stopped(threading.Event(), 30, pump, poll_s=0.05)
        assert time.monotonic() - started < 20 and exit_code(err.value) == 1
    stop = threading.Event()
    stop.set()
    with FramePump(cam, bands=1) as healthy:
        wait_until_stopped(stop, 30, healthy)  # a stop request returns quietly


def _with(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


def _imx219() -> str:
    return (resources.files("rollcam.hw_configs") / "imx219.yaml").read_text()


def test_a_yaml_alias_bomb_is_refused_before_it_is_expanded(tmp_path):
    levels = ["&a0 [x, x, x, x, x, x, x, x, x]"]
    levels += [f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]  # 9**9 strings
    text = _imx219()
    path = tmp_path / "bomb.yaml"
    path.write_text(text[:text.index("\nsources:") + 1] + "sources: [" + ", ".join(levels) + "]\n")
    started = time.monotonic()
    with pytest.raises(ConfigError, match=r"bomb\.yaml: its aliases expand it to [\d,]+ values; .* at most 100,000"):
        load_sensor(path)
    assert time.monotonic() - started < 10


def test_a_bad_value_is_shown_short_in_the_message(tmp_path):
    path = tmp_path / "long.yaml"
    path.write_text(_with(_imx219(), "name: imx219", "name: [" + ", ".join(["[1, 2, 3, 4, 5, 6]"] * 2000) + "]"))
    with pytest.raises(ConfigError) as err:
        load_sensor(path)
    assert "name" in str(err.value) and len(str(err.value)) < 400


def test_a_frame_length_past_its_register_width_is_refused(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text(_with(_imx219(), "frame_length_lines: 3526", "frame_length_lines: " + "1" + "0" * 38))
    with pytest.raises(ConfigError, match=r"modes\[0\]\.frame_length_lines: expected <= 65535, the most its "
                                          r"16-bit frame_length register holds"):
        load_sensor(path)
