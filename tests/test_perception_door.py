"""A fixture's door on a vertical hinge: its look, its reading from the slab's points, the body
fitted without the open door, and the door's points kept out of the object cloud (issue 28)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.perception.door import DoorLook, door_points, door_reading, thin_parts_removed
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.fixtures import without_door

#: LIBERO's microwave door as its look is measured (model frame; the joint shut at 0, open to -2.094)
DOOR = {"hinge_m": [-0.1725, -0.088], "shut_yaw_rad": 0.0, "sign": 1.0, "range_rad": [-2.094, 0.0], "shut_rad": 0.0,
        "width_m": 0.259, "thickness_m": 0.024, "mid_m": 0.013, "outer": -1.0, "z_m": [0.0035, 0.1885],
        "handle_r_m": 0.2375, "handle_out_m": 0.054, "handle_z_m": [0.021, 0.171]}


def _slab(door: DoorLook, origin: np.ndarray, yaw: float, q: float, *, step: float = 0.004) -> np.ndarray:
    """Points on both faces and the top edge of ``door``'s slab at joint ``q`` (world m)."""
    a = door.door_yaw(q, yaw)
    u, n = np.array([math.cos(a), math.sin(a)]), door.outer_normal(a)
    hinge = door.hinge_xy(origin, yaw)
    pts = []
    for r in np.arange(0.0, door.width_m, step):
        for z in np.arange(door.z_m[0], door.z_m[1], step):
            for off in (door.mid_m - 0.5 * door.thickness_m, door.mid_m + 0.5 * door.thickness_m):
                xy = hinge + r * u + off * n
                pts.append([xy[0], xy[1], origin[2] + z])
    return np.asarray(pts)


def test_a_door_look_reads_back_what_it_writes_and_names_its_keys_when_malformed():
    door = DoorLook.from_dict(DOOR, "microwave_1")
    assert DoorLook.from_dict(door.to_dict(), "microwave_1") == door
    assert door.open_rad == -2.094
    with pytest.raises(PerceptionError, match="hinge_m"):
        DoorLook.from_dict({k: v for k, v in DOOR.items() if k != "width_m"}, "microwave_1")
    with pytest.raises(PerceptionError, match="one of its ends"):
        DoorLook.from_dict({**DOOR, "shut_rad": -1.0}, "microwave_1")
    with pytest.raises(PerceptionError, match="1 or -1"):
        DoorLook.from_dict({**DOOR, "sign": 0.5}, "microwave_1")


@pytest.mark.parametrize("q", [-2.0, -1.6, -1.3, -0.4, 0.0])
def test_the_door_is_read_from_its_slab_whichever_face_is_seen(q):
    door = DoorLook.from_dict(DOOR, "microwave_1")
    origin, yaw = np.array([0.0, 0.35, 0.92]), 0.1
    pts = _slab(door, origin, yaw, q)
    reading = door_reading(pts, door, origin, yaw)
    assert reading is not None and abs(reading[0] - q) < 0.01
    a = door.door_yaw(q, yaw)
    n = door.outer_normal(a)
    hinge = door.hinge_xy(origin, yaw)
    outer_only = pts[(pts[:, :2] - hinge) @ n > door.mid_m]  # one face seen: the reading does not lean
    reading = door_reading(outer_only, door, origin, yaw)
    assert reading is not None and abs(reading[0] - q) < 0.01
    assert door_reading(pts[:10], door, origin, yaw) is None  # too few points: not read


def test_an_open_door_is_left_out_of_the_body_it_hangs_from():
    rng = np.random.default_rng(0)
    top = np.column_stack([rng.uniform(-0.17, 0.17, 6000), rng.uniform(-0.11, 0.11, 6000), np.full(6000, 0.2)])
    front = np.column_stack([rng.uniform(-0.17, 0.17, 3000), np.full(3000, -0.11), rng.uniform(0.0, 0.2, 3000)])
    body = np.vstack([top, front])  # its top and its front face, seen edge-on from above: a straight edge
    door = DoorLook.from_dict(DOOR, "microwave_1")
    slab = _slab(door, np.array([0.0, 0.0, 0.0]), 0.0, -1.7)
    knot = np.column_stack([rng.uniform(-0.22, -0.19, 200), rng.uniform(-0.33, -0.30, 200), np.full(200, 0.1)])
    pts = np.vstack([body, slab, knot])
    keep = thin_parts_removed(pts[:, :2])
    assert keep[: len(body)].mean() > 0.97 and not keep[len(body):].any()
    heights = pts[:, 2].copy()
    fitted = without_door(pts, heights, np.arange(len(pts)))
    assert fitted is not None
    assert np.allclose(2.0 * fitted.half_extents[:2], [0.34, 0.22], atol=0.01)
    assert abs(fitted.yaw) < 0.01 and np.allclose(fitted.position[:2], [0.0, 0.0], atol=0.01)


def test_the_door_s_points_are_the_fixture_s_own_not_an_object_beside_it():
    door = DoorLook.from_dict(DOOR, "microwave_1")
    origin, yaw, q = np.array([0.0, 0.35, 0.92]), 0.0, -1.6
    slab = _slab(door, origin, yaw, q)
    mug = np.array([[-0.02, 0.0, 0.97], [0.0, -0.02, 1.0]])  # a mug 10 cm off the open door's face
    own = door_points(np.vstack([slab, mug]), door, origin, yaw, q, margin_m=0.02)
    assert own[: len(slab)].all() and not own[len(slab):].any()


def test_only_a_declared_fixture_with_a_door_is_noted_shut():
    from phyagentos.perception import Perceiver, PerceptionConfig  # noqa: PLC0415

    micro = {"name": "microwave_1", "class": "microwave", "size_m": [0.3469, 0.1497, 0.2078],
             "root": {"offset_m": [-0.0007, 0.0378, 0.02], "yaw_rad": 0.0, "body_yaw_rad": 0.0}, "door": DOOR}
    p = Perceiver(PerceptionConfig.default(), {"objects": [], "fixtures": [micro]})
    p.note_door_stop("microwave_1", stamp_s=3.0)
    assert p.export_fixtures() == {}  # not seen yet: nothing to export, the note waits for the sighting
    with pytest.raises(PerceptionError, match="microwave_1"):
        p.note_door_stop("stove_1", stamp_s=3.0)


def test_the_room_behind_a_door_stands_where_the_fixture_does_and_names_its_keys_when_malformed():
    from phyagentos.perception.door import InsideLook  # noqa: PLC0415

    room = InsideLook.from_dict({"lo_m": [-0.1435, -0.089], "hi_m": [0.0635, 0.0805], "floor_m": 0.024,
                                 "roof_m": 0.168, "mouth": [0.0, -1.0]}, "microwave_1")
    centre, half, yaw, floor_z, roof_z, mouth = room.world(np.array([0.0, 0.35, 0.92]), math.pi)
    # turned half a turn: its middle the other side of the origin, its mouth facing +y
    assert np.allclose(centre, [0.04, 0.35 + 0.00425], atol=1e-6) and np.allclose(half, [0.1035, 0.08475])
    assert (floor_z, roof_z) == pytest.approx((0.944, 1.088)) and np.allclose(mouth, [0.0, 1.0], atol=1e-9)
    with pytest.raises(PerceptionError, match="mouth"):
        InsideLook.from_dict({"lo_m": [0, 0], "hi_m": [1, 1], "floor_m": 0, "roof_m": 1}, "microwave_1")
    with pytest.raises(PerceptionError, match="unit vector"):
        InsideLook.from_dict({"lo_m": [0, 0], "hi_m": [1, 1], "floor_m": 0, "roof_m": 1, "mouth": [0, 2]}, "m")


def test_a_thing_seen_through_a_rooms_mouth_is_not_too_shallow_for_its_look():
    from phyagentos.perception.association import _size_error  # noqa: PLC0415
    from phyagentos.perception.descriptors import ObjectDescriptor  # noqa: PLC0415
    from phyagentos.perception.detect import Detection  # noqa: PLC0415

    mug = ObjectDescriptor(name="white_yellow_mug_1", size_m=(0.1038, 0.1036, 0.1038))
    # its front face only, 3.5 cm deep, as the wrist sees it from the microwave's mouth
    face = Detection(np.array([0.0, 0.28, 0.997]), 0.0, np.array([0.048, 0.0177, 0.053]), "box", np.zeros(3),
                     np.zeros(3), 1152, 1, 0.002, math.pi, 1.0, 0.0, cut_direction=np.array([0.0, 1.0]),
                     cut_by_body=True)
    through_mouth = Detection(**{**face.__dict__, "cut_by_room": True})
    assert _size_error(through_mouth, mug) < 0.002
    assert _size_error(face, mug) > 0.004  # cut by a drawer's carcass, half its depth would have to show


def test_what_stands_in_a_room_rests_on_its_floor_though_the_mouths_lip_hides_its_foot():
    # LIBERO-10 task 9 init 1: the wrist, looking in from the microwave's mouth, saw the mug's
    # lowest points 2 cm over the floor (more than relations.on_gap_m); standing on the table it
    # was 14.9 cm tall, too tall for the mug, and left unknown
    from phyagentos.perception.config import PerceptionConfig  # noqa: PLC0415
    from phyagentos.perception.detect import Detection, stack  # noqa: PLC0415
    from phyagentos.perception.perceiver import ROOM_LIP_HIDES_M  # noqa: PLC0415
    from phyagentos.perception.cloud import Plane  # noqa: PLC0415

    cfg = PerceptionConfig.default()
    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.9, 1000, True)

    def segment(xy, low_m, top_m):
        return Detection(np.array([xy[0], xy[1], 0.9 + 0.5 * top_m]), 0.0, np.array([0.05, 0.05, 0.5 * top_m]),
                         "cylinder", np.zeros(3), np.zeros(3), 1600, 1, 0.002, math.pi, 1.0, 0.0, low_m=low_m)

    def floor(hidden_above_m):
        return Detection(np.array([-0.047, 0.352, 0.922]), 0.0, np.array([0.104, 0.085, 0.022]), "box",
                         np.zeros(3), np.zeros(3), 0, 0, 0.01, math.pi, 1.0, 0.0, hidden_above_m=hidden_above_m)

    mug = segment((-0.007, 0.326), 0.0635, 0.149)
    rested = stack([mug, floor(ROOM_LIP_HIDES_M)], plane, cfg)[0]
    assert rested.bottom_m == pytest.approx(0.044) and rested.top_m == pytest.approx(0.149)
    assert stack([mug, floor(0.0)], plane, cfg)[0].bottom_m == 0.0  # a plain support: on_gap_m only
    outside = segment((-0.007, 0.15), 0.0635, 0.149)  # in front of the mouth, over no floor
    assert stack([outside, floor(ROOM_LIP_HIDES_M)], plane, cfg)[0].bottom_m == 0.0
    # task 9 init 8: a sliver of the mug's far rim seen over its front, its lowest points 10 cm up,
    # is not a thing standing on the floor (10.7 cm tall, it was a rival for the mug's name)
    sliver = segment((-0.002, 0.341), 0.1457, 0.1513)
    assert stack([sliver, floor(ROOM_LIP_HIDES_M)], plane, cfg)[0].bottom_m == 0.0
    # a box in the room with the mug on it: within on_gap_m of the box's top, it rests on the box
    box = Detection(np.array([-0.007, 0.326, 0.9 + 0.055]), 0.0, np.array([0.06, 0.06, 0.011]), "box",
                    np.zeros(3), np.zeros(3), 900, 1, 0.002, 0.1, 1.0, 0.044, low_m=0.05)
    on_box = segment((-0.007, 0.326), 0.07, 0.18)
    assert stack([on_box, box, floor(ROOM_LIP_HIDES_M)], plane, cfg)[0].bottom_m == pytest.approx(0.066)
