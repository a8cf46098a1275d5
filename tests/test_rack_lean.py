"""A wine bottle set down on LIBERO's wine rack is let go leant back onto the rack's ramp (issue 28).

libero_goal task 9 ("put the wine bottle on the rack"): the bottle was let go upright over the
rack's body, on the upper ramp (31 degrees), and in this environment it toppled off to the
table as the hand rose, after LIBERO's checker had counted it. The rack takes a bottle lying
back on its ramp, its base against the lip at the ramp's foot: the fixture's look now carries
that crest and the ramp's slope (``lean``, measured on the rack's own collision geometry), and
the place lets the bottle go over the crest leant by the slope, turned about its base at the
height the hand closed on it (``grasp_z_tcp_m``). Scenes are generated (LIBERO's sampler),
never an evaluation init state.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.geometry import rotation_about
from phyagentos.motion.grasp import place_pose, top_down_rotation
from phyagentos.perception import PerceptionError
from phyagentos.perception.fixtures import FixtureLook, LeanLook
from phyagentos.primitives.perception import leant_place

LEAN = {"offset_m": [-0.0003, 0.0689], "height_m": 0.2481, "toward_xy": [0.0, -1.0], "angle_rad": 0.5459}


def test_a_lean_look_turns_with_its_fixture_and_malformed_ones_are_refused():
    look = FixtureLook.from_dict({"name": "wine_rack_1", "class": "wine_rack", "size_m": [0.27, 0.14, 0.32],
                                  "lean": LEAN})
    assert isinstance(look.lean, LeanLook)
    xy, height, toward = look.lean.at(np.array([1.0, 2.0]))
    assert np.allclose(xy, [0.9997, 2.0689]) and height == 0.2481 and np.allclose(toward, [0.0, -1.0])
    xy, _, toward = look.lean.at(np.array([1.0, 2.0]), math.pi)  # the rack standing the other way round
    assert np.allclose(xy, [1.0003, 1.9311]) and np.allclose(toward, [0.0, 1.0], atol=1e-9)
    for bad, match in (({**LEAN, "toward_xy": [0.5, 0.5]}, "unit toward_xy"),
                       ({**LEAN, "angle_rad": 1.7}, "angle_rad"),
                       ({**LEAN, "height_m": -0.1}, "height_m"),
                       ({k: v for k, v in LEAN.items() if k != "angle_rad"}, "keys")):
        with pytest.raises(PerceptionError, match=match):
            FixtureLook.from_dict({"name": "r", "class": "wine_rack", "size_m": [0.27, 0.14, 0.32], "lean": bad})


def test_a_leant_place_turns_the_object_about_its_base_and_keeps_the_edge_towards_the_ramp_where_the_base_was():
    half = np.array([0.018, 0.018, 0.078])  # a bottle, upright in the hand
    T_tcp_obj = np.eye(4)
    T_tcp_obj[:3, :3] = top_down_rotation(0.0).T  # upright in the world when the hand is top-down at yaw 0
    T_tcp_obj[2, 3] = 0.127 - half[2]  # its centre below the tcp (the tcp's z points down)
    crest = np.array([0.1, -0.2, 1.15])
    up = place_pose(crest, half, T_tcp_object=T_tcp_obj, surface_z_m=crest[2], yaw_rad=0.0)
    angle, toward = 0.55, np.array([0.0, -1.0])
    T = leant_place(up, half, T_tcp_obj, toward_xy=toward, angle_rad=angle)
    R_obj = (T @ T_tcp_obj)[:3, :3]
    axis = R_obj @ np.array([0.0, 0.0, 1.0])  # the object's up axis, leant towards the ramp by the angle
    assert math.degrees(math.acos(axis[2])) == pytest.approx(math.degrees(angle), abs=1e-6)
    assert axis[1] < 0.0 and abs(axis[0]) < 1e-9
    base = (T @ T_tcp_obj)[:3, 3] - R_obj @ np.array([0.0, 0.0, half[2]])  # the base's centre
    assert np.allclose(base[:2], crest[:2], atol=1e-9)  # over the crest, as upright
    lowest = min((base + R_obj @ np.array([c * half[0], s * half[1], 0.0]))[2]
                 for c, s in ((1, 0), (-1, 0), (0, 1), (0, -1)))  # its base's rim: the edge on the ramp's side
    assert lowest == pytest.approx(crest[2] + 0.003, abs=1e-6)  # as high as the upright base (place_pose's clearance)
    # the hand turned by the same angle about the same axis
    assert np.allclose(T[:3, :3], rotation_about([1.0, 0.0, 0.0], angle) @ up[:3, :3])


@pytest.mark.sim
def test_a_bottle_let_go_leant_over_the_racks_crest_lies_on_its_ramp_where_upright_it_falls():
    """The rack's crest and slope from its own collision geometry (generated libero_goal task 9
    scene 500), then physics alone: the bottle let go leant back by the measured slope lies on
    the ramp, LIBERO's checker (ground truth, read by this test only) holding, over the crest
    and 1 cm either side of it; upright, 1 cm in front of the crest, it falls off to the table
    (upright it stands only on the lip's 1 cm top)."""
    import mujoco

    from phyagentos.geometry import matrix_to_quat
    from phyagentos.targets.libero import LiberoScene
    from phyagentos.targets.libero.descriptors import _lean_look
    from phyagentos.targets.libero.target import LiberoTarget

    t = LiberoTarget("rack", LiberoScene(suite="libero_goal", task=9, generated=True), seed=500)
    try:
        lean = _lean_look(t, "wine_rack_1", "wine_rack")
        assert lean is not None
        m, d = t.model, t.data
        rack = d.xpos[m.body(t.env.env.get_object("wine_rack_1").root_body).id]
        # the crest is the lip at the ramp's foot, 7-8 cm in front of the rack's frame; the ramp rises away from it
        assert 0.07 < float(np.dot(lean["xy"] - rack[:2], -lean["toward_xy"])) < 0.085
        assert math.degrees(lean["angle_rad"]) == pytest.approx(31.0, abs=3.0)
        body = t._obj_body["wine_bottle_1"]
        adr = m.jnt_qposadr[m.body_jntadr[body]]
        vadr = m.jnt_dofadr[m.body_jntadr[body]]
        start = (d.qpos.copy(), d.qvel.copy())
        u = np.array([*lean["toward_xy"], 0.0])
        ends = {}
        for name, angle, ahead in (("upright", 0.0, 0.01), ("leant", lean["angle_rad"], 0.0),
                                   ("leant behind", lean["angle_rad"], -0.01), ("leant ahead", lean["angle_rad"], 0.01)):
            d.qpos[:], d.qvel[:] = start
            R = rotation_about(np.cross([0.0, 0.0, 1.0], u), angle)
            xy = lean["xy"] - ahead * u[:2]
            d.qpos[adr:adr + 3] = [xy[0], xy[1], lean["z"] + 0.018 * math.sin(angle) + 0.004]
            d.qpos[adr + 3:adr + 7] = matrix_to_quat(R)
            d.qvel[vadr:vadr + 6] = 0.0
            mujoco.mj_forward(m, d)
            t.hold(duration_s=2.0)
            ends[name] = (float(d.xpos[body][2]), math.degrees(math.acos(min(1.0, d.xmat[body][8]))),
                          bool(t.env.check_success()))
    finally:
        t.close()
    assert ends["upright"][0] < 0.95 and not ends["upright"][2]  # on the table
    for name in ("leant", "leant behind", "leant ahead"):
        z, tilt, ok = ends[name]
        assert z > 1.1 and 40.0 < tilt < 60.0 and ok, (name, ends[name])  # lying back on the ramp, LIBERO's checker holding
