"""``rollcam list`` device sections: found devices, and the reason when a section is empty."""

from __future__ import annotations

import types

from rollcam.host.sources.discover import oak_devices, usb_video_devices, v4l2_devices


def test_v4l2_lists_nodes_with_names(tmp_path):
    dev, sysfs = tmp_path / "dev", tmp_path / "sys"
    dev.mkdir()
    (dev / "video0").touch()
    (dev / "video10").touch()
    (sysfs / "video0").mkdir(parents=True)
    (sysfs / "video0" / "name").write_text("Integrated Camera\n")
    rows, note = v4l2_devices(dev, sysfs)
    assert [r["uri"] for r in rows] == [f"v4l2:{dev}/video0", f"v4l2:{dev}/video10"] and not note
    assert rows[0]["name"] == "Integrated Camera"
    rows, note = v4l2_devices(tmp_path / "empty", sysfs)
    assert rows == [] and "no camera plugged in" in note


def test_oak_section_on_the_mock(mock_depthai):
    rows, note = oak_devices(mock_depthai)
    assert rows[0]["uri"] == "oak:14442C10D13EABCE00" and not note
    mock_depthai.devices.clear()
    assert "plug one in" in oak_devices(mock_depthai)[1]


def test_usb_section_filters_video_class():
    def device(vid, pid, classes):
        cfg = [types.SimpleNamespace(bInterfaceClass=c) for c in classes]
        return types.SimpleNamespace(idVendor=vid, idProduct=pid, bDeviceClass=0xEF, bus=1, address=4,
                                     __iter__=None, configs=[cfg])

    class Dev(types.SimpleNamespace):
        def __iter__(self):
            return iter(self.configs)

    devs = [Dev(**vars(device(0x1209, 0x0001, [0x0E, 0x0E]))), Dev(**vars(device(0x046D, 0xC52B, [0x03])))]
    rows, note = usb_video_devices(lambda find_all: devs)
    assert [r["uri"] for r in rows] == ["uvc:1209:0001"] and not note

    class NoBackendError(Exception):
        pass

    def broken(find_all):
        raise NoBackendError("No backend available")

    rows, note = usb_video_devices(broken)
    assert rows == [] and "libusb-1.0" in note
