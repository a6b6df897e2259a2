"""The camera's line-based serial control protocol: one command per line, one reply line per command.

Commands are case-insensitive words separated by spaces; numbers are decimal or ``0x`` hex; lines end in
LF, CR or CRLF. A query ends in ``?``. Replies: a value, ``OK`` (or ``OK <value>``), or
``ERR <code> <message>`` naming the problem (codes in ``ERRORS``). The table ``COMMANDS`` is the protocol;
``rollcam emulate --serial`` serves it on a pseudo-terminal and ``rollcam://`` through pyserial.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from rollcam.common.errors import ConfigError, DeviceError, ProtocolError
from rollcam.common.values import parse_bool, parse_size

from .camera import FirmwareCamera
from .imu import device_samples
from .options import OPTIONS, SCENE_OPTIONS, as_text

MAX_LINE = 256
MAX_IMU_REPLY = 32
"""Most IMU samples one ``IMU?`` reply holds (ask again from its ``next=`` for more)."""
MAX_INSENSOR_REPLY = 4
"""Most in-sensor results one ``INSENSOR?`` reply holds (ask again from its ``next=`` for more)."""
ERRORS = {100: "unknown command", 101: "wrong arguments", 102: "invalid value", 103: "refused by the device",
          104: "malformed line"}


class CommandError(ProtocolError):
    """A command the protocol rejects; ``code`` is one of ``ERRORS``."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def parse_int(text: str, what: str = "value") -> int:
    """A decimal or 0x-hex integer argument."""
    try:
        return int(text, 0)
    except ValueError:
        raise CommandError(102, f"{what} {text!r} is not an integer (decimal or 0x hex)") from None


def _reg_key(text: str) -> int | str:
    return parse_int(text, "address") if text[:1].isdigit() else text


def _on_off(text: str) -> bool:
    try:
        return parse_bool(text)
    except ValueError as exc:
        raise CommandError(102, str(exc)) from None


def _ctrl_line(cam: FirmwareCamera) -> str:
    parts = []
    for name, c in cam.controls().items():
        extra = f" {'|'.join(c['menu'])}" if c["menu"] else (f" {c['unit']}" if c["unit"] else "")
        parts.append(f"{name}={c['value']} [{c['min']}..{c['max']}]{extra}{' ro' if c['read_only'] else ''}")
    return "; ".join(parts)


def _size(cam: FirmwareCamera, text: str) -> str:
    cam.set_size(*parse_size(text))
    return "OK"


def _fmt(cam: FirmwareCamera, text: str) -> str:
    """Select a format; fourccs are matched exactly, else case-insensitively (``rg10``), with a 3-letter
    one's trailing space implied (``Y10``)."""
    want = text.ljust(4) if len(text) == 3 else text
    if want not in cam.formats:
        want = next((f for f in cam.formats if f.upper() == want.upper()), text)
    return f"OK {cam.set_format(want).strip()}"


def _scene(cam: FirmwareCamera, key: str, value: str) -> str:
    name = key.lower()
    if name not in SCENE_OPTIONS:
        raise CommandError(102, f"SCENE {key!r} is not a scene option; options: {sorted(SCENE_OPTIONS)}")
    cam.set_options({name: value})
    return "OK"


def _set_option(cam: FirmwareCamera, key: str, value: str) -> str:
    name = key.lower()
    if name not in OPTIONS:
        raise CommandError(102, f"{key!r} is not a camera option; options: {sorted(OPTIONS)}")
    cam.set_options({name: value})
    return f"OK {as_text(cam.spec.option_values()[name])}"


def _get_option(cam: FirmwareCamera, key: str) -> str:
    name = key.lower()
    if name not in OPTIONS:
        raise CommandError(102, f"{key!r} is not a camera option; options: {sorted(OPTIONS)}")
    return as_text(cam.spec.option_values()[name])


def _scene_query(cam: FirmwareCamera) -> str:
    return " ".join(f"{k}={v}" for k, v in cam.scene_options.items())


def _or_ignored(start_ns: int | None) -> str:
    return "IGNORED" if start_ns is None else str(start_ns)


def _imu(cam: FirmwareCamera, since: str) -> str:
    """``n=N next=T t,wx,wy,wz,ax,ay,az;...``: samples stamped from ``since`` to the device clock now."""
    t0 = parse_int(since, "start time")
    s = device_samples(cam, t0, MAX_IMU_REPLY)
    nxt = int(s.t_ns[-1]) + 1 if len(s) else t0
    rows = ";".join(",".join([str(r[0]), *(f"{v:.9g}" for v in r[1:])]) for r in s.to_rows())
    return f"n={len(s)} next={nxt} {rows}".rstrip()


def _insensor(cam: FirmwareCamera, since: str) -> str:
    """``n=N next=SEQ SEQ,T0,INPUT,DONE,K[,x0,y0,x1,y1,score,cls]*;...``: results of frames from ``since`` on
    that are done on the device clock now (T0 the frame's first-line start of exposure; times in ns)."""
    if cam.spec.insensor is None:
        raise DeviceError("no in-sensor network (OPT insensor SPEC sets one)")
    first = parse_int(since, "frame sequence number")
    got = cam.insensor.recent(cam.clock_ns(), first)[:MAX_INSENSOR_REPLY]
    nxt = got[-1].seq + 1 if got else first
    parts = []
    for r in got:
        dets = [f"{b[0]:.1f},{b[1]:.1f},{b[2]:.1f},{b[3]:.1f},{sc:.3f},{c}"
                for b, sc, c in zip(r.boxes, r.scores, r.classes, strict=True)]
        parts.append(",".join([str(r.seq), str(r.timestamp_ns), str(r.input_ns), str(r.done_ns), str(len(r)),
                               *dets]))
    return f"n={len(got)} next={nxt} {';'.join(parts)}".rstrip()


def _ledger(cam: FirmwareCamera) -> str:
    doc = cam.insensor.ledger(cam.spec).to_json()
    rows = " ".join(f"{k}={v['bytes_per_frame']}" for k, v in doc["rows"].items())
    util = doc["rows"]["sent"]["utilisation"]
    e = doc["energy_uj_per_frame"]
    return (f"{rows} util={'none' if util is None else f'{util:.6f}'} insensor_uj={e['insensor']:.3f} "
            f"host_uj={e['host']:.3f}")


def _stats(cam: FirmwareCamera) -> str:
    return " ".join(f"{k}={v}" for k, v in dataclasses.asdict(cam.stats).items())


@dataclass(frozen=True)
class Command:
    """One protocol command: argument names, handler, one-line help."""

    args: tuple[str, ...]
    run: Callable[..., str]
    help: str


COMMANDS: dict[str, Command] = {
    "*IDN?": Command((), lambda c: c.identity(), "identify: maker,model,serial,firmware"),
    "HELP": Command((), lambda c: " | ".join(f"{k} {' '.join(v.args)}".strip() for k, v in COMMANDS.items()),
                    "list the commands"),
    "REG?": Command(("ADDR|NAME",), lambda c, k: f"0x{c.read_register(_reg_key(k)):04X}", "read a register"),
    "REG": Command(("ADDR|NAME", "VALUE"),
                   lambda c, k, v: f"OK 0x{c.write_register(_reg_key(k), parse_int(v)):04X}",
                   "write a register; replies with its new value"),
    "CTRL?": Command(("NAME",), lambda c, n: str(c.get_control(n.lower())), "read a control"),
    "CTRL": Command(("NAME", "VALUE"), lambda c, n, v: f"OK {c.set_control(n.lower(), parse_int(v))}",
                    "set a control (clamped to range); replies with the value in effect"),
    "CTRLS?": Command((), _ctrl_line, "every control: name=value [min..max] unit"),
    "STREAM": Command(("ON|OFF",), lambda c, v: (c.stream_on() if _on_off(v) else c.stream_off()) or "OK",
                      "start or stop streaming"),
    "STREAM?": Command((), lambda c: "ON" if c.streaming else "OFF", "streaming state"),
    "SHUTTER": Command(("ROLLING|GLOBAL",), lambda c, v: c.set_shutter(v.lower()) or "OK",
                       "shutter mode (sensors that have both)"),
    "SHUTTER?": Command((), lambda c: c.state.shutter.upper(), "shutter mode"),
    "TRIGMODE": Command(("FREE|EXTERNAL",), lambda c, v: c.set_trigger_mode(v.lower()) or "OK",
                        "free-running or one frame per TRIGGER"),
    "TRIGMODE?": Command((), lambda c: c.trigger_mode.upper(), "trigger mode"),
    "TRIGGER": Command((), lambda c: f"OK {_or_ignored(c.trigger())}",
                       "trigger pulse: starts a frame (or latches one during a frame); replies with its start "
                       "(device ns) or IGNORED (one already latched)"),
    "CLOCK?": Command((), lambda c: str(c.clock_ns()), "device clock, integer ns since boot"),
    "INTERVAL?": Command((), lambda c: str(c.frame_interval_ns), "frame interval, ns"),
    "SIZE": Command(("WxH",), _size, "select the mode of this output size (not while streaming)"),
    "SIZE?": Command((), lambda c: "{}x{}".format(*c.size), "output size"),
    "FMT": Command(("FOURCC",), _fmt, "select the pixel format (not while streaming); replies with the fourcc in "
                   "effect (raw: in the Bayer order of the flips)"),
    "FMT?": Command((), lambda c: c.pixel_format.strip(), "current pixel format (a raw one follows the flips)"),
    "FMTS?": Command((), lambda c: " ".join(f.strip() for f in c.formats), "formats: processed, then raw"),
    "SCENE": Command(("KEY", "VALUE"), _scene, "scene control: scene, seed, and the kind's own options"),
    "SCENE?": Command((), _scene_query, "scene options"),
    "OPT": Command(("NAME", "VALUE"), _set_option, "set a camera option as the emu: URI names it (gain 2, "
                   "exposure_us 5000, format RG10, ...); replies with the value in effect"),
    "OPT?": Command(("NAME",), _get_option, "a camera option's value in effect"),
    "IMU?": Command(("SINCE_NS",), _imu, f"IMU samples stamped from SINCE_NS (device ns) until now, at most "
                    f"{MAX_IMU_REPLY}: n=N next=T t,wx,wy,wz,ax,ay,az;... (rad/s, m/s^2)"),
    "INSENSOR?": Command(("SINCE_SEQ",), _insensor, f"in-sensor results of frames from SINCE_SEQ done by now, at "
                         f"most {MAX_INSENSOR_REPLY}: n=N next=SEQ seq,t0_ns,input_ns,done_ns,k"
                         "[,x0,y0,x1,y1,score,cls]*;..."),
    "LEDGER?": Command((), _ledger, "bytes per frame (raw, isp, meta, tensor, sent), link utilisation, energy per "
                       "frame (uJ) of the in-sensor and host pipelines"),
    "STATS?": Command((), _stats, "frames made, skipped, triggers taken and ignored, in-sensor runs and skips"),
}
"""The protocol: command word -> Command."""


def handle_line(camera: FirmwareCamera, line: str) -> str:
    """The reply to one command line (never raises for bad input: errors become ``ERR`` replies)."""
    try:
        return _dispatch(camera, line)
    except CommandError as exc:
        return f"ERR {exc.code} {exc}"
    except ConfigError as exc:
        return f"ERR 102 {exc}"
    except DeviceError as exc:
        return f"ERR 103 {exc}"


def _dispatch(camera: FirmwareCamera, line: str) -> str:
    words = line.split()
    if not words:
        raise CommandError(104, "empty command; try HELP")
    name, args = words[0].upper(), words[1:]
    cmd = COMMANDS.get(name)
    if cmd is None:
        raise CommandError(100, f"unknown command {words[0]!r}; try HELP")
    if len(args) != len(cmd.args):
        form = " ".join((name, *cmd.args))
        raise CommandError(101, f"{name} takes {len(cmd.args)} argument(s) ({form}), got {len(args)}")
    return cmd.run(camera, *args)


class ProtocolSession:
    """Bytes in, reply bytes out, for one connection: splits lines, bounds their length, answers each."""

    def __init__(self, camera: FirmwareCamera, newline: bytes = b"\r\n") -> None:
        self.camera = camera
        self.newline = newline
        self._buf = bytearray()
        self._discarding = False
        self.lines = 0

    def feed(self, data: bytes) -> bytes:
        """Consume received bytes; return the replies to every line they complete."""
        out = bytearray()
        for byte in data:
            if byte in (0x0A, 0x0D):
                if self._discarding:
                    out += f"ERR 104 line longer than {MAX_LINE} bytes".encode() + self.newline
                    self._discarding = False
                elif self._buf:
                    out += self.reply(bytes(self._buf)) + self.newline
                self._buf.clear()
            elif self._discarding:
                continue
            elif len(self._buf) >= MAX_LINE:
                self._discarding, self._buf = True, bytearray()
            else:
                self._buf.append(byte)
        return bytes(out)

    def reply(self, raw: bytes) -> bytes:
        """The reply to one raw line (without its terminator)."""
        self.lines += 1
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            return f"ERR 104 line is not ASCII text: {raw[:40]!r}".encode()
        if not text.isprintable():
            return f"ERR 104 line holds control characters: {text[:40]!r}".encode()
        return handle_line(self.camera, text).encode("ascii", "backslashreplace")
