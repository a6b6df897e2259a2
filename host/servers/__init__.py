"""The emulated camera served to other programs: ``rollcam emulate`` (HTTP, serial, USB/IP), ``rollcam view``,
``rollcam run``'s device nodes (``devnodes``, on the LD_PRELOAD library of ``rollcam.emu.preload``), the
PipeWire node, and the stand-in modules (``picamera2``) those programs import."""
