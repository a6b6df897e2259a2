#!/bin/sh
# Rebuild the packaged personnet detector (host/detectors/models/personnet/) from nothing but rollcam: render
# its datasets, train it in three stages, measure it, and copy the model with its cards and licence into the
# package.
#   tools/train_personnet.sh [OUT]      (default OUT: rollcam_out/personnet; rerun to resume)
# Stage 1 trains from scratch on 640 pairs; stage 2 fine-tunes its model.onnx on 2,000 pairs (the study's design:
# 40 scenes); stage 3 fine-tunes stage 2's for one epoch on the train split of 4,000 pairs of 80 other scenes
# (dataset seed 1, scenes 0..63) with background images (flat frames, person-free crops, empty streets, crops
# flush with a frame edge), so that it reports nobody in featureless frames. The figures are measured on that
# dataset's scenes no stage trained on: the NMS IoU and the score threshold on its validation split (64..71), the
# targets on its test split (72..79), and false positives on 450 empty street frames of scenes of their own.
# Every dataset build and training resumes from where an interruption left it. Cost on this project's 2-core
# machine, idle: ~1.5 + ~4 + ~12 min to render, ~46 + ~56 + ~17 min to train (two threads), ~6 min to measure.
# ROLLCAM and PYTHON name the programs (default: rollcam and python on PATH).
set -eu
OUT=${1:-rollcam_out/personnet}
ROLLCAM=${ROLLCAM:-rollcam}
PYTHON=${PYTHON:-python}
$ROLLCAM dataset --out "$OUT/data" --frames 640 --scenes 30 --workers 2
$ROLLCAM train "$OUT/data" --model nano --imgsz 640x360 --epochs 36 --batch 8 --lr 5e-3 --seed 0 --threads 2 \
    --val-every 4 --out "$OUT/run"
$ROLLCAM dataset --out "$OUT/data-2000" --frames 2000 --scenes 40 --workers 2
$ROLLCAM train "$OUT/data-2000" --model nano --imgsz 640x360 --epochs 14 --batch 8 --lr 3e-3 --seed 0 \
    --threads 2 --val-every 2 --init "$OUT/run/model.onnx" --out "$OUT/run-2000"
$ROLLCAM dataset --out "$OUT/data-4000s1" --frames 4000 --scenes 80 --seed 1 --workers 2
$ROLLCAM train "$OUT/data-4000s1" --model nano --imgsz 640x360 --epochs 1 --batch 8 --lr 2e-3 --seed 0 \
    --threads 2 --ema 0.999 --background 0.25 --background-kinds flat,crop,street,street,edge \
    --init "$OUT/run-2000/model.onnx" --out "$OUT/run-4000"
$ROLLCAM bench personnet --model "$OUT/run-4000/model.onnx" --dataset "$OUT/data-4000s1" --empty-scenes 30 \
    --out "$OUT/bench"
$PYTHON tools/ship_personnet.py "$OUT/run-4000" "$OUT/bench/personnet.json" host/detectors/models/personnet
