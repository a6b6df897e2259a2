#!/bin/sh
# Rebuild the packaged personnet-raw detector (host/detectors/models/personnet_raw/) from nothing but rollcam:
# render the raw-mosaic dataset (the study's reduced setting's raw dataset: letsroll 320x180, fast walkers, RGGB),
# train on its mosaics, measure it, and copy the model with its cards and licence into the package.
#   tools/train_personnet_raw.sh [OUT] [EPOCHS]   (default OUT: rollcam_out/personnet-raw, EPOCHS 100; rerun to resume)
# Cost on this project's shared 2-core machine (loaded by other jobs): ~7 s an epoch to train (738 s for the 100
# epochs of the shipped model); the render was not timed here (the shipped model's data was the study's own run).
# ROLLCAM and PYTHON name the programs (default: rollcam and python on PATH).
set -eu
OUT=${1:-rollcam_out/personnet-raw}
EPOCHS=${2:-100}
ROLLCAM=${ROLLCAM:-rollcam}
PYTHON=${PYTHON:-python}
$ROLLCAM dataset --out "$OUT/data" --sensor letsroll --size 320x180 --frames 200 --scenes 20 --cameras 5 \
    --times morning,noon,dusk --speeds fast --raw RGGB --workers 2
$ROLLCAM train "$OUT/data" --model pico --input raw --imgsz 320x180 --epochs "$EPOCHS" --batch 16 --lr 6e-3 \
    --seed 0 --threads 1 --val-every 10 --out "$OUT/run"
$PYTHON tools/ship_personnet_raw.py "$OUT/run" "$OUT/data" host/detectors/models/personnet_raw
