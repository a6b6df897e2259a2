"""``rollcam dataset``: build paired GS/RS datasets (Ultralytics YOLO + COCO + card) from emulated scenes."""

from __future__ import annotations

import argparse
import json
from typing import Any

from rollcam.common.values import box_size, fraction, name_list, parse_size, positive_int

from . import Subparsers, value_type

DESCRIPTION = """\
Render paired global- and rolling-shutter images of the same instants with exact labels, by default the
design of the 'Let's Roll' study: 40 street scenes x 5 cameras x 5 times of day, normal and fast walkers,
split 800/100/100 per speed by scene. Writes four datasets (normal_gs, normal_rs, fast_gs, fast_rs), each an
Ultralytics folder (data.yaml, images/, labels/) with COCO files in annotations/, and a dataset card
(README.md, dataset.json). Interrupt it at any time: rerunning the same command continues where it stopped.
With --from-footage, the pairs come from your own global-shutter footage and its per-frame labels instead
(instance masks, COCO, MOT or YOLO): RS images and their labels are composed line by line (footage_gs,
footage_rs)."""

EPILOG = """\
examples:
  rollcam dataset --out data/letsroll                      # the study's size (2,000 pairs at 1920x1080)
  rollcam dataset --out data/small --frames 40 --size 960x540 --workers 2
  rollcam dataset --out /shared/lr --executor dask://10.0.0.5:8786 --worker-writes
  rollcam dataset --out data/mine --from-footage 'file:frames/?fps=32400&sensor=letsroll&labels=masks/'"""

_COUNT = value_type(positive_int, "an integer >= 1")


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam dataset``."""
    p = sub.add_parser("dataset", help="build paired GS/RS datasets with exact labels (YOLO + COCO + card)",
                       description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (rerun to resume)")
    p.add_argument("--from-footage", default=None, metavar="FILE_URI",
                   help="build from footage instead of emulated scenes: a file: URI composing RS frames "
                        "(line_time_ns= or sensor=) with per-frame labels (labels=PATH)"),
    p.add_argument("--sensor", default="letsroll", help="emulated sensor (default: %(default)s, the study's camera)")
    p.add_argument("--size", type=value_type(parse_size), default=None,
                   help="image WxH (default: the sensor's default mode)")
    p.add_argument("--frames", type=_COUNT, default=None, metavar="N",
                   help="total GS/RS pairs over all speeds (default: the full grid, 2,000 for the study's design)")
    p.add_argument("--scenes", type=_COUNT, default=40, help="street scenes (default: %(default)s)")
    p.add_argument("--cameras", type=_COUNT, default=5, help="cameras per scene, 1-5 (default: %(default)s)")
    p.add_argument("--times", type=value_type(name_list), default=None,
                   help="times of day (default: dawn,morning,noon,afternoon,dusk)")
    p.add_argument("--speeds", type=value_type(name_list), default=("normal", "fast"),
                   help="walker speeds: normal, fast, static or a multiplier (default: normal,fast)")
    p.add_argument("--ego", default="none", help="camera ego-motion: none, pan, walk, vehicle, drone (default: none)")
    p.add_argument("--pedestrians", type=_COUNT, default=20, help="pedestrians per scene (default: 20)")
    p.add_argument("--seed", type=value_type(int, "an integer"), default=0, help="dataset seed (default: 0)")
    p.add_argument("--image-format", choices=("png", "jpg"), default="png", help="image files (default: png)")
    p.add_argument("--raw", default=None, metavar="FORMAT",
                   help="store the sensor's raw output instead of BGR images: passed to the emu: source as format=")
    p.add_argument("--source-options", default="", metavar="QUERY",
                   help="extra emu: options for every sample, e.g. 'exposure_us=2000&gain=2'")
    p.add_argument("--min-box", type=value_type(box_size), default=(6.0, 16.0), metavar="WxH",
                   help="smallest labelled box in px; smaller people become ignore regions (default: 6x16)")
    p.add_argument("--min-visible", type=value_type(fraction, "a number in [0, 1]"), default=0.3,
                   help="smallest unoccluded fraction of a labelled person, in [0, 1] (default: 0.3)")
    p.add_argument("--workers", type=_COUNT, default=1, help="local worker processes (default: 1)")
    p.add_argument("--executor", default=None, metavar="SPEC",
                   help="'local' (default) or 'dask://HOST:PORT' (a Dask distributed scheduler)")
    p.add_argument("--worker-writes", action="store_true",
                   help="cluster workers write files into --out themselves (it must be shared storage at the same "
                        "path on every worker); otherwise they send them back")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset built with other options in --out")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


# Options that describe emulated scenes, with their defaults: --from-footage refuses any that is changed.
_SCENE_OPTIONS = {"sensor": "letsroll", "size": None, "scenes": 40, "cameras": 5, "times": None,
                  "speeds": ("normal", "fast"), "ego": "none", "pedestrians": 20, "seed": 0, "raw": None,
                  "source_options": ""}


def config_from_args(args: argparse.Namespace) -> Any:
    """The DatasetConfig (or FootageConfig, with --from-footage) the options describe."""
    from rollcam.common.errors import ConfigError
    from rollcam.sim.scenegen import DATASET_TIMES

    from ..datasets.plan import DatasetConfig, LabelPolicy

    policy = LabelPolicy(min_width_px=args.min_box[0], min_height_px=args.min_box[1], min_visible=args.min_visible)
    if args.from_footage is not None:
        from ..datasets.footage import FootageConfig

        changed = [k for k, v in _SCENE_OPTIONS.items() if getattr(args, k) != v]
        if changed:
            flag = "--" + changed[0].replace("_", "-")
            raise ConfigError(f"{flag} describes emulated scenes; it does not apply with --from-footage")
        return FootageConfig(source=args.from_footage, frames=args.frames, image_format=args.image_format,
                             policy=policy)
    return DatasetConfig(
        sensor=args.sensor, size=args.size, scenes=args.scenes, cameras=args.cameras,
        times=args.times or DATASET_TIMES, speeds=args.speeds, frames=args.frames, ego=args.ego,
        pedestrians=args.pedestrians, seed=args.seed, image_format=args.image_format, raw_format=args.raw,
        emu_options=args.source_options, policy=policy,
    )


def run(args: argparse.Namespace) -> int:
    """Build (or resume) the dataset and print what it holds."""
    from ..datasets.build import build_dataset
    from .compile_notice import notify_if_cold

    cfg = config_from_args(args)
    notify_if_cold()
    result = build_dataset(cfg, args.out, workers=args.workers, executor=args.executor,
                           worker_writes=True if args.worker_writes else None, overwrite=args.overwrite,
                           progress=True if args.progress else None)
    if args.json:
        print(json.dumps(result.to_json()))
        return 0
    rate = f", {result.rendered / result.seconds:.2f} pairs/s" if result.rendered and result.seconds > 0 else ""
    resumed = f" ({result.resumed} already done)" if result.resumed else ""
    if result.redone:
        resumed += f" ({result.redone} redone: their files no longer matched their records)"
    print(f"dataset: {result.pairs} GS/RS pairs in {result.out_dir}/{resumed}; rendered {result.rendered} in "
          f"{result.seconds:.1f} s{rate} on {result.executor} x{result.workers}")
    for name, sub in result.card["subsets"].items():
        st = sub["splits"]
        print(f"  {name:<10} " + "  ".join(f"{sp} {st[sp]['images']} img {st[sp]['boxes']} boxes" for sp in st))
    print(f"card: {result.out_dir / 'README.md'}")
    return 0
