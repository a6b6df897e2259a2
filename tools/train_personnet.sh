#!/bin/sh
# Rebuild the packaged personnet detector (host/detectors/models/personnet/) from nothing but rollcam: render
# its dataset, train it, measure it, and copy the model with its cards and licence into the package.
#   tools/train_personnet.sh [OUT]      (default OUT: rollcam_out/personnet; rerun to resume)
# The dataset build and the training each resume from where an interruption left them. Cost on this project's
# shared 2-core machine: ~1.5 min to render, ~46 min to train (two threads, idle machine), ~1 min to measure.
# ROLLCAM and PYTHON name the programs (default: rollcam and python on PATH).
set -eu
OUT=${1:-rollcam_out/personnet}
ROLLCAM=${ROLLCAM:-rollcam}
PYTHON=${PYTHON:-python}
$ROLLCAM dataset --out "$OUT/data" --frames 640 --scenes 30 --workers 2
$ROLLCAM train "$OUT/data" --model nano --imgsz 640x360 --epochs 36 --batch 8 --lr 5e-3 --seed 0 --threads 2 \
    --val-every 4 --out "$OUT/run"
$ROLLCAM bench personnet --model "$OUT/run/model.onnx" --dataset "$OUT/data" --out "$OUT/bench"
$PYTHON tools/ship_personnet.py "$OUT/run" "$OUT/bench/personnet.json" host/detectors/models/personnet
