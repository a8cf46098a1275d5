"""Closing one MuJoCo renderer leaves another's images intact (``phyagentos.renderer``).

``mujoco.Renderer.close()`` frees its render context on whatever GL context is current: when
another renderer drew last, that renderer's framebuffer and textures go, and its next depth
image is not finite (a perception-pipeline test failed so in a fresh clone). With
``mujoco.Renderer`` in place of ``phyagentos.renderer.Renderer`` both tests below fail."""

from __future__ import annotations

import gc

import mujoco
import numpy as np
import pytest

from phyagentos.renderer import Renderer

XML = """<mujoco><visual><global offwidth="64" offheight="48"/></visual><worldbody><light pos="0 0 3"/>
<geom type="plane" size="1 1 .1" rgba=".2 .6 .2 1"/><geom type="box" pos="0 0 .1" size=".1 .1 .1" rgba="1 0 0 1"/>
<camera name="c" pos="0 -1 .5" xyaxes="1 0 0 0 .45 .9"/></worldbody></mujoco>"""


@pytest.fixture()
def world():
    m = mujoco.MjModel.from_xml_string(XML)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return m, d


def _depth(r: mujoco.Renderer, d: mujoco.MjData) -> np.ndarray:
    r.enable_depth_rendering()
    r.update_scene(d, camera="c")
    out = r.render().copy()
    r.disable_depth_rendering()
    return out


@pytest.mark.parametrize("how", ["close", "garbage_collected"])
def test_a_renderer_freed_while_another_draws_leaves_the_others_depth_as_it_was(world, how):
    m, d = world
    a = Renderer(m, 48, 64)
    before = _depth(a, d)
    assert np.isfinite(before).all() and before.max() > 0.5  # the box and the plane, about 1 m away
    b = Renderer(m, 48, 64)
    _depth(b, d)
    _depth(a, d)  # a's GL context is the current one when b goes
    if how == "close":
        b.close()
    else:
        del b
        gc.collect()
    after = _depth(a, d)
    assert np.isfinite(after).all()
    assert after == pytest.approx(before, abs=1e-4)
    a.close()
    a.close()  # a second close frees nothing


def test_rgb_images_after_another_renderer_closed_match_the_first(world):
    m, d = world
    a = Renderer(m, 48, 64)
    a.update_scene(d, camera="c")
    before = a.render().copy()
    b = Renderer(m, 48, 64)
    b.update_scene(d, camera="c")
    b.render()
    a.update_scene(d, camera="c")
    a.render()
    b.close()
    a.update_scene(d, camera="c")
    assert np.array_equal(a.render(), before)
    a.close()
