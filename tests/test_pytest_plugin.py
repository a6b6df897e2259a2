"""The pytest plugin as a user meets it: registered by entry point, fixtures usable with no import."""

from __future__ import annotations

from importlib.metadata import entry_points

pytest_plugins = ["pytester"]


def test_plugin_is_registered_by_entry_point():
    eps = {ep.name: ep.value for ep in entry_points(group="pytest11")}
    assert eps.get("rollcam") == "rollcam.host.testing"


def test_users_tests_run_on_the_fixtures(pytester):
    pytester.makepyfile(test_user='''
        import cv2

        def run_oak_capture():
            import depthai as dai
            frames = []
            with dai.Pipeline() as pipeline:
                cam = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
                queue = cam.requestOutput((320, 180), dai.ImgFrame.Type.BGR888i).createOutputQueue()
                pipeline.start()
                while pipeline.isRunning():
                    frames.append(queue.get().getCvFrame())
            return frames

        def test_camera(rollcam_camera):
            cam = rollcam_camera("imx219", scene="street", speed="fast", seed=4, size="320x180")
            frame = cam.read()
            assert frame.data.shape == (180, 320, 3) and frame.objects is not None

        def test_oak_script_without_an_oak(mock_depthai):
            mock_depthai.devices[0].frames = 3
            assert len(run_oak_capture()) == 3

        def test_stream(rollcam_camera, rollcam_mjpeg_server):
            cam = rollcam_camera("ov9281", scene="chart", size="160x100")
            server = rollcam_mjpeg_server([cam.read(), cam.read()])
            cap = cv2.VideoCapture(server.url)  # OpenCV reads the same stream
            assert cap.isOpened() and cap.read()[0]
            cap.release()
            from rollcam.host import open_camera
            with open_camera(server.url) as src:
                assert [f.shutter for f in src] == ["global", "global"]

        def test_pyusb_finds_and_negotiates(rollcam_usb_backend):
            import usb.core
            backend = rollcam_usb_backend("imx219", cameras=2, scene="flat")
            devs = list(usb.core.find(find_all=True, idVendor=0x1209, backend=backend))
            assert sorted(d.idProduct for d in devs) == [0x0001, 0x0002]
            dev = devs[0]
            dev.set_configuration()
            probe = dev.ctrl_transfer(0xA1, 0x87, 0x0100, 1, 34)  # GET_DEF of VS_PROBE_CONTROL
            assert len(probe) == 34

        def test_serial_port(rollcam_serial_port):
            import serial
            port = rollcam_serial_port("imx219", scene="flat")
            with serial.Serial(port.path, timeout=5) as ser:
                ser.write(b"*IDN?\\n")
                assert ser.readline().startswith(b"rollcam,IMX219-EMU,")
    ''')
    # labgrid's plugin (the labgrid extra) starts a process-wide step logger once: an in-process run leaves it out
    result = pytester.runpytest_inprocess("-q", "-p", "no:cacheprovider", "-p", "no:labgrid")
    result.assert_outcomes(passed=5)
