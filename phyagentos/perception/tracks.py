"""Per-session object tracks: fusion of associated detections over observations.

A track is a 1-D Kalman filter per horizontal coordinate with a random-walk process model
(variance grows by q^2 * dt while unobserved, q = ``fusion.process_noise_m_per_sqrt_s``) and
the detection's ``position_std_m`` as measurement noise: the fused estimate is the
inverse-variance weighted mean, so agreeing views shrink the uncertainty (Kalman 1960; with
a static object this is the weighted average of all views). A measurement farther than
``fusion.innovation_gate_sigma`` sigmas restarts the track (the object was moved). Yaw is
fused the same way modulo the footprint's symmetry (pi, or pi/2 for a square footprint).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.detect import Detection
from phyagentos.perception.handle import RoundBody
from phyagentos.geometry import turned_xy

__all__ = ["REMEMBERED_CONFIDENCE", "Track", "object_pose", "yaw_period"]

#: An object not seen now but hidden where it was is reported at its track's confidence times
#: this (the perceiver's ``remembered``); a weak sighting of part of it where it stands keeps at
#: least as much (:meth:`Track.update`'s ``weak_below``).
REMEMBERED_CONFIDENCE = 0.9


def yaw_period(half_extents: np.ndarray, shape: str) -> float:
    """Symmetry period of the yaw (rad): pi for a rectangle, pi/2 for a square footprint."""
    if shape != "box":
        return 2.0 * math.pi
    hx, hy = float(half_extents[0]), float(half_extents[1])
    return math.pi / 2.0 if abs(hx - hy) < 0.1 * max(hx, hy) else math.pi


def _local_top_knob(det: Detection, position: np.ndarray, yaw: float) -> np.ndarray | None:
    """``det``'s knob in the frame of a track at ``position`` ((3,) world, m) turned ``yaw``
    (rad): :attr:`Track.top_knob`'s layout; None when ``det`` shows none. The track's own
    pose, not the sighting's: a box's fused yaw may differ from a sighting's by its period."""
    k = det.top_knob
    if k is None:
        return None
    axis = np.nan if k.axis_rad is None else k.axis_rad - yaw
    return np.r_[turned_xy(k.xy - np.asarray(position, dtype=float)[:2], -yaw), k.top_m - det.top_m, k.radius_m,
                 det.top_m - k.base_m, axis]


def _wrap(a: float, period: float) -> float:
    return (a + period / 2.0) % period - period / 2.0


@dataclass
class Track:
    """What perception believes about one declared object (mutable, internal)."""

    name: str
    position: np.ndarray
    var_xy: float
    yaw: float
    var_yaw: float
    half_extents: np.ndarray
    shape: str
    colour_rgb: np.ndarray
    points: int
    confidence: float
    last_seen_s: float
    bottom_m: float
    cameras: tuple[str, ...] = ()
    shape_votes: dict = field(default_factory=dict)
    observations: int = 1
    held: bool = False
    grasp_offset: np.ndarray | None = None  # (4, 4) object pose in the tcp frame while held
    seen_now: bool = True
    #: Name of the declared container the object was last seen inside (contents of its
    #: segment, see :mod:`phyagentos.perception.perceiver`), else None.
    inside_of: str | None = None
    #: Stamp (s) at which the hand let the object go; None once it has been seen since.
    released_s: float | None = None
    #: (2,) world x, y (m) where the hand let the object go, from proprioception; kept until
    #: the object is held again or seen confidently away from it, else None.
    placed_xy: np.ndarray | None = None
    #: Its height (m) as known when the hand last let it go (kept when the track restarts: it
    #: is as tall wherever it is seen): a later sighting that reaches down to the table with its
    #: top higher than that stands on something hidden under it (a plate under the mug set on
    #: it); None for an object never let go.
    known_height_m: float | None = None
    #: The round body with a handle its latest sighting showed, in the object's frame (its
    #: position and yaw: :meth:`~phyagentos.perception.handle.RoundBody.local`), else None.
    body: RoundBody | None = None
    #: How far its inside's floor lies below its top in its latest sighting, m (an open
    #: container's: :attr:`~phyagentos.perception.detect.Detection.open_depth_m`); 0 for a solid top.
    open_depth_m: float = 0.0
    #: The knob on its top (:attr:`~phyagentos.perception.detect.Detection.top_knob`) in its latest
    #: sighting that showed one, in the object's frame: (6,) its centre's x, y from the object's
    #: centre along the object's axes (m), how far its top rises above the object's (m), its
    #: radius (m), how far the body's top under it lies below the object's top (m), and its
    #: reach axis from the object's x axis (rad, modulo pi; nan: none); else None.
    top_knob: np.ndarray | None = None
    #: (3,) m, in the tcp frame: how far the held body's base was found to hang from the pose it
    #: had when the fingers closed (:mod:`~phyagentos.perception.hang`), since that grasp; None
    #: while not held or not read.
    hang_tcp: np.ndarray | None = None
    #: Where the held object's centre sat along the tcp's z axis (down the fingers), m, when the
    #: hand closed on it, as seen before the close; None while not held or not seen then. Its
    #: carried pose keeps the perceiver's rule for that height (centred for a grasp across:
    #: :meth:`~phyagentos.perception.Perceiver.note_grasp_close`); this is reported beside it.
    grasp_z_tcp: float | None = None
    #: Its round body's base, slice by slice up from its lowest points, as the cameras off the hand saw
    #: it standing (:func:`~phyagentos.perception.hang.base_profile`: (6,) radii, m, 0 where
    #: unseen), else None.
    base_profile_m: np.ndarray | None = None
    #: The height (m above the support plane) of its top face as last found between a
    #: container's walls (the perceiver's look for a released object, which reports the object
    #: where it rests, not where that face puts it); None once it is seen on its own.
    face_top_m: float | None = None
    #: While weak sightings follow one another where it stands (:meth:`update`'s
    #: ``weak_below``), the confidence it had before the first of them; None otherwise.
    confident_before: float | None = None

    @classmethod
    def start(cls, name: str, det: Detection, confidence: float, stamp_s: float,
              cameras: tuple[str, ...]) -> "Track":
        """A new track from its first detection."""
        return cls(name=name, position=det.position.copy(), var_xy=det.position_std_m ** 2, yaw=det.yaw,
                   var_yaw=det.yaw_std_rad ** 2, half_extents=det.half_extents.copy(), shape=det.shape,
                   colour_rgb=det.colour_rgb.copy(), points=det.points, confidence=confidence,
                   last_seen_s=stamp_s, bottom_m=det.bottom_m, cameras=cameras, shape_votes={det.shape: 1},
                   body=None if det.body is None else det.body.local(det.position[:2], det.yaw),
                   open_depth_m=det.open_depth_m, top_knob=_local_top_knob(det, det.position, det.yaw))

    def predicted_var(self, stamp_s: float, config: PerceptionConfig) -> float:
        """Position variance (m^2) grown by the random walk since the last sighting."""
        dt = max(0.0, stamp_s - self.last_seen_s)
        return self.var_xy + config.fusion.process_noise_m_per_sqrt_s ** 2 * dt

    def within_gate(self, det: Detection, stamp_s: float, config: PerceptionConfig) -> bool:
        """Whether ``det``'s centre lies within ``fusion.innovation_gate_sigma`` sigmas of the
        track's predicted position (horizontal; both variances summed)."""
        var_p = self.predicted_var(stamp_s, config)
        innov = float(np.linalg.norm(det.position[:2] - self.position[:2]))
        return innov <= config.fusion.innovation_gate_sigma * math.sqrt(var_p + det.position_std_m ** 2)

    def update(self, det: Detection, confidence: float, stamp_s: float, cameras: tuple[str, ...],
               config: PerceptionConfig, *, weak_below: float = 0.0) -> bool:
        """Fuse a new detection; returns False when it restarted the track instead.

        ``weak_below``: a sighting less confident than this, within the gate of a track held
        at least that confidently and not in the hand, is part of the object where it stands
        (the rest hidden, or out of the frame); it leaves the track at least
        :data:`REMEMBERED_CONFIDENCE` times the confidence it had before the first of such
        sightings in a row, as not seeing it at all behind something would, however many
        frames see it so (each taking the remembered share of the last wore a mug in LIBERO's
        microwave from 0.74 to 0.32 in seven frames). 0 (the default): agreeing sightings
        only fuse."""
        var_p = self.predicted_var(stamp_s, config)
        var_m = det.position_std_m ** 2
        within = self.within_gate(det, stamp_s, config)
        before = self.confidence if self.confident_before is None else self.confident_before
        weak = confidence < weak_below <= before and not self.held and within
        keep = before * REMEMBERED_CONFIDENCE if weak else 0.0
        if self.held or not within or det.shape != self.shape and self.observations < 2:
            fresh = Track.start(self.name, det, confidence, stamp_s, cameras)
            fresh.known_height_m = self.known_height_m  # moved or taken, it is as tall as it was
            if not self.held and within and fresh.body is None and self.body is not None:
                # restarted where it stood only for its shape (its second sighting, of another
                # side): the handle its first showed stays where it was seen, in the world
                fresh.body = self.body.placed(object_pose(self.position, self.yaw)).local(det.position[:2], det.yaw)
            self.__dict__.update(fresh.__dict__)
            return False
        yaw_before = self.yaw
        k = var_p / (var_p + var_m)
        self.position[:2] = self.position[:2] + k * (det.position[:2] - self.position[:2])
        self.position[2] = det.position[2]
        self.var_xy = var_p * var_m / (var_p + var_m)
        self.shape_votes[det.shape] = self.shape_votes.get(det.shape, 0) + 1
        self.shape = max(self.shape_votes, key=self.shape_votes.get)
        if self.shape == "box" and det.shape == "box":
            period = yaw_period(det.half_extents, det.shape)
            var_y, var_ym = self.var_yaw, det.yaw_std_rad ** 2
            ky = var_y / (var_y + var_ym)
            self.yaw = _wrap(self.yaw + ky * _wrap(det.yaw - self.yaw, period), math.pi)
            self.var_yaw = var_y * var_ym / (var_y + var_ym)
        else:
            self.yaw, self.var_yaw = det.yaw, det.yaw_std_rad ** 2
        n = self.observations
        self.half_extents = (n * self.half_extents + det.half_extents) / (n + 1)
        self.colour_rgb = (n * self.colour_rgb + det.colour_rgb) / (n + 1)
        self.points, self.bottom_m, self.cameras = det.points, det.bottom_m, cameras
        self.open_depth_m, self.face_top_m = det.open_depth_m, None
        if det.body is not None:  # the latest sighting of it
            self.body = det.body.local(det.position[:2], det.yaw)
        elif self.body is not None:  # one that missed the handle keeps the last, turned as it stood
            self.body = self.body.turned(yaw_before - self.yaw)
        if det.top_knob is not None:
            self.top_knob = _local_top_knob(det, self.position, self.yaw)
        elif self.top_knob is not None:  # as the body: the last one seen, turned as it stood
            turn = yaw_before - self.yaw
            self.top_knob = np.r_[turned_xy(self.top_knob[:2], turn), self.top_knob[2:5], self.top_knob[5] + turn]
        # agreeing sightings raise confidence: 1 - (1 - c_now)(1 - c_before / 2)
        self.confidence = max(1.0 - (1.0 - confidence) * (1.0 - 0.5 * self.confidence), keep)
        self.confident_before = before if weak else None
        self.last_seen_s = stamp_s
        self.observations = n + 1
        return True



def object_pose(position: np.ndarray, yaw: float) -> np.ndarray:
    """(4, 4) world pose of an object at ``position`` ((3,) world, m) turned ``yaw`` (rad about
    world z)."""
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = position
    return T
