"""Instance masks of rollcam renders: which actor each pixel shows, and every pixel each actor covers.

For footage rendered by rollcam and labelled as other renderers label theirs (``rollcam.sim.label_formats``'s
``masks`` form), and for checking label composition against the renderer. The masks follow the line kernel's
rules: a part's span on a line is ``part_span`` at the line's centre, a pixel belongs to a span when its centre
lies in it, a nearer part hides a farther one and equal depths go to the later actor. So per line, an actor's
covered pixels are ``LineTruth.area`` and its shown pixels ``LineTruth.visible`` exactly (the tests check it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _actors as A
from ._jitcache import guard
from ._kernels import part_span
from .render import Renderer


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
                if pt[p, A.Q_KIND] == A.PART_NONE or yc < pt[p, A.Q_YMIN] or yc > pt[p, A.Q_YMAX]:
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
    ids = np.asarray(renderer.actor_ids, np.int64)
    owner = np.zeros((n_lines, n_along), np.int32)
    cover = np.zeros((len(ids), n_lines, n_along), np.bool_)
    if len(ids):
        _mask_lines(parts, line_k.astype(np.int64), ids, owner, cover)
    if by_column:
        owner, cover = owner.T.copy(), cover.transpose(0, 2, 1)
    return owner, {int(i): np.ascontiguousarray(cover[o]) for o, i in enumerate(ids) if cover[o].any()}


guard(__name__)
