"""The serial control protocol: commands, error replies, and a fuzzed parser that never stops answering."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import COMMANDS, MAX_LINE, ProtocolSession, handle_line

FUZZ_COUNTS: dict[str, int] = {}


def session() -> ProtocolSession:
    return ProtocolSession(FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480)))


def ask(s: ProtocolSession, *lines: str) -> list[str]:
    out = s.feed("".join(f"{line}\r\n" for line in lines).encode()).decode()
    return out.split("\r\n")[:-1]


def test_identify_scpi_style():
    maker, model, serial, fw = ask(session(), "*IDN?")[0].split(",")
    assert (maker, model) == ("rollcam", "IMX219-EMU") and serial and fw


def test_register_read_write_and_controls():
    s = session()
    assert ask(s, "REG? 0x0000", "reg? chip_id") == ["0x0219", "0x0219"]
    assert ask(s, "REG 0x0160 2000", "REG? FRM_LENGTH_A") == ["OK 0x07D0", "0x07D0"]
    assert ask(s, "CTRL EXPOSURE 99999") == ["OK 1996"]
    assert ask(s, "CTRL? vblank") == [str(2000 - 480)]
    assert "exposure=1996 [4..1996] lines" in ask(s, "CTRLS?")[0]


def test_stream_trigger_clock_and_size():
    s = session()
    assert ask(s, "STREAM?", "SIZE 1920x1080", "SIZE?", "STREAM ON", "STREAM?") == ["OFF", "OK", "1920x1080", "OK",
                                                                                   "ON"]
    assert ask(s, "SIZE 640x480")[0].startswith("ERR 103 cannot change the mode while streaming")
    t0, t1 = (int(v) for v in ask(s, "CLOCK?", "CLOCK?"))
    assert 0 <= t0 <= t1
    assert ask(s, "TRIGGER")[0].startswith("ERR 103 trigger needs trigger mode")
    reply = ask(s, "TRIGMODE EXTERNAL", "TRIGGER")
    assert reply[0] == "OK" and reply[1].startswith("OK ") and int(reply[1][3:]) >= t1


def test_errors_name_the_problem():
    s = session()
    assert ask(s, "FOO")[0] == "ERR 100 unknown command 'FOO'; try HELP"
    assert ask(s, "REG? 0x0160 7")[0].startswith("ERR 101 REG? takes 1 argument(s) (REG? ADDR|NAME), got 2")
    assert ask(s, "REG 0x0160 zz")[0] == "ERR 102 value 'zz' is not an integer (decimal or 0x hex)"
    assert ask(s, "REG? 0x9999")[0] == "ERR 102 no register at address 0x9999"
    assert ask(s, "SHUTTER GLOBAL")[0] == "ERR 103 sensor 'imx219' has only a rolling shutter"
    assert ask(s, "CTRL pixel_rate 1")[0] == "ERR 103 control 'pixel_rate' is read-only"
    assert s.feed(b"\xff\r\n").startswith(b"ERR 104 line is not ASCII")
    assert s.feed(b"A" * (MAX_LINE + 10) + b"\n") == f"ERR 104 line longer than {MAX_LINE} bytes\r\n".encode()
    assert ask(s, "*IDN?")[0].startswith("rollcam,")  # still serving


def test_help_lists_every_command():
    reply = handle_line(FirmwareCamera("letsroll", scene={"scene": "flat"}), "HELP")
    assert all(name in reply for name in COMMANDS)


_words = st.sampled_from([*COMMANDS, "0x0160", "0x0000", "1", "-5", "ON", "OFF", "exposure", "vblank",
                          "hflip", "test_pattern", "scene", "seed", "chart", "flat", "999999999999", "1920x1080"])
_lines = st.lists(_words, min_size=0, max_size=4).map(" ".join)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chunks=st.lists(st.one_of(st.binary(max_size=300), _lines.map(lambda t: (t + "\n").encode())),
                       min_size=1, max_size=8))
def _fuzz_parser(chunks):
    """Random bytes and random command-word lines: every complete line gets exactly one reply line."""
    FUZZ_COUNTS["serial_parser"] = FUZZ_COUNTS.get("serial_parser", 0) + 1
    s = session()
    data = b"".join(chunks)
    out = s.feed(data) + s.feed(b"\n")
    replies = out.split(b"\r\n")[:-1]
    assert all(r and b"\n" not in r and b"\r" not in r for r in replies)
    assert all(r.isascii() for r in replies)
    assert ask(s, "*IDN?")[0].startswith("rollcam,")  # the device still answers


def test_fuzz_parser_always_answers():
    FUZZ_COUNTS["serial_parser"] = 0
    _fuzz_parser()
    assert FUZZ_COUNTS["serial_parser"] >= 100  # hypothesis really ran (it stops early only on failure)
    print(f"serial parser fuzz: {FUZZ_COUNTS['serial_parser']} inputs")


def test_size_reads_the_one_wxh_parser():
    s = session()
    assert ask(s, "SIZE 640", "SIZE 0x480", "SIZE 640X480") == [
        "ERR 102 size '640' is not WIDTHxHEIGHT (e.g. 1920x1080)", "ERR 102 size '0x480' must be positive", "OK"]
