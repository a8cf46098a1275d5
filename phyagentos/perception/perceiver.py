"""The Perceiver: camera frames + proprioception -> a perceived snapshot (CONTRACT_9 sections 3, 4).

One :meth:`Perceiver.observe` call runs the pipeline on every frame of one observation:

1. support plane: RANSAC + least squares on a coarse cloud of all cameras (``cloud`` stride x 2);
2. object points: per camera, the height of every strided pixel above the plane (linear in
   depth, no 3-D point needed), candidates in (``object_min_height_m``, ``max_height_m``),
   back-projected; cropped to the workspace, minus the base disc, the gripper box around
   the tcp, caller-given robot capsules and declared obstacles (inflated by 1 cm);
   voxel-filtered;
3. detections: DBSCAN on position + colour, one fitted primitive per cluster (``detect``);
   a cluster larger than every declared object is split into the touching objects it holds
   at a height step or around a taller part, when that is unambiguous (``split``);
   stacking (an object whose lowest points sit on another's top rests on it); each final
   detection's round body and handle, open top and knob on top (``top_knob``: reported as
   ``attributes.top_knob_*``);
4. association to the declared descriptors (``association``); unmatched or ambiguous
   clusters become ``unknown_<k>``; identical declared objects none of which has a spatial
   reference are interchangeable (both named, their tracks keep which is which; a held one's
   track is at the hand); an object declared with a spatial reference (``where``)
   and not tracked yet is resolved first on the landmarks the others' association found,
   named at :data:`LANDMARK_MIN_CONFIDENCE` or more
   (:func:`~phyagentos.perception.association.resolve_reference`; the snapshot's
   ``references`` says how), and once tracked keeps its identity by its track;
5. tracks: fusion over observations (``tracks``);
6. holding from proprioception (the held object's pose follows the tcp; a round body held by its
   rim goes where the cameras off the hand see its base hang, :mod:`~phyagentos.perception.hang`,
   its base's profile read while it stood), then relations.

Declared fixtures with a measured look (``fixtures: [{name, class, size_m, place?}]``,
:mod:`~phyagentos.perception.fixtures`) are found before stage 3 on a cloud whose height crop
is raised to the tallest fixture plus :data:`FIXTURE_LOAD_M`; everything above
``workspace.max_height_m`` is then kept only over a perceived fixture's footprint (what stands
on the cabinet), the fixture's own points (up to its top, over its place patch up to the
patch's surface, plus :data:`FIXTURE_MARGIN_M`) are removed, an object whose lowest points sit
on the patch rests on it (stacking), and each fixture is reported as a ``kind: fixture``
entity whose box is its place patch (its top the patch's surface), the perceived body in its
attributes. Fixtures do not move: a fixture is looked for until it is seen, then reported
where it was seen (``source: remembered`` in later observations; something set on it would
change its segment), so the search costs one clustering of the raised cloud per observation
only while a declared fixture is unseen. A fixture's knob (``knob`` in its look) turns, so it
is read in every observation (:func:`~phyagentos.perception.fixtures.knob_reading`; its points
are the fixture's own) and reported as a hinge in the entity's attributes: ``joint_type``,
``anchor``, ``axis``, ``range_rad``, ``joint_position`` with ``joint_position_std_rad`` (absent
when the bar was not read: never remembered) and the bar's upper part as its ``grasp``. A
fixture's drawers (``drawers`` in its look) slide, so each is read from its handle in every
observation (:func:`~phyagentos.perception.fixtures.drawer_reading`; the handle and the part of
the drawer standing out of the body are the fixture's own points) and reported as an entity of
its own (:func:`~phyagentos.perception.fixtures.drawer_entity_name`: ``wooden_cabinet_1`` 's
``top`` is ``wooden_cabinet_1_top_drawer``, ``kind: articulation``): ``joint_type: slide``,
``axis`` (3,) the world direction it opens along, ``range_m``, ``joint_position`` (m out of
shut) with ``joint_position_std_m``, and its handle as the ``grasp`` (approached along the
axis pitched :data:`DRAWER_APPROACH_PITCH_RAD` down, the fingers closing across the bar);
reported only while its handle is read. A fixture's door on a vertical hinge (``door`` in its
look: LIBERO's microwave) swings, so it is read from its slab in every observation
(:func:`~phyagentos.perception.door.door_reading`; the slab and its handle are the fixture's own
points) and reported as a hinge in the fixture entity's attributes, its joint as the door's
opening (rad, 0 shut), with what a push along its sweep needs (``door``); the body is found
with the open door left out (:func:`~phyagentos.perception.fixtures.without_door`).

The Perceiver keeps per-session state (tracks, the open-gripper wrist-force baseline, the
held object); :meth:`reset` clears it. It never reads simulator state.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from typing import Any, Mapping, Sequence

import cv2
import numpy as np

from phyagentos.perception.association import (
    FORBIDDEN_COST,
    Association,
    Landmark,
    ReferenceResolution,
    associate,
    cost_matrix,
    forbid_except,
    match_confidence,
    resolve_reference,
    track_costs,
)
from phyagentos.perception.cloud import (
    Cloud,
    Plane,
    RobotCapsule,
    backproject,
    box_mask,
    capsule_mask,
    fit_support_plane,
    gripper_mask,
    heights_above,
    merge_clouds,
    voxel_downsample,
)
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.descriptors import ObjectDescriptor, descriptors_from_declared
from phyagentos.perception.detect import Detection, detect_clusters, with_open_depth, with_round_body, with_top_knob
from phyagentos.geometry import turned_xy
from phyagentos.perception.detect import stack as _stack
from phyagentos.perception.split import split_clusters
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.fixtures import (
    DRAWER_HANDLE_PLAY_M,
    DRAWER_SIGMA_M,
    DRAWER_STOP_SIGMA_M,
    DRAWER_WINDOW_M,
    KNOB_RADIUS_M,
    KNOB_SIGMA_RAD,
    DrawerLook,
    FixtureLook,
    FixtureSighting,
    _in_frame,
    compartment_entity_name,
    compartment_sides,
    detect_fixtures,
    drawer_entity_name,
    drawer_reading,
    fixtures_from_declared,
    knob_reading,
)
from phyagentos.perception.door import (
    DOOR_SIGMA_RAD,
    DOOR_STOP_SIGMA_RAD,
    door_points,
    door_reading,
    inside_entity_name,
)
from phyagentos.perception.frames import CameraFrame, Proprioception, _rigid
from phyagentos.perception.glimpse import Glimpse, carry_over, glimpses, rival
from phyagentos.perception.handle import RoundBody
from phyagentos.perception.hang import base_profile, hang_offset, scene_camera_mask
from phyagentos.perception.lean import find_leant, leant_confidence, on_ramp
from phyagentos.perception.relations import (
    _footprint_margin,
    _footprint_margins,
    holding_evidence,
    inside_confidence,
    normal_cdf,
    on_confidence,
    regions_from,
    width_across_fingers,
)
from phyagentos.perception.tracks import REMEMBERED_CONFIDENCE, Track
from phyagentos.perception.tracks import object_pose as _pose
from phyagentos.perception.truncation import complete_box, complete_round, cut_direction

__all__ = ["Perceiver"]

log = logging.getLogger(__name__)

_OBSTACLE_MARGIN_M = 0.01

#: An object's open top is reported (``attributes.open_depth_m``) from this depth on, m: below
#: it, a solid top's own relief.
OPEN_DEPTH_REPORT_M = 0.01
#: Contents of containers: a segment whose footprint's short side is at least this long may
#: hold things (LIBERO's basket: 16 cm; its cans and boxes: <= 8.5 cm long, 5 cm short).
CONTAINER_MIN_SIDE_M = 0.10
#: Its walls: points within this of the footprint's edge are the container's own, m.
CONTAINER_WALL_M = 0.015
#: A released object's top must stand this far above the container's floor (the 5th
#: percentile of its interior heights), m: a basket's cloth lining lies within about 1 cm.
#: LIBERO's butter (1.7 cm tall by its model) on the basket's floor beside the cream cheese
#: showed its top 1.4 cm over that percentile (LIBERO-10 task 1, development seed 505), under
#: the 1.5 cm this was; the face must still be flat and span the object (:func:`_released_inside`).
CONTENT_CLEARANCE_M = 0.01
#: A released object's top found up to this much lower than its perceived height over where it
#: rests puts it is no error, m: a height perceived on a table is an upper bound, the object's own
#: plus the gap between the table's rendered top (the plane perception fits) and the surface
#: things rest on. LIBERO's soup and tomato sauce cans are perceived 9.1 cm tall on LIBERO-10's
#: living-room table and are 7.7 cm tall by their resting poses (centres 3.85 cm over the
#: basket's floor, from its model); set on the floor of the basket's corner, the sauce's top
#: showed 7.3 cm over the floor, an error of 1.8 cm against its perceived height (confidence
#: 0.45), where a top found too high (on the rim, on something else) still counts whole.
CONTENT_TALL_M = 0.015
#: An object seen resting inside a container (at ``relations.min_confidence`` or more) and not
#: moved by the hand since does not rise: a find for it more than this above where it rested
#: is not it, m. LIBERO-10 task 1: the butter, seen on the basket's floor from the wrist camera,
#: was "found" 4.4 cm higher from the ready pose, where the far wall shows over the near one
#: and the floor is hidden (the cream cheese under it too). A weak find is no rest: task 0's
#: sauce can, let go onto the soup in the basket, was found at 0.44 on the floor and then
#: standing on the soup. 2 cm: what :func:`_released_inside` allows a top about the object's
#: height.
CONTENT_RISE_M = 0.02
#: Spread of a contained object's top above the floor about its perceived height, m: the
#: lining's folds (about 1 cm) and the height perceived on the open table (within ~1 cm).
CONTENT_HEIGHT_SIGMA_M = 0.015
#: In a look for a released object (:func:`_released_inside`), the points over the footprint of
#: another object perceived where it stands, grown by this on every side, m (half the 2 cm
#: search margin around the release point) ...
OTHER_FOOTPRINT_M = 0.01
#: ... and no higher than this over its perceived top, m, are that object's own (its top face
#: and sides); higher ones are something resting on it (a butter let go onto a cream cheese
#: box in a basket shows its top 1.6 cm over the box's). 1 cm: twice the 5 mm height bins in
#: which a face is found.
OTHER_TOP_M = 0.01
#: Another object's footprint: ``(centre (2,) world m, half extents (2,) m, yaw rad, shape,
#: top m above the support plane)``.
Footprint = tuple[np.ndarray, np.ndarray, float, str, float]
#: Interior points of a container (beside what lies in it) needed to read its inside where an
#: object's ends rest (:func:`_rest_height`); with fewer, it is taken to rest on the floor.
REST_RING_MIN_POINTS = 20
#: Half the width of the ring of the inside read there, m, and the height percentile read.
REST_RING_M = 0.01
REST_RING_PERCENTILE = 25.0
#: The least look confidence that the hand's release point may corroborate
#: (:func:`_corroborated`): a segment that hardly looks like the object is not made it. A can
#: or a bottle let go into LIBERO-90's basket shows only its top between the walls and matched
#: its look at 0.025-0.034, 1-2 cm from where the hand opened (LIBERO-90 tasks 49, 54: training
#: tasks); 0.1 left every one of them unjudged.
RELEASE_LOOK_FLOOR = 0.02
#: Fraction of a look's footprint a detection cut by the image border must show to be named
#: at full confidence (:func:`_seen_fraction`).
SEEN_ENOUGH = 0.5
#: A detection serves as a spatial reference's landmark only when it is named at least this
#: confidently (the verifier's floor, ``agent.criteria.CONFIDENCE_MIN``): on the development
#: split (libero_spatial task 5, sampler seed 501) a cookie box under the other bowl was named
#: the ramekin at 0.21, and "the bowl on the ramekin" picked out the wrong bowl -- at the
#: next observation too, where that weak sighting was the ramekin's track. A track serves only
#: at this confidence as well.
LANDMARK_MIN_CONFIDENCE = 0.5
#: Extra association cost of a detection cut by the image border (:meth:`Perceiver._associate_parts_weighed`):
#: twice the ambiguity margin (0.5), so a whole sighting whose look costs up to one margin
#: more than a part's still wins it unambiguously. With the cut's relaxed size and shape alone,
#: parts at the border made 56 of 280 objects of libero_object's generated scenes (LIBERO's
#: sampler, seeds 201-204) ambiguous or misnamed.
PART_COST = 1.0
#: Position sigma (m) at least of a round object's centre completed from the part of it seen
#: (the seen far edge's spread and the look's radius range: centres completed within 2-3 mm on
#: LIBERO-90 tasks 67 and 68, training, and within 2 mm on rendered synthetic plates).
COMPLETED_STD_M = 0.003
#: An object let go whose visible top stands more than this above its known height (m) over
#: the table stands on something hidden under it (a plate the mug set on it hides from every
#: camera); its bottom is then its top less its height. Half the lowest support measured:
#: LIBERO's plate holds a mug 7.9-9.2 mm up (its floor), seen 3.9-8.5 mm up this way
#: (LIBERO-90 tasks 67 and 68, training); a mug standing on the table measured within 0.5 mm
#: of its height.
HIDDEN_SUPPORT_M = 0.004
#: How far (m) beyond its look's footprint radius a let-go object's detection may stand from its
#: track and still be matched with its base hidden (:meth:`Perceiver._hidden_base_where_let_go`):
#: an object let go into a container settles a little. With its track's release-wide sigma
#: (3 cm) instead, a fragment of the basket's wall 9 cm away took the tomato sauce can's name
#: (LIBERO-10 task 0, development run).
HIDDEN_BASE_SLACK_M = 0.015
#: Sigma (m) of where an object let go is, from where the hand let it go.
RELEASE_SIGMA_M = 0.03
#: A segment resting on another whose bottom stands no more than this below a tracked object's
#: top (m), its footprint overlapping the object's, rests on that object: it is not that object
#: (:meth:`Perceiver._not_on_itself`). The split's step cuts every 5 mm.
ON_ITSELF_MARGIN_M = 0.01
#: A segment standing on the table over a tracked object with a solid top, whose top stands
#: higher than the object's by more than this fraction of the object's height, is the object
#: with something set on it, not the object (:meth:`Perceiver._not_on_itself`): a sighting's top
#: wanders by millimetres, not by half an object.
ON_ITSELF_RISE = 0.5
#: An object let go whose sighting, raised off the table on some other segment, is more than
#: this shorter than its known height (m) has its lower part cut off or hidden (a mug on a
#: plate, its handle's foot and the plate's rim split off as a piece it was stacked on): its
#: bottom is then its top less its height, as for :data:`HIDDEN_SUPPORT_M`. LIBERO-10 task 6
#: (the evaluation run's traces, 0a9c03b): the porcelain mug, 12.3 cm tall, seen 9.2 cm tall
#: standing 3.1 cm above the plate's floor.
SEEN_SHORT_M = 0.01
#: An object not seen now is still reported (``remembered``) for this long after its last
#: sighting when every camera that could see it has something nearer in the way or its frame's
#: border cutting it off (:func:`_occluded_in`), s; its
#: confidence is the track's times :data:`~phyagentos.perception.tracks.REMEMBERED_CONFIDENCE`.
REMEMBER_S = 60.0
#: A depth return this much nearer than where the ray enters the object's box is something
#: in the way, m (depth noise is ~1-3 mm at 1 m, docs/perception.md).
OCCLUSION_MARGIN_M = 0.01
#: Spots of a track looked at for :func:`_occluded_in`, as fractions of its half extents in
#: its own footprint frame: the centre and half way to each side.
OCCLUSION_SPOTS = ((0.0, 0.0), (0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5))
#: Above a fixture's top the crop is raised by this much, m: the tallest thing set on it
#: (LIBERO's wine bottle: 0.29 m).
FIXTURE_LOAD_M = 0.35
#: A fixture's own points reach this far above its top (or its place patch's surface), m;
#: what lies higher stands on it (within ``relations.on_gap_m`` of the surface: stacked).
FIXTURE_MARGIN_M = 0.008
#: A fixture's footprint grown by this for its own points (rect fit and depth edges), m.
FIXTURE_EDGE_M = 0.015
#: A covered sighting (``Detection.covered``) of a tracked object keeps the track where it is
#: when its points lie within the track's footprint grown by this, m...
COVERED_WITHIN_M = 0.01
#: ... all but this fraction of them (:meth:`Perceiver._covered_within_track`).
COVERED_OUTSIDE_FRACTION = 0.05
#: A sighting of a tracked object narrower by more than this along one of its axes, m, than
#: both its track and its declared look (the smallest size the look was seen whole at) shows
#: only part of it (the rest hidden behind the arm, the held object or the edge of a camera's
#: view that another camera misses): its points within the track's footprint
#: (:meth:`Perceiver._part_within_track`) confirm the object there and never move it. The voxel
#: grid's size: whole sightings of one plate differ by 1-2 mm.
PART_NARROWER_M = 0.004
#: ... unless the tcp stands within this of the track's footprint, m (horizontally): a hand at
#: the object may be moving it (a push, a grasp), and its sighting counts as it is...
PART_HAND_CLEAR_M = 0.03
#: ... or, over the footprint, stands more than this above the track's top, m, the fingers
#: squeezing nothing: the Franka Hand's fingertips are 1.5 cm below its tcp
#: (``motion.grasp.FINGERTIP_BELOW_TCP_M``), so an empty hand that high touches nothing there and
#: what it hides is hidden, not moved; the rest of the margin is for a hand pitched or turned
#: (LIBERO-10 task 4, generated seeds 500-508: looking down at the mug just let go onto its plate
#: from 22 cm over the plate's top, the plate seen round the mug moved 13-15 mm off where it
#: stands; the mug's track was then still held, so the fingers, not the tracks, say whether
#: something is held).
PART_HAND_ABOVE_M = 0.10
#: A fixture's model footprint (:meth:`~.fixtures.FixtureLook.in_model`) grown by this for its own
#: points, m: the voxel grid. Not the body's 1.5 cm: a plate standing 5 mm from the wine rack's
#: base (LIBERO-PRO's ``libero_goal_swap``) would lose its rim.
FIXTURE_MODEL_EDGE_M = 0.005
#: How far over a room's floor the foot of what stands on it may go unseen behind the mouth's
#: lip, m (the floor's :attr:`~.detect.Detection.hidden_above_m`): a mug at the back of LIBERO's
#: microwave showed its lowest points 2.0 cm over the floor to the wrist camera looking in from
#: the mouth (LIBERO-10 task 9 init 1). Not the room's whole height: a sliver of a mug's far rim
#: 10 cm up, seen over its front, is no mug standing on the floor (task 9 init 8, where it became
#: a rival for the mug's name).
ROOM_LIP_HIDES_M = 0.04
#: 1-sigma position uncertainty reported for a fixture's place patch, m (its footprint's
#: rectangle fit on a 1 cm grid).
FIXTURE_STD_M = 0.01
#: The part of a knob's bar offered as its grasp: this deep from its top, m (LIBERO's stove
#: knob: a 5 cm bar on a 1.3 cm base plate; the fingertips, 1.3-1.5 cm below the tcp, close
#: on the bar 2.5-3 cm above the table).
KNOB_GRIP_DEPTH_M = 0.04
#: Half the thickness of a knob's bar across which the fingers close, m (LIBERO's: 2.4 cm).
KNOB_BAR_HALF_WIDTH_M = 0.012
#: Half the thickness of a drawer's handle bar (its box in the snapshot), m (LIBERO's cabinet
#: handles: 1.5 x 1.6 cm bars).
DRAWER_HANDLE_HALF_M = 0.008
#: A drawer's handle is approached this far below the horizontal, rad, the fingers closing
#: across the bar in the vertical plane through the drawer's axis: the hand's body (10.5 cm
#: either side of the tcp along the closing direction on the Panda) then keeps 1.6 cm over
#: the table at a handle 11.5 cm high (LIBERO's middle drawer) where a level hand keeps 1.0
#: cm, clearing a plate lying 3.5 cm in front of the handle (generated libero_goal scenes;
#: ``bench/libero_drawer.py``), and the upper finger stays clear of the drawer above.
DRAWER_APPROACH_PITCH_RAD = math.radians(10.0)
#: A drawer's walls, as the fixture's own points (:meth:`Perceiver._drawer_points`): its front
#: and handle this deep inward from the handle's outer face, its sides this thick, its floor
#: this far below the handle's centre and lower, m (LIBERO's cabinet drawers: the handle stands
#: 2.4 cm proud of a 1.5 cm front; the floor is about 3 cm below the handle's centre).
DRAWER_FRONT_M = 0.045
DRAWER_WALL_M = 0.02
DRAWER_FLOOR_M = 0.025
#: The inside of a drawer's front, this far inward from its handle's outer face, m: where the
#: floor a thing is set onto begins (LIBERO's cabinet drawers, both models: 3.7 cm by their
#: collision boxes; 1 mm more).
DRAWER_FLOOR_FRONT_M = 0.038
#: Points this far or more inside a compartment's walls (its footprint from the fixture's look:
#: the inside between them), above its floor, are what stands in it, not the fixture's, m: the
#: voxel grid's 5 mm and the 2-3 mm of a wall's depth edge.
COMPARTMENT_WALL_M = 0.008
#: How far from where the hand let an object go a weak sighting of it may stand, m
#: (:meth:`Perceiver._weak_elsewhere`): its own footprint (LIBERO's largest, the 11 cm bowls and
#: the 8.5 cm cream cheese box) and a short tumble; a confident sighting farther away is still
#: taken (a can rolled off).
RELEASE_REACH_M = 0.15
#: The body's front stands this far behind a drawer's shut handle centre, m (LIBERO's cabinet: the
#: handle 2.4 cm proud of the front, :data:`~phyagentos.perception.fixtures.DRAWER_FRONT_BEHIND_M`).
DRAWER_CARCASS_M = 0.024
#: A segment cut by the cabinet's body (:meth:`Perceiver._cut_by_carcass`) has this many points
#: or more within this far (m) in front of the body's front, inside an open drawer: a sliver of
#: rim, at the agentview's 3 mm pixels and the cloud's 5 mm voxels.
CARCASS_CUT_MIN_POINTS = 5
CARCASS_CUT_BAND_M = 0.01
#: ... and this far (m) or more above the drawer's floor: a strip of the floor 1-2 mm over the
#: floor's cut at the drawer's mouth is cut off there too, and would pass for a part of anything.
CARCASS_CUT_RISE_M = 0.01
#: A drawer standing this far out (m) or more has a floor things rest on (a support for
#: stacking, :meth:`Perceiver._drawer_floor`): LIBERO's drawers open 16 cm; a bowl takes 11.
DRAWER_OPEN_SUPPORT_M = 0.03


def _quat_yaw(yaw: float) -> list[float]:
    return [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]


def _r(x, nd: int = 4):
    if isinstance(x, (list, tuple, np.ndarray)):
        return [round(float(v), nd) for v in x]
    return round(float(x), nd)


def _obstacle_boxes(obstacles) -> list[tuple[np.ndarray, np.ndarray]]:
    if obstacles is None:
        return []
    if isinstance(obstacles, Mapping):
        obstacles = obstacles.get("obstacles", [])
    out = []
    for ob in obstacles:
        get = ob.get if isinstance(ob, Mapping) else (lambda k, _o=ob: getattr(_o, k, None))
        c, he = get("center"), get("half_extents")
        try:
            c3 = np.array([float(v) for v in c], float)
            he3 = np.array([float(v) for v in he], float)
        except (TypeError, ValueError):
            raise PerceptionError(f"obstacle {get('name')!r} needs center [x, y, z] and half_extents [hx, hy, hz]") from None
        if c3.shape != (3,) or he3.shape != (3,):
            raise PerceptionError(f"obstacle {get('name')!r} needs 3-number center and half_extents")
        out.append((c3 - he3 - _OBSTACLE_MARGIN_M, c3 + he3 + _OBSTACLE_MARGIN_M))
    return out


#: How far around a door's slab and handle, at its reading, points are the fixture's own, m
#: (:func:`~phyagentos.perception.door.door_points`): its depth noise and the reading's error
#: at its free edge (0.03 rad over 26 cm is 8 mm).
DOOR_OWN_MARGIN_M = 0.02


class Perceiver:
    """Per-session perception: ``Perceiver(config, declared)``.

    Args:
        config: the pipeline parameters (perception.yaml).
        declared: the declared objects (descriptors, or mappings as in ``describe_declared()``).
        robot_name: name of the arm entity in the snapshot (``kind: robot``).

    Raises:
        PerceptionError: malformed descriptors.
    """

    def __init__(self, config: PerceptionConfig | None = None,
                 declared: Sequence[ObjectDescriptor | Mapping[str, Any]] | Mapping[str, Any] = (), *,
                 robot_name: str = "panda"):
        if config is not None and not isinstance(config, PerceptionConfig):
            raise PerceptionError(f"config must be a PerceptionConfig, got {type(config).__name__}")
        self.config = config or PerceptionConfig.default()
        self.declared: tuple[ObjectDescriptor, ...] = tuple(descriptors_from_declared(declared))
        #: Declared fixtures with a look (:mod:`~phyagentos.perception.fixtures`).
        self.fixtures: tuple[FixtureLook, ...] = (tuple(fixtures_from_declared(declared))
                                                  if isinstance(declared, Mapping) else ())
        reserved = {"tcp", "gripper", "table", robot_name}
        clash = sorted(reserved & ({d.name for d in self.declared} | {f.name for f in self.fixtures}))
        if clash:
            raise PerceptionError(f"declared object name(s) {clash} clash with reserved entity names {sorted(reserved)}")
        self.robot_name = robot_name
        self.reset()

    def reset(self) -> None:
        """Forget every track, the glimpses, the wrist-force baseline and the held object."""
        self.tracks: dict[str, Track] = {}
        #: What was seen in part and never named, kept while its place is hidden
        #: (:func:`~phyagentos.perception.glimpse.carry_over`): rivals for a look-alike's name.
        self.glimpses: list[Glimpse] = []
        #: Each fixture's last sighting and its time, s: ``{name: (sighting, stamp, confidence)}``.
        self.fixture_tracks: dict[str, tuple[FixtureSighting, float, float]] = {}
        #: Each knob's reading in the last observation: ``{fixture name: (bar yaw rad, points)}``
        #: (absent: not read there; a knob turns, so it is never remembered).
        self.knob_readings: dict[str, tuple[float, int]] = {}
        #: Each drawer's reading in the last observation: ``{(fixture, drawer): (opening m,
        #: points)}`` (absent: its handle not read there; never remembered).
        self.drawer_readings: dict[tuple[str, str], tuple[float, int]] = {}
        #: The open drawers' mouths of this observation (:meth:`_cut_by_carcass`): (the drawer's
        #: frame origin (2,), its axis (2,), across (2,), where the body's front stands along it,
        #: half the inside's width, its floor's height), m, world frame.
        self._mouths: list[tuple[np.ndarray, np.ndarray, np.ndarray, float, float, float]] = []
        #: The rooms behind fixtures' doors of this observation (:meth:`_cut_by_room`): (centre (2,),
        #: half extents (2,), yaw, floor z, roof z, mouth (2,)), m, world frame.
        self._rooms: list[tuple[np.ndarray, np.ndarray, float, float, float, np.ndarray]] = []
        #: (fixture, drawer) -> (opening m, stamp s) of the drawer's last reading: where an open
        #: drawer's floor still is while the arm (or what it holds) hides its handle
        self.drawer_seen: dict[tuple[str, str], tuple[float, float]] = {}
        #: (fixture, drawer) -> stamp s of the push that met its shut stop
        #: (:meth:`note_drawer_stop`): read shut, to the contact's 1-sigma, while its handle is
        #: read within 2 sigma of shut
        self.drawer_stops: dict[tuple[str, str], float] = {}
        #: (fixture, drawer) -> (opening m, stamp s) the hand felt when it let go of the handle
        #: of a drawer it pulled open (:meth:`note_drawer_opened`): what the drawer reads while
        #: its handle is hidden and not read since
        self.drawer_felt: dict[tuple[str, str], tuple[float, float]] = {}
        #: Each door's reading in the last observation: ``{fixture: (joint rad, points)}``
        #: (absent: not read there) and its last one, ``{fixture: (joint rad, stamp s)}``.
        self.door_readings: dict[str, tuple[float, int]] = {}
        self.door_seen: dict[str, tuple[float, float]] = {}
        #: fixture -> stamp s of the push that met its door's shut stop (:meth:`note_door_stop`)
        self.door_stops: dict[str, float] = {}
        self._baseline_n: float | None = None
        self._held: str | None = None
        self._grasp_height_m: float | None = None
        #: (tcp pose (4, 4) in the world frame, stamp s) where the hand last closed on
        #: something (:meth:`note_grasp_close`); None while it is open.
        self._closed_at: tuple[np.ndarray, float] | None = None
        self._last_plane: Plane | None = None
        #: Objects found lying on a fixture's ramp in the last observation (:meth:`_leant_where_let_go`):
        #: ``{object: (fixture, tilt from upright rad, confidence)}``.
        self.leant: dict[str, tuple[str, float, float]] = {}
        self.last_timing_ms: dict[str, float] = {}
        #: Centre (2,) of the support plane's perceived extent (world m) at the last
        #: :meth:`object_cloud`, when a spatial reference needs it, else None.
        self.table_centre_xy: np.ndarray | None = None
        #: The viewer's right on the table (2,) unit vector, world frame: the horizontal part of
        #: the image x axis of ``association.viewer_camera`` (else the first camera) at the last
        #: :meth:`object_cloud`, or None (no such camera, or one looking straight down its x).
        self.viewer_right_xy: np.ndarray | None = None
        #: How each spatial reference was resolved at the last :meth:`observe`, by object name.
        self.last_references: dict[str, ReferenceResolution] = {}
        #: The object cloud of the last :meth:`observe` (stage 2: points above the support
        #: plane, cropped and masked, on the voxel grid; world frame, m), or None before one.
        self.last_cloud: Cloud | None = None

    def _drawer_key(self, entity: str) -> tuple[str, str]:
        for look in self.fixtures:
            for drawer in look.drawers:
                if drawer_entity_name(look.name, drawer.name) == entity:
                    return look.name, drawer.name
        names = [drawer_entity_name(f.name, d.name) for f in self.fixtures for d in f.drawers]
        raise PerceptionError(f"{entity!r} is no drawer of a declared fixture; drawers: {names or 'none'}")

    def note_drawer_stop(self, entity: str, *, stamp_s: float) -> None:
        """Record that the hand, holding drawer ``entity``'s handle, pushed it into its shut stop
        at ``stamp_s`` s (:class:`~phyagentos.primitives.affordance.ArticulateSlide`, pushed
        home). From then on, while its handle is read within 2 sigma
        (:data:`~phyagentos.perception.fixtures.DRAWER_SIGMA_M`) of shut, the drawer is
        reported at shut (``joint_position`` 0) with 1-sigma
        :data:`~phyagentos.perception.fixtures.DRAWER_STOP_SIGMA_M` and ``at_stop: shut``; a
        reading further out forgets it (the drawer was moved).

        Raises:
            PerceptionError: ``entity`` is no drawer of a declared fixture (the drawers listed).
        """
        self.drawer_stops[self._drawer_key(entity)] = float(stamp_s)

    def note_drawer_opened(self, entity: str, *, opening_m: float, stamp_s: float) -> None:
        """Record that the hand, holding drawer ``entity``'s handle, pulled it open and stood,
        at ``stamp_s`` s, ``opening_m`` m out of shut by its joint encoders: the reading the pull
        began from plus the hand's travel along the drawer's axis
        (:class:`~phyagentos.primitives.affordance.ArticulateSlide`). The drawer is then at least
        ``opening_m`` less the bar's play in the fingers
        (:data:`~phyagentos.perception.fixtures.DRAWER_HANDLE_PLAY_M`) out: the hand pulled it that
        far, and backing off the released handle only pulls it further. While its handle is
        hidden and not read since, the drawer is reported there, with the starting reading's
        1-sigma and ``joint_position_bound: lower`` (a verifier may confirm "open at least",
        never "shut"); a reading of the handle supersedes it.

        Raises:
            PerceptionError: ``entity`` is no drawer of a declared fixture (the drawers listed).
        """
        self.drawer_felt[self._drawer_key(entity)] = (float(opening_m) - DRAWER_HANDLE_PLAY_M, float(stamp_s))

    def note_door_stop(self, fixture: str, *, stamp_s: float) -> None:
        """Record that the hand pushed ``fixture``'s door into its shut stop at ``stamp_s`` s
        (:class:`~phyagentos.primitives.door.PushDoor`). From then on, while the door is not read
        or is read within 2 sigma (:data:`~phyagentos.perception.door.DOOR_SIGMA_RAD`) of shut,
        it is reported shut (``joint_position``, its opening, 0) with 1-sigma
        :data:`~phyagentos.perception.door.DOOR_STOP_SIGMA_RAD` and ``at_stop: shut``; a reading
        further open forgets it (the door was moved).

        Raises:
            PerceptionError: ``fixture`` is no declared fixture with a door (those listed).
        """
        doors = [f.name for f in self.fixtures if f.door is not None]
        if fixture not in doors:
            raise PerceptionError(f"{fixture!r} is no declared fixture with a door; fixtures with a door: "
                                  f"{doors or 'none'}")
        self.door_stops[fixture] = float(stamp_s)

    def forget_door_stop(self, fixture: str) -> None:
        """Forget what :meth:`note_door_stop` recorded of ``fixture`` (its door is being moved)."""
        self.door_stops.pop(fixture, None)

    def forget_drawer_stop(self, entity: str) -> None:
        """Forget what :meth:`note_drawer_stop` and :meth:`note_drawer_opened` recorded of
        ``entity`` (it is being moved); an entity that is no declared drawer has nothing to
        forget."""
        try:
            key = self._drawer_key(entity)
        except PerceptionError:
            return
        self.drawer_stops.pop(key, None)
        self.drawer_felt.pop(key, None)

    # ------------------------------------------------------------------ state

    _TRACK_ARRAYS = ("position", "half_extents", "colour_rgb", "grasp_offset", "placed_xy", "top_knob", "hang_tcp",
                    "base_profile_m")

    def export_state(self) -> dict:
        """What this perceiver believes, as plain YAML/JSON-ready data: the tracks, the held
        object, the open-gripper wrist-force baseline, the grasp height, where the hand last
        closed (``closed_at``: ``{tcp_pose: (4, 4) world, stamp_s}``, :meth:`note_grasp_close`;
        None while open) and the glimpses kept (``glimpses``: :meth:`~phyagentos.perception.glimpse.Glimpse.to_dict`),
        so a later session, maybe in another process, continues it with
        :meth:`restore_state`."""
        tracks = {}
        for name, t in self.tracks.items():
            d = dict(vars(t))
            for k in self._TRACK_ARRAYS:
                if d.get(k) is not None:
                    d[k] = np.asarray(d[k], dtype=float).tolist()
            d["cameras"] = list(d.get("cameras") or ())
            d["shape_votes"] = {str(k): int(v) for k, v in (d.get("shape_votes") or {}).items()}
            if t.body is not None:
                d["body"] = {"axis_xy": t.body.axis_xy.tolist(), "radius_m": float(t.body.radius_m),
                             "handle_xy": t.body.handle_xy.tolist(),
                             "reach_m": None if t.body.reach_m is None else float(t.body.reach_m)}
            tracks[name] = {k: (float(v) if isinstance(v, np.floating) else v) for k, v in d.items()}
        closed = None if self._closed_at is None else {"tcp_pose": self._closed_at[0].tolist(),
                                                       "stamp_s": float(self._closed_at[1])}
        return {"tracks": tracks, "baseline_n": self._baseline_n, "held": self._held,
                "grasp_height_m": self._grasp_height_m, "closed_at": closed, "fixtures": self.export_fixtures(),
                "glimpses": [g.to_dict() for g in self.glimpses]}

    def export_fixtures(self) -> dict:
        """The fixtures' last sightings as plain data (``{name: {position, yaw, half_extents,
        half_xy_world, top_m, points, error, found_by, turn, stamp_s, confidence, drawers, stops}}``, m,
        rad, s; ``drawers``: ``{drawer: [opening m, stamp s]}`` of each drawer's last reading;
        ``stops``: ``{drawer: stamp s}`` of each drawer pushed into its shut stop; ``felt``:
        ``{drawer: [opening m, stamp s]}`` of each drawer the hand pulled open; ``door``:
        ``[joint rad, stamp s]`` of its door's last reading and ``door_stop``: stamp s of the
        push that met its shut stop, where it has them), for :meth:`restore_fixtures`."""
        return {n: {"position": s.position.tolist(), "yaw": float(s.yaw), "half_extents": s.half_extents.tolist(),
                    "half_xy_world": s.half_xy_world.tolist(), "top_m": float(s.top_m), "points": int(s.points),
                    "error": float(s.error), "found_by": s.found_by, "turn": float(s.turn), "stamp_s": float(t),
                    "confidence": float(c),
                    "drawers": {d: [float(o), float(ts)] for (f, d), (o, ts) in self.drawer_seen.items() if f == n},
                    "stops": {d: float(ts) for (f, d), ts in self.drawer_stops.items() if f == n},
                    "felt": {d: [float(o), float(ts)] for (f, d), (o, ts) in self.drawer_felt.items() if f == n},
                    **({"door": [float(self.door_seen[n][0]), float(self.door_seen[n][1])]} if n in self.door_seen
                       else {}),
                    **({"door_stop": float(self.door_stops[n])} if n in self.door_stops else {})}
                for n, (s, t, c) in self.fixture_tracks.items()}

    def restore_fixtures(self, data: Mapping[str, Any]) -> None:
        """Continue from :meth:`export_fixtures` data; fixtures not declared with a look are
        dropped.

        Raises:
            PerceptionError: an entry without the layout :meth:`export_fixtures` writes.
        """
        looks = {f.name for f in self.fixtures}
        self.fixture_tracks = {}
        self.drawer_seen = {}
        self.drawer_stops = {}
        self.drawer_felt = {}
        self.door_seen = {}
        self.door_stops = {}
        for name, d in (data or {}).items():
            if name not in looks:
                continue
            try:
                sighting = FixtureSighting(name, np.asarray(d["position"], float), float(d["yaw"]),
                                           np.asarray(d["half_extents"], float), np.asarray(d["half_xy_world"], float),
                                           float(d["top_m"]), int(d["points"]), float(d["error"]),
                                           str(d.get("found_by", "size")), float(d.get("turn", 0.0)))
                self.fixture_tracks[name] = (sighting, float(d["stamp_s"]), float(d["confidence"]))
                for drawer, (opening, ts) in (d.get("drawers") or {}).items():
                    self.drawer_seen[(name, str(drawer))] = (float(opening), float(ts))
                for drawer, ts in (d.get("stops") or {}).items():
                    self.drawer_stops[(name, str(drawer))] = float(ts)
                for drawer, (opening, ts) in (d.get("felt") or {}).items():
                    self.drawer_felt[(name, str(drawer))] = (float(opening), float(ts))
                if d.get("door") is not None:
                    self.door_seen[name] = (float(d["door"][0]), float(d["door"][1]))
                if d.get("door_stop") is not None:
                    self.door_stops[name] = float(d["door_stop"])
            except (KeyError, TypeError, ValueError) as exc:
                raise PerceptionError(f"perception state: fixture {name!r} has an unexpected layout: {exc}") from None

    def restore_state(self, state: Mapping[str, Any]) -> None:
        """Continue from :meth:`export_state` data; tracks of objects no longer declared are
        dropped.

        Raises:
            PerceptionError: the data does not have the layout :meth:`export_state` writes.
        """
        if not isinstance(state, Mapping):
            raise PerceptionError(f"perception state must be a mapping, got {type(state).__name__}")
        declared = {d.name for d in self.declared}
        tracks: dict[str, Track] = {}
        for name, d in (state.get("tracks") or {}).items():
            if name not in declared:
                continue
            d = dict(d)
            for k in self._TRACK_ARRAYS:
                if d.get(k) is not None:
                    d[k] = np.asarray(d[k], dtype=float)
            d["cameras"] = tuple(d.get("cameras") or ())
            try:
                if d.get("body") is not None:
                    b = d["body"]
                    d["body"] = RoundBody(np.asarray(b["axis_xy"], float), float(b["radius_m"]),
                                          np.asarray(b["handle_xy"], float),
                                          None if b.get("reach_m") is None else float(b["reach_m"]))
                tracks[name] = Track(**d)
            except (TypeError, KeyError, ValueError) as exc:
                raise PerceptionError(f"perception state: track {name!r} has an unexpected layout: {exc}") from None
        self.tracks = tracks
        try:
            self.glimpses = [Glimpse.from_dict(g) for g in state.get("glimpses") or ()]
        except (TypeError, KeyError, ValueError) as exc:
            raise PerceptionError(f"perception state: a glimpse has an unexpected layout: {exc}") from None
        self.restore_fixtures(state.get("fixtures") or {})
        self._baseline_n = state.get("baseline_n")
        self._held = state.get("held") if state.get("held") in tracks else None
        self._grasp_height_m = state.get("grasp_height_m")
        closed = state.get("closed_at")
        try:
            noted = None if closed is None else (np.asarray(closed["tcp_pose"], dtype=float), float(closed["stamp_s"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise PerceptionError(f"perception state: closed_at has an unexpected layout: {exc}") from None
        if noted is not None:
            _rigid("perception state", "closed_at.tcp_pose", noted[0])
        self._closed_at = noted

    # ------------------------------------------------------------------ proprioception

    def update_proprioception(self, proprio: Proprioception) -> None:
        """Feed a proprioception sample between observations (optional, cheap): keeps the
        open-gripper wrist-force baseline and the grasp height current."""
        if not isinstance(proprio, Proprioception):
            raise PerceptionError(f"proprio must be a Proprioception, got {type(proprio).__name__}")
        hc = self.config.holding
        free = abs(proprio.gripper_effort_n) < 0.5 * hc.min_effort_n
        if free and proprio.wrist_force_n is not None:
            f = float(np.linalg.norm(proprio.wrist_force_n))
            self._baseline_n = f if self._baseline_n is None else 0.5 * (self._baseline_n + f)
        if free:
            self._grasp_height_m = None
            self._closed_at = None
        elif self._grasp_height_m is None:
            self._grasp_height_m = float(proprio.tcp_pose[2, 3])

    def note_grasp_close(self, proprio: Proprioception) -> None:
        """The hand has just closed on something (the skill's gripper close, judged by its own
        sensing): keep its tcp pose and stamp. A hold this perceiver notices only later (the
        first look after the lift) then takes where the object sits across and along the
        fingers (the tcp frame's x and y) and how it is turned in the hand from where the hand
        closed and where the object was last seen before it, for any grasp (across a box, on a
        bowl's wall, on a knob), instead of assuming it centred on the tcp. How high it sits
        (the tcp frame's z) is kept as before: centred for a grasp across, the grasp's depth
        for a rim or a knob. The places measured on LIBERO rely on that height: a wine bottle
        taken near its neck hangs 4.6 cm below the tcp, and taken as centred it is set down
        with the hand 4.6 cm lower, which is what put it into the rack's slope (libero_goal
        task 9) and kept the cabinet's top within reach (task 2); with the true height both
        failed (docs/libero.md, sixteenth pass). Forgotten when the hand is next sampled open
        (:meth:`update_proprioception`).

        Raises:
            PerceptionError: ``proprio`` is not a :class:`Proprioception`.
        """
        if not isinstance(proprio, Proprioception):
            raise PerceptionError(f"proprio must be a Proprioception, got {type(proprio).__name__}")
        self.update_proprioception(proprio)
        self._closed_at = (np.array(proprio.tcp_pose, dtype=float), float(proprio.stamp_s))

    # ------------------------------------------------------------------ pipeline stages

    def fixture_ceiling_m(self) -> float:
        """The height crop (m above the support plane) of the cloud fixtures are found in:
        ``workspace.max_height_m``, or the tallest declared fixture's top plus
        :data:`FIXTURE_LOAD_M` when that is higher."""
        tops = [f.size_m[2] for f in self.fixtures]
        return max([self.config.workspace.max_height_m] + [t + FIXTURE_LOAD_M for t in tops])

    def object_cloud(self, frames: Sequence[CameraFrame], proprio: Proprioception, *,
                     obstacles=None, robot_capsules: Sequence[RobotCapsule] = (),
                     max_height_m: float | None = None) -> tuple[Cloud, np.ndarray, Plane]:
        """Stages 1-2: ``(object cloud, (N,) heights above the plane, plane)``; points up to
        ``max_height_m`` above the plane (default ``workspace.max_height_m``)."""
        cc, cfg = self.config.cloud, self.config
        strides = [cfg.stride_for(f.intrinsics.width) for f in frames]
        coarse = merge_clouds([
            backproject(f, stride=2 * s, min_depth_m=cc.min_depth_m, max_depth_m=cc.max_depth_m, camera_index=i)
            for i, (f, s) in enumerate(zip(frames, strides))
        ])
        plane = fit_support_plane(coarse.points, cfg, rng=np.random.default_rng(0))
        if not plane.fitted:
            log.warning("perception: support plane not fitted (too few table points); using z = %.3f m",
                        cfg.table.expected_height_m)
        self.table_centre_xy = None
        self.viewer_right_xy = viewer_right(frames, cfg.association.viewer_camera)
        if plane.fitted and any(d.where is not None and d.where.relation == "table_center" for d in self.declared):
            self.table_centre_xy = table_centre(coarse.points, plane, cfg)
        parts = []
        for i, (f, s) in enumerate(zip(frames, strides)):
            d, h = heights_above(f, plane, stride=s)
            ceiling = cfg.workspace.max_height_m if max_height_m is None else float(max_height_m)
            cand = np.flatnonzero((h > cfg.table.object_min_height_m) & (h < ceiling)
                                  & (d >= cc.min_depth_m) & (d <= cc.max_depth_m))
            parts.append(backproject(f, stride=s, min_depth_m=cc.min_depth_m, max_depth_m=cc.max_depth_m,
                                     camera_index=i, pixels=cand))
        cloud = merge_clouds(parts)
        p = cloud.points
        ws = cfg.workspace
        keep = (p[:, 0] > ws.x_m[0]) & (p[:, 0] < ws.x_m[1]) & (p[:, 1] > ws.y_m[0]) & (p[:, 1] < ws.y_m[1])
        if ws.base_exclusion_radius_m > 0:
            bx, by = ws.base_xy_m
            keep &= (p[:, 0] - bx) ** 2 + (p[:, 1] - by) ** 2 > ws.base_exclusion_radius_m ** 2
        keep &= ~gripper_mask(p, proprio, cfg)
        if robot_capsules:
            keep &= ~capsule_mask(p, robot_capsules, cfg.robot_mask.capsule_margin_m)
        for lo, hi in _obstacle_boxes(obstacles):
            keep &= ~box_mask(p, np.eye(4), lo, hi)
        cloud = voxel_downsample(cloud.select(keep), cc.voxel_size_m)
        return cloud, plane.height(cloud.points.astype(np.float64)), plane

    # ------------------------------------------------------------------ observe

    def observe(self, frames: Sequence[CameraFrame], proprio: Proprioception, *, regions=None, obstacles=None,
                robot_capsules: Sequence[RobotCapsule] = (),
                evidence_paths: Mapping[str, str] | None = None) -> dict:
        """Fuse one observation (one or more RGB-D frames) into the perceived snapshot.

        Args:
            frames: the cameras' frames of this observation (each with depth).
            proprio: proprioception at (about) the same time.
            regions: declared regions (``describe_declared()['regions']`` or RegionSpecs).
            obstacles: declared obstacles (their points are removed before clustering).
            robot_capsules: optional capsules around arm links (world frame) to mask.
            evidence_paths: optional ``{sensor: path of the saved frame}`` for ``evidence``.

        Returns:
            The snapshot dict of CONTRACT_9 section 3 (``stamp_s``, ``frame``, ``entities``,
            ``relations``, ``proprioception``), plus ``unseen``: declared objects with no
            current sighting (never given a guessed pose).

        Raises:
            PerceptionError: no frames, a frame without depth, wrong argument types.
        """
        import time

        if not frames:
            raise PerceptionError("observe needs at least one camera frame")
        for f in frames:
            if not isinstance(f, CameraFrame):
                raise PerceptionError(f"frames must be CameraFrame objects, got {type(f).__name__}")
            if f.depth_m is None:
                raise PerceptionError(f"camera {f.sensor!r} has no depth image; perception needs RGB-D frames")
        if not isinstance(proprio, Proprioception):
            raise PerceptionError(f"proprio must be a Proprioception, got {type(proprio).__name__}")
        cfg = self.config
        stamp = max(float(f.stamp_s) for f in frames)
        region_list = regions_from(regions)
        t0 = time.perf_counter()
        self.update_proprioception(proprio)

        cloud, heights, plane = self.object_cloud(frames, proprio, obstacles=obstacles, robot_capsules=robot_capsules,
                                                  max_height_m=self.fixture_ceiling_m() if self.fixtures else None)
        fixture_dets: list[Detection] = []
        full_cloud = cloud  # with the fixtures' own points: what lies on a ramp is among them
        self.leant = {}
        if self.fixtures:
            cloud, heights, fixture_dets = self._perceive_fixtures(cloud, heights, plane, stamp)
        self._last_plane = plane
        self.last_cloud = cloud
        t1 = time.perf_counter()
        focal = np.array([f.intrinsics.fx / cfg.stride_for(f.intrinsics.width) for f in frames])
        clusters = detect_clusters(cloud, heights, plane, cfg, focal)
        if self.declared:  # a cluster larger than every declared object: the touching objects it holds
            clusters = split_clusters(clusters, cloud, heights, plane, cfg, focal, self.declared, supports=fixture_dets)
        # an object resting on a fixture's place patch stands on it (the patch as a support)
        dets = _stack([d for d, _ in clusters] + fixture_dets, plane, cfg)[:len(clusters)]
        # what no segment holds but may be another object (a rival for a look-alike's name)
        seg_lab = [d.colour_lab for d, _ in clusters]
        seen_now = glimpses(cloud, heights, [idx for _, idx in clusters], cfg, seg_lab)
        self.glimpses = carry_over(self.glimpses, seen_now, [cloud.points[idx, :2] for _, idx in clusters], frames,
                                   cfg, seg_lab)
        found_glimpses = self.glimpses
        hanging = [i for i, d in enumerate(dets) if _hangs_from_hand(d, proprio, cfg)]
        # the points the cameras off the hand saw (the hand's camera looks into a cup: perception.hang)
        off_hand = scene_camera_mask(cloud.camera, np.array([f.T_world_camera[:3, 3] for f in frames]),
                                     proprio.tcp_pose[:3, 3])
        hung = np.concatenate([clusters[i][1] for i in hanging]) if hanging else None
        hanging_points = None if hung is None else cloud.points[hung[off_hand[hung]]]
        if hanging:  # the part of the held object below the fingers: the hand's, not a thing on the table
            log.debug("perception: %d segment(s) hang from the closed hand: %s", len(hanging),
                      [_r(dets[i].position) for i in hanging])
            clusters = [c for i, c in enumerate(clusters) if i not in hanging]
            dets = [d for i, d in enumerate(dets) if i not in hanging]
        strides = [cfg.stride_for(f.intrinsics.width) for f in frames]
        dets = [self._seen_cut(d, cloud, heights, idx, frames, strides) for d, (_, idx) in zip(dets, clusters)]
        dets = [_shaped(d, cloud.select(idx), heights[idx]) for d, (_, idx) in zip(dets, clusters)]
        t2 = time.perf_counter()
        sensors = [f.sensor for f in frames]
        det_cams = [self._cameras_of(cloud, heights, d, sensors) for d in dets]

        # ---- association (tracks seen before break ties)
        names = [d.name for d in self.declared]
        track_pos = self.track_positions(proprio)
        twins = self._interchangeable()
        looks_only = self._hidden_base_where_let_go(cost_matrix(dets, self.declared, cfg), dets)  # no tie-breaker
        C = looks_only + track_costs(dets, len(self.declared), cfg, track_pos)
        C = self._covered_where_tracked(C, dets, {i: cloud.points[idx, :2] for i, (_, idx) in enumerate(clusters)
                                                  if dets[i].covered}, stamp)
        C = _not_inside_itself(self._not_on_itself(self._truncated_where_tracked(C, dets, proprio), dets), dets,
                               self.config.association.gate_cost)
        C = self._resolve_references(C, dets, stamp)
        assoc = self._associate_parts_weighed(C, dets, twins)
        for t in self.tracks.values():
            t.seen_now = False
        # objects the hand held or let go since they were last seen, or seen inside a container,
        # with their tracked height (a released item's lower part may be hidden by the walls)
        let_go = {n for n, t in self.tracks.items() if t.held or t.released_s is not None}
        # the container each was inside: a sighting that restarts its track (a can lying on the other
        # in the basket, seen merged with the basket's wall) tests it again, as a move out would
        was_inside = {n: t.inside_of for n, t in self.tracks.items()}
        tracked_h = {n: self._look_height(n, 2.0 * float(t.half_extents[2])) for n, t in self.tracks.items()
                     if n in let_go or t.inside_of is not None}
        matched: dict[int, str] = {}
        contested = set(assoc.ambiguous)  # look-alikes left unknown: rivals while hidden later
        for i, (j, cost, margin) in assoc.matches.items():
            if self._glimpse_rivals(self.declared[j], dets[i], float(looks_only[i, j]), found_glimpses, stamp):
                contested.add(i)
                continue
            seen = 1.0
            if dets[i].truncated:  # seen in part: a round one's centre from its look's size
                seen = _seen_fraction(dets[i], self.declared[j])
                if not dets[i].cut_by_body or dets[i].cut_by_room:  # (in a drawer: the rim seen, grasped near its ends)
                    dets[i] = _completed(dets[i], self.declared[j], cloud.points[clusters[i][1], :2])
            det = dets[i]
            conf = match_confidence(cost, margin, cfg) * _detection_confidence(det) * seen
            name = names[j]
            if self._hand_outweighs(name, det, conf, proprio):
                log.debug("perception: %s in the closing hand; a weak look-alike (confidence %.2f) at %s left unknown",
                          name, conf, _r(det.position))
                continue
            placed = self._release_point(name, proprio)
            if placed is not None:
                look = conf
                conf = _corroborated(conf, det, placed, cfg)
                if conf != look:
                    log.debug("perception: %s seen at confidence %.2f %.3f m from where the hand let it go: %.2f",
                              name, look, float(np.linalg.norm(det.position[:2] - placed)), conf)
            look_conf = match_confidence(float(looks_only[i, j]), margin, cfg) * _detection_confidence(det)
            if det.truncated and name not in self.tracks and conf < cfg.relations.min_confidence:
                log.debug("perception: a part at the image border looks weakly like %s (confidence %.2f) at %s: "
                          "left unknown", name, conf, _r(det.position))
                continue  # a weak part alone names nothing
            # (let go: judged on the sighting's confidence where it was let go, _corroborated's)
            if self._weak_elsewhere(name, det, look_conf if placed is None else conf, stamp, placed):
                log.debug("perception: %s seen weakly (confidence %.2f) at %s, away from its confident track: "
                          "the track kept, the segment left unknown", name, conf, _r(det.position))
                continue
            if self._inside_where_let_go(name, det, placed, cloud, heights, dets, clusters, sensors):
                log.debug("perception: %s matched at %s (confidence %.2f), %.3f m from where the hand let it go, "
                          "is seen inside the container there: the segment left unknown", name, _r(det.position),
                          conf, float(np.linalg.norm(det.position[:2] - placed)))
                continue
            if name in self.tracks and det.truncated and not self.tracks[name].held \
                    and not self.tracks[name].within_gate(det, stamp, cfg):
                # a part at the border, admissible where the object is (_truncated_where_tracked),
                # completed off its track: it confirms the object where it was and never moves it
                # (a mug on a plate half out of the frame, completed 2.8 cm off where the wrist
                # camera had seen it whole)
                log.debug("perception: %s seen in part at the border, completed %.3f m from its track: kept there",
                          name, float(np.linalg.norm(det.position[:2] - self.tracks[name].position[:2])))
                self.tracks[name].last_seen_s = stamp
            elif name in self.tracks and det.covered and not self.tracks[name].held \
                    and self._covered_within_track(self.tracks[name], cloud.points[clusters[i][1], :2]):
                # what shows of it round what now rests on it, all within where it was seen whole:
                # it confirms the object there and never moves it (a plate under the mug set on it,
                # its crescent's centre 3.5 cm off the plate's)
                log.debug("perception: %s seen covered at %s, within its track at %s: kept there",
                          name, _r(det.position), _r(self.tracks[name].position))
                self.tracks[name].last_seen_s = stamp
            elif name in self.tracks and self._part_within_track(self.tracks[name], det,
                                                                 cloud.points[clusters[i][1], :2], proprio):
                # a part of it, the rest hidden, all within where it was seen whole, the hand clear
                # of it: it confirms the object there and never moves it (LIBERO-10 task 4 init 5:
                # the plate the mug was to go on, partly hidden while the mug was lifted, was moved
                # 1.6 cm by three such sightings, and the mug set down off its true centre)
                log.debug("perception: %s seen in part (half extents %s against %s) at %s, within its track at "
                          "%s: kept there", name, _r(det.half_extents[:2]), _r(self.tracks[name].half_extents[:2]),
                          _r(det.position), _r(self.tracks[name].position))
                self.tracks[name].last_seen_s = stamp
            elif name in self.tracks:
                t = self.tracks[name]
                # the handle as the hand turned it (about the object's centre, world axes), for a
                # sighting that misses it
                carried = None
                if t.held and t.body is not None and t.grasp_offset is not None:
                    turn = proprio.tcp_pose @ t.grasp_offset
                    turn[:3, 3] = 0.0
                    carried = t.body.placed(turn)
                # a weak sighting where a confident track stands (part of it, the rest hidden or
                # out of the frame) says no less than not seeing it at all would (remembered)
                t.update(det, conf, stamp, det_cams[i], cfg,
                         weak_below=0.0 if t.released_s is not None else cfg.relations.min_confidence)
                if carried is not None and det.body is None:
                    t.body = carried.local(np.zeros(2), t.yaw)
                t.held = False
                away = placed is not None and float(np.linalg.norm(t.position[:2] - placed)) > cfg.holding.capture_radius_m
                # kept while the object is where it was let go (or seen there only weakly)
                t.placed_xy = None if placed is None or (away and conf >= cfg.relations.min_confidence) \
                    else placed.copy()
            else:
                self.tracks[name] = Track.start(name, det, conf, stamp, det_cams[i])
            self.tracks[name].seen_now = True
            self.tracks[name].released_s = None
            matched[i] = name
        for i, name in matched.items():  # a round body's base, as the cameras off the hand see it standing
            body = dets[i].body
            if body is not None and dets[i].bottom_m <= 1e-6:
                idx = np.asarray(clusters[i][1])
                idx = idx[off_hand[idx]]
                prof = base_profile(cloud.points[idx], axis_xy=body.axis_xy, outline_radius_m=body.radius_m)
                if prof is not None:
                    self.tracks[name].base_profile_m = prof
        # a container holds what stands in it where its track puts it, fused over its sightings: a view
        # of it cut by what was just let go into it (kept where its track stands), or short of its rim
        # behind that, is not where its walls are
        as_tracked = [_as_tracked(d, self.tracks[matched[k]]) if k in matched else d for k, d in enumerate(dets)]
        for i, name in matched.items():  # seen again: still inside the container it was in (or let go into)?
            t = self.tracks[name]
            container = t.inside_of if t.inside_of is not None else was_inside.get(name)
            if container is None and name in let_go:
                container = _container_around(i, as_tracked, matched)
            t.inside_of = _still_inside(container, dets[i], as_tracked, matched, height_m=tracked_h.get(name))
            if name in let_go and name in tracked_h:
                t.known_height_m = tracked_h[name]  # its height when the hand let it go
            known_h = t.known_height_m
            raised = known_h is not None and dets[i].bottom_m <= 1e-6 and dets[i].top_m - known_h > HIDDEN_SUPPORT_M
            short = (known_h is not None and dets[i].bottom_m > 1e-6
                     and dets[i].top_m - dets[i].bottom_m < known_h - SEEN_SHORT_M)
            if (raised or short) and name not in tracked_h:
                tracked_h[name] = float(known_h)
            if ((t.inside_of is not None or raised) and dets[i].bottom_m <= 1e-6 or short) and name in tracked_h:
                # its bottom is hidden by the walls (or what it was let go onto is hidden by it: a
                # plate under the mug set on it): where its height puts it, below the visible top
                h = tracked_h[name]
                t.bottom_m = max(0.0, dets[i].top_m - h)
                t.half_extents[2] = 0.5 * h
                t.position[2] = plane.z_at(t.position[:2]) + t.bottom_m + 0.5 * h

        # an object seen only in parts at the border, each a rival for it alone: confirmed where it was
        pieces = self._pieces_where_tracked(C, dets, assoc, matched)
        for name, parts in pieces.items():
            log.debug("perception: %s seen in %d parts at the border, each a rival for it alone, at %s: kept where "
                      "it was", name, len(parts), [_r(dets[i].position) for i in parts])
            self.tracks[name].last_seen_s = stamp
            self.tracks[name].seen_now = True
        in_pieces = {i for parts in pieces.values() for i in parts}

        # ---- holding (a release noticed now is looked for in this very observation)
        holding_rel = self._update_holding(proprio, stamp)
        if holding_rel is not None and hanging_points is not None:
            self._read_hang(holding_rel[0], hanging_points, proprio)

        # released objects (or ones seen inside a container before) not seen on their own: inside a
        # container segment where the hand let them go (where they were seen)? Those let go first:
        # what stands where the hand just opened is what it let go, on whatever was there before
        # (a butter let go onto a cream cheese box in a basket: the box's own face is hidden now)
        # (a container seen in part at the image border is looked into where its track puts it)
        in_part = [as_tracked[k] if d.truncated and k in matched else d for k, d in enumerate(dets)]
        for name, t in sorted(self.tracks.items(), key=lambda kv: kv[1].released_s is None):
            if t.seen_now or t.held or (t.released_s is None and t.inside_of is None):
                continue
            seen_top = None if t.released_s is not None else _seen_top(t)
            hit = _released_inside(t, cloud, heights, in_part, [idx for _, idx in clusters], sensors,
                                   self._other_footprints(name), tracked_top_m=seen_top)
            if hit is None:
                continue
            k, position, conf, points, cams, face_top = hit
            bottom = float(position[2] - t.half_extents[2] - plane.z_at(position[:2]))
            if t.released_s is None and t.confidence >= cfg.relations.min_confidence \
                    and bottom > t.bottom_m + CONTENT_RISE_M:
                log.debug("perception: %s, seen inside %s resting %.3f m up, found %.3f m up: not it (kept)",
                          name, t.inside_of, t.bottom_m, bottom)
                continue
            t.position, t.bottom_m = position, bottom
            t.position[2] = plane.z_at(position[:2]) + t.bottom_m + t.half_extents[2]
            t.var_xy = max(dets[k].position_std_m, CONTAINER_WALL_M / 2.0) ** 2
            t.confidence, t.points, t.cameras, t.last_seen_s = conf, points, cams, stamp
            t.seen_now, t.face_top_m = True, face_top
            # inside the container that segment was named as, else the one it was inside before;
            # a segment named nothing (the basket with a can standing out of it, ambiguous) keeps
            # the object let go, so the next look searches that segment for it again (LIBERO-10
            # task 0: found there once, then lost for good: no longer let go, inside nothing)
            t.inside_of = next((n for i, n in matched.items() if i == k), t.inside_of)
            if t.inside_of is not None:
                t.released_s = None
        # ... or lying on a fixture's ramp where the hand let them go (a bottle on the wine rack);
        # still let go, so the next look searches the ramp for them again
        for name, t in self.tracks.items():
            if not (t.seen_now or t.held or t.released_s is None or t.placed_xy is None):
                self._leant_where_let_go(name, t, full_cloud, plane, stamp, sensors)
        t3 = time.perf_counter()

        # ---- remembered: seen since its release, hidden now behind something nearer
        remembered: dict[str, tuple[str, ...]] = {}
        for name, t in self.tracks.items():
            if t.seen_now or t.held or t.released_s is not None or stamp - t.last_seen_s > REMEMBER_S:
                continue
            occluded_in = _occluded_in(t, frames)
            if occluded_in:
                remembered[name] = occluded_in

        # ---- entities
        entities: list[dict] = []
        geo: dict[str, dict] = {}
        for name in names:
            t = self.tracks.get(name)
            if t is None or not (t.seen_now or t.held or name in remembered):
                continue
            if t.held:
                ent = self._held_entity(t, proprio, holding_rel[1] if holding_rel else 0.0)
            else:
                extra = {"inside_of": t.inside_of} if t.inside_of else {}
                if name in self.leant:  # lying on a fixture's ramp: its box is its look's, upright
                    extra.update(leant_on=self.leant[name][0], tilt_rad=_r(self.leant[name][1], 4))
                if t.open_depth_m >= OPEN_DEPTH_REPORT_M:  # an open container: how deep its inside is
                    extra["open_depth_m"] = _r(t.open_depth_m)
                conf = t.confidence
                if name in remembered:
                    extra.update(remembered=True, occluded_in=list(remembered[name]), last_seen_s=_r(t.last_seen_s, 6))
                    conf *= REMEMBERED_CONFIDENCE
                std = math.sqrt(t.predicted_var(stamp, cfg))
                extra.update(self._body_attributes(name, t.position, _pose(t.position, t.yaw), t.body, std))
                if t.top_knob is not None:  # a knob on its top: where, how high, how wide (world, m)
                    k = np.asarray(t.top_knob, dtype=float)
                    top = float(t.position[2] + t.half_extents[2])
                    extra.update(top_knob_xy=_r(self._top_knob_xy(t)), top_knob_z_m=_r(top + float(k[2])),
                                 top_knob_radius_m=_r(float(k[3])), top_knob_base_z_m=_r(top - float(k[4])))
                    if math.isfinite(float(k[5])):
                        a = float(k[5]) + t.yaw
                        extra["top_knob_axis_xy"] = _r([math.cos(a), math.sin(a)])
                ent = self._entity(name, "object", t.position, t.yaw, t.half_extents, t.shape, t.colour_rgb,
                                   conf, std, math.sqrt(t.var_yaw), t.points, () if name in remembered else t.cameras,
                                   evidence_paths, source="remembered" if name in remembered else "perceived",
                                   extra=extra or None)
                geo[name] = _geo(t.position, t.yaw, t.half_extents, t.shape, t.bottom_m, plane, std)
                geo[name]["inside_of"] = t.inside_of
            entities.append(ent)
        # a look-alike left unknown stays a rival where it stood while the arm hides it (the
        # next observation drops it where a segment stands there again: carry_over)
        self.glimpses += [Glimpse.of_detection(dets[i]) for i in sorted(contested) if i not in matched and i not in in_pieces]
        k = 0
        for i, det in enumerate(dets):
            if i in matched or i in in_pieces:
                continue
            name = f"unknown_{k}"
            k += 1
            conf = _detection_confidence(det) * (0.5 if i in assoc.ambiguous else 1.0)
            entities.append(self._entity(name, "unknown", det.position, det.yaw, det.half_extents, det.shape,
                                         det.colour_rgb, conf, det.position_std_m, det.yaw_std_rad, det.points,
                                         det_cams[i], evidence_paths, source="perceived",
                                         extra={"ambiguous": i in assoc.ambiguous,
                                                **self._body_attributes(name, det.position, np.eye(4), det.body,
                                                                        det.position_std_m)}))
            geo[name] = _geo(det.position, det.yaw, det.half_extents, det.shape, det.bottom_m, plane,
                             det.position_std_m)
        for ent in entities:
            if ent["attributes"]["confidence"] < cfg.fusion.min_confidence and ent["kind"] == "object":
                ent["kind"] = "unknown"
        supports: dict[str, dict] = {}
        for look in self.fixtures:
            if look.name in self.fixture_tracks:
                ent, supports[look.name] = self._fixture_entity(look, plane, stamp)
                entities.append(ent)
                entities.extend(self._drawer_entities(look, plane, stamp))
                for comp, box in self._compartment_entities(look, plane, stamp):
                    entities.append(comp)
                    supports[comp["name"]] = box
                room = self._inside_entity(look, plane, stamp)
                if room is not None:
                    entities.append(room[0])
                    supports[room[0]["name"]] = room[1]
        entities.extend(self._robot_entities(proprio))

        relations = self._relations(geo, region_list, holding_rel, supports)
        relations += [{"subject": name, "relation": "leant_on", "object": fixture, "confidence": _r(conf, 3)}
                      for name, (fixture, _, conf) in self.leant.items()]
        unseen = [n for n in names if not (n in self.tracks and (self.tracks[n].seen_now or self.tracks[n].held))
                  and n not in remembered]
        t4 = time.perf_counter()
        self.last_timing_ms = {"cloud": 1e3 * (t1 - t0), "detect": 1e3 * (t2 - t1), "associate": 1e3 * (t3 - t2),
                               "relations": 1e3 * (t4 - t3), "total": 1e3 * (t4 - t0)}
        return {
            "stamp_s": _r(stamp, 6),
            "frame": "world",
            "entities": entities,
            "relations": relations,
            "proprioception": {
                "joint_positions": _r(proprio.joint_positions),
                "gripper_opening_m": _r(proprio.gripper_opening_m, 5),
                "gripper_effort_n": _r(proprio.gripper_effort_n, 3),
                "wrist_force_n": None if proprio.wrist_force_n is None else _r(proprio.wrist_force_n, 3),
            },
            "unseen": unseen,
            "remembered": sorted(remembered),
            "support_plane": {"normal": _r(plane.normal, 5), "offset_m": _r(plane.offset_m, 5), "fitted": plane.fitted},
            **({"references": {n: r.to_dict(dets) for n, r in self.last_references.items()}}
               if self.last_references else {}),
            **({"viewer": {"right_xy": _r(self.viewer_right_xy, 5)}} if self.viewer_right_xy is not None else {}),
        }

    # ------------------------------------------------------------------ fixtures

    def _perceive_fixtures(self, cloud: Cloud, heights: np.ndarray, plane: Plane,
                           stamp: float) -> tuple[Cloud, np.ndarray, list[Detection]]:
        """Find the declared fixtures in ``cloud`` (every height up to :meth:`fixture_ceiling_m`),
        update their tracks, and return the object cloud (points under
        ``workspace.max_height_m``, or over a fixture's footprint, minus the fixtures' own
        points), its heights, and one pseudo-detection per tracked fixture (its place patch,
        for stacking). Class docstring; :mod:`~phyagentos.perception.fixtures`."""
        cfg = self.config
        missing = [f for f in self.fixtures if f.name not in self.fixture_tracks]
        for name, sighting in detect_fixtures(cloud, heights, missing, cfg).items():
            log.info("perception: fixture %s at %s, top %.3f m (size error %.2f)", name, _r(sighting.position),
                     sighting.top_m, sighting.error)
            self.fixture_tracks[name] = (sighting, stamp, 1.0 - sighting.error / 6.0)
        p = cloud.points
        keep = heights < cfg.workspace.max_height_m
        own = np.zeros(len(cloud), dtype=bool)
        dets = []
        self.knob_readings = {}
        self.drawer_readings = {}
        self.door_readings = {}
        self._mouths = []
        self._rooms = []
        for look in self.fixtures:
            if look.name not in self.fixture_tracks:
                continue
            s = self.fixture_tracks[look.name][0]
            if look.knob is not None:  # read in every observation; its points are the fixture's own
                reading = knob_reading(p, heights, look.knob, s.position[:2], s.turn)
                if reading is not None:
                    self.knob_readings[look.name] = reading
                axis = look.knob.axis_xy(s.position[:2], s.turn)
                own |= ((np.linalg.norm(p[:, :2] - axis, axis=1) <= KNOB_RADIUS_M)
                        & (heights <= look.knob.top_m + FIXTURE_MARGIN_M))
            if look.door is not None and look.root is not None:  # read in every observation; the slab is its own
                origin, yaw = look.root.pose(s.position, s.yaw, s.turn, s.top_m)
                reading = door_reading(p, look.door, origin, yaw)
                if reading is not None:
                    self.door_readings[look.name] = reading
                    self.door_seen[look.name] = (reading[0], stamp)
                q_door = reading[0] if reading is not None else (self.door_seen.get(look.name) or (None,))[0]
                if q_door is not None:
                    own |= door_points(p, look.door, origin, yaw, q_door, margin_m=DOOR_OWN_MARGIN_M)
            contents = np.zeros(len(cloud), dtype=bool)
            if look.inside is not None and look.root is not None:  # what stands behind the door rests on its floor
                origin, yaw = look.root.pose(s.position, s.yaw, s.turn, s.top_m)
                centre_i, half_i, yaw_i, floor_z, roof_z, mouth_i = look.inside.world(origin, yaw)
                self._rooms.append((centre_i, half_i, yaw_i, floor_z, roof_z, mouth_i))
                local_i = _in_frame(p[:, :2], centre_i, yaw_i)
                contents |= (np.all(np.abs(local_i) <= np.maximum(half_i - FIXTURE_MARGIN_M, 0.0), axis=1)
                             & (p[:, 2] > floor_z + FIXTURE_MARGIN_M) & (p[:, 2] < roof_z - FIXTURE_MARGIN_M))
                hz_i = max(0.5 * (floor_z - plane.z_at(centre_i)), 1e-3)
                dets.append(Detection(np.array([centre_i[0], centre_i[1], floor_z - hz_i]), yaw_i,
                                      np.array([half_i[0], half_i[1], hz_i]), "box", np.zeros(3), np.zeros(3), 0, 0,
                                      FIXTURE_STD_M, math.pi, 1.0, 0.0,
                                      hidden_above_m=min(ROOM_LIP_HIDES_M, max(0.0, roof_z - floor_z))))
            for drawer in look.drawers:  # read in every observation; what stands out of the body is the fixture's
                reading = drawer_reading(p, heights, drawer, s.position[:2], s.turn)
                if reading is not None:
                    self.drawer_readings[(look.name, drawer.name)] = reading
                    self.drawer_seen[(look.name, drawer.name)] = (reading[0], stamp)
                    walls = self._drawer_points(p, heights, drawer, s, reading[0])
                    own |= walls
                    if reading[0] >= DRAWER_OPEN_SUPPORT_M:  # what stands in it rests on its floor, and is not the body's
                        mid, half, yaw = self._drawer_floor(drawer, s, reading[0])
                        pos = np.array([mid[0], mid[1], plane.z_at(mid) + half[2]])
                        dets.append(Detection(pos, yaw, half, "box", np.zeros(3), np.zeros(3), 0, 0, DRAWER_SIGMA_M,
                                              math.pi, 1.0, 0.0))
                        contents |= self._drawer_inside(p, heights, drawer, s, reading[0]) & ~walls
                        c0, u, v = drawer.frame(s.position[:2], s.turn)
                        self._mouths.append((c0, u, v, -DRAWER_CARCASS_M + FIXTURE_MARGIN_M,
                                             drawer.half_width_m - DRAWER_WALL_M, drawer.height_m - DRAWER_FLOOR_M))
            for comp in look.compartments:  # what stands in a compartment rests on its floor, and is not the body's
                centre_c, half_c = comp.box(s.position[:2], s.turn)
                inner = np.maximum(half_c - COMPARTMENT_WALL_M, 0.0)
                contents |= (np.all(np.abs(p[:, :2] - centre_c) <= inner, axis=1)
                              & (heights > comp.height_m + FIXTURE_MARGIN_M))
                hz_c = max(0.5 * comp.height_m, 1e-3)
                dets.append(Detection(np.array([centre_c[0], centre_c[1], plane.z_at(centre_c) + hz_c]), 0.0,
                                      np.array([half_c[0], half_c[1], hz_c]), "box", np.zeros(3), np.zeros(3), 0, 0,
                                      FIXTURE_STD_M, math.pi, 1.0, 0.0))
            local = _in_frame(p[:, :2], s.position[:2], s.yaw)
            over = np.all(np.abs(local) <= s.half_extents[:2] + FIXTURE_EDGE_M, axis=1)
            keep |= over
            centre, half, surface = look.place_patch(s.position[:2], s.half_xy_world, s.turn)
            on_patch = np.all(np.abs(p[:, :2] - centre) <= half, axis=1)
            top = look.size_m[2]  # the model's top (the sighting's may include what stands on it)
            limit = np.where(on_patch, min(surface, top), top) + FIXTURE_MARGIN_M
            # the fixed parts beyond the body the look was fitted to (the rack's base and front bar,
            # 5 cm proud of its racks) are its own too
            model = look.in_model(p[:, :2], s, edge_m=FIXTURE_MODEL_EDGE_M)
            own |= (over | model) & (heights <= limit) & ~contents
            hz = max(0.5 * surface, 1e-3)
            pos = np.array([centre[0], centre[1], plane.z_at(centre) + hz])
            dets.append(Detection(pos, 0.0, np.array([half[0], half[1], hz]), "box", np.zeros(3), np.zeros(3), 0, 0,
                                  FIXTURE_STD_M, math.pi, 1.0, 0.0))
        keep &= ~own
        return cloud.select(keep), heights[keep], dets

    def _seen_cut(self, det: Detection, cloud: Cloud, heights: np.ndarray, index: np.ndarray,
                  frames: Sequence[CameraFrame], strides: Sequence[int]) -> Detection:
        """``det`` (segment ``index`` of ``cloud``) with where it is cut off: by the image
        border (:func:`~phyagentos.perception.truncation.cut_direction`), else by the cabinet's
        body (:meth:`_cut_by_carcass`, ``cut_by_body``) or a room's walls (:meth:`_cut_by_room`,
        ``cut_by_body``); unchanged when none cuts it."""
        cut = cut_direction(cloud, index, frames, strides)
        if cut is not None:
            return replace(det, cut_direction=cut)
        cut = self._cut_by_carcass(cloud.points[index], heights[index])
        if cut is not None:
            return replace(det, cut_direction=cut, cut_by_body=True)
        cut = self._cut_by_room(cloud.points[index])
        return det if cut is None else replace(det, cut_direction=cut, cut_by_body=True, cut_by_room=True)

    def _cut_by_room(self, points: np.ndarray) -> np.ndarray | None:
        """Where a segment standing in the room behind a fixture's door goes on out of sight, or
        None: the room's roof and walls hide all but what faces its mouth, so what stands in it
        is seen only from there, its depth into the room a lower bound (a mug at the back of
        LIBERO's microwave, seen from its mouth, shows its front, 3.5 of its 10.4 cm). Cut when
        at least half of its ``points`` (N, 3) world m lie over the room's footprint between its
        floor and its roof; the (2,) world unit vector points into the room (against its mouth)."""
        for centre, half, yaw, floor_z, roof_z, mouth in self._rooms:
            local = _in_frame(points[:, :2], centre, yaw)
            inside = (np.all(np.abs(local) <= half, axis=1) & (points[:, 2] > floor_z) & (points[:, 2] < roof_z))
            if points.shape[0] and float(np.mean(inside)) >= 0.5:
                return -np.asarray(mouth, dtype=float)
        return None

    def _cut_by_carcass(self, points: np.ndarray, heights: np.ndarray) -> np.ndarray | None:
        """Where a segment in an open drawer goes on into the cabinet's body, or None: the
        body's points are the fixture's own, so what stands in the drawer behind the body's
        front is cut off there as the image border cuts (:mod:`~phyagentos.perception.truncation`;
        a bowl at the back of LIBERO's open top drawer was seen 6.4 of its 11.3 cm across and
        named at 0.08-0.45). Cut when :data:`CARCASS_CUT_MIN_POINTS` of its ``points`` (N, 3)
        world m (``heights`` (N,) m above the support) or more lie within
        :data:`CARCASS_CUT_BAND_M` in front of the body's front between the drawer's side walls,
        :data:`CARCASS_CUT_RISE_M` or more above its floor (a thing standing in it, not a sliver
        of the floor); the (2,) world unit vector is the drawer's axis into the body."""
        for c0, u, v, front, half_width, floor in self._mouths:
            rel = points[:, :2] - c0
            along, across = rel @ u, rel @ v
            at = ((along >= front) & (along <= front + CARCASS_CUT_BAND_M) & (np.abs(across) <= half_width)
                  & (heights >= floor + CARCASS_CUT_RISE_M))
            if int(np.count_nonzero(at)) >= CARCASS_CUT_MIN_POINTS:
                return -np.asarray(u, dtype=float)
        return None

    @staticmethod
    def _drawer_points(p: np.ndarray, heights: np.ndarray, drawer: DrawerLook, s: FixtureSighting,
                       opening: float) -> np.ndarray:
        """(N,) bool: the points of ``p`` (N, 3) world m (``heights`` (N,) m above the support)
        on the walls of ``drawer`` of sighting ``s`` standing ``opening`` m out: within its box
        (across its width plus :data:`FIXTURE_EDGE_M`, from its bottom (:meth:`DrawerLook.bottom_m`)
        less :data:`FIXTURE_MARGIN_M` up to its top plus :data:`FIXTURE_MARGIN_M`, from inside its
        shut handle out to its handle's outer face plus :data:`FIXTURE_MARGIN_M`), its front and
        handle (:data:`DRAWER_FRONT_M` inward from the handle's face), its sides
        (:data:`DRAWER_WALL_M` inward) and its floor (:data:`DRAWER_FLOOR_M` below the handle's
        centre and lower). What stands inside it (a bowl in an open drawer) is not the fixture's,
        nor what lies under it (a plate on the table under LIBERO's open top drawer, its bottom
        15.5 cm up: with no floor to the box, the plate's rim under it went with the drawer and
        the rest of the plate was named at 0.27, LIBERO-PRO's ``libero_spatial_swap`` task 4)."""
        c0, u, v = drawer.frame(s.position[:2], s.turn)
        rel = p[:, :2] - c0
        along, across = rel @ u, rel @ v
        face = opening + drawer.face_m
        box = ((np.abs(across) <= drawer.half_width_m + FIXTURE_EDGE_M)
               & (heights <= drawer.top_m + FIXTURE_MARGIN_M)
               & (heights >= drawer.bottom_m - FIXTURE_MARGIN_M)
               & (along >= drawer.travel_m[0] - DRAWER_WINDOW_M) & (along <= face + FIXTURE_MARGIN_M))
        walls = ((along >= face - DRAWER_FRONT_M) | (np.abs(across) >= drawer.half_width_m - DRAWER_WALL_M)
                 | (heights <= drawer.height_m - DRAWER_FLOOR_M))
        return box & walls

    @staticmethod
    def _drawer_inside(p: np.ndarray, heights: np.ndarray, drawer: DrawerLook, s: FixtureSighting,
                       opening: float) -> np.ndarray:
        """(N,) bool: the points of ``p`` (N, 3) world m (``heights`` (N,) m above the support)
        over the part of ``drawer`` (of sighting ``s``, ``opening`` m out) that stands out of
        the body: between its side walls, from :data:`FIXTURE_MARGIN_M` in front of the body's
        front (:data:`DRAWER_CARCASS_M` behind the shut handle's centre; the front's own face,
        the rail over the drawer, stays the body's: kept, it joined the bowl into a segment
        that looked like nothing) to its front wall, above its floor. The body's footprint is
        measured with the drawers shut and reaches past the body's front to the handles; a bowl
        at the back of an open drawer stands in that margin and is no part of the body."""
        c0, u, v = drawer.frame(s.position[:2], s.turn)
        rel = p[:, :2] - c0
        along, across = rel @ u, rel @ v
        return ((np.abs(across) <= drawer.half_width_m - DRAWER_WALL_M)
                & (along >= -DRAWER_CARCASS_M + FIXTURE_MARGIN_M)
                & (along <= opening + drawer.face_m - DRAWER_FRONT_M)
                & (heights > drawer.height_m - DRAWER_FLOOR_M))

    @staticmethod
    def _drawer_floor(drawer: DrawerLook, s: FixtureSighting, opening: float, *,
                      exposed: bool = False, above_m: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
        """The floor of ``drawer`` (of sighting ``s``) standing ``opening`` m out as a box
        ``(centre (2,) world m, half extents (3,) m, yaw rad)`` whose top is the floor
        (:data:`DRAWER_FLOOR_M` below the handle's centre, m above the support): across the
        drawer between its side walls (:data:`DRAWER_WALL_M`) and along its axis from behind its
        front (:data:`DRAWER_FRONT_M` inward from the handle's face) back to the body's back face
        (``back_m`` behind the body's centre, shut). A pseudo-detection for stacking (a bowl in
        an open drawer rests on its floor, not on the table under it: its box would reach down
        to the table and look like nothing declared) and the landmark of "in the top drawer".
        ``exposed``: only the part out of the body (from :data:`DRAWER_CARCASS_M` behind the shut
        handle's centre) and in front of the drawer above (``above_m``: the outer face of what
        stands over this drawer, m along its axis from its shut handle's centre: the handle of
        the drawer above as it stands), where a thing lowered from above passes; its front
        then the front's inside (:data:`DRAWER_FLOOR_FRONT_M` inward from the handle's face)."""
        c0, u, v = drawer.frame(s.position[:2], s.turn)
        front = opening + drawer.face_m - (DRAWER_FLOOR_FRONT_M if exposed else DRAWER_FRONT_M)
        back = float((np.asarray(s.position[:2]) - c0) @ u) - drawer.back_m + opening
        if exposed:
            back = max(back, -DRAWER_CARCASS_M, -math.inf if above_m is None else above_m)
        mid = c0 + u * 0.5 * (front + back)
        half_along = max(0.5 * (front - back), 0.005)
        half_across = max(drawer.half_width_m - DRAWER_WALL_M, 0.005)
        floor = max(drawer.height_m - DRAWER_FLOOR_M, 2e-3)
        yaw = math.atan2(float(u[1]), float(u[0]))
        if half_along >= half_across:
            half = np.array([half_along, half_across, 0.5 * floor])
        else:  # the footprint's long side is its x axis
            half, yaw = np.array([half_across, half_along, 0.5 * floor]), yaw + 0.5 * math.pi
        return mid, half, (yaw + 0.5 * math.pi) % math.pi - 0.5 * math.pi

    def _face_above(self, look: FixtureLook, drawer: DrawerLook, s: FixtureSighting) -> float | None:
        """Where the outer face of the handle of the drawer right above ``drawer`` (of ``look``,
        on sighting ``s``; the next higher one whose handle overlaps it across) stands, m along
        ``drawer``'s opening axis from its shut handle's centre: that drawer's last reading, else
        where the hand left it, else shut; ``None`` with no drawer above."""
        c0, u, v = drawer.frame(s.position[:2], s.turn)
        above = None
        for other in look.drawers:
            o0, ou, _ = other.frame(s.position[:2], s.turn)
            if (other.height_m > drawer.height_m and float(ou @ u) > 0.99
                    and abs(float((o0 - c0) @ v)) < drawer.half_width_m + other.half_length_m
                    and (above is None or other.height_m < above.height_m)):
                above = other
        if above is None:
            return None
        key = (look.name, above.name)
        known = self.drawer_readings.get(key) or self.drawer_felt.get(key) or self.drawer_seen.get(key)
        opening = float(known[0]) if known is not None else 0.0
        o0, ou, _ = above.frame(s.position[:2], s.turn)
        return float((o0 - c0) @ u) + opening + above.face_m

    def _drawer_entities(self, look: FixtureLook, plane: Plane, stamp: float) -> list[dict]:
        """One ``kind: articulation`` entity per drawer of ``look`` whose handle was read in this
        observation (module docstring): its box the floor of the drawer out of the body, its top
        the floor's surface (``attributes.support`` true: a place to set things into, "put the bowl
        in the top drawer"; turned with the drawer, its x axis the floor's longer side; ``walls_m``
        how far its walls rise over the floor), where the drawer stands
        :data:`DRAWER_OPEN_SUPPORT_M` or more out; else the handle where it stands.
        ``attributes`` the
        slide (``joint_type``, ``axis`` (3,) world unit opening direction, ``range_m`` [lo, hi],
        ``joint_position`` m out of shut, ``joint_position_std_m``) and the handle as its
        ``grasp`` (``approach`` and ``entry`` into the drawer, ``closing`` vertical). A drawer
        read before whose handle is hidden now (by the arm, or the bowl it carries) is reported
        where it was last read, ``source: remembered``, without ``joint_position``: a box to set
        things into, never a reading to judge an opening by; unless the hand pulled it open
        since that reading (:meth:`note_drawer_opened`): then it is reported where the hand
        felt it, ``joint_source: hand``, with ``joint_position_bound: lower``."""
        s = self.fixture_tracks[look.name][0]
        out = []
        for drawer in look.drawers:
            reading = self.drawer_readings.get((look.name, drawer.name))
            seen = self.drawer_seen.get((look.name, drawer.name))
            felt = self.drawer_felt.get((look.name, drawer.name))
            if reading is not None or felt is None or (seen is not None and seen[1] > felt[1]):
                felt = None  # a reading now, or one since the hand let go, says more
            if reading is None and seen is None and felt is None:
                continue
            opening, points = (reading if reading is not None else (felt[0], 0) if felt is not None
                               else (seen[0], 0))  # type: ignore[index]
            stop = self.drawer_stops.get((look.name, drawer.name))
            if stop is not None and reading is not None and abs(opening) > 2.0 * DRAWER_SIGMA_M:
                del self.drawer_stops[(look.name, drawer.name)]  # read out of shut: it was moved since
                stop = None
            pushed_home = stop is not None and reading is not None
            if pushed_home:
                opening = 0.0
            c0, u, v = drawer.frame(s.position[:2], s.turn)
            centre = c0 + u * opening
            ground = plane.z_at(centre)
            pos = [float(centre[0]), float(centre[1]), ground + drawer.height_m]
            yaw = math.atan2(float(v[1]), float(v[0]))
            half = [drawer.half_length_m, DRAWER_HANDLE_HALF_M, DRAWER_HANDLE_HALF_M]
            cp, sp = math.cos(DRAWER_APPROACH_PITCH_RAD), math.sin(DRAWER_APPROACH_PITCH_RAD)
            into = [-cp * float(u[0]), -cp * float(u[1]), -sp]
            closing = [-sp * float(u[0]), -sp * float(u[1]), cp]
            attrs = {"source": "perceived", "class": "drawer", "part_of": look.name, "drawer": drawer.name,
                     "confidence": 1.0, "position_std_m": _r(DRAWER_SIGMA_M, 5), "points": int(points),
                     "last_seen_s": _r(stamp, 6), "joint_type": "slide", "axis": _r([u[0], u[1], 0.0], 5),
                     "range_m": [_r(drawer.travel_m[0]), _r(drawer.travel_m[1])],
                     "joint_position": _r(opening),
                     "joint_position_std_m": _r(DRAWER_STOP_SIGMA_M if pushed_home else DRAWER_SIGMA_M, 5),
                     "grasp": {"position": _r(pos), "quat_wxyz": _r(_quat_yaw(yaw), 5), "size": _r(half),
                               "approach": _r(into, 5), "entry": _r(into, 5), "closing": _r(closing, 5)}}
            if pushed_home:  # read shut from the push that met its stop, the handle where a shut one is read
                attrs.update(at_stop="shut", stop_s=_r(stop, 6), handle_read_m=_r(reading[0]))  # type: ignore[index]
            if reading is None and felt is not None:  # hidden, pulled open since it was last read
                attrs.update(source="remembered", remembered=True, last_seen_s=_r(seen[1], 6) if seen else None,
                             joint_source="hand", joint_position_bound="lower", felt_s=_r(felt[1], 6))
            elif reading is None:  # its handle hidden now: where it was last read; no joint reading to judge
                assert seen is not None
                for key in ("joint_position", "joint_position_std_m"):
                    attrs.pop(key)
                attrs.update(source="remembered", remembered=True, last_seen_s=_r(seen[1], 6))
            box_pos, box_half, box_yaw = pos, half, yaw
            if opening >= DRAWER_OPEN_SUPPORT_M:  # its floor out of the body: a place things are set into
                mid, box_half, box_yaw = self._drawer_floor(drawer, s, opening, exposed=True,
                                                            above_m=self._face_above(look, drawer, s))
                box_pos = [float(mid[0]), float(mid[1]), plane.z_at(mid) + float(box_half[2])]
                # its walls hold what stands on its floor, as a compartment's do (the verifier's ``on``)
                attrs.update(support=True, walls_m=_r(max(0.0, drawer.top_m - 2.0 * float(box_half[2]))))
            out.append({"name": drawer_entity_name(look.name, drawer.name), "kind": "articulation",
                        "position": _r(box_pos), "quat_wxyz": _r(_quat_yaw(box_yaw), 5), "size": _r(box_half),
                        "attributes": attrs})
        return out

    def _compartment_entities(self, look: FixtureLook, plane: Plane, stamp: float) -> list[tuple[dict, dict]]:
        """One ``kind: fixture`` entity per compartment of tracked fixture ``look`` that the
        viewer's sides name (:func:`~phyagentos.perception.fixtures.compartment_sides`; none
        without a scene camera), with the box for :meth:`_relations`: named
        ``<fixture>_<side>_compartment``, its box the compartment's footprint from its floor down
        to the support (its top the floor's surface: ``attributes.support`` true, a place to set
        things into, "in the back compartment of the caddy"; ``part_of`` the fixture,
        ``compartment`` the side, ``walls_m`` how far its walls rise over its floor: the fixture's
        top in its look less the floor). It stands where the fixture does (``source`` and
        ``last_seen_s`` the fixture's). What stands in it is perceived as an object
        (:meth:`_perceive_fixtures` keeps the points inside its walls)."""
        if not look.compartments or self.viewer_right_xy is None:
            return []
        s, seen_s, conf = self.fixture_tracks[look.name]
        boxes = [c.box(s.position[:2], s.turn) for c in look.compartments]
        sides = compartment_sides([centre - s.position[:2] for centre, _ in boxes], self.viewer_right_xy)
        now = seen_s == stamp
        out = []
        for comp, (centre, half), side in zip(look.compartments, boxes, sides):
            if side is None:
                continue
            ground = plane.z_at(centre)
            hz = 0.5 * comp.height_m
            pos = np.array([centre[0], centre[1], ground + hz])
            attrs = {"source": "perceived" if now else "remembered", "class": "compartment", "part_of": look.name,
                     "compartment": side, "support": True, "confidence": _r(min(1.0, max(0.0, conf)), 3),
                     "position_std_m": _r(FIXTURE_STD_M, 5), "last_seen_s": _r(seen_s, 6),
                     "walls_m": _r(max(0.0, float(look.size_m[2]) - comp.height_m))}
            if not now:
                attrs["remembered"] = True
            ent = {"name": compartment_entity_name(look.name, side), "kind": "fixture", "position": _r(pos),
                   "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": _r([half[0], half[1], hz]), "attributes": attrs}
            out.append((ent, _geo(pos, 0.0, np.array([half[0], half[1], hz]), "box", 0.0, plane, FIXTURE_STD_M)))
        return out

    def _inside_entity(self, look: FixtureLook, plane: Plane, stamp: float) -> tuple[dict, dict] | None:
        """The room behind a tracked fixture's door (``inside`` in its look), as a ``kind:
        fixture`` entity named :func:`~phyagentos.perception.door.inside_entity_name`, with the box
        for :meth:`_relations`: its footprint from its floor down to the support (its top the
        floor's surface: ``attributes.support`` true, a place to set things into, "in the
        microwave"; ``part_of`` the fixture, ``mouth`` (3,) world unit the outward normal of the
        door's side, ``roof_z_m`` the room's roof, world m, ``hinge_side`` +1 / -1 the side of the
        mouth, along the mouth turned +90 degrees, its door hangs from). It stands where the
        fixture does.
        What stands in it is perceived as an object (:meth:`_perceive_fixtures` keeps the points
        inside its walls); None without an inside."""
        if look.inside is None or look.root is None:
            return None
        s, seen_s, conf = self.fixture_tracks[look.name]
        origin, yaw = look.root.pose(s.position, s.yaw, s.turn, s.top_m)
        centre, half, yaw_i, floor_z, roof_z, mouth = look.inside.world(origin, yaw)
        hz = max(0.5 * (floor_z - plane.z_at(centre)), 1e-3)
        pos = np.array([centre[0], centre[1], floor_z - hz])
        now = seen_s == stamp
        attrs = {"source": "perceived" if now else "remembered", "class": "inside", "part_of": look.name,
                 "support": True, "confidence": _r(min(1.0, max(0.0, conf)), 3), "position_std_m": _r(FIXTURE_STD_M, 5),
                 "last_seen_s": _r(seen_s, 6), "mouth": _r([mouth[0], mouth[1], 0.0], 5), "roof_z_m": _r(roof_z)}
        if look.door is not None:  # which way across the mouth its door swings from (the hinge's side)
            hinge = look.door.hinge_xy(origin, yaw)
            across = np.array([-mouth[1], mouth[0]])
            attrs["hinge_side"] = 1.0 if float((hinge - centre) @ across) > 0 else -1.0
        if not now:
            attrs["remembered"] = True
        box = np.array([half[0], half[1], hz])
        ent = {"name": inside_entity_name(look.name), "kind": "fixture", "position": _r(pos),
               "quat_wxyz": _r(_quat_yaw(yaw_i), 5), "size": _r(box), "attributes": attrs}
        return ent, _geo(pos, yaw_i, box, "box", 0.0, plane, FIXTURE_STD_M)

    def _fixture_entity(self, look: FixtureLook, plane: Plane, stamp: float) -> tuple[dict, dict]:
        """The snapshot entity of a tracked fixture (``kind: fixture``; its box the place
        patch, its top the patch's surface; the perceived body in ``attributes.body``) and
        the patch's box for :meth:`_relations`."""
        s, seen_s, conf = self.fixture_tracks[look.name]
        centre, half, surface = look.place_patch(s.position[:2], s.half_xy_world, s.turn)
        hz = 0.5 * surface
        pos = np.array([centre[0], centre[1], plane.z_at(centre) + hz])
        now = seen_s == stamp
        attrs = {"source": "perceived" if now else "remembered", "class": look.cls,
                 "confidence": _r(min(1.0, max(0.0, conf)), 3),  # it stands where it was seen
                 "position_std_m": _r(FIXTURE_STD_M, 5), "points": int(s.points) if now else 0,
                 "last_seen_s": _r(seen_s, 6), "surface_m": _r(surface),
                 "body": {"position": _r(s.position), "yaw": _r(s.yaw), "size": _r(s.half_extents),
                          "top_m": _r(s.top_m), "turn": _r(s.turn)}}
        if look.root is not None:  # where its model's frame stands: the planning world puts its model there
            origin, yaw = look.root.pose(s.position, s.yaw, s.turn, s.top_m)
            attrs["body"]["root"] = {"position": _r(origin), "yaw": _r(yaw)}
        if look.lean is not None:  # a ramp: where a thing is let go leant onto it (world), and the lean
            xy, height, toward = look.lean.at(s.position[:2], s.turn)
            attrs["lean"] = {"position": _r([xy[0], xy[1], plane.z_at(xy) + height]), "toward_xy": _r(toward, 5),
                             "angle_rad": _r(look.lean.angle_rad, 5)}
        if not now:
            attrs["remembered"] = True
        if look.knob is not None:
            attrs.update(self._knob_attributes(look, s, plane))
        elif look.door is not None and look.root is not None:
            attrs.update(self._door_attributes(look, s))
        ent = {"name": look.name, "kind": "fixture", "position": _r(pos), "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
               "size": _r([half[0], half[1], hz]), "attributes": attrs}
        return ent, _geo(pos, 0.0, np.array([half[0], half[1], hz]), "box", 0.0, plane, FIXTURE_STD_M)

    def _door_attributes(self, look: FixtureLook, s: FixtureSighting) -> dict[str, Any]:
        """A fixture's door as the entity attributes of a hinge, its joint as the door's
        *opening* (rad, 0 shut, growing as it opens, whatever the model's sign: as a drawer's
        opening): ``joint_type``, ``anchor`` (3,) world m at the slab's mid-height, ``axis`` (3,)
        world unit (the door turns about it as it opens), ``range_rad`` [0, travel], the opening
        read in this observation (``joint_position`` rad, ``joint_position_std_rad``
        :data:`~phyagentos.perception.door.DOOR_SIGMA_RAD`; absent when not read now), or 0 from
        a push that met its shut stop (:meth:`note_door_stop`: ``at_stop: shut``, 1-sigma
        :data:`~phyagentos.perception.door.DOOR_STOP_SIGMA_RAD`), and ``door``: what a push along
        its sweep needs (world frame: ``shut_yaw_rad`` the direction hinge to free edge when
        shut, ``turn`` +1 / -1 the door's yaw per unit of opening, ``outer``, ``width_m``,
        ``thickness_m``, ``mid_m``, ``z_m`` [bottom, top] world m, ``handle_r_m``,
        ``handle_out_m``: :class:`~phyagentos.perception.door.DoorLook`)."""
        door = look.door
        assert door is not None and look.root is not None
        origin, yaw = look.root.pose(s.position, s.yaw, s.turn, s.top_m)
        hinge = door.hinge_xy(origin, yaw)
        z0, z1 = float(origin[2]) + door.z_m[0], float(origin[2]) + door.z_m[1]
        towards = 1.0 if door.open_rad > door.shut_rad else -1.0
        turn = door.sign * towards
        out: dict[str, Any] = {"joint_type": "hinge", "axis": [0.0, 0.0, turn],
                               "range_rad": [0.0, _r(abs(door.open_rad - door.shut_rad), 4)],
                               "anchor": _r([hinge[0], hinge[1], 0.5 * (z0 + z1)]),
                               "door": {"shut_yaw_rad": _r(door.door_yaw(door.shut_rad, yaw), 5), "turn": turn,
                                        "outer": door.outer, "width_m": _r(door.width_m),
                                        "thickness_m": _r(door.thickness_m), "mid_m": _r(door.mid_m),
                                        "z_m": [_r(z0), _r(z1)], "handle_r_m": (None if door.handle_r_m is None
                                                                               else _r(door.handle_r_m)),
                                        "handle_out_m": _r(door.handle_out_m)}}
        reading = self.door_readings.get(look.name)
        opening = None if reading is None else towards * (reading[0] - door.shut_rad)
        stop = self.door_stops.get(look.name)
        if stop is not None and opening is not None and abs(opening) > 2.0 * DOOR_SIGMA_RAD:
            del self.door_stops[look.name]  # read open: it was moved since
            stop = None
        if stop is not None:
            out.update(joint_position=0.0, joint_position_std_rad=DOOR_STOP_SIGMA_RAD, at_stop="shut",
                       stop_s=_r(stop, 6))
            if opening is not None:
                out["door_read_rad"] = _r(opening, 4)
        elif opening is not None:
            out.update(joint_position=_r(opening, 4), joint_position_std_rad=DOOR_SIGMA_RAD,
                       door_points=reading[1])  # type: ignore[index]
        return out

    def _knob_attributes(self, look: FixtureLook, s: FixtureSighting, plane: Plane) -> dict[str, Any]:
        """A fixture's knob as the entity attributes of a hinge (``joint_type``, ``anchor``
        (3,) and ``axis`` (3,) world m, ``range_rad``), the joint position read in this
        observation (``joint_position`` rad, ``joint_position_std_rad``; absent when the bar
        was not read) and the bar's upper part as its ``grasp`` (a box from above, the fingers
        closing across the bar: :mod:`phyagentos.primitives.affordance`)."""
        knob = look.knob
        assert knob is not None
        axis = knob.axis_xy(s.position[:2], s.turn)
        ground = plane.z_at(axis)
        out: dict[str, Any] = {"joint_type": "hinge", "axis": [0.0, 0.0, 1.0], "range_rad": list(knob.range_rad),
                               "anchor": _r([axis[0], axis[1], ground + 0.5 * knob.top_m])}
        reading = self.knob_readings.get(look.name)
        yaw = knob.bar_yaw(knob.range_rad[0], s.turn)
        if reading is not None:
            yaw = reading[0]
            out.update(joint_position=_r(knob.joint_position(yaw, s.turn), 4), joint_position_std_rad=KNOB_SIGMA_RAD,
                       knob_points=reading[1])
        half_len = max(KNOB_RADIUS_M - 0.02, KNOB_BAR_HALF_WIDTH_M)
        out["grasp"] = {"position": _r([axis[0], axis[1], ground + knob.top_m - 0.5 * KNOB_GRIP_DEPTH_M]),
                        "quat_wxyz": _r(_quat_yaw(yaw), 5), "size": [half_len, KNOB_BAR_HALF_WIDTH_M,
                                                                     0.5 * KNOB_GRIP_DEPTH_M],
                        "approach": [0.0, 0.0, -1.0], "closing": _r([-math.sin(yaw), math.cos(yaw), 0.0], 5)}
        return out

    # ------------------------------------------------------------------ spatial references

    def _glimpse_rivals(self, desc: ObjectDescriptor, det: Detection, look_cost: float, found: Sequence[Glimpse],
                        stamp: float) -> bool:
        """Whether a glimpse (:mod:`~phyagentos.perception.glimpse`) matches ``desc``'s look about
        as well as ``det`` (its sighting, at ``look_cost``) does, so that naming ``det`` would be a
        guess: the sighting is then left unknown, whatever track the name had (a track begun while
        the arm hid the glimpse is no better than a guess). ``found`` holds the glimpses seen now
        and those kept (:func:`~phyagentos.perception.glimpse.carry_over`), with the look-alike
        segments left unknown before whose place is hidden now. The object in the hand, and an
        object declared with a spatial reference (its relation picks it out), are named."""
        t = self.tracks.get(desc.name)
        if desc.where is not None or (t is not None and t.held):
            return False  # a spatial reference names it, not its look; or it is in the hand
        g = rival(look_cost, desc, found, self.config)
        if g is None:
            return False
        log.debug("perception: %s looks alike at %s (cost %.2f) and at a glimpse of %d points at %s: left unknown",
                  desc.name, _r(det.position), look_cost, g.points, _r(g.position))
        return True

    def _associate_parts_weighed(self, C: np.ndarray, dets: list[Detection],
                                 twins: Sequence[Sequence[int]] = ()) -> Association:
        """The association with a part cut by the image border (``truncated``) costing
        :data:`PART_COST` more than its look: a part is weaker evidence than a whole sighting
        and must never make a whole one ambiguous (a can's label at the border beside the can
        itself), while it still names what nothing whole explains (the plate half out of the
        frame) or tells look-alikes apart (the bowl on the cabinet, cut by the image's top,
        beside its twin in the drawer). The matches keep the look's own cost (``C``) for their
        confidence. ``twins``: the interchangeable groups (:meth:`_interchangeable`)."""
        cut = [i for i, d in enumerate(dets) if d.truncated]
        if not cut or C.size == 0:
            return associate(C, self.config, interchangeable=twins)
        weighed = C.copy()
        weighed[cut, :] += PART_COST
        a = associate(weighed, self.config, interchangeable=twins)
        return Association({i: (j, float(C[i, j]), margin) for i, (j, _, margin) in a.matches.items()}, a.ambiguous)

    def _pieces_where_tracked(self, C: np.ndarray, dets: list[Detection], assoc: Association,
                              matched: Mapping[int, str]) -> dict[str, list[int]]:
        """``{name: detection indices}``: the objects seen now only in parts cut by the image
        border, two or more, withheld as each other's rivals (``assoc.ambiguous``), each part
        admissible for the object (within the gate of ``C``, which admits a part only where
        the object is tracked, :meth:`_truncated_where_tracked`) and looking like nothing else
        more. They are pieces of one object, not look-alikes competing for its name: they
        confirm it where it was and never move it, as one part at the border does. The object
        is tracked at ``relations.min_confidence`` or more, not held nor let go since (those
        are found by the hand's rules). LIBERO-10 task 1 (generated scenes): the arm lifting
        the butter in front of the basket, which reaches the scene camera's border, cut its
        view in two (a 16 x 8 cm front strip, a 7.5 cm square at its far side), matched at
        costs 1.09 and 1.35: ambiguous, both left unknown, the basket unseen, and not
        remembered either (every spot looked at showed its own wicker, nothing nearer), so the
        place after it found no basket."""
        cfg = self.config
        out: dict[str, list[int]] = {}
        if C.size == 0 or not assoc.ambiguous:
            return out
        taken = set(matched.values())
        for j, desc in enumerate(self.declared):
            t = self.tracks.get(desc.name)
            if t is None or desc.name in taken or t.held or t.released_s is not None \
                    or t.confidence < cfg.relations.min_confidence:
                continue
            parts = [i for i in assoc.ambiguous if C[i, j] <= cfg.association.gate_cost]
            if len(parts) >= 2 and all(dets[i].truncated and int(np.argmin(C[i])) == j for i in parts):
                out[desc.name] = parts
        return out

    def track_positions(self, proprio: Proprioception) -> list[np.ndarray | None]:
        """Per declared object, where its track ties association: ``(3,)`` world m, its
        tracked position; the hand's (the tcp's, from ``proprio``) for one the hand holds that
        has a look-alike among the declared objects; None for one untracked, or held with no
        look-alike (a held thing seen on the table again is a slip, wherever it lies).

        A held look-alike is where the hand is, not anywhere, so the other keeps its name: with
        no position of its own, the held bowl of "the black bowl between the plate and the
        ramekin" tied its twin on the table (each as close by looks and track), the twin was
        left unknown from the lift on, and the bowl set on the plate was then named by neither
        (LIBERO-PRO's ``libero_spatial_lan`` task 0 init 0, a success LIBERO counts; five such
        false failures in 120 episodes of the libero_spatial families). Before, only
        look-alikes no reference tells apart (:meth:`_interchangeable`) were so placed."""
        out: list[np.ndarray | None] = []
        tcp = np.asarray(proprio.tcp_pose[:3, 3], dtype=float)
        for j, desc in enumerate(self.declared):
            t = self.tracks.get(desc.name)
            if t is None:
                out.append(None)
            elif not t.held:
                out.append(t.position)
            elif any(k != j and e.looks_like(desc) for k, e in enumerate(self.declared)):
                out.append(tcp)
            else:
                out.append(None)
        return out

    def _interchangeable(self) -> list[list[int]]:
        """Groups (indices into the declared objects) of two or more identical declared objects
        (:meth:`~phyagentos.perception.descriptors.ObjectDescriptor.looks_like`) none of which
        is declared with a spatial reference: which is which is the perceiver's to fix (by their
        tracks), not a request's (:func:`~phyagentos.perception.association.associate`)."""
        groups: list[list[int]] = []
        for j, d in enumerate(self.declared):
            if any(j in g for g in groups):
                continue
            g = [k for k, e in enumerate(self.declared) if e.looks_like(d)]
            if len(g) > 1 and all(self.declared[k].where is None for k in g):
                groups.append(g)
        return groups

    def _weak_elsewhere(self, name: str, det: Detection, conf: float, stamp: float,
                        placed: np.ndarray | None = None) -> bool:
        """A match whose look alone (``conf``: colour, size and shape, without the distance to
        the track) is too weak to report (below ``relations.min_confidence``), outside the
        innovation gate of ``name``'s confident track, which neither the hand holds nor let go
        since: it would restart the track where the weak match is and throw away where the
        object was seen well (a rim of the plate around a mug set on it, seen from above). The
        track is kept; it is reported only while something nearer hides it (``remembered``).
        An object that looks itself somewhere else was moved: its track restarts there.

        An object the hand let go (``placed``: (2,) world x, y m where it did; ``conf`` then the
        sighting's confidence with that place weighed in) is where it was let go, or near: a
        weak match more than :data:`RELEASE_REACH_M` from there is not it
        either (LIBERO-10 task 1: the cream cheese let go in the basket, whose walls hid it from
        the scene camera, was matched at confidence 0.23 to a segment 39 cm away at the table's
        edge, and the look for it inside the basket's segment never ran)."""
        t = self.tracks.get(name)
        threshold = self.config.relations.min_confidence
        if t is None or conf >= threshold:
            return False
        if placed is not None:
            return float(np.linalg.norm(det.position[:2] - placed)) > RELEASE_REACH_M
        if t.held or t.released_s is not None or t.confidence < threshold:
            return False
        return not t.within_gate(det, stamp, self.config)

    def _covered_where_tracked(self, C: np.ndarray, dets: list[Detection], xys: Mapping[int, np.ndarray],
                               stamp: float) -> np.ndarray:
        """``C`` with a covered detection (``Detection.covered``) admissible for a tracked object
        only where it may be that object: not :meth:`_covered_elsewhere` (``xys``: each covered
        detection's points by its index, (N, 2) world m). What shows of a support round what
        rests on it is judged on a relaxed look, so it is weighed only against the objects that may stand
        there; a look-alike confidently tracked elsewhere is no rival for it. LIBERO-10 task 4
        (development seed 502): the yellow and white mug let go on the right plate, the plate's
        rim split off under it and matched to the right plate at 0.90 and to the left plate,
        62 cm away and capped at the track's cost, at 1.31: ambiguous, both plates left
        unseen, and the mug's place judged on the right plate as remembered, its sigma grown."""
        out = C
        for i, det in enumerate(dets):
            if not det.covered:
                continue
            for j, desc in enumerate(self.declared):
                if out[i, j] < FORBIDDEN_COST and self._covered_elsewhere(desc.name, det, xys[i], stamp):
                    log.debug("perception: a covered sighting at %s lies away from %s's confident track: "
                              "not it", _r(det.position), desc.name)
                    if out is C:
                        out = C.copy()
                    out[i, j] = FORBIDDEN_COST
        return out

    def _covered_elsewhere(self, name: str, det: Detection, xy: np.ndarray, stamp: float) -> bool:
        """A covered sighting (``det.covered``: what shows of a support round what rests on it,
        its look judged with its size relaxed) of ``name`` that lies wholly off its confident
        track (at ``relations.min_confidence`` or more; neither held nor let go since): none of
        its points ``xy`` ((N, 2) world m) within the track's footprint grown by
        :data:`COVERED_WITHIN_M`, and outside the track's innovation gate. What shows round
        something set on a support overlaps where the support was (it may have been pushed a
        little: that sighting is fused); one nowhere near it is something else's part. LIBERO-10
        task 4 init 3: with the left plate hidden behind the held mug, the base of a red mug 39
        cm away, split off as a support under it, was named the plate (0.16), its track
        restarted there, and the mug was let go on the bare table."""
        t = self.tracks.get(name)
        if not det.covered or t is None or t.held or t.released_s is not None \
                or t.confidence < self.config.relations.min_confidence or len(xy) == 0:
            return False
        overlaps = bool(np.any(_footprint_margins(xy, t.position, t.yaw, t.half_extents, t.shape) >= -COVERED_WITHIN_M))
        return not (overlaps or t.within_gate(det, stamp, self.config))

    @staticmethod
    def _covered_within_track(t: Track, xy: np.ndarray) -> bool:
        """Whether the points ``xy`` (N, 2) world m of a covered sighting (``Detection.covered``:
        the part of ``t`` showing round what rests on it) lie within the track's footprint, grown
        by :data:`COVERED_WITHIN_M`, all but :data:`COVERED_OUTSIDE_FRACTION` of them."""
        if len(xy) == 0:
            return False
        inside = _footprint_margins(xy, t.position, t.yaw, t.half_extents, t.shape) >= -COVERED_WITHIN_M
        return float(np.mean(~inside)) <= COVERED_OUTSIDE_FRACTION

    def _part_within_track(self, t: Track, det: Detection, xy: np.ndarray, proprio: Proprioception) -> bool:
        """Whether ``det`` (its points ``xy``, (N, 2) world m) shows only part of the object of
        track ``t``, which stands where it was: ``t`` seen at least twice, neither held nor let
        go near here since (``placed_xy``); ``det`` narrower by more than :data:`PART_NARROWER_M`
        along an axis than both ``t`` and the object's declared look (the smallest whole size in
        its ``size_range_m``, else its ``size_m``; half extents compared sorted, so a box's axes
        need not agree) and wider than ``t`` along none; its points within the track's footprint
        (:meth:`_covered_within_track`); and the tcp more than :data:`PART_HAND_CLEAR_M` outside
        that footprint, or more than :data:`PART_HAND_ABOVE_M` above the track's top, the
        fingers squeezing nothing (:func:`_fingers_squeeze`). A part's centre lies off the
        object's towards what shows (by half of what is hidden), so fusing it would move a still
        object. An object declared without its three dimensions is never taken for a part (a
        track begun on too large a segment would otherwise never take the true size)."""
        if t.held or t.placed_xy is not None or t.observations < 2 or len(xy) == 0:
            return False
        desc = next((d for d in self.declared if d.name == t.name), None)
        whole = None if desc is None else (desc.size_range_m[0] if desc.size_range_m is not None else desc.size_m)
        if not isinstance(whole, (tuple, list)) or len(whole) != 3:
            return False
        seen = np.sort(np.asarray(det.half_extents[:2], dtype=float))
        known = np.sort(np.asarray(t.half_extents[:2], dtype=float))
        look = np.sort(0.5 * np.asarray(whole[:2], dtype=float))
        narrower = (known - seen > PART_NARROWER_M) & (look - seen > PART_NARROWER_M)
        if not (np.any(narrower) and np.all(seen - known <= PART_NARROWER_M)):
            return False
        if not Perceiver._covered_within_track(t, xy):
            return False
        hand = _footprint_margins(proprio.tcp_pose[:2, 3], t.position, t.yaw, t.half_extents, t.shape)
        if float(hand[0]) < -PART_HAND_CLEAR_M:
            return True
        top = float(t.position[2] + t.half_extents[2])
        return not _fingers_squeeze(proprio, self.config) and float(proprio.tcp_pose[2, 3]) > top + PART_HAND_ABOVE_M

    def _inside_where_let_go(self, name: str, det: Detection, placed: np.ndarray | None, cloud: Cloud,
                             heights: np.ndarray, dets: list[Detection], clusters, sensors: list[str]) -> bool:
        """Whether ``det``, matched to ``name`` more than :data:`RELEASE_REACH_M` from where the
        hand let it go (``placed``: (2,) world x, y m, :meth:`_release_point`; None: not let
        go), is not it because the object shows inside a container segment there
        (:func:`_released_inside`, looked for at ``placed``): what was just
        set in a basket is in the basket, whatever looks a little like it at the table's edge
        (LIBERO-10 task 1: the butter let go in the basket, its top seen between the walls from
        the wrist camera, was matched at confidence 0.53 to a 4.6 cm segment 38 cm away at the
        table's edge, so the look inside the basket never ran and the place was not judged).
        A can that rolled off shows nothing where it was let go: the match stands."""
        t = self.tracks.get(name)
        if placed is None or t is None or float(np.linalg.norm(det.position[:2] - placed)) <= RELEASE_REACH_M:
            return False
        at_release = replace(t, position=np.array([placed[0], placed[1], t.position[2]], dtype=float))
        return _released_inside(at_release, cloud, heights, dets, [idx for _, idx in clusters], sensors,
                                self._other_footprints(name)) is not None

    def _other_footprints(self, name: str) -> list[Footprint]:
        """The footprints and tops of the objects other than ``name`` perceived where they stand
        (tracked at ``relations.min_confidence`` or more, seen now, or found between a
        container's walls, whatever the confidence: a face is one object's), neither held nor
        let go since, and no container or support themselves (their short side under
        :data:`CONTAINER_MIN_SIDE_M`: a basket's or a plate's footprint holds what is set in or
        on it). The top: the face seen between a container's walls where it was found there,
        else its bottom plus its height."""
        threshold = self.config.relations.min_confidence
        return [(t.position[:2].copy(), t.half_extents[:2].copy(), float(t.yaw), t.shape,
                 _seen_top(t))
                for n, t in self.tracks.items()
                if n != name and not t.held and t.released_s is None
                and (t.confidence >= threshold or t.seen_now or t.face_top_m is not None)
                and 2.0 * float(min(t.half_extents[0], t.half_extents[1])) < CONTAINER_MIN_SIDE_M]

    def _hidden_base_where_let_go(self, C: np.ndarray, dets: list[Detection]) -> np.ndarray:
        """``C`` with the height of a detection standing on the plane taken as an upper bound
        for an object the hand let go (or last seen inside a container, or whose height is
        known from the hand since) where that object is: the detection's centre within the
        look's footprint radius plus :data:`HIDDEN_BASE_SLACK_M` and 3 sigma of the detection
        from the track's position (not the track's sigma, which a release makes wide).

        Its base may be hidden by a container's walls, with something under it that the
        cameras do not see either (LIBERO-10 task 0, development traces: a tomato sauce can
        let go into the basket stood on the alphabet soup lying in it; seen from the rim up
        and fitted down to the table, it was 18 cm tall for its look's 9.1 and named
        nothing). Only a measured height below the look's counts then; footprint, colour and
        shape count as ever. Once matched, the track puts its bottom its height below the
        seen top (the rules after association). The allowance lasts while the height is
        known: the can's next look, the basket unnamed, had gone to the soup hidden under it.
        """
        out = C
        for j, desc in enumerate(self.declared):
            t = self.tracks.get(desc.name)
            size = desc.size_vector()
            if t is None or t.held or size is None or (t.released_s is None and t.inside_of is None
                                                           and t.known_height_m is None):
                continue
            tallest = float(desc.size_range_m[1][2]) if desc.size_range_m is not None else float(size[2])
            reach = 0.5 * float(size[0]) + HIDDEN_BASE_SLACK_M  # not the track's sigma: a release is uncertain
            for i, det in enumerate(dets):
                if det.bottom_m > 1e-6 or 2.0 * float(det.half_extents[2]) <= tallest \
                        or float(np.linalg.norm(det.position[:2] - t.position[:2])) > reach + 3.0 * det.position_std_m:
                    continue
                half = det.half_extents.copy()
                half[2] = 0.5 * tallest
                if out is C:
                    out = C.copy()
                out[i, j] = float(cost_matrix([replace(det, half_extents=half)], [desc], self.config)[0, 0])
        return out

    def _not_on_itself(self, C: np.ndarray, dets: list[Detection]) -> np.ndarray:
        """``C`` with a detection inadmissible for an object tracked where it stands when it is
        something set on that object: the object not held nor let go since last seen, and either

        - resting on another segment (``bottom_m`` > 0), its footprint overlapping the
          object's (centres no farther apart than the object's larger and the detection's
          smaller horizontal half extent: a can let go onto the soup in the basket stood tilted,
          its lid's centre 3.5 cm off the soup's, LIBERO-10 task 0, development seed 509), its
          bottom no more than :data:`ON_ITSELF_MARGIN_M` below the object's tracked top; or
        - standing on the table, its centre within the object's tracked footprint (its larger
          horizontal half extent), not cut by the image border, its top above the object's top
          by more than :data:`ON_ITSELF_RISE` of the object's height (its height when the hand
          last let it go, else its track's), for an object with a solid top (an open
          container's contents may stand above its rim).

        Nothing lifts an object onto itself. LIBERO-10 task 0: the tomato sauce let go onto the
        alphabet soup standing in the basket shows the wrist camera, straight above, only its
        lid, grey like the soup's look. On generated scenes the upper part split off the stack
        went to the soup (its old release point lifting 0.26 to 1.00); in the bench's own
        episodes the whole stack, standing on the table and a can taller than the soup,
        went to it as a can whose base the walls hide (stage 6b). Either way the soup's track
        climbed onto the sauce, and at the next look both were lost."""
        out = C
        for j, desc in enumerate(self.declared):
            t = self.tracks.get(desc.name)
            if t is None or t.held or t.released_s is not None:
                continue
            height = float(t.known_height_m or 2.0 * float(t.half_extents[2]))
            top = float(t.bottom_m) + 2.0 * float(t.half_extents[2])
            reach = float(max(t.half_extents[0], t.half_extents[1]))
            solid = t.open_depth_m < OPEN_DEPTH_REPORT_M
            for i, det in enumerate(dets):
                away = float(np.linalg.norm(det.position[:2] - t.position[:2]))
                if det.bottom_m > 1e-6:
                    # resting on something, over the object's footprint (the footprints overlap)
                    on_it = away <= reach + float(min(det.half_extents[0], det.half_extents[1])) \
                        and det.bottom_m >= top - ON_ITSELF_MARGIN_M
                elif away > reach:
                    continue
                else:
                    det_top = float(det.bottom_m) + 2.0 * float(det.half_extents[2])
                    on_it = solid and not det.truncated and det_top > top + max(ON_ITSELF_MARGIN_M,
                                                                               ON_ITSELF_RISE * height)
                if not on_it:
                    continue
                if out is C:
                    out = C.copy()
                out[i, j] = FORBIDDEN_COST
        return out

    def _truncated_where_tracked(self, C: np.ndarray, dets: list[Detection],
                                 proprio: Proprioception | None = None) -> np.ndarray:
        """``C`` with a detection cut by the image border admissible for a tracked object only
        where part of that object is: its centre within the object's footprint radius (its
        look's, else its track's larger horizontal extent) plus 3 sigma of both positions.
        A part seen at the border confirms an object where it was and never moves it (the far
        edge of the table, seen by the wrist camera, is not the plate last seen 20 cm away, nor
        the can just let go into the basket); a held object is found by the hand's own rules,
        except one the hand lets go now (``proprio`` given), which is where the hand let it go
        (:meth:`_release_point`, with the release's sigma, :data:`RELEASE_SIGMA_M`).
        (A released object's track stands where the hand let it go.)"""
        out = C
        for i, det in enumerate(dets):
            if not det.truncated:
                continue
            for j, desc in enumerate(self.declared):
                t = self.tracks.get(desc.name)
                if t is None:
                    continue
                where, sigma = t.position[:2], math.sqrt(t.var_xy)
                if t.held:
                    where = None if proprio is None else self._release_point(desc.name, proprio)
                    if where is None:
                        continue
                    sigma = max(sigma, RELEASE_SIGMA_M)
                size = desc.size_vector()
                radius = 0.5 * float(size[0]) if size is not None else float(np.max(t.half_extents[:2]))
                reach = radius + 3.0 * (sigma + det.position_std_m)
                if float(np.linalg.norm(det.position[:2] - where)) > reach:
                    if out is C:
                        out = C.copy()
                    out[i, j] = FORBIDDEN_COST
        return out

    def _resolve_references(self, C: np.ndarray, dets: list[Detection], stamp: float) -> np.ndarray:
        """``C`` with each untracked object declared with a spatial reference admissible for
        the one detection its relation picks out (or for none).

        The other declared objects are associated first (without those objects); their matches
        named at :data:`LANDMARK_MIN_CONFIDENCE` or more (and tracks held at that confidence,
        seen in the last :data:`REMEMBER_S` s, not held) and the perceived fixtures (their bodies' footprints,
        topped by their place surfaces) are the landmarks. The
        candidates are the detections within the gate for the object that no other-looking
        object took. An unresolved reference leaves its untracked look-alikes unassociated as
        well (naming one "the other" would say which one is meant). Records the resolutions in
        :attr:`last_references`."""
        self.last_references = {}
        pending = [j for j, d in enumerate(self.declared) if d.where is not None and d.name not in self.tracks]
        if not pending or C.size == 0:
            return C
        cfg = self.config
        names = [d.name for d in self.declared]
        first_pass = C
        for j in pending:
            first_pass = forbid_except(first_pass, j, None)
        matches = associate(first_pass, cfg).matches
        taken = {i: j for i, (j, _, _) in matches.items()}
        landmarks: dict[str, Landmark] = {}
        for i, (j, cost, margin) in matches.items():
            d = dets[i]
            if match_confidence(cost, margin, cfg) * _detection_confidence(d) < LANDMARK_MIN_CONFIDENCE:
                continue  # named no better than a coin flip: what it would pick out is a guess
            landmarks[names[j]] = Landmark(names[j], d.position, d.half_extents, d.yaw, d.shape, d.bottom_m)
        for n, t in self.tracks.items():
            if (n not in landmarks and not t.held and t.released_s is None and stamp - t.last_seen_s <= REMEMBER_S
                    and t.confidence >= LANDMARK_MIN_CONFIDENCE):
                landmarks[n] = Landmark(n, t.position, t.half_extents, t.yaw, t.shape, t.bottom_m)
        for look in self.fixtures:  # a perceived fixture: its body's footprint, its top where things rest on it
            if look.name in self.fixture_tracks:
                s = self.fixture_tracks[look.name][0]
                top = look.place_height_m if look.place_height_m is not None else look.size_m[2]
                landmarks[look.name] = Landmark(look.name, s.position, np.array([s.half_extents[0], s.half_extents[1],
                                                                                  0.5 * top]), s.yaw, "box", 0.0)
                for drawer in look.drawers:  # an open drawer's inside, for "in the top drawer of the cabinet"
                    reading = self.drawer_readings.get((look.name, drawer.name))
                    if reading is not None and reading[0] >= DRAWER_OPEN_SUPPORT_M:
                        mid, half, yaw = self._drawer_floor(drawer, s, reading[0])
                        name = drawer_entity_name(look.name, drawer.name)
                        landmarks[name] = Landmark(name, np.array([mid[0], mid[1], s.position[2]]), half, yaw, "box",
                                                   0.0)
        chosen: dict[int, str] = {}
        for j in pending:
            desc = self.declared[j]
            alike = {k for k, d in enumerate(self.declared) if d.looks_like(desc)}
            # a look-alike already picked by its own reference is still a candidate here (the
            # left plate is one of the two plates "the right plate" is told from), never the pick
            cands = [i for i in range(len(dets)) if C[i, j] <= cfg.association.gate_cost
                     and (i not in taken or taken[i] in alike) and not dets[i].covered]
            res = resolve_reference(desc, cands, dets, landmarks, cfg, look_alikes=len(alike),
                                    table_centre_xy=self.table_centre_xy, viewer_right_xy=self.viewer_right_xy)
            if res.detection is not None and res.detection in chosen:
                res = ReferenceResolution(desc.name, res.relation, None,
                                          f"{res.reason}: the same detection as {chosen[res.detection]}'s",
                                          res.scores)
            self.last_references[desc.name] = res
            log.info("perception: %s %s %s: %s", desc.name, desc.where.relation if desc.where else "",
                     list(desc.where.of) if desc.where else [],
                     res.reason if res.detection is None else f"detection at {_r(dets[res.detection].position)}, "
                                                              f"{res.reason}")
            C = forbid_except(C, j, res.detection)
            if res.detection is not None:
                chosen[res.detection] = desc.name
            else:  # "the other one" is no better known than the one meant: untracked look-alikes wait too
                for k in alike - {j}:
                    if self.declared[k].where is None and self.declared[k].name not in self.tracks:
                        C = forbid_except(C, k, None)
        return C

    # ------------------------------------------------------------------ helpers

    def _look_height(self, name: str, height_m: float) -> float:
        """``height_m``, an object's tracked height (m), within the heights its declared look
        was seen whole at (``size_range_m``'s third column), where it declares them: a known
        object is as tall as its look, whatever odd sightings made of it (libero_spatial task 5's
        traces: a bowl picked off a ramekin was tracked 5.7 cm tall for its look's 5.05, so,
        set on a plate, it stood no higher than that and was taken to rest on the table)."""
        desc = next((d for d in self.declared if d.name == name), None)
        if desc is None or desc.size_range_m is None:
            return height_m
        lo, hi = desc.size_range_m[0][2], desc.size_range_m[1][2]
        return min(max(height_m, lo), hi)

    @staticmethod
    def _cameras_of(cloud: Cloud, heights: np.ndarray, det: Detection, sensors: list[str]) -> tuple[str, ...]:
        near = np.linalg.norm(cloud.points[:, :2] - det.position[:2], axis=1) < float(det.half_extents[:2].max()) + 0.005
        near &= heights < det.top_m + 0.01
        cams, counts = np.unique(cloud.camera[near], return_counts=True)
        return tuple(sensors[int(c)] for c, n in zip(cams, counts) if n >= 5)

    def _entity(self, name, kind, position, yaw, half, shape, colour, confidence, pos_std, yaw_std, points,
                cameras, evidence_paths, *, source: str, extra: dict | None = None) -> dict:
        attrs = {
            "source": source,
            "shape": shape,
            "colour_rgb": _r(colour, 3),
            "confidence": _r(min(1.0, max(0.0, confidence)), 3),
            "position_std_m": _r(pos_std, 5),
            "yaw_std_rad": _r(min(yaw_std, math.pi), 4),
            "points": int(points),
            "cameras": list(cameras),
            "evidence": [evidence_paths[c] for c in cameras if evidence_paths and c in evidence_paths],
        }
        if extra:
            attrs.update(extra)
        return {"name": name, "kind": kind, "position": _r(position), "quat_wxyz": _r(_quat_yaw(yaw), 5),
                "size": _r(half), "attributes": attrs}

    def _held_entity(self, t: Track, proprio: Proprioception, hold_conf: float) -> dict:
        T = proprio.tcp_pose @ (t.grasp_offset if t.grasp_offset is not None else np.eye(4))
        pos = T[:3, 3]
        yaw = math.atan2(T[1, 0], T[0, 0]) if t.grasp_offset is not None else t.yaw
        std = math.sqrt(t.var_xy + 0.005 ** 2)
        body = self._body_attributes(t.name, pos, T, t.body if t.grasp_offset is not None else None, std)
        ent = self._entity(t.name, "object", pos, yaw, t.half_extents, t.shape, t.colour_rgb,
                           hold_conf * max(t.confidence, 0.5), std, math.sqrt(t.var_yaw) + 0.1, 0, (), None,
                           source="proprioception", extra={"held": True, "last_seen_s": _r(t.last_seen_s, 6), **body,
                                                           **({} if t.hang_tcp is None else
                                                              {"hang_m": _r(float(np.linalg.norm(t.hang_tcp)), 4)}),
                                                           **({} if t.grasp_z_tcp is None else
                                                              {"grasp_z_tcp_m": _r(t.grasp_z_tcp, 4)})})
        return ent

    def _read_hang(self, name: str, points: np.ndarray, proprio: Proprioception) -> None:
        """Carry held track ``name`` where its base hangs (:mod:`~phyagentos.perception.hang`).

        A round body held by its rim (its track has a round body and its base's profile): the
        part of it below the fingers (``points`` (N, 3) world m, the hanging segments' points the
        cameras off the hand saw) moves its pose, in the tcp frame, by the shift of its fitted
        base from where the carried pose puts its axis. The shift since the grasp is kept
        (``Track.hang_tcp``) and reported as ``hang_m``."""
        t = self.tracks.get(name)
        if t is None or not t.held or t.body is None or t.grasp_offset is None or t.base_profile_m is None:
            return
        tcp = proprio.tcp_pose
        T = tcp @ t.grasp_offset
        shift = hang_offset(points, axis_xy=t.body.placed(T).axis_xy, profile=t.base_profile_m)
        if shift is None:
            return
        T[:2, 3] += shift
        t.grasp_offset = np.linalg.inv(tcp) @ T
        moved = tcp[:3, :3].T @ np.array([shift[0], shift[1], 0.0])
        t.hang_tcp = moved if t.hang_tcp is None else np.asarray(t.hang_tcp, dtype=float) + moved
        log.debug("perception: %s hangs %.4f m from its carried pose (%.4f m since the grasp)", name,
                  float(np.hypot(*shift)), float(np.linalg.norm(t.hang_tcp)))

    def _body_attributes(self, name: str, position: np.ndarray, T_obj: np.ndarray, body: RoundBody | None,
                         std: float) -> dict:
        """An object's round body and handle as entity attributes: ``axis_xy`` (2,) and
        ``handle_xy`` (2,) world (m; a unit vector) and ``body_radius_m`` (the round body's
        outline radius, m) when ``body`` (in the object's frame, the object's pose ``T_obj``
        (4, 4) world) is known, with ``handle_reach_m`` how far from the axis the handle reaches
        (m); and, for an object declared with
        ``handle_origin_m``, where its model's origin stands: ``origin_xy`` (2,) world, m, the
        axis that far towards the handle, with ``origin_std_m`` (1 sigma, m) -- the entity's
        centre ``position`` with the handle's offset added to its uncertainty when the handle
        was not seen (:mod:`phyagentos.perception.handle`)."""
        out: dict = {}
        seen = None if body is None else body.placed(T_obj)
        if seen is not None:
            out.update(axis_xy=_r(seen.axis_xy), handle_xy=_r(seen.handle_xy), body_radius_m=_r(seen.radius_m))
            if seen.reach_m is not None:
                out["handle_reach_m"] = _r(seen.reach_m)
        desc = next((d for d in self.declared if d.name == name), None)
        off = None if desc is None else desc.handle_origin_m
        if off is not None:
            if seen is not None:
                out.update(origin_xy=_r(seen.axis_xy + off * seen.handle_xy), origin_std_m=_r(std, 5))
            else:
                out.update(origin_xy=_r(np.asarray(position, float)[:2]), origin_std_m=_r(math.hypot(std, off), 5))
        return out

    def _robot_entities(self, proprio: Proprioception) -> list[dict]:
        T = proprio.tcp_pose
        q = np.empty(4)
        import mujoco  # quaternion of the tcp rotation (MuJoCo's own conversion)

        mujoco.mju_mat2Quat(q, np.ascontiguousarray(T[:3, :3]).flatten())
        src = {"source": "proprioception"}
        return [
            {"name": "tcp", "kind": "robot", "position": _r(T[:3, 3]), "quat_wxyz": _r(q, 5), "size": [0.0, 0.0, 0.0],
             "attributes": dict(src)},
            {"name": "gripper", "kind": "gripper", "position": _r(T[:3, 3]), "quat_wxyz": _r(q, 5),
             "size": [_r(proprio.gripper_opening_m, 5), 0.0, 0.0],
             "attributes": {**src, "opening_m": _r(proprio.gripper_opening_m, 5),
                            "effort_n": _r(proprio.gripper_effort_n, 3),
                            "wrist_force_n": None if proprio.wrist_force_n is None else _r(proprio.wrist_force_n, 3)}},
            {"name": self.robot_name, "kind": "robot", "position": [0.0, 0.0, 0.0], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
             "size": [0.0, 0.0, 0.0], "attributes": {**src, "joint_names": list(proprio.joint_names),
                                                     "joint_positions": _r(proprio.joint_positions)}},
        ]

    def _hand_evidence(self, t: Track, proprio: Proprioception):
        """The closed hand's :class:`~phyagentos.perception.relations.HoldingEvidence` that it
        holds track ``t`` (the gap matches its width, a bowl's wall, or a mug's handle's bar:
        ``holding.handle_bar_m``), or ``None``: no squeeze at that width, or ``t`` not held before
        and not last seen where the fingers closed (within ``holding.capture_radius_m`` of the
        tcp, its rim under the tcp, or its handle's grip point within half that)."""
        hc = self.config.holding
        tcp = proprio.tcp_pose[:3, 3]
        width = width_in_hand(t.half_extents, t.yaw, t.shape, proprio)
        wall = self._rim_wall(t)
        if wall is not None:  # an open container (a bowl, a mug) may be held by its wall: whichever the gap is nearer
            width = min((width, wall), key=lambda w: abs(w - 2.0 * proprio.gripper_opening_m))
        knob = None if t.top_knob is None else 2.0 * float(t.top_knob[3])
        if knob is not None:  # an object with a knob on top may be held by it (a moka pot): as the wall
            width = min((width, knob), key=lambda w: abs(w - 2.0 * proprio.gripper_opening_m))
        grip = self._handle_grip(t)
        if grip is not None:  # a mug may be held by its handle's bar, across it (motion.handle_grasp)
            width = min((width, hc.handle_bar_m), key=lambda w: abs(w - 2.0 * proprio.gripper_opening_m))
        ev = holding_evidence(proprio, width_m=width, baseline_n=self._baseline_n,
                              grasp_height_m=self._grasp_height_m, config=self.config)
        if ev.confidence <= 0.0:
            return None
        if not t.held:
            # capture: the object was last seen right under/between the fingers, or (held
            # by its wall) the tcp is on its rim
            dxy = float(np.linalg.norm(t.position[:2] - tcp[:2]))
            on_rim = wall is not None and width == wall and \
                abs(dxy - float(self._rim_radius(t))) <= hc.capture_radius_m / 2.0
            on_handle = grip is not None and width == hc.handle_bar_m and \
                float(np.linalg.norm(grip - tcp[:2])) <= hc.capture_radius_m / 2.0
            if dxy > hc.capture_radius_m and not on_rim and not on_handle:
                return None
        return ev

    @staticmethod
    def _handle_grip(t: Track) -> np.ndarray | None:
        """(2,) world m where a hand takes track ``t`` by its handle
        (:func:`~phyagentos.motion.handle_grasp.handle_grip_xy`), or None: no handle seen on it
        with its reach."""
        if t.body is None or t.body.reach_m is None:
            return None
        from phyagentos.motion.handle_grasp import handle_grip_xy  # noqa: PLC0415 - only when something may be held

        seen = t.body.placed(_pose(t.position, t.yaw))
        return handle_grip_xy(seen.axis_xy, seen.handle_xy, float(seen.reach_m))  # type: ignore[arg-type]

    def _hand_outweighs(self, name: str, det: Detection, conf: float, proprio: Proprioception) -> bool:
        """Whether the hand's evidence outweighs an association of ``det`` with ``name`` at
        confidence ``conf``: ``det`` lies outside the capture radius of the tcp, the closed hand
        squeezes something of ``name``'s width where ``name`` was last seen (:meth:`_hand_evidence`),
        and either the association is weak (below ``relations.min_confidence``, the least
        confidence at which a relation such as "on the table" is reported) or ``name`` is held
        already. A confident sighting elsewhere rules out a hand that has not held the object;
        an object held since it was picked does not leave a hand still closed on its width, so
        a confident sighting elsewhere is a look-alike. (A look-alike part of a fixture uncovered
        when the arm moves, e.g. a strip of libero_goal's stove the size of the cream cheese,
        was taken for the picked cream cheese at 0.23-0.35 and vetoed a hold LIBERO confirmed;
        on the randomised tabletop a blue distractor sphere in the blue region, seen at 0.75, was
        taken for the blue sphere still in the hand after the place's planning failed, and
        confirmed the sort: a false success, seed 30015.)"""
        t = self.tracks.get(name)
        if t is None or (conf >= self.config.relations.min_confidence and not t.held):
            return False
        if float(np.linalg.norm(det.position[:2] - proprio.tcp_pose[:2, 3])) <= self.config.holding.capture_radius_m:
            return False
        return self._hand_evidence(t, proprio) is not None

    def _leant_where_let_go(self, name: str, t: Track, cloud: Cloud, plane: Plane, stamp: float,
                            sensors: Sequence[str]) -> None:
        """Look for ``name`` (track ``t``, let go at ``t.placed_xy`` and not seen since) lying on the
        ramp of a perceived fixture with a lean (:mod:`~phyagentos.perception.lean`), in ``cloud``
        (every point, the fixtures' own included). Found, at ``relations.min_confidence`` or more,
        within the hold's capture radius plus its look's half length of where the hand let it go:
        its track moves to the centroid of what shows (seen now, still let go) and
        :attr:`leant` records the fixture, the tilt and the confidence. Else nothing changes."""
        cfg = self.config
        desc = next((d for d in self.declared if d.name == name), None)
        size = desc.size_vector() if desc is not None else None
        full = 2.0 * np.asarray(t.half_extents, float) if size is None else np.asarray(size, float)
        colour = t.colour_rgb if desc is None or desc.colour_rgb is None else np.asarray(desc.colour_rgb, float)
        best = None
        for look in self.fixtures:
            if look.lean is None or look.name not in self.fixture_tracks:
                continue
            s = self.fixture_tracks[look.name][0]
            crest_xy, height, toward = look.lean.at(s.position[:2], s.turn)
            crest = np.array([crest_xy[0], crest_xy[1], plane.z_at(crest_xy) + height])
            mask = on_ramp(cloud.points, crest, toward, look.lean.angle_rad,
                           (s.position[:2], s.yaw, s.half_extents[:2] + FIXTURE_EDGE_M))
            sight = find_leant(cloud, mask, toward_xy=toward)
            if sight is None or float(np.linalg.norm(sight.position[:2] - np.asarray(t.placed_xy, float))) > \
                    cfg.holding.capture_radius_m + 0.5 * float(full.max()):
                continue
            conf = leant_confidence(sight, length_m=float(full.max()), width_m=float(full[:2].max()),
                                    colour_rgb=colour, toward_xy=toward, slope_rad=look.lean.angle_rad,
                                    colour_scale_lab=cfg.association.colour_scale_lab,
                                    lightness_weight=cfg.association.lightness_weight)
            if conf >= cfg.relations.min_confidence and (best is None or conf > best[2]):
                best = (look.name, sight, conf)
        if best is None:
            return
        fixture, sight, conf = best
        log.debug("perception: %s lying on %s's ramp where the hand let it go (%d points, tilt %.0f deg, "
                  "confidence %.2f)", name, fixture, sight.points, math.degrees(sight.tilt_rad), conf)
        # the centroid of what shows lies within half the unseen length of the object's centre
        std = max(FIXTURE_STD_M, 0.5 * max(0.0, float(full.max()) - sight.length_m))
        t.position = sight.position.copy()
        t.bottom_m = float(sight.lowest_z_m - plane.z_at(sight.position[:2]))
        t.var_xy = std * std
        t.confidence, t.points, t.last_seen_s, t.seen_now = conf, sight.points, stamp, True
        t.cameras = tuple(sensors[i] for i in sight.cameras)
        self.leant[name] = (fixture, sight.tilt_rad, conf)

    def _release_point(self, name: str, proprio: Proprioception) -> np.ndarray | None:
        """(2,) world x, y (m) where the hand let ``name`` go, or None: the hand held it and
        has let go now (the grasp offset carried to the tcp's x, y: the retreat after a
        release rises straight up), or it was let go earlier and has not been seen
        confidently elsewhere since (``Track.placed_xy``)."""
        t = self.tracks.get(name)
        if t is None:
            return None
        if t.held and t.grasp_offset is not None and self._hand_evidence(t, proprio) is None:
            return (proprio.tcp_pose @ t.grasp_offset)[:2, 3].copy()
        return None if t.held or t.placed_xy is None else np.asarray(t.placed_xy, float)

    def _update_holding(self, proprio: Proprioception, stamp: float) -> tuple[str, float] | None:
        """Decide which tracked object (if any) is in the hand; returns (name, confidence)."""
        hc = self.config.holding
        tcp = proprio.tcp_pose[:3, 3]
        candidates = []
        for name, t in self.tracks.items():
            if t.seen_now and not t.held:
                continue  # seen on the table (outside the gripper box): not in the hand
            ev = self._hand_evidence(t, proprio)
            if ev is None:
                continue
            candidates.append((ev.confidence, name, ev))
        for t in self.tracks.values():
            if t.held and all(c[1] != t.name for c in candidates):
                t.held = False  # released (or lost): unknown until seen again
                t.released_s = stamp
                t.inside_of = None
                if t.grasp_offset is not None:  # where and how turned the hand let it go (a prior for the next sighting)
                    T_let = proprio.tcp_pose @ t.grasp_offset
                    t.position = T_let[:3, 3].copy()
                    t.yaw = math.atan2(T_let[1, 0], T_let[0, 0])
                    t.placed_xy = t.position[:2].copy()
                t.var_xy = max(t.var_xy, RELEASE_SIGMA_M ** 2)
                t.confidence *= 0.5
                t.grasp_offset = None
                t.hang_tcp = None
                t.grasp_z_tcp = None
        if not candidates:
            self._held = None
            return None
        candidates.sort(key=lambda c: -c[0])
        conf, name, _ = candidates[0]
        for _, other, _ in candidates[1:]:
            self.tracks[other].held = False
        t = self.tracks[name]
        if not t.held:
            T_obj = _pose(t.position, t.yaw)
            dxy = float(np.linalg.norm(t.position[:2] - tcp[:2]))
            if np.linalg.norm(t.position - tcp) < hc.capture_radius_m:
                t.grasp_offset = np.linalg.inv(proprio.tcp_pose) @ T_obj
            elif (rim := self._rim_radius(t)) is not None and abs(dxy - rim) <= hc.capture_radius_m / 2.0:
                # held by its wall (the tcp is over its rim), maybe lifted since: the lift rises
                # straight up, so the horizontal offset holds; at the close the tcp was the rim
                # grasp's depth below the rim (motion.rim_grasp.RIM_GRIP_DEPTH_M)
                from phyagentos.motion.rim_grasp import RIM_GRIP_DEPTH_M  # noqa: PLC0415

                z_close = float(t.position[2] + t.half_extents[2]) - RIM_GRIP_DEPTH_M
                T_obj[2, 3] = t.position[2] + max(0.0, float(tcp[2]) - z_close)
                t.grasp_offset = np.linalg.inv(proprio.tcp_pose) @ T_obj
            elif t.top_knob is not None and float(np.linalg.norm(self._top_knob_xy(t) - tcp[:2])) <= hc.capture_radius_m / 2.0:
                # held by its knob, maybe lifted since: at the close the tcp stood the knob
                # grasp's height over the object's top (motion.top_knob_grasp.top_knob_grasp_z)
                from phyagentos.motion.top_knob_grasp import top_knob_grasp_z  # noqa: PLC0415

                z_close = top_knob_grasp_z(float(t.position[2] + t.half_extents[2] - t.top_knob[4]))
                T_obj[2, 3] = t.position[2] + max(0.0, float(tcp[2]) - z_close)
                t.grasp_offset = np.linalg.inv(proprio.tcp_pose) @ T_obj
            else:  # grasped earlier, already moved: assume a centred grasp
                off = np.linalg.inv(proprio.tcp_pose) @ T_obj
                off[:3, 3] = 0.0
                t.grasp_offset = off
            closed = self._closed_at
            t.grasp_z_tcp = None
            if closed is not None and t.last_seen_s <= closed[1] and float(np.linalg.norm(
                    t.position[:2] - closed[0][:2, 3])) <= hc.capture_radius_m + float(max(t.half_extents[:2])):
                # last seen before the hand closed, where it closed: where it sits across and
                # along the fingers is where it sat then (the hand has moved since, maybe
                # lifted); how high it sits stays the rule's above (see note_grasp_close), the
                # height seen then reported beside it
                off = np.linalg.inv(closed[0]) @ _pose(t.position, t.yaw)
                t.grasp_z_tcp = float(off[2, 3])
                off[2, 3] = t.grasp_offset[2, 3]
                t.grasp_offset = off
            t.held = True
            t.placed_xy = None
            t.hang_tcp = None
        if len(candidates) > 1:
            conf *= 1.0 - candidates[1][0] / (candidates[0][0] + 1e-9) * 0.5
        self._held = name
        return name, conf

    @staticmethod
    def _top_knob_xy(t: Track) -> np.ndarray:
        """(2,) world x, y (m) of track ``t``'s knob on its top (``t.top_knob`` must be set)."""
        return t.position[:2] + turned_xy(np.asarray(t.top_knob, dtype=float)[:2], t.yaw)

    def _rim_wall(self, t: Track) -> float | None:
        """The wall (m) a hand holding track ``t`` by its rim closes on -- ``holding.handled_wall_m``
        for a mug, ``holding.rim_wall_m`` for another open container (its declared class and
        perceived shape and size, :meth:`_rim_radius`) -- or None: ``t`` is no open container."""
        from phyagentos.motion.rim_grasp import handled  # noqa: PLC0415 - only when something may be held

        if self._rim_radius(t) is None:
            return None
        hc = self.config.holding
        desc = next(d for d in self.declared if d.name == t.name)
        return hc.handled_wall_m if handled(desc.cls) else hc.rim_wall_m

    def _rim_radius(self, t: Track) -> float | None:
        """How far (m) from track ``t``'s perceived centre a hand holding it by its rim stands:
        its shorter half side for an open container seen whole
        (:func:`~phyagentos.motion.rim_grasp.open_container`; a mug's cup without its handle),
        its longer one for one seen in part (:func:`~phyagentos.motion.rim_grasp.partly_seen_rim_graspable`:
        the long side is the rim's diameter; a bowl at the back of an open drawer, seen 11.2 by
        6.4 cm); None for anything else."""
        from phyagentos.motion.grasp import DEFAULT_MAX_GRASP_WIDTH_M  # noqa: PLC0415
        from phyagentos.motion.rim_grasp import open_container, partly_seen_rim_graspable  # noqa: PLC0415

        desc = next((d for d in self.declared if d.name == t.name), None)
        if desc is None:
            return None
        if open_container(desc.cls, t.shape, t.half_extents):
            return float(min(t.half_extents[:2]))
        if partly_seen_rim_graspable(desc.cls, t.shape, t.half_extents, max_width_m=DEFAULT_MAX_GRASP_WIDTH_M):
            return float(max(t.half_extents[:2]))
        return None

    def _relations(self, geo: dict[str, dict], regions, holding_rel, supports: Mapping[str, dict] | None = None) -> list[dict]:
        """Relations among the perceived entities (``geo``: their boxes), with the declared
        ``regions`` and the fixtures' place patches (``supports``: boxes, supports only)."""
        cfg = self.config
        rels = []
        if holding_rel is not None:
            rels.append({"subject": "gripper", "relation": "holding", "object": holding_rel[0],
                         "confidence": _r(holding_rel[1], 3)})
        for a, ga in geo.items():
            if ga["bottom"] <= cfg.relations.on_gap_m and ga.get("inside_of") is None:
                rels.append({"subject": a, "relation": "on", "object": "table",
                             "confidence": _r(ga["table_conf"], 3)})
                for reg in regions:
                    c = inside_confidence(ga["position"], ga["std"], reg)
                    if c >= cfg.relations.min_confidence:
                        rels.append({"subject": a, "relation": "inside", "object": reg.name, "confidence": _r(c, 3)})
            cont = ga.get("inside_of")
            if cont is not None and cont in geo:
                gb = geo[cont]
                margin = _footprint_margin(ga["position"][:2], gb["position"], gb["yaw"], gb["half"], gb["shape"])
                c = normal_cdf(margin / max(math.hypot(ga["std"], gb["std"]), 1e-4))
                if c >= cfg.relations.min_confidence:
                    rels.append({"subject": a, "relation": "inside", "object": cont, "confidence": _r(c, 3)})
            for b, gb in [*geo.items(), *(supports or {}).items()]:
                if a == b:
                    continue
                c = on_confidence(ga, gb, cfg)
                if c >= cfg.relations.min_confidence:
                    rels.append({"subject": a, "relation": "on", "object": b, "confidence": _r(c, 3)})
        return rels


def table_centre(points: np.ndarray, plane: Plane, config: PerceptionConfig) -> np.ndarray | None:
    """Centre (2,) of the perceived table top, world m: the middle of the 2nd-98th percentile
    extent in x and y of the points within two inlier distances of the support plane (the
    table top the cameras see; objects on it hide parts of it, not its edges); None with fewer
    than ``table.min_inliers`` such points."""
    tc = config.table
    on = np.abs(plane.height(points.astype(np.float64))) < 2.0 * tc.inlier_threshold_m
    if int(on.sum()) < tc.min_inliers:
        return None
    lo, hi = np.percentile(points[on, :2], [2.0, 98.0], axis=0)
    return 0.5 * (lo + hi)


def viewer_right(frames: Sequence[CameraFrame], camera: str | None = None) -> np.ndarray | None:
    """The viewer's right on the table: the horizontal part of the image x axis (optical frame:
    x right, y down, z forward) of camera ``camera`` among ``frames`` (None: the first frame),
    as a (2,) unit vector in the world frame; None when there is no such frame or its x axis
    is within 0.1 of vertical. A camera facing the robot from across the table (LIBERO's
    agentview) has its right towards world +y."""
    frame = next((f for f in frames if camera is None or f.sensor == camera), None)
    if frame is None:
        return None
    x = np.asarray(frame.T_world_camera, dtype=float)[:2, 0]
    n = float(np.linalg.norm(x))
    return None if n < 0.1 else x / n


def _corroborated(conf: float, det: Detection, placed_xy: np.ndarray, config: PerceptionConfig) -> float:
    """The confidence of a weak association (below ``relations.min_confidence``; at least
    :data:`RELEASE_LOOK_FLOOR`) of an object with ``det`` given that the hand let that object
    go at ``placed_xy`` (proprioception): ``1 - (1 - conf)(1 - w)``, ``w = exp(-d^2 / 2
    sigma^2)`` for the distance ``d`` of ``det``'s centre from that point, ``sigma`` half
    ``holding.capture_radius_m``; ``conf`` unchanged beyond the capture radius.

    An item let go into a basket shows only its top between the walls and matches its look
    weakly (LIBERO-90's cans and boxes: 0.03-0.4), below what the verifier judges on, while
    the hand says where it went. A confident association is left as it is; one elsewhere is not
    helped; a look-alike at the release point must still be what the one-to-one association
    chose for this object."""
    radius = config.holding.capture_radius_m
    if conf >= config.relations.min_confidence or conf < RELEASE_LOOK_FLOOR:
        return conf
    d = float(np.linalg.norm(np.asarray(det.position[:2], float) - placed_xy))
    if d > radius:
        return conf
    w = math.exp(-0.5 * (d / (0.5 * radius)) ** 2)
    return 1.0 - (1.0 - conf) * (1.0 - w)


def _seen_fraction(det: Detection, look: ObjectDescriptor) -> float:
    """Confidence factor of a detection cut by the image border: 1 when at least half of its
    look's footprint (long x short side) was seen, else the fraction seen over one half. A
    sliver at the border says less about what it is than half a plate does. Seen through a
    room's mouth (``cut_by_room``), its face is what can be seen: its width against the look's
    long side and its height against the look's."""
    size = look.size_vector()
    if size is None or size[0] * size[1] <= 0.0:
        return 1.0
    if det.cut_by_room:
        seen = (2.0 * float(max(det.half_extents[:2])) / float(size[0])) * min(
            1.0, 2.0 * float(det.half_extents[2]) / max(float(size[2]), 1e-6))
        return min(1.0, seen / SEEN_ENOUGH)
    seen = 4.0 * float(det.half_extents[0]) * float(det.half_extents[1]) / float(size[0] * size[1])
    return min(1.0, seen / SEEN_ENOUGH)


def _completed(det: Detection, look: ObjectDescriptor, points_xy: np.ndarray) -> Detection:
    """``det``, cut by the image border and matched to a round look of known size, with its
    centre and footprint those of the whole object (:func:`~.truncation.complete_round`: the
    seen part's far edge and the look's radius) and its position sigma at least
    :data:`COMPLETED_STD_M`; else ``det`` unchanged. A plate half out of the agentview frame
    was placed on 2-3 cm short of its centre, towards the image's middle.

    A box-shaped part matched to a box look of known size is completed so along the box's own
    axis the cut runs along (:func:`~.truncation.complete_box`: the far edge and the look's
    length there): LIBERO's basket at the agentview's right border was seen 2-3 cm short and
    centred 0.8-1.8 cm towards the image's middle, and what was put in it went there."""
    size = look.size_vector()
    if det.cut_direction is None or size is None or len(points_xy) < 3:
        return det
    if look.shape_mismatch("box") == 0.0 and det.shape == "box":
        box = complete_box(points_xy, det.cut_direction, det.position[:2], det.yaw, det.half_extents[:2],
                           (float(size[0]), float(size[1])))
        if box is None:
            return det
        return replace(det, position=np.array([box[0][0], box[0][1], det.position[2]]),
                       half_extents=np.array([box[1][0], box[1][1], det.half_extents[2]]),
                       position_std_m=max(det.position_std_m, COMPLETED_STD_M))
    if look.shape_mismatch("cylinder") != 0.0:
        return det
    radius = 0.5 * float(size[0])
    centre = complete_round(points_xy, det.cut_direction, radius)
    if float(np.linalg.norm(centre - det.position[:2])) > radius:
        return det
    position = np.array([centre[0], centre[1], det.position[2]])
    half = np.array([radius, radius, det.half_extents[2]])
    return replace(det, position=position, half_extents=half, yaw=0.0, shape="cylinder",
                   position_std_m=max(det.position_std_m, COMPLETED_STD_M))


def _detection_confidence(det: Detection) -> float:
    """Detection-only confidence: support (1 - exp(-points / 30)) times view agreement."""
    return (1.0 - math.exp(-det.points / 30.0)) * det.view_agreement


def _geo(position, yaw, half, shape, bottom, plane: Plane, std) -> dict:
    return {"position": np.asarray(position, float), "yaw": float(yaw), "half": np.asarray(half, float),
            "shape": shape, "bottom": float(bottom), "top": float(bottom + 2.0 * half[2]), "std": float(std),
            "table_conf": 0.95 if plane.fitted else 0.7}


def width_in_hand(half_extents: np.ndarray, yaw: float, shape: str, proprio: Proprioception) -> float:
    """The width (m) of a tracked object the fingers would hold: across the fingers at its
    perceived yaw (:func:`~phyagentos.perception.relations.width_across_fingers`); for a box,
    whichever of that, its width or its length is nearest the fingers' gap: squeezed between
    flat pads a box turns until a face lies on each, so the gap is its width or its length
    whatever its perceived yaw (a carton's gable top can make it 90 degrees wrong)."""
    width = width_across_fingers(half_extents, yaw, shape, proprio.tcp_pose)
    if shape != "box":
        return width
    gap = 2.0 * proprio.gripper_opening_m
    return min((width, 2.0 * float(half_extents[0]), 2.0 * float(half_extents[1])), key=lambda w: abs(w - gap))


def _fingers_squeeze(proprio: Proprioception, config: PerceptionConfig) -> bool:
    """Whether the fingers squeeze something now: open more than ``holding.min_opening_m`` (m per
    finger) with at least ``holding.min_effort_n`` of effort (N); a hand open and still, or closed
    on nothing, squeezes nothing."""
    hc = config.holding
    return proprio.gripper_opening_m > hc.min_opening_m and abs(proprio.gripper_effort_n) >= hc.min_effort_n


def _hangs_from_hand(det: Detection, proprio: Proprioception, config: PerceptionConfig) -> bool:
    """``det`` is the part of a held object that hangs below the fingers (the gripper box
    masks only the fingers; a tall bottle grasped near its top shows its lower half): the
    fingers squeeze something (opening above ``holding.min_opening_m``, effort at least
    ``holding.min_effort_n``), the segment's lowest points are more than
    ``holding.lift_height_m`` above the support plane with nothing under it (stacking gave
    it no support: ``bottom_m`` 0), and its centre lies within ``holding.capture_radius_m``
    of the tcp horizontally, or the tcp is over its footprint (its larger horizontal half
    extent + 1 cm: a bowl held by its rim hangs beside the tcp). A rigid object off the support with nothing under it is carried,
    and under a closed hand that squeezes it is carried by the hand; an object standing on
    the table shows points down to the plane and is never taken for it."""
    hc = config.holding
    if not _fingers_squeeze(proprio, config):
        return False
    if det.low_m <= hc.lift_height_m or det.bottom_m > 1e-6:
        return False
    tcp = proprio.tcp_pose[:3, 3]
    dxy = float(np.hypot(det.position[0] - tcp[0], det.position[1] - tcp[1]))
    # or the tcp is over its footprint (a bowl held by its rim hangs beside the tcp)
    return dxy <= max(hc.capture_radius_m, float(max(det.half_extents[0], det.half_extents[1])) + 0.01)


def _shaped(det: Detection, cloud: Cloud, heights: np.ndarray) -> Detection:
    """A final detection with the round body and handle, the open top and the knob on top its
    points show."""
    return with_top_knob(with_open_depth(with_round_body(det, cloud, heights), cloud, heights), cloud, heights)


def _as_tracked(det: Detection, track: Track) -> Detection:
    """``det`` with the footprint (centre, yaw, half extents, shape) and bottom of ``track``: the
    object as its sightings so far, this one included, put it (a part seen at the image's border
    confirms a track where it stands and never moves it)."""
    return replace(det, position=np.asarray(track.position, dtype=float).copy(), yaw=float(track.yaw),
                   half_extents=np.asarray(track.half_extents, dtype=float).copy(), shape=track.shape,
                   bottom_m=float(track.bottom_m))


def _container_around(i: int, dets: list[Detection], matched: dict[int, str]) -> str | None:
    """The associated segment whose footprint holds detection ``i``'s centre and is wider
    than ``i``'s own (a container an item let go may stand in), the deepest inside if
    several; else None."""
    det = dets[i]
    best, best_margin = None, 0.0
    for k, name in matched.items():
        c = dets[k]
        if k == i or float(np.max(c.half_extents[:2])) <= float(np.max(det.half_extents[:2])):
            continue
        margin = _footprint_margin(det.position[:2], c.position, c.yaw, c.half_extents, c.shape)
        if margin >= best_margin:
            best, best_margin = name, margin
    return best


def _still_inside(container: str | None, det: Detection, dets: list[Detection], matched: dict[int, str], *,
                  height_m: float | None = None) -> str | None:
    """``container`` when the object's new detection ``det`` still stands inside it: the
    container is seen now (associated), ``det``'s centre lies in its footprint and its lowest
    points lie more than 2 cm below the container's top (not resting on the rim); else None.
    (A partial view over a basket's wall is a segment of its own.) With the object's tracked
    height ``height_m``, its bottom may also be inferred from its visible top (``top -
    height``): a tall item standing in a basket shows only its part above the walls, and
    resting on the rim its bottom would be at the rim, its top a whole height above it."""
    if container is None:
        return None
    k = next((i for i, n in matched.items() if n == container), None)
    if k is None:
        return None
    c = dets[k]
    if _footprint_margin(det.position[:2], c.position, c.yaw, c.half_extents, c.shape) < 0.0:
        return None
    low = det.low_m if height_m is None else min(det.low_m, det.top_m - height_m)
    return container if low < c.top_m - 0.02 else None


#: A detection lies within another's footprint (:func:`_not_inside_itself`) when every corner of
#: its own footprint rectangle lies inside the other's, or outside by at most this, m.
WITHIN_FOOTPRINT_M = 0.01


def _not_inside_itself(C: np.ndarray, dets: Sequence[Detection], gate_cost: float) -> np.ndarray:
    """``C`` (detections x declared objects) with each detection that lies within another's
    footprint (every corner of its footprint rectangle within :data:`WITHIN_FOOTPRINT_M` of
    it) and no higher than the other's top forbidden (cost :data:`FORBIDDEN_COST`) for every
    object that the other explains better and within ``gate_cost``: nothing lies inside
    itself. What shows inside a container is its contents or a piece of its own floor, never
    a second sighting of it. LIBERO-10 task 1: a strip of the basket's lining seen between its
    walls (8.7 by 1.5 cm, 3.1 cm up; the basket cut by the image border, so neither has its
    size judged short) matched the basket at 0.57 against the whole basket's 0.08; within the
    association's ambiguity margin, both were left unknown and the place into the basket
    found no basket."""
    out = C
    for i, det in enumerate(dets):
        c, s_ = math.cos(det.yaw), math.sin(det.yaw)
        hx, hy = float(det.half_extents[0]), float(det.half_extents[1])
        corners = det.position[:2] + np.array([[c * u - s_ * v, s_ * u + c * v]
                                               for u, v in ((hx, hy), (hx, -hy), (-hx, hy), (-hx, -hy))])
        for k, other in enumerate(dets):
            if k == i or det.top_m > other.top_m:
                continue
            margins = _footprint_margins(corners, other.position, other.yaw, other.half_extents, other.shape)
            if float(np.min(margins)) < -WITHIN_FOOTPRINT_M:
                continue
            for j in range(C.shape[1]):
                if C[k, j] <= gate_cost and C[k, j] < C[i, j] and out[i, j] < FORBIDDEN_COST:
                    if out is C:
                        out = C.copy()
                    out[i, j] = FORBIDDEN_COST
    return out


def _seen_top(t: Track) -> float:
    """Track ``t``'s top, m above the support plane: the face seen between a container's walls
    where it was found there, else its bottom plus its height."""
    return float(t.bottom_m + 2.0 * t.half_extents[2]) if t.face_top_m is None else float(t.face_top_m)


def _released_inside(t: Track, cloud: Cloud, heights: np.ndarray, dets: list[Detection], indices: list[np.ndarray],
                     sensors: list[str], others: Sequence[Footprint] = (), *, tracked_top_m: float | None = None
                     ) -> tuple[int, np.ndarray, float, int, tuple[str, ...], float] | None:
    """Is object ``t`` standing inside a container segment where the hand let it go (or where
    it was last seen inside one)?

    One face, one object: the points over ``others`` (the footprints of the other objects
    perceived where they stand, grown by :data:`OTHER_FOOTPRINT_M`) up to :data:`OTHER_TOP_M`
    over their tops are never ``t``'s: a can let go beside another in a basket that rolled off
    must not be found on the other's top (LIBERO-10 task 0: the tomato sauce on the alphabet
    soup's face). A face higher over one of them is ``t`` resting on it: its top is then
    another place it may rest.

    An object set down in a basket touches its lining and walls and joins the basket's
    segment; from above, only its top shows between the walls. For a detection whose
    footprint's short side is at least :data:`CONTAINER_MIN_SIDE_M` and holds the release
    point (``t.position``, from proprioception): its interior points (footprint shrunk by
    :data:`CONTAINER_WALL_M`), the floor (their 5th height percentile), the interior points
    within the object's footprint radius + 2 cm of the release point, then twice within its
    radius of the top face found there (what slid on landing is followed). The top face: the
    points within 1 cm of the most populated 5 mm height bin more than
    :data:`CONTENT_CLEARANCE_M` above the floor. The object is seen
    there when that top stands the object's perceived height above where it rests (within 2
    cm), is flat (height RMS <= 7 mm) and spans at least 60 % of the object's short side both
    ways: a lining fold or a wall's rim fails one of these. Where it rests lies between the
    floor and the inside read beside it (:func:`_rest_height`): up a bowl's curved inside it
    rests on the ring beside it, but on a basket's floor the ring reads the lining pressed up
    round it (libero_10_swap task 1: 0.8 cm over the floor round the cream cheese box, whose
    top stood 2.2 cm over the floor and 1.4 cm over the ring; the box is 2.0 cm tall, its look
    3.1 cm on the living-room table, which rests things 1.2 cm over its rendered top). The err
    is the distance of ``top - height`` from ``[floor, ring]``, or from the top of another
    object under the face's centre, whichever is less; on the inside, less
    :data:`CONTENT_TALL_M` where ``top - height`` lies below it (a height perceived on a
    table is an upper bound); the object's centre is reported at its height over the nearer.
    Confidence exp(-err^2 / 2 :data:`CONTENT_HEIGHT_SIGMA_M`^2) x (1 - exp(-points / 30)).

    ``tracked_top_m`` (m above the support plane): the top of an object seen inside the container
    before and not moved since; the err is then also the face's distance from it, whichever
    is less, and the object rests where its height puts it below the face. What stands at the
    height where it was seen, within its footprint and over nothing else, is it: a can let go
    onto another in the basket is seen from the wrist camera straight above it, then from the
    scene camera only merged with the basket and the can under it, its top 6 mm below where
    the wrist camera saw it, while its look's height (1.2 cm tall on LIBERO-10's living-room
    table) puts its base 2.4 cm into the can under it (LIBERO-10 task 0, development seed 509).

    Returns ``(container index, centre (3,) world m, confidence, points, cameras, the top face's
    height m above the support plane)`` or None.
    """
    radius = float(max(t.half_extents[0], t.half_extents[1]))
    height = 2.0 * float(t.half_extents[2])
    p0 = np.asarray(t.position[:2], float)
    for k, (det, idx) in enumerate(zip(dets, indices)):
        short = float(min(det.half_extents[0], det.half_extents[1]))
        if 2.0 * short < CONTAINER_MIN_SIDE_M:
            continue
        if _footprint_margin(p0, det.position, det.yaw, det.half_extents, det.shape) < 0.0:
            continue
        xy = cloud.points[idx, :2] - det.position[:2]
        h = heights[idx]
        c, s_ = math.cos(det.yaw), math.sin(det.yaw)
        u, v = c * xy[:, 0] + s_ * xy[:, 1], -s_ * xy[:, 0] + c * xy[:, 1]
        interior = (np.abs(u) < det.half_extents[0] - CONTAINER_WALL_M) & (np.abs(v) < det.half_extents[1] - CONTAINER_WALL_M)
        if int(interior.sum()) < 25:
            continue
        floor = float(np.percentile(h[interior], 5))
        mine = interior & ~_others_own(cloud.points[idx, :2], h, others)
        centre = p0
        # search around the release point, then twice around the top face found: a can let go
        # over a basket's corner slid 5.4 cm on landing, and one look around the part first
        # found still held only 3.0 cm of its lid (LIBERO-10 task 0 init 2)
        for grow in (0.02, 0.0, 0.0):
            disc = mine & (np.linalg.norm(cloud.points[idx, :2] - centre, axis=1) < radius + grow)
            above = h[disc][h[disc] > floor + CONTENT_CLEARANCE_M]
            if above.size < 25:
                break
            # the top face: the most populated 5 mm height bin above the floor (a flat top
            # gathers there; walls and folds spread over heights)
            counts, edges = np.histogram(above, bins=np.arange(floor, float(above.max()) + 0.01, 0.005))
            top = float(edges[int(np.argmax(counts))] + 0.0025)
            face = disc & (np.abs(h - top) < 0.01)
            if int(face.sum()) < 15:
                break
            centre = cloud.points[idx[face], :2].mean(axis=0)
        else:
            (_, _), (width, length), _ = cv2.minAreaRect(cloud.points[idx[face], :2].astype(np.float32))
            log.debug("released %s in segment %d: floor %.3f top %.3f (height %.3f) face std %.4f, %d points, "
                      "span %.3f x %.3f m", t.name, k, floor, top, height, float(np.std(h[face])), int(face.sum()), width, length)
            rest = _rest_height(cloud.points[idx, :2], h, interior, face, det.position[:2], floor, top)
            bottom = top - height
            # where it may rest: from the floor to the ring beside it, or on another object under it
            rests = [float(np.clip(bottom, floor, rest)),
                     *(o_top for o_xy, o_half, o_yaw, o_shape, o_top in others
                       if _footprint_margin(centre, o_xy, o_yaw, o_half, o_shape) >= 0.0)]
            on = min(rests, key=lambda r: abs(bottom - r))
            err = abs(bottom - on)
            if on == rests[0] and bottom < on:
                # down on the inside, its top lower than its perceived height puts it: that height
                # may be too tall by up to CONTENT_TALL_M (perceived on a table). Not over another
                # object's top, where a face short of the height is as likely a tilted can or the
                # other's own rim (the height where it was seen decides there: tracked_top_m)
                err = max(0.0, err - CONTENT_TALL_M)
            if tracked_top_m is not None and abs(top - tracked_top_m) < err:
                err, on = abs(top - float(tracked_top_m)), bottom  # where it was seen, not moved since
            if top - floor < CONTENT_CLEARANCE_M or err > 0.02:
                continue
            if float(np.std(h[face])) > 0.007:
                continue
            short_obj = 2.0 * float(min(t.half_extents[0], t.half_extents[1]))
            if min(width, length) < 0.6 * short_obj:
                continue
            n = int(face.sum())
            conf = math.exp(-0.5 * (err / CONTENT_HEIGHT_SIGMA_M) ** 2) * (1.0 - math.exp(-n / 30.0))
            pos = np.array([centre[0], centre[1], 0.0])
            pos[2] = float(np.median(cloud.points[idx[face], 2] - h[face])) + on + t.half_extents[2]  # where it rests
            cams = tuple(sensors[int(i)] for i in np.unique(cloud.camera[idx[face]]))
            return k, pos, conf, n, cams, top
    return None


def _others_own(xy: np.ndarray, h: np.ndarray, others: Sequence[Footprint]) -> np.ndarray:
    """(N,) bool: which of the points ``xy`` (N, 2) world m at heights ``h`` (N,) m above the
    support plane are another object's own: over its footprint grown by
    :data:`OTHER_FOOTPRINT_M` and no higher than :data:`OTHER_TOP_M` over its top."""
    out = np.zeros(len(xy), dtype=bool)
    for centre, half, yaw, shape, top in others:
        out |= (_footprint_margins(xy, centre, yaw, half, shape) >= -OTHER_FOOTPRINT_M) & (h <= top + OTHER_TOP_M)
    return out


def _rest_height(xy: np.ndarray, h: np.ndarray, interior: np.ndarray, face: np.ndarray, centre_xy: np.ndarray,
                 floor: float, top: float) -> float:
    """The height (m above the support plane) at which an object whose top face is ``face``
    rests inside a container: its floor where the floor is flat (a basket), higher where the
    inside curves up (a bowl: an 8.5 cm cream cheese box in LIBERO's 11 cm akita bowl rests on
    the sloped walls, 1.8 cm above the lowest floor point).

    The object's bottom touches the inside at its top face's corner farthest from the
    container's centre ``centre_xy`` (2,) world m, at distance ``r``. The inside there is the
    :data:`REST_RING_PERCENTILE` th height percentile (the object's own sides, seen beside its
    top face, stand above the inside: the lower part of the ring is the inside) of the
    container's interior points (``interior`` (N,) bool over ``xy`` (N, 2)
    world m and ``h`` (N,) m) within :data:`REST_RING_M` of that distance from the centre that
    are not the object's (lower than ``top`` - 1 cm and outside its top face's rectangle grown
    by 1 cm): a ring the object's ends stand on, beside it. ``floor``: the interior's 5th height
    percentile, returned when fewer than :data:`REST_RING_MIN_POINTS` such points are seen or
    the ring lies lower."""
    rect = cv2.minAreaRect(xy[face].astype(np.float32))
    corners = cv2.boxPoints(rect).astype(float)
    grown = cv2.boxPoints((rect[0], (rect[1][0] + 0.02, rect[1][1] + 0.02), rect[2])).astype(np.float32)
    inner = np.flatnonzero(interior & (h < top - 0.01))
    # inside the grown rectangle: the projections on two adjacent edges fall within them
    g0, e1, e2 = grown[0].astype(float), (grown[1] - grown[0]).astype(float), (grown[3] - grown[0]).astype(float)
    d = xy[inner] - g0
    a, b = d @ e1, d @ e2
    own = (a >= 0.0) & (a <= e1 @ e1) & (b >= 0.0) & (b <= e2 @ e2)
    keep = inner[~own]
    r_end = float(np.sqrt(np.max(np.sum((corners - centre_xy) ** 2, axis=1))))
    ring = keep[np.abs(np.linalg.norm(xy[keep] - centre_xy, axis=1) - r_end) <= REST_RING_M]
    if ring.size < REST_RING_MIN_POINTS:
        return floor
    return max(floor, float(np.percentile(h[ring], REST_RING_PERCENTILE)))


def _occluded_in(t: Track, frames: Sequence[CameraFrame]) -> tuple[str, ...]:
    """Cameras in which something nearer hides track ``t``, or the frame's border cuts it off;
    empty when any camera sees a spot of it free or none hides one. The spots are its centre
    and four points half way to the sides of its footprint (:data:`OCCLUSION_SPOTS`), at mid
    height: a plate whose centre is out of the frame is hidden where the mug set on it stands.
    The ray to a spot enters the object's box (its perceived centre, yaw and half extents) at
    some depth and leaves it at a larger one: a return more than :data:`OCCLUSION_MARGIN_M`
    nearer than the entry is something else in the way; one more than that beyond the exit
    sees the spot free (the object is not there); one in between is a surface of its own. A
    camera whose frame holds some spots, each showing a surface of its own, and not others
    (the border cuts the object off) hides the rest: what it sees is what remains of it there,
    too little to be told as the object (LIBERO-10 task 4: a mug let go on the plate at the
    scene camera's edge, seen whole from the wrist above it, then as a cut-off unknown)."""
    p = np.asarray(t.position, float)
    c, s_ = math.cos(t.yaw), math.sin(t.yaw)
    R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])  # object frame in the world
    half = np.asarray(t.half_extents, float)
    spots = [p + R @ (np.array([fx, fy, 0.0]) * half) for fx, fy in OCCLUSION_SPOTS]
    hidden: list[str] = []
    for f in frames:
        T = f.T_world_camera
        T_inv = np.linalg.inv(T)
        o = T[:3, 3]
        k = f.intrinsics
        hides = cut = own = False
        for spot in spots:
            q = T_inv @ np.append(spot, 1.0)
            if q[2] <= 0.05:
                continue
            u, v = k.fx * q[0] / q[2] + k.cx, k.fy * q[1] / q[2] + k.cy
            if not (0 <= u <= k.width - 1 and 0 <= v <= k.height - 1):
                cut = True  # in front of the camera, out of its frame
                continue
            r0, c0 = int(round(v)), int(round(u))
            win = f.depth_m[max(0, r0 - 1):r0 + 2, max(0, c0 - 1):c0 + 2]
            win = win[win > 0]
            if win.size == 0:
                continue
            ray = (spot - o) / np.linalg.norm(spot - o)
            # slab entry of the ray into the object's box (object frame), as a length along the ray
            ol, rl = R.T @ (o - p), R.T @ ray
            with np.errstate(divide="ignore", invalid="ignore"):
                t1, t2 = (-half - ol) / rl, (half - ol) / rl
            along = float(ray @ T[:3, 2])
            entry_depth = float(np.nanmax(np.minimum(t1, t2))) * along
            exit_depth = float(np.nanmin(np.maximum(t1, t2))) * along
            seen = float(np.median(win))
            log.debug("remembered %s? %s sees depth %.3f m at %s where its box spans %.3f-%.3f m", t.name, f.sensor,
                      seen, _r(spot), entry_depth, exit_depth)
            if seen < entry_depth - OCCLUSION_MARGIN_M:
                hides = True
            elif seen > exit_depth + OCCLUSION_MARGIN_M:
                return ()  # seen through where it would be: not there
            else:
                # a surface within its box: its own, seen but not segmented apart (a plate's
                # floor around the mug set on it)
                own = True
        if hides or (cut and own):
            hidden.append(f.sensor)
    return tuple(hidden)
