"""Object detection on the object points: clustering, then per cluster a fitted primitive.

Clustering is DBSCAN (scikit-learn; Ester et al. 1996) on a joint feature of position and
colour, ``[x, y, z, w_c r/(r+g+b), w_c g/(r+g+b), w_i (r+g+b)/768]`` with
``w_c = eps / chromaticity_scale`` and ``w_i = eps / lightness_scale``: the chromaticity is
invariant to a common gain, so one object's lit and shaded faces stay together, while two
touching objects of clearly different colours separate.

Per cluster (:func:`fit_cluster`): height above the support plane -> top and bottom; the
top-face points (within ``shape.top_band_m`` of the top) give the footprint (OpenCV
``minAreaRect`` -> centre, yaw, half extents) and its corner fraction (points outside the
ellipse inscribed in that rectangle: 21.5 % for a rectangle, 0 for a disc); a least-squares sphere fit (the
algebraic fit of |p|^2 = 2 c.p + (r^2 - |c|^2)) with a small residual and a height close to
its diameter means a sphere. Colour is the median sRGB of the top-face points (or of all
the segment's points, or of its most chromatic third: ``shape.colour_from``).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from phyagentos.perception.cloud import Cloud, Plane
from phyagentos.perception.colour import srgb_to_lab
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.handle import UPPER_FRACTION, RoundBody, round_body
from phyagentos.perception.top_knob import Knob, top_knob

__all__ = ["Detection", "dbscan", "cluster", "fit_cluster", "open_depth", "with_open_depth", "with_round_body",
           "with_top_knob", "detect", "detect_clusters", "stack", "resting_at"]

log = logging.getLogger(__name__)

#: ``shape.colour_from: vivid`` keeps this most chromatic fraction of a segment's points.
_VIVID_FRACTION = 1.0 / 3.0
#: A detection whose lowest points (2nd percentile) stand this far above ``object_min_height_m``
#: may rest on another (:func:`stack`), m.
RAISED_LOW_M = 0.008
#: An open top (:func:`open_depth`): the inside is the footprint's inscribed ellipse shrunk by
#: this on every side (the walls and the rim on them), m; the walls' ring is the rest of it.
OPEN_WALL_M = 0.015
#: ... read where at least this many of the segment's points fall inside ...
OPEN_MIN_POINTS = 25
#: ... its floor the inside's heights at this percentile (a few points of noise below it) ...
OPEN_FLOOR_PERCENTILE = 5.0
#: ... and the walls stand to within this of the top (m) in at least :data:`OPEN_RIM_SECTORS`
#: of the eight 45-degree sectors about the centre that hold wall points: the rim goes round
#: (a mug merged with the plate under it has only the plate's low edge there).
OPEN_RIM_TOL_M = 0.015
OPEN_RIM_SECTORS = 6


@dataclass(frozen=True)
class Detection:
    """One perceived object in one observation (all cameras fused at the point level).

    Attributes:
        position: (3,) world centre, m.
        yaw: rad about world z of the footprint's x axis (0 for round shapes), in [-pi/2, pi/2).
        half_extents: (3,) m; hx >= hy for boxes (the footprint's long side is x).
        shape: ``box`` | ``cylinder`` | ``sphere``.
        colour_rgb: (3,) median sRGB in [0, 1].
        colour_lab: (3,) CIELAB of ``colour_rgb``.
        points: supporting points (after voxel filtering).
        cameras: number of cameras that saw it (with >= 5 points each).
        position_std_m: 1-sigma horizontal position uncertainty, m.
        yaw_std_rad: 1-sigma yaw uncertainty, rad (pi for round shapes: yaw is meaningless).
        view_agreement: 0..1, how well the per-camera centres agree (1 for one camera).
        bottom_m: bottom height above the support plane, m (0 for objects on the table).
        low_m: height of the cluster's lowest points (2nd percentile) above the plane, m.
        cut_direction: (2,) world horizontal unit vector towards where the segment runs out of
            view, when its points reach the image border in every camera that saw it
            (:func:`phyagentos.perception.truncation.cut_direction`), else None: the object
            may go on beyond what was seen, so its size is a lower bound, its shape that of
            the part seen and its centre short of the object's on that side.
        cut_by_body: ``cut_direction`` is where a cabinet's body, whose points are the
            fixture's own, cuts off what stands in its open drawer behind its front
            (:meth:`phyagentos.perception.perceiver.Perceiver._cut_by_carcass`), not the image
            border: its size counts as a lower bound, but the part seen is kept as seen (never
            completed to its look: the rim of a container seen in part is taken near the ends
            of its seen long side).
        cut_by_room: with ``cut_by_body``: what cuts it off is the room behind a fixture's door
            it stands in (:meth:`phyagentos.perception.perceiver.Perceiver._cut_by_room`), seen
            only through the room's mouth: its depth into the room is hidden, whatever it is (a
            round one is completed to its look along ``cut_direction``).
        body: the round body with a handle its footprint shows (a mug's cup and handle:
            :func:`with_round_body`), else None.
        covered: the lower part of a stack split at a height step
            (:func:`phyagentos.perception.split.split_cluster`) with a part resting on it:
            its top and its far side are hidden under that part, so its footprint is a lower
            bound and its shape that of what shows; never what a spatial reference picks out
            (what stands on it does).
        open_depth_m: how far its inside's floor lies below its top, m, where it is an open
            container (a basket, a bowl: :func:`with_open_depth`); 0 for a solid top.
        top_knob: the small part standing on its top (a moka pot's lid knob:
            :func:`with_top_knob`), else None. Its top is above :attr:`top_m`, which is the
            segment's 98th percentile height (the body's top).
        foot_hidden_m: how far below :attr:`bottom_m` its foot may reach unseen, m: the upper
            part of a height step standing within what shows all round it below the cut (a mug
            in a plate's well, its base below the rim: :func:`phyagentos.perception.split._rested`),
            so its whole height lies between its height as seen and that plus this. 0 for
            everything else.
        hidden_above_m: as a support (a fixture's pseudo-detection), how far over its top the
            foot of what rests on it may go unseen, m: a room's floor behind a fixture's door,
            seen through the mouth over its front lip, has what stands on it rise from it
            unseen (a mug at the back of LIBERO's microwave showed its lowest points 2 cm over
            the floor; the perceiver's ``ROOM_LIP_HIDES_M``). 0 for everything else: only
            :attr:`~phyagentos.perception.config.RelationsConfig.on_gap_m` is allowed.
    """

    position: np.ndarray
    yaw: float
    half_extents: np.ndarray
    shape: str
    colour_rgb: np.ndarray
    colour_lab: np.ndarray
    points: int
    cameras: int
    position_std_m: float
    yaw_std_rad: float
    view_agreement: float
    bottom_m: float
    low_m: float = 0.0
    cut_direction: np.ndarray | None = None
    cut_by_body: bool = False
    cut_by_room: bool = False
    covered: bool = False
    body: RoundBody | None = None
    open_depth_m: float = 0.0
    top_knob: Knob | None = None
    hidden_above_m: float = 0.0
    foot_hidden_m: float = 0.0

    @property
    def truncated(self) -> bool:
        """Cut by the image border or a cabinet's body (``cut_direction`` known): seen only
        in part."""
        return self.cut_direction is not None

    @property
    def top_m(self) -> float:
        """Top height above the support plane, m."""
        return self.bottom_m + 2.0 * float(self.half_extents[2])


def dbscan(features: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """DBSCAN labels (N,) (-1 = noise) of (N, D) ``features`` (Ester et al. 1996).

    Same definition as scikit-learn's ``DBSCAN`` (a point is core when at least
    ``min_samples`` points, itself included, lie within ``eps``; clusters are the connected
    components of core points; a border point joins a cluster of one of its core neighbours),
    built from scipy's ``cKDTree.query_pairs`` and ``connected_components``; scikit-learn's
    per-call input validation costs more than the clustering itself at our sizes (measured
    in bench/perception.py, ``--clustering sklearn``).
    """
    n = features.shape[0]
    labels = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return labels
    pairs = cKDTree(features).query_pairs(eps, output_type="ndarray")
    deg = np.bincount(pairs.ravel(), minlength=n) + 1
    core = deg >= min_samples
    if not np.any(core):
        return labels
    both = core[pairs[:, 0]] & core[pairs[:, 1]]
    cp = pairs[both]
    graph = coo_matrix((np.ones(cp.shape[0], dtype=np.int8), (cp[:, 0], cp[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    # consecutive labels for the core components
    _, core_lab = np.unique(comp[core], return_inverse=True)
    labels[core] = core_lab
    one = core[pairs[:, 0]] ^ core[pairs[:, 1]]
    bp = pairs[one]
    c_idx = np.where(core[bp[:, 0]], bp[:, 0], bp[:, 1])
    b_idx = np.where(core[bp[:, 0]], bp[:, 1], bp[:, 0])
    labels[b_idx] = labels[c_idx]
    return labels


def cluster(cloud: Cloud, config: PerceptionConfig) -> list[np.ndarray]:
    """Index arrays of the clusters of ``cloud`` (largest first), each >= ``min_points``."""
    if len(cloud) == 0:
        return []
    cc = config.clustering
    rgb = cloud.rgb.astype(np.float64) + 1.0
    total = rgb.sum(axis=1, keepdims=True)
    chroma = rgb[:, :2] / total  # (r, g) chromaticity: invariant to shading (a common gain)
    w = cc.eps_m / cc.chromaticity_scale
    feat = np.column_stack([
        cloud.points.astype(np.float64),
        w * chroma,
        (cc.eps_m / cc.lightness_scale) * total[:, 0] / 768.0,
    ])
    if cc.method == "sklearn":
        from sklearn.cluster import DBSCAN

        labels = DBSCAN(eps=cc.eps_m, min_samples=cc.min_samples, algorithm="kd_tree").fit_predict(feat)
    else:
        labels = dbscan(feat, cc.eps_m, cc.min_samples)
    out = []
    for k in range(labels.max() + 1):
        idx = np.flatnonzero(labels == k)
        if idx.size >= cc.min_points:
            out.append(idx)
    out.sort(key=lambda a: -a.size)
    return out


def _corner_fraction(xy: np.ndarray, centre: np.ndarray, yaw: float, half: np.ndarray,
                     tol_m: float = 0.0) -> float:
    """Fraction of footprint points outside the ellipse inscribed in the min-area rectangle
    (grown by ``tol_m``, the sampling and noise tolerance).

    A uniformly sampled rectangle puts 1 - pi/4 = 21.5 % of its points there (fewer with a
    tolerance), a disc none: a scale-free circle-vs-rectangle test for sparse samples.
    """
    if xy.shape[0] < 5 or half[0] <= 0 or half[1] <= 0:
        return 1.0
    c, s = math.cos(yaw), math.sin(yaw)
    d = xy - centre
    u = (c * d[:, 0] + s * d[:, 1]) / half[0]
    v = (-s * d[:, 0] + c * d[:, 1]) / half[1]
    lim = (1.0 + tol_m / float(min(half[0], half[1]))) ** 2
    return float(np.mean(u * u + v * v > lim))


def _sphere_fit(p: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares sphere (centre (3,), radius, RMS radial residual) of (N, 3) points."""
    A = np.column_stack([2.0 * p, np.ones(p.shape[0])])
    b = np.sum(p * p, axis=1)
    # normal equations via einsum (a 4x4 solve; avoids a multithreaded BLAS call)
    sol = np.linalg.solve(np.einsum("ni,nj->ij", A, A) + 1e-12 * np.eye(4), np.einsum("ni,n->i", A, b))
    c = sol[:3]
    r2 = sol[3] + c @ c
    r = math.sqrt(max(r2, 1e-12))
    res = np.linalg.norm(p - c, axis=1) - r
    return c, r, float(np.sqrt(np.mean(res * res)))


def _rect(xy: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """(centre (2,), yaw in [-pi/2, pi/2), half extents (2,) with hx >= hy) of the min-area rect."""
    (cx, cy), (w, h), ang = cv2.minAreaRect(xy.astype(np.float32))
    yaw = math.radians(ang)
    if h > w:
        w, h = h, w
        yaw += math.pi / 2.0
    yaw = (yaw + math.pi / 2.0) % math.pi - math.pi / 2.0
    return np.array([cx, cy]), yaw, np.array([w / 2.0, h / 2.0])


#: A thin thing lying tilted (:func:`_level_band`): at most this tall over the support, m (a
#: plate, 1.8 cm; a flat box), its heights sloping at least this much (rise per run), and its
#: top band's footprint at most this fraction of all its points' (the band only the raised side).
TILT_MAX_HEIGHT_M = 0.035
TILT_MIN_SLOPE = 0.025
TILT_BAND_FRACTION = 0.8


def _level_band(points: np.ndarray, heights: np.ndarray, band: np.ndarray, top_m: float, band_m: float) -> np.ndarray:
    """The top band of a thin thing lying tilted, measured from its own slope.

    A plate resting with its rim on the corner of a box beside it (LIBERO-PRO's
    ``libero_spatial_swap`` task 1: tilted 3.5 degrees) lifts one side of its rim 8 mm over the
    other: the band within ``band_m`` of the top is that side only, and its footprint a
    crescent (14 by 10 cm for a 13.85 cm plate, matching no look). Where the thing stands at
    most :data:`TILT_MAX_HEIGHT_M` (``top_m``, its 98th height percentile, m), ``band``'s
    footprint is at most :data:`TILT_BAND_FRACTION` of all ``points``' (N, 3) world m, and the
    least-squares plane of its ``heights`` (N,) m over x, y slopes at least
    :data:`TILT_MIN_SLOPE`, the band is taken again on the heights less that plane: returned
    when its footprint is larger; else ``band`` (N,) bool unchanged."""
    if top_m > TILT_MAX_HEIGHT_M or int(band.sum()) < 5 or points.shape[0] < 20:
        return band
    xy = points[:, :2].astype(np.float64)

    def area(sel: np.ndarray) -> float:
        (_, _), (w, h), _ = cv2.minAreaRect(xy[sel].astype(np.float32))
        return float(w * h)

    everything = np.ones(len(xy), dtype=bool)
    whole, upper = area(everything), area(band)
    if whole <= 0.0 or upper > TILT_BAND_FRACTION * whole:
        return band
    centred = xy - xy.mean(axis=0)
    A = np.column_stack([centred, np.ones(len(xy))])
    slope = np.linalg.lstsq(A, heights.astype(np.float64), rcond=None)[0][:2]
    if float(np.hypot(*slope)) < TILT_MIN_SLOPE:
        return band
    level = heights - centred @ slope
    lo, hi = (float(v) for v in np.percentile(level, [2, 98]))
    again = level > hi - max(band_m, 0.15 * (hi - lo))
    return again if int(again.sum()) >= 5 and area(again) > upper else band


def fit_cluster(cloud: Cloud, heights: np.ndarray, plane: Plane, config: PerceptionConfig,
                focal_px: np.ndarray, *, rests_at_m: float | None = None) -> Detection | None:
    """Fit one cluster (its points ``cloud`` and their ``heights`` above ``plane``).

    ``focal_px``: (n_cameras,) focal lengths (px / stride) used for the lateral resolution
    term of the uncertainty. ``rests_at_m``: the height (m above ``plane``) it is known to rest
    at (the upper part of a height step, at the cut: :func:`phyagentos.perception.split.split_cluster`),
    else None: the sphere test takes its height from there (a bowl's wall raised 4.5 cm on a
    ramekin is a cap 5 cm tall, not a 10 cm ball); the fit itself stands on the plane, as
    every fit, until :func:`stack` or the split raises it. Returns None when the cluster has
    no usable top face.
    """
    sc, fc = config.shape, config.fusion
    h = heights
    top, low = (float(v) for v in np.percentile(h, [98, 2]))
    # Objects rest on the support plane; :func:`stack` raises the bottom of an object whose
    # lowest points sit on another detection's top.
    bottom = 0.0
    height = max(top - bottom, 1e-3)
    band = h > top - max(sc.top_band_m, 0.15 * height)
    band = _level_band(cloud.points, h, band, top, sc.top_band_m)
    top_xy = cloud.points[band, :2]
    if top_xy.shape[0] < 5:
        top_xy = cloud.points[:, :2]
    centre_xy, yaw, hxy = _rect(top_xy)
    # pixel footprint at the observed range: edges are uncertain by about one sample
    fpx = focal_px[cloud.camera.astype(int)]
    range_m = float(np.median(cloud.range_m))
    pix_m = float(np.median(cloud.range_m / fpx))
    corner = _corner_fraction(top_xy, centre_xy, yaw, hxy, 0.5 * pix_m)
    hxy = hxy + 0.5 * pix_m  # points sample pixel centres: the true edge lies ~half a pixel out

    shape = "box" if corner >= sc.box_corner_fraction else "cylinder"
    sphere_c = None
    if cloud.points.shape[0] >= 10:
        c, r, rms = _sphere_fit(cloud.points.astype(np.float64))
        # a sphere's surface fits within the depth noise; a cylinder's rim and a box's edges
        # leave a larger residual (measured on 223 rendered objects: residual / limit is
        # 0.32-1.0 for spheres, >= 0.96 for cylinders, >= 1.3 for boxes; docs/perception.md)
        limit = sc.sphere_residual * r + sc.sphere_noise_factor * float(config.depth_sigma_m(range_m))
        own = height if rests_at_m is None else max(top - float(rests_at_m), 1e-3)
        diam_ok = abs(own - 2.0 * r) / (2.0 * r) < sc.sphere_height_tolerance
        # a ball seen from above bulges towards the cameras: its points stand round or above
        # its centre; a bowl's inside is a sphere seen from within, its centre above the points
        # (0.51 r below it: a black bowl tilted on a ramekin, libero_spatial_lan task 5 init 0)
        bulge = float(np.median(h)) - float(plane.height(c[None, :])[0])
        if rms < limit and diam_ok and bulge >= -sc.sphere_bulge_min * r:
            shape, sphere_c = "sphere", c
    if shape == "sphere":
        r = 0.5 * height
        centre_xy = sphere_c[:2]
        half = np.array([r, r, r])
        yaw = 0.0
    elif shape == "cylinder":
        # the top disc: centre from its rect, radius = mean of the rect's half sides
        r = float(hxy.mean())
        half = np.array([r, r, 0.5 * height])
        yaw = 0.0
    else:
        half = np.array([hxy[0], hxy[1], 0.5 * height])
    z = plane.z_at(centre_xy) + bottom + half[2]
    position = np.array([centre_xy[0], centre_xy[1], z])

    rgb_sel = cloud.rgb[band] if band.sum() >= 5 and sc.colour_from == "top" else cloud.rgb
    lab = srgb_to_lab(rgb_sel)
    if sc.colour_from == "vivid" and lab.shape[0] >= 15:
        chroma = np.hypot(lab[:, 1], lab[:, 2])
        vivid = chroma >= np.percentile(chroma, 100.0 * (1.0 - _VIVID_FRACTION))
        rgb_sel, lab = rgb_sel[vivid], lab[vivid]
    med_lab = np.median(lab, axis=0)
    colour = np.median(rgb_sel, axis=0) / 255.0

    # ---- uncertainty: per camera, a centre from that camera's points; inverse-variance fuse
    cams, counts = np.unique(cloud.camera, return_counts=True)
    per_cam, per_var = [], []
    for cam, cnt in zip(cams, counts):
        if cnt < 5:
            continue
        sel = cloud.camera == cam
        rng_m = float(np.median(cloud.range_m[sel]))
        pm = rng_m / float(focal_px[int(cam)])
        sd = float(config.depth_sigma_m(rng_m))
        var = fc.position_floor_m ** 2 + (pm * pm / 12.0 + sd * sd) * 4.0 / max(math.sqrt(cnt), 1.0)
        pts_c = cloud.points[sel & band] if np.count_nonzero(sel & band) >= 5 else cloud.points[sel]
        per_cam.append(pts_c[:, :2].mean(axis=0))
        per_var.append(var)
    if not per_var:
        per_var = [fc.position_floor_m ** 2 + pix_m ** 2]
        per_cam = [centre_xy]
    per_var_a = np.asarray(per_var)
    fused_var = 1.0 / float(np.sum(1.0 / per_var_a))
    agreement = 1.0
    if len(per_cam) > 1:
        # per-camera centres of visible points are biased by self-occlusion; compare their
        # spread with the object size instead of their std (a crude but monotone measure)
        spread = float(np.max(np.linalg.norm(np.asarray(per_cam) - np.mean(per_cam, axis=0), axis=1)))
        agreement = float(math.exp(-max(0.0, spread - 0.5 * float(half[:2].max())) / 0.01))
        fused_var += (1.0 - agreement) * spread ** 2
    pos_std = math.sqrt(fused_var)
    if shape == "box":
        long_side = max(float(2.0 * hxy[0]), 1e-3)
        yaw_std = math.sqrt(fc.yaw_floor_rad ** 2 + (2.0 * pix_m / long_side) ** 2 / len(per_var))
    else:
        yaw_std = math.pi
    return Detection(
        position=position, yaw=float(yaw), half_extents=half, shape=shape, colour_rgb=colour,
        colour_lab=med_lab, points=int(cloud.points.shape[0]), cameras=len(per_var),
        position_std_m=pos_std, yaw_std_rad=yaw_std, view_agreement=agreement, bottom_m=bottom,
        low_m=low,
    )


def open_depth(xy: np.ndarray, heights: np.ndarray, centre: np.ndarray, yaw: float, half_xy: np.ndarray,
               top_m: float) -> float:
    """How far the floor inside an open container lies below its top, m; 0 for a solid top.

    ``xy``: (N, 2) world x, y of a segment's points, m; ``heights``: (N,) their heights above
    the support plane, m; ``centre`` (2,), ``yaw`` (rad about world z) and ``half_xy`` (2,) m:
    its footprint's rectangle; ``top_m``: its top above the plane, m. The inside is the ellipse
    inscribed in the footprint shrunk by :data:`OPEN_WALL_M` (at least 1 cm across each half
    axis, and :data:`OPEN_MIN_POINTS` points in it), its floor their
    :data:`OPEN_FLOOR_PERCENTILE` th height percentile. It counts only where the walls' points
    outside that ellipse reach to within :data:`OPEN_RIM_TOL_M` of the top all round (in at
    least :data:`OPEN_RIM_SECTORS` of the eight sectors that hold wall points): a rim, not an
    object standing on a flat one (a mug on a plate, seen as one segment)."""
    a, b = float(half_xy[0]) - OPEN_WALL_M, float(half_xy[1]) - OPEN_WALL_M
    if min(a, b) < 0.01 or xy.shape[0] < OPEN_MIN_POINTS:
        return 0.0
    c, s = math.cos(yaw), math.sin(yaw)
    d = xy - np.asarray(centre, dtype=float)[:2]
    u, v = (c * d[:, 0] + s * d[:, 1]) / a, (-s * d[:, 0] + c * d[:, 1]) / b
    inner = u * u + v * v < 1.0
    if int(inner.sum()) < OPEN_MIN_POINTS:
        return 0.0
    floor = float(np.percentile(heights[inner], OPEN_FLOOR_PERCENTILE))
    sector = ((np.arctan2(v, u) + math.pi) / (math.pi / 4.0)).astype(int) % 8
    wall, hw = sector[~inner], heights[~inner]
    held = [k for k in range(8) if np.any(wall == k)]
    rim = sum(1 for k in held if float(hw[wall == k].max()) >= top_m - OPEN_RIM_TOL_M)
    if rim < OPEN_RIM_SECTORS:
        return 0.0
    return max(0.0, top_m - floor)


def with_open_depth(det: Detection, cloud: Cloud, heights: np.ndarray) -> Detection:
    """``det`` (fitted to the points ``cloud`` with their ``heights`` above the plane, m) with
    its :attr:`Detection.open_depth_m` (:func:`open_depth` over its footprint and top). Run on
    the final detections only, as :func:`with_round_body`."""
    depth = open_depth(cloud.points[:, :2], heights, det.position[:2], det.yaw, det.half_extents[:2], det.top_m)
    return replace(det, open_depth_m=depth) if depth > 0.0 else det


def with_round_body(det: Detection, cloud: Cloud, heights: np.ndarray) -> Detection:
    """``det`` (fitted to the points ``cloud`` with their ``heights`` above the plane, m) with
    the round body and handle its footprint shows (``Detection.body``), from the outline of its
    upper part (:data:`phyagentos.perception.handle.UPPER_FRACTION` of its height above its
    lowest points) about its centre; a sphere has none. Run on the final detections only (a
    split tries hundreds of candidate parts)."""
    if det.shape == "sphere" or heights.size < 5:
        return det
    top, low = (float(v) for v in np.percentile(heights, [98, 2]))
    upper = heights >= low + UPPER_FRACTION * (top - low)
    body = round_body(cloud.points[upper, :2], det.position[:2])
    return det if body is None else replace(det, body=body)


#: Percentiles of the points' projections that bound a footprint fitted along a known axis
#: (:func:`with_top_knob`): a stray depth sample does not widen it.
AXIS_FIT_PERCENTILES = (0.5, 99.5)


def with_top_knob(det: Detection, cloud: Cloud, heights: np.ndarray) -> Detection:
    """``det`` (fitted to the points ``cloud`` with their ``heights`` above the plane, m) with
    the knob standing on its top (:attr:`Detection.top_knob`,
    :func:`~phyagentos.perception.top_knob.top_knob`); run on the final detections only, as
    :func:`with_round_body`. A box whose knob gives the way it reaches farthest
    (``axis_rad``) has its footprint's rectangle fitted along that axis instead
    (:data:`AXIS_FIT_PERCENTILES` of the points' projections): its yaw, centre and horizontal
    half extents."""
    knob = top_knob(cloud.points[:, :2], heights)
    if knob is None:
        return det
    if knob.axis_rad is None or det.shape != "box":
        return replace(det, top_knob=knob)
    # the footprint's rectangle along the way the object reaches farthest from its knob (a
    # moka pot's handle): a min-area rectangle of an octagon with a handle and a spout stands
    # up to 27 deg off its axes (generated LIBERO-10 task 8 scenes)
    a = knob.axis_rad
    u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    xy = cloud.points[:, :2]
    (lo_u, hi_u), (lo_v, hi_v) = np.percentile(xy @ u, AXIS_FIT_PERCENTILES), np.percentile(xy @ v, AXIS_FIT_PERCENTILES)
    half = np.array([0.5 * (hi_u - lo_u), 0.5 * (hi_v - lo_v), float(det.half_extents[2])])
    centre = 0.5 * (lo_u + hi_u) * u + 0.5 * (lo_v + hi_v) * v
    if half[1] > half[0]:
        half[[0, 1]], a = half[[1, 0]], a + 0.5 * math.pi
    yaw = (a + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    return replace(det, top_knob=knob, yaw=float(yaw), half_extents=half,
                   position=np.array([centre[0], centre[1], float(det.position[2])]))


def stack(dets: list[Detection], plane: Plane, config: PerceptionConfig) -> list[Detection]:
    """Raise the bottom of detections resting on another detection (object on object).

    A detection whose lowest points (``low_m``) are well above the table and within
    ``relations.on_gap_m`` of another detection's top, over that detection's footprint,
    rests on it: its bottom becomes the other's top and its height shrinks accordingly.
    Failing that, it rests on a support whose :attr:`Detection.hidden_above_m` reaches its
    lowest points (a room's floor, the foot of what stands on it hidden by the mouth's lip).
    Heights are m above ``plane``; returns a new list in the same order.
    """
    from phyagentos.perception.relations import _footprint_margin

    out = list(dets)
    order = sorted(range(len(out)), key=lambda i: out[i].top_m)
    for i in order:
        a = out[i]
        if a.low_m < config.table.object_min_height_m + RAISED_LOW_M:
            continue
        under = None
        for j in order:
            b = out[j]
            if j == i or b.top_m >= a.top_m:
                continue
            rise = a.low_m - b.top_m
            near = abs(rise) <= config.relations.on_gap_m
            if not near and not 0.0 < rise <= b.hidden_above_m:
                continue
            if _footprint_margin(a.position[:2], b.position, b.yaw, b.half_extents, b.shape) < -0.005:
                continue
            if near:  # resting within on_gap_m of it beats a support whose hidden foot reaches
                under = j
                break
            if under is None:
                under = j
        if under is not None:
            out[i] = resting_at(a, out[under].top_m, plane)
    return out


def resting_at(det: Detection, bottom_m: float, plane: Plane) -> Detection:
    """``det`` with its bottom raised to ``bottom_m`` (m above ``plane``), its top kept: its
    height shrinks and its centre rises accordingly (an object resting on another)."""
    half = det.half_extents.copy()
    half[2] = max(0.5 * (det.top_m - bottom_m), 1e-3)
    pos = det.position.copy()
    pos[2] = plane.z_at(pos[:2]) + bottom_m + half[2]
    return replace(det, bottom_m=bottom_m, half_extents=half, position=pos)


def detect_clusters(cloud: Cloud, heights: np.ndarray, plane: Plane, config: PerceptionConfig,
                    focal_px: np.ndarray) -> list[tuple[Detection, np.ndarray]]:
    """``(detection, index array into cloud)`` per cluster (see :func:`fit_cluster`). A
    cluster holding touching objects is split afterwards, against the declared objects
    (:func:`phyagentos.perception.split.split_clusters`)."""
    out = []
    for idx in cluster(cloud, config):
        det = fit_cluster(cloud.select(idx), heights[idx], plane, config, focal_px)
        if det is not None:
            out.append((det, idx))
    return out


def detect(cloud: Cloud, heights: np.ndarray, plane: Plane, config: PerceptionConfig,
           focal_px: np.ndarray) -> list[Detection]:
    """Cluster the object points and fit each cluster (see :func:`fit_cluster`)."""
    return [det for det, _ in detect_clusters(cloud, heights, plane, config, focal_px)]
