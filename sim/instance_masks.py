"""Instance masks of rollcam renders: which actor each pixel shows, and every pixel each actor covers.

For footage rendered by rollcam and labelled as other renderers label theirs (``rollcam.sim.label_formats``'s
``masks`` form), and for checking label composition against the renderer. The masks follow the line kernel's
rules: a part's span on a line is ``part_span`` at the line's centre, a pixel belongs to a span when its centre
lies in it, a nearer part hides a farther one and equal depths go to the later actor. So per line, an actor's
covered pixels are ``LineTruth.area`` and its shown pixels ``LineTruth.visible`` exactly (the tests check it).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit
from rollcam.common.errors import SourceError
from rollcam.common.files import OS_FS, RENAME_ONLY_FS, FileSystem, write_atomic

from ._jitcache import guard
from .codecs import encode_image
from .render import actors as A
from .render.lines import part_span
from .render.parts import PART_SHADOW
from .render.renderer import Renderer


@njit(cache=True)
def _mask_lines(parts, line_k, ids, owner, cover):
    """Fill ``owner`` (lines x along: id shown, 0 none) and ``cover`` (actors x lines x along) line by line."""
    n_act = parts.shape[0]
    n_lines, n_along = owner.shape
    lohi = np.empty(2)
    best = np.empty(n_along)
    for line in range(n_lines):
        yc = line + 0.5
        k = line_k[line]
        best[:] = np.inf
        for o in range(n_act):
            pt = parts[o, k]
            for p in range(A.MAX_PARTS):
                if pt[p, A.Q_KIND] in (A.PART_NONE, PART_SHADOW) or yc < pt[p, A.Q_YMIN] or yc > pt[p, A.Q_YMAX]:
                    continue
                part_span(pt, p, yc, lohi)
                if lohi[1] <= lohi[0] or lohi[1] <= 0.0 or lohi[0] >= n_along:
                    continue
                a = max(int(math.ceil(lohi[0] - 0.5)), 0)
                b = min(int(math.ceil(lohi[1] - 0.5)), n_along)
                d = pt[p, A.Q_DEPTH]
                for i in range(a, b):
                    cover[o, line, i] = True
                    if d <= best[i]:
                        best[i] = d
                        owner[line, i] = ids[o]


def render_masks(renderer: Renderer, times_ns: np.ndarray, *, by_column: bool = False
                 ) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Masks of the frame whose line ``i`` is at ``times_ns[i]`` (one time per row, or column ``by_column``).

    Returns the visible mask (H x W int32: the id of the actor each pixel shows, 0 for none) and the amodal
    masks (id -> H x W bool, for actors that cover some pixel), in image orientation.
    """
    n_lines, n_along = renderer.render_shape(by_column)
    times_ns = np.asarray(times_ns, np.int64)
    if times_ns.shape != (n_lines,):
        raise ValueError(f"need one time per line: {n_lines} lines, got times of shape {times_ns.shape}")
    ut_ns, line_k = np.unique(times_ns, return_inverse=True)
    # The renderer's own seconds for these times (render_lines converts the same way).
    parts = renderer.actor_parts(ut_ns.astype(np.float64) * 1e-9, by_column=by_column)
    # Props are scenery: their pixels read as background (0) and hide the objects behind them.
    ids = np.where(renderer.actor_labelled, np.asarray(renderer.actor_ids, np.int64), 0)
    owner = np.zeros((n_lines, n_along), np.int32)
    cover = np.zeros((len(ids), n_lines, n_along), np.bool_)
    if len(ids):
        _mask_lines(parts, line_k.astype(np.int64), ids, owner, cover)
    if by_column:
        owner, cover = owner.T.copy(), cover.transpose(0, 2, 1)
    return owner, {int(i): np.ascontiguousarray(cover[o]) for o, i in enumerate(ids) if i != 0 and cover[o].any()}



def write_labelled_footage(renderer: Renderer, times_ns: np.ndarray, folder: str | Path, *,
                           durable: bool = True) -> tuple[Path, Path]:
    """Render GS frames at ``times_ns`` into ``folder/frames/`` (PNG) with their instance masks in
    ``folder/masks/`` (16-bit PNG ids, amodal masks in ``masks/amodal/<frame>/<id>.png``), as footage from
    another renderer would come: ``file:folder/frames?fps=..&labels=folder/masks`` reads it back.

    Returns the two folders. Each file is written whole or not at all; ``durable=False`` skips the fsyncs
    (a power cut may then lose the newest files), which makes a long export many times faster.
    """
    fs = OS_FS if durable else RENAME_ONLY_FS
    root = Path(folder)
    frames, masks = root / "frames", root / "masks"
    n_lines = renderer.render_shape(False)[0]
    digits = max(6, len(str(len(times_ns) - 1)))
    for k, t in enumerate(np.asarray(times_ns, np.int64).tolist()):
        line_times = np.full(n_lines, t, np.int64)
        name = f"{k:0{digits}d}.png"
        _write_png(frames / name, renderer.render_lines(line_times).image, fs)
        vis, amodal = render_masks(renderer, line_times)
        _write_png(masks / name, vis.astype(np.uint16), fs)
        for oid, cover in amodal.items():
            _write_png(masks / "amodal" / name[:-4] / f"{oid}.png", cover.astype(np.uint8) * 255, fs)
    return frames, masks


def _write_png(path: Path, img: np.ndarray, fs: FileSystem) -> None:
    data = encode_image(img, "png", error=SourceError, what=repr(str(path)))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, data, fs)


guard(__name__)  # after every kernel: see rollcam.sim._jitcache
