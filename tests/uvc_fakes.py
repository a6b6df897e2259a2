"""A small deterministic FrameProducer for the UVC and USB/IP tests: flat frames, a clock the test moves."""

from __future__ import annotations

import numpy as np
from helpers import FakeClock
from rollcam.common.errors import DeviceError
from rollcam.emu.uvc.producer import ControlRange
from rollcam.sim.frame import Frame
from rollcam.sim.timing import Readout


class FakeProducer:
    """Frames whose pixels encode their index; sizes and intervals fixed; controls kept in a dict."""

    name = "fake"

    def __init__(self, sizes=((64, 48), (32, 24)), intervals_ns=(33_333_333, 66_666_667), clock=None,
                 start_ns: int = 0) -> None:
        self._sizes = list(sizes)
        self._intervals = list(intervals_ns)
        self.clock = clock or FakeClock()
        self.start_ns = start_ns
        self.size = self._sizes[0]
        self.interval_ns = self._intervals[0]
        self.controls = {"exposure_ns": 10_000_000, "gain": 100}
        self.ranges = {"exposure_ns": ControlRange(100_000, 30_000_000, 10_000_000, 100_000),
                       "gain": ControlRange(100, 1600, 100)}
        self.configured = []
        self.rendered = []

    def sizes(self):
        return list(self._sizes)

    def intervals_ns(self, width, height):
        return list(self._intervals)

    def configure(self, width, height, interval_ns):
        if (width, height) not in self._sizes:
            raise DeviceError(f"size {width}x{height}")
        self.size, self.interval_ns = (width, height), interval_ns
        self.configured.append((width, height, interval_ns))
        self.t0 = self.now_ns()

    def timestamp_ns(self, index):
        return getattr(self, "t0", 0) + index * self.interval_ns

    def frame_due_ns(self, index):
        return self.timestamp_ns(index) + self.interval_ns

    def frame(self, index):
        self.rendered.append(index)
        w, h = self.size
        data = np.full((h, w, 3), (index * 37) % 200 + 20, np.uint8)
        return Frame(data=data, format="BGR3", sequence=index, timestamp_ns=self.timestamp_ns(index),
                     line_time_ns=1000, readout=Readout.TOP_TO_BOTTOM, exposure_ns=self.controls["exposure_ns"])

    def now_ns(self):
        return self.start_ns + self.clock()

    def control_range(self, name):
        return self.ranges[name]

    def get_control(self, name):
        return self.controls[name]

    def set_control(self, name, value):
        r = self.ranges[name]
        self.controls[name] = min(max(value, r.minimum), r.maximum)
        return self.controls[name]
