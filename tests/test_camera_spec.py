"""One camera from one spec: the same settings through every door give the same spec and byte-identical frames."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys

import numpy as np
import pytest
from rollcam.common.errors import ConfigError, SourceError
from rollcam.emu.v4l2 import Device
from rollcam.emu.v4l2 import functions as fn
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.imaging import encode
from rollcam.firmware.options import OPTIONS, parse_options
from rollcam.firmware.protocol import ProtocolSession, handle_line
from rollcam.firmware.spec import CameraSpec
from rollcam.host.sources import open_camera

LINES = 300  # a non-default exposure, in whole lines of the 640x480 mode (line_offset_ns(1) = 18903 ns)
EXPOSURE_US = LINES * 18903 / 1000
START_NS = 0  # devices below boot at host time 0 and start streaming then: frame 0 starts at device time 0
URI = (f"emu:imx219?size=640x480&scene=street&seed=2&speed=fast&hflip=on&exposure_us={EXPOSURE_US}&gain=2"
       f"&start_ns={START_NS}")


def _uri_frame(fourcc: str):
    with open_camera(f"{URI}&format={fourcc}&frames=1") as src:
        return src.read(), src.spec


def _serial_device(fourcc: str) -> FirmwareCamera:
    cam = FirmwareCamera("imx219", clock=lambda: 0)
    session = ProtocolSession(cam)
    lines = ["SIZE 640x480", "SCENE scene street", "SCENE seed 2", "SCENE speed fast", "CTRL hflip 1",
             f"CTRL exposure {LINES}", "CTRL analogue_gain 128", f"FMT {fourcc}"]  # 256 / (256 - 128) = 2x
    replies = session.feed("".join(f"{line}\n" for line in lines).encode()).decode().split()
    assert all(not r.startswith("ERR") for r in replies), replies
    return cam


def _register_device(fourcc: str) -> FirmwareCamera:
    cam = FirmwareCamera("imx219", size=(640, 480), scene={"scene": "street", "seed": 2, "speed": "fast"},
                         clock=lambda: 0)
    cam.write_register("ORIENTATION", 0b01)  # hflip
    cam.write_register("COARSE_INTEGRATION_TIME", LINES)
    cam.write_register("ANALOG_GAIN", 128)
    cam.set_format(fourcc)
    return cam


def _device_frame(cam: FirmwareCamera):
    return encode(cam.render(FramePlan(0, cam.schedule(START_NS))), cam.spec)


@pytest.mark.parametrize("fourcc", ["RG10", "pRAA", "YUYV", "BGR3"])
def test_uri_serial_and_registers_give_the_same_spec_and_bytes(fourcc):
    want, spec = _uri_frame(fourcc)
    assert spec.hflip and spec.gain == 2.0 and spec.settings.exposure_ns == spec.settings.timing.line_offset_ns(LINES)
    for make in (_serial_device, _register_device):
        cam = make(fourcc)
        assert cam.spec == spec, make.__name__
        got = _device_frame(cam)
        assert (got.format, got.timestamp_ns, got.sequence) == (want.format, want.timestamp_ns, want.sequence)
        assert got.data.dtype == want.data.dtype and np.array_equal(got.data, want.data), make.__name__
        assert np.array_equal(got.row_times_ns, want.row_times_ns) and got.objects == want.objects
    if fourcc != "BGR3":
        assert want.meta["noise_stages"]  # the sensor model ran (raw, and processed formats but BGR3)


def test_v4l2_s_fmt_and_s_ctrl_give_the_same_raw_bytes():
    want, spec = _uri_frame("RG10")
    with Device.open("imx219", scene={"scene": "street", "seed": 2, "speed": "fast"}, realtime=False,
                     clock=lambda: 0) as d:
        d.set_format(640, 480, "RG10")
        d.controls["hflip"].value = 1
        d.controls["exposure"].value = LINES
        d.controls["analogue_gain"].value = 128
        assert d.driver.camera.spec == spec
        fn.request_buffers(d.driver, 2)
        fn.queue_buffer(d.driver, 0)
        fn.stream_on(d.driver)
        buf, data = fn.dequeue_buffer(d.driver)
        assert bytes(data[: buf.bytesused]) == want.data.tobytes()
        assert d.driver.fmt.pixelformat == want.format != "RG10"  # the flip's Bayer order, as a sensor driver
        fn.stream_off(d.driver)


def test_the_same_seed_gives_the_same_bytes_and_frames_carry_their_start():
    a, _ = _uri_frame("pRAA")
    b, _ = _uri_frame("pRAA")
    assert np.array_equal(a.data, b.data)
    cam = FirmwareCamera(CameraSpec.create("imx219", size=(64, 48), scene="chart"))
    synth = cam.synthetic
    with pytest.raises(AttributeError):
        synth.start_ns = 5  # no clock to set: each render is given its frame's start
    f1, f2 = synth.render(3, 1_000_000), synth.render(3, 9_000_000)
    assert (f1.timestamp_ns, f2.timestamp_ns) == (1_000_000, 9_000_000) and f1.sequence == 3
    assert np.array_equal(synth.render(3, 1_000_000).data, f1.data)


def test_spec_validates_once_and_replace_revalidates():
    spec = CameraSpec.create("imx219", size=(640, 480))
    assert spec.pixel_format == "BGR3" and spec.gain == 1.0 and spec.serial == "0001"
    with pytest.raises(ConfigError, match="gain"):
        dataclasses.replace(spec, gain=float("nan"))
    with pytest.raises(ConfigError, match="physics"):
        dataclasses.replace(spec, pixel_format="RG10", physics=False)
    with pytest.raises(ConfigError, match="shorter than"):
        dataclasses.replace(spec, frame_length_lines=100)
    flipped = dataclasses.replace(spec, pixel_format="RG10", hflip=True)
    assert flipped.pixel_format == "RG10" and flipped.output_format != "RG10"
    assert dataclasses.replace(flipped, pixel_format=flipped.output_format) == flipped  # either order's name
    with pytest.raises(ConfigError, match="12 bits"):
        CameraSpec.create("imx219", pixel_format="RG12")


def test_one_option_table_one_rule_for_fps_and_scene_options():
    with pytest.raises(SourceError, match=r"fps=1000\.0 is above the sensor's maximum") as uri_err:
        open_camera("emu:imx219?fps=1000")
    res = subprocess.run([sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--fps", "1000",
                          "--duration", "0"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and res.stderr.startswith("rollcam: error:")
    assert res.stderr.split("error: ", 1)[1].strip() == str(uri_err.value).split(": ", 1)[1]
    assert handle_line(FirmwareCamera("imx219"), "OPT fps 1000").startswith("ERR 102 fps=1000.0 is above")
    with pytest.raises(ConfigError, match="does not apply to scene='flat'"):
        parse_options({"scene": "flat", "speed": "fast"}, "x")
    assert set(parse_options({}, "x")) == set()
    assert all(o.doc for o in OPTIONS.values())


def test_rollcam_url_rejects_repeated_and_unknown_options():
    serial = pytest.importorskip("serial")
    if "rollcam.emu" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("rollcam.emu")
    with pytest.raises(serial.SerialException, match="'seed' given twice"):
        serial.serial_for_url("rollcam://imx219?seed=1&seed=2")
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("rollcam://imx219?colour=red")
    with serial.serial_for_url("rollcam://imx219?scene=flat&gain=2&size=640x480", timeout=2) as port:
        port.write(b"OPT? gain\nSCENE?\nCTRL? analogue_gain\n")
        assert [port.readline().strip() for _ in range(3)] == [b"2", b"scene=flat seed=0", b"128"]


def test_gain_is_the_linear_total_gain_on_every_door():
    cam = FirmwareCamera("imx219", size=(640, 480))
    cam.write_register("ANALOG_GAIN", 128)  # 2x
    cam.write_register("DIGITAL_GAIN", 0x0200)  # 2x
    assert cam.spec.gain == pytest.approx(4.0)
    assert handle_line(cam, "OPT? gain") == "4"
    cam.set_options({"gain": "1.5"})  # a gain the codes cannot hold exactly stays exact in the spec
    assert cam.spec.gain == 1.5 and cam.get_control("analogue_gain") == round(256 - 256 / 1.5)


def test_the_option_table_names_the_simulators_shutters():
    from rollcam.firmware import options
    from rollcam.sim import synthetic

    assert options.SHUTTERS == synthetic.SHUTTERS  # kept apart so the table loads without numpy


def test_create_with_fps_keeps_the_line_length_it_is_given():
    spec = CameraSpec.create("imx219", size=(640, 480), fps=30, line_length_pck=5000)
    assert spec.line_length_pck == 5000 or spec.settings.timing.line_length_pck == 5000
    assert abs(spec.settings.timing.fps - 30) < 0.05


def test_typed_scene_values_keep_their_precision():
    spec = CameraSpec.create("imx219", size=(640, 480), scene={"scene": "street", "speed": 12.3456789})
    assert dict(spec.scene_options)["speed"] == "12.3456789"


def test_every_scene_kind_of_the_option_table_is_one_the_simulator_builds():
    # the option table lists the kinds without importing the simulator; make_scene is the one that builds them
    from rollcam.firmware.options import SCENE_KINDS
    from rollcam.sim.scenegen import make_scene

    for kind in SCENE_KINDS:
        assert make_scene(kind, 0).cameras, kind
    with pytest.raises(ConfigError, match=re.escape(str(list(SCENE_KINDS)))):
        make_scene("moon", 0)
