"""Shadows (``shadows=on``): the ground under each walker's feet darkened, softly, by at most the contact
shadow's strength, and in daylight the sun's shadow along the ground away from the sun taking the sun's share
of the ground's light; nothing else in the image changes, and no box or visibility moves."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.host import open_camera
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scenegen import CONTACT_SHADOW, make_street_scene


def _pair(**kw):
    out = []
    for shadows in (False, True):
        r = Renderer(make_street_scene(3, n_pedestrians=20, width=480, height=270, shadows=shadows, **kw))
        out.append(r.render_lines(np.full(270, 10**9, np.int64), linear=True))
    return out


def test_shadows_darken_the_ground_under_the_walkers_and_nothing_else():
    off, on = _pair(time_of_day="dusk")  # the sun too low for its shadows: contact shadows alone
    assert on.truth.boxes() == off.truth.boxes()
    assert np.array_equal(on.truth.visible, off.truth.visible) and np.array_equal(on.truth.area, off.truth.area)
    ratio = on.linear / np.maximum(off.linear, 1e-9)
    changed = np.abs(on.linear - off.linear).max(axis=-1) > 0
    assert changed.any() and changed.mean() < 0.02  # under the feet only
    assert ratio.max() <= 1.0 + 1e-6  # darker or the same, never brighter
    assert ratio.min() == pytest.approx(1.0 - CONTACT_SHADOW, abs=0.05)  # the centre takes the strength
    # every changed pixel lies at the feet: in the lowest fifth of some walker's box, or just below it
    near_feet = np.zeros_like(changed)
    for box in on.truth.boxes():
        if box is not None:
            x0, y0, x1, y1 = box
            h = y1 - y0
            near_feet[max(int(y1 - 0.2 * h), 0):int(y1 + 0.15 * h) + 1, max(int(x0) - 2, 0):int(x1) + 3] = True
    assert not (changed & ~near_feet).any()


def test_the_suns_shadow_falls_away_from_the_sun_and_takes_its_share():
    from rollcam.sim.render.tables import _cast_shadow

    off, on = _pair(time_of_day="noon")
    scene = make_street_scene(3, n_pedestrians=20, width=480, height=270, time_of_day="noon")
    cast_x, cast_y, share = _cast_shadow(scene.lighting)
    assert np.hypot(cast_x, cast_y) > 0.05 and min(share) > 0.3
    assert on.truth.boxes() == off.truth.boxes()
    assert np.array_equal(on.truth.visible, off.truth.visible)
    ratio = on.linear / np.maximum(off.linear, 1e-9)
    changed = np.abs(on.linear - off.linear).max(axis=-1) > 0
    assert ratio.max() <= 1.0 + 1e-6
    # the sun's shadow's flat core, where no contact shadow overlaps it, keeps 1 - share of each channel (RGB)
    core = np.ones(changed.shape, bool)
    for c in range(3):
        core &= np.abs(ratio[..., c] - (1.0 - share[c])) < 1e-3
    assert core.sum() > 20
    dusk_off, dusk_on = _pair(time_of_day="dusk")  # no sun shadows: only the contact shadows change pixels
    assert changed.sum() > (np.abs(dusk_on.linear - dusk_off.linear).max(axis=-1) > 0).sum()


def test_the_device_option_turns_them_on():
    frames = []
    for value in ("off", "on"):
        with open_camera(f"emu:imx219?size=320x240&pedestrians=20&shadows={value}&noise=off") as cam:
            frames.append(cam.read().data.astype(int))
    assert (frames[1] <= frames[0] + 1).all() and (frames[1] < frames[0] - 2).any()
