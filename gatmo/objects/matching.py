"""Matching a chair hypothesis to a map object (paper, Sec. V): principal axes by SVD give
candidate alignments (four per axis pair: the 2- and 4-fold ambiguity of boxes), each scored on
a gaussian-blurred grid of the object's edge points with a local search around it."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from gatmo.geometry import points_to_beams, wrap_angle
from gatmo.objects.objectmap import MapObject


@dataclass
class Match:
    object_id: int
    score: float
    pose_xytheta: np.ndarray  # new p_i (object frame -> map)


class EdgeField:
    """exp(-d^2 / 2 sigma^2) of the distance d to the object's edge points, in its own frame
    (the paper's "grids formed by adding a Gaussian distribution around each edge point"), at
    two widths: ``sigma_m`` for scoring and 2.5 sigma for the coarse search. Also keeps the
    object's dominant edge directions (:func:`line_directions`) and its cells' smallest
    rectangle (:func:`min_rect`)."""

    def __init__(self, obj: MapObject, sigma_m: float, pad_m: float = 1.0):
        res = obj.resolution_m / 2.0
        pts = obj.edge_xy if len(obj.edge_xy) else obj.shape_xy
        lo = pts.min(axis=0) - pad_m
        hi = pts.max(axis=0) + pad_m
        shape = np.ceil((hi - lo) / res).astype(int) + 1
        mask = np.ones((shape[1], shape[0]), dtype=bool)
        idx = np.floor((pts - lo) / res).astype(int)
        mask[idx[:, 1], idx[:, 0]] = False
        d = ndimage.distance_transform_edt(mask) * res
        self.val = np.exp(-(d**2) / (2 * sigma_m**2))
        self.coarse = np.exp(-(d**2) / (2 * (2.5 * sigma_m) ** 2))
        self.lo, self.res = lo, res
        self.extent_m = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
        self.lines = line_directions(pts)
        self.principal = principal_angle(pts)
        self.rect = min_rect(obj.shape_xy)

    def score(self, q_xy: np.ndarray) -> np.ndarray:
        """Mean field value of point sets q (..., P, 2) in the object frame -> (...)."""
        idx = np.floor((q_xy - self.lo) / self.res).astype(np.int64)
        h, w = self.val.shape
        ok = (idx[..., 0] >= 0) & (idx[..., 0] < w) & (idx[..., 1] >= 0) & (idx[..., 1] < h)
        v = np.where(ok, self.val[np.clip(idx[..., 1], 0, h - 1), np.clip(idx[..., 0], 0, w - 1)],
                     0.0)
        return v.mean(axis=-1)

    def score_poses(self, pts_centred: np.ndarray, thetas: np.ndarray, offs: np.ndarray,
                    coarse: bool = False) -> np.ndarray:
        """Scores (R, T, T) of centred points for rotations (R,) and translations offs x offs."""
        from gatmo.objects._kernels import score_poses_kernel

        val = self.coarse if coarse else self.val
        return score_poses_kernel(val, float(self.lo[0]), float(self.lo[1]), float(self.res),
                                  np.ascontiguousarray(pts_centred, dtype=np.float64),
                                  np.ascontiguousarray(thetas, dtype=np.float64),
                                  np.ascontiguousarray(offs, dtype=np.float64),
                                  np.ascontiguousarray(offs, dtype=np.float64))


def principal_angle(points_xy: np.ndarray) -> float:
    d = points_xy - points_xy.mean(axis=0)
    if len(d) < 2:
        return 0.0
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    return float(np.arctan2(vt[0, 1], vt[0, 0]))


def line_directions(points_xy: np.ndarray, radius_m: float = 0.12, max_lines: int = 3,
                    min_support: int = 4) -> list[float]:
    """Directions [rad, in [0, pi)] of the dominant straight edges of a point set (paper, Sec. V:
    "lines are fit to the sets of edge points"): every point's local direction by SVD of its
    neighbours within ``radius_m``, weighted by how line-like that neighbourhood is, voted into
    5-degree bins; peaks at least 20 degrees apart with ``min_support`` points, strongest first.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points_xy, dtype=float)
    if len(pts) < 3:
        return []
    tree = cKDTree(pts)
    angles, weights = [], []
    for nb in tree.query_ball_point(pts, radius_m):
        if len(nb) < 3:
            continue
        q = pts[nb] - pts[nb].mean(axis=0)
        _, sv, vt = np.linalg.svd(q, full_matrices=False)
        lin = 1.0 - sv[1] / max(sv[0], 1e-12)
        if lin < 0.5:
            continue  # a corner or a blob: no direction
        angles.append(np.arctan2(vt[0, 1], vt[0, 0]) % np.pi)
        weights.append(lin)
    if not angles:
        return []
    a = np.array(angles)
    w = np.array(weights)
    nb = 36
    hist = np.bincount((a / np.pi * nb).astype(int) % nb, weights=w, minlength=nb)
    count = np.bincount((a / np.pi * nb).astype(int) % nb, minlength=nb)
    smooth = hist + 0.5 * (np.roll(hist, 1) + np.roll(hist, -1))
    out: list[float] = []
    for b in np.argsort(-smooth):
        if len(out) >= max_lines or smooth[b] <= 0:
            break
        support = count[b] + count[(b - 1) % nb] + count[(b + 1) % nb]
        if support < min_support:
            continue
        centre = (b + 0.5) * np.pi / nb
        d = np.abs(((a - centre + np.pi / 2) % np.pi) - np.pi / 2)
        m = d < np.radians(7.5)
        # circular mean of the members (angles mod pi: double them)
        ang = 0.5 * np.arctan2(np.sum(w[m] * np.sin(2 * a[m])), np.sum(w[m] * np.cos(2 * a[m])))
        ang = ang % np.pi
        if all(abs(((ang - o + np.pi / 2) % np.pi) - np.pi / 2) > np.radians(20) for o in out):
            out.append(float(ang))
    return out


class _AxesCache:
    """The last few point sets' (:func:`line_directions`, :func:`principal_angle`), keyed by
    their bytes: one chair is matched against every candidate object in turn, and its lines
    were found again for each (a tenth of a slow scan's time)."""

    def __init__(self, size: int = 8):
        self.size = size
        self._d: dict[tuple, tuple[tuple[float, ...], float]] = {}
        self._lock = threading.Lock()  # one module-wide cache: stacks in threads share it

    def get(self, points_xy: np.ndarray) -> tuple[tuple[float, ...], float]:
        pts = np.ascontiguousarray(points_xy, dtype=float)
        key = (pts.shape, pts.tobytes())
        with self._lock:
            hit = self._d.pop(key, None)
        if hit is None:
            hit = (tuple(line_directions(pts)), principal_angle(pts))
        with self._lock:
            self._d.pop(key, None)
            while len(self._d) >= self.size:
                self._d.pop(next(iter(self._d)))
            self._d[key] = hit  # the most recent last
        return hit


_AXES = _AxesCache()


def candidate_rotations(points_xy: np.ndarray, field: EdgeField) -> np.ndarray:
    """Rotations (object frame -> map) that align a line of the points with a line of the
    object (two each: the line may face either way), plus the four principal-axis alignments;
    "usually between two and five" per line pair in the paper."""
    lines_p, a_p = _AXES.get(points_xy)
    cands = []
    for a_p_line in lines_p:
        for a_o in field.lines:
            cands += [a_p_line - a_o, a_p_line - a_o + np.pi]
    cands += [a_p - field.principal + k * np.pi / 2 for k in range(4)]
    out: list[float] = []
    for th in cands:
        th = float(wrap_angle(th))
        if all(abs(wrap_angle(th - o)) > np.radians(2.5) for o in out):
            out.append(th)
    return np.array(out)


def _best_first(scores: np.ndarray, k: int) -> np.ndarray:
    """Indices of the ``k`` highest of ``scores`` (N,), highest first, ties in index order
    (a stable sort's order). A partition then a sort of ``k``: a full sort of the coarse
    search's (R, T, T) scores took a tenth of a slow scan's time."""
    neg = -np.asarray(scores, dtype=float)
    if k <= 0:
        return np.zeros(0, dtype=np.int64)
    if k >= neg.size:
        return np.argsort(neg, kind="stable")
    thr = neg[np.argpartition(neg, k - 1)[k - 1]]  # the k-th highest score
    less = np.flatnonzero(neg < thr)
    top = np.concatenate([less, np.flatnonzero(neg == thr)[:k - len(less)]])
    return top[np.lexsort((top, neg[top]))]


def match_points(points_xy: np.ndarray, obj: MapObject, cfg, field: EdgeField | None = None,
                 prior_yaw: float | None = None, accept=None) -> Match:
    """Best pose of ``obj`` explaining world points (P, 2), with its score in [0, 1].

    Candidate alignments from lines and principal axes (:func:`candidate_rotations`), each
    searched coarsely (+-6 deg, translations of the object's centroid over its own size around
    the points' centroid, on the wide field), the best few refined on the sharp field.
    ``accept(pose_xytheta) -> bool`` (beyond the paper): the best refined alignment it accepts
    (a partial view fits several; the one that covers space seen free is not it), the best of
    all if it accepts none."""
    field = field or EdgeField(obj, cfg.match_edge_sigma_m)
    pts = np.asarray(points_xy, dtype=float)
    c_p = pts.mean(axis=0)
    P = pts - c_p
    rots = candidate_rotations(pts, field)
    dth = np.radians(np.arange(-6.0, 6.01, 3.0))
    thetas = (rots[:, None] + dth[None, :]).ravel()
    reach = cfg.match_search_m + field.extent_m / 2
    step = 0.1
    offs = np.arange(-reach, reach + 1e-9, step)
    s = field.score_poses(P, thetas, offs, coarse=True)
    picks: list[tuple[float, float, float]] = []
    for f in _best_first(s.ravel(), 200):
        r, i, j = np.unravel_index(f, s.shape)
        cand = (thetas[r], offs[i], offs[j])
        if all(abs(wrap_angle(cand[0] - p[0])) > np.radians(4) or
               np.hypot(cand[1] - p[1], cand[2] - p[2]) > 0.15 for p in picks):
            picks.append(cand)
        if len(picks) >= 6:
            break
    fth = np.radians(np.arange(-3.0, 3.01, 1.0))
    foff = np.arange(-0.1, 0.1 + 1e-9, 0.025)
    refined = []
    for th0, tx, ty in picks:
        sf = field.score_poses(P - np.array([tx, ty]), th0 + fth, foff)
        r, i, j = np.unravel_index(int(np.argmax(sf)), sf.shape)
        refined.append((float(sf[r, i, j]),
                        np.array([c_p[0] + tx + foff[i], c_p[1] + ty + foff[j], th0 + fth[r]])))
    refined.sort(key=lambda x: -x[0])  # stable: ties keep the coarse order
    score, pose = refined[0] if refined else (-1.0, np.zeros(3))
    if accept is not None:
        score, pose = next((x for x in refined if accept(x[1])), (score, pose))
    if prior_yaw is not None:
        pose[2] = _closest_symmetric_yaw(obj, field, pts, pose, prior_yaw, score)
    pose[2] = float(wrap_angle(pose[2]))
    return Match(obj.id, score, pose)


def _closest_symmetric_yaw(obj, field, points_xy, pose, prior_yaw, score) -> float:
    """Among the poses rotated by k*pi/2 about the object's centre that score as well (a
    symmetric shape), report the one closest to the previous yaw."""
    best = pose[2]
    for k in (1, 2, 3):
        th = pose[2] + k * np.pi / 2
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        s = field.score((points_xy - pose[:2]) @ R)
        closer = abs(wrap_angle(th - prior_yaw)) < abs(wrap_angle(best - prior_yaw))
        if s >= score - 0.02 and closer:
            best = th
    return best


def beam_consistency(obj: MapObject, pose_xytheta: np.ndarray, views: list,
                     hit_tolerance_m: float = 0.1, through_m: float = 0.2) -> tuple[int, int]:
    """The object placed at ``pose_xytheta`` (map frame) against the scans that saw a chair:
    (beams that end on its predicted surface, beams that pass well beyond it). Beyond the
    paper, whose score looks only from the chair's points to the object's edges: a cabinet fits
    the visible half of a lounge chair, but placed there it would have stopped beams that went
    on. ``views``: (laser pose (3,) map frame, beam angles (B,) sorted [rad], ranges (B,) [m],
    reach [m]) per scan; only the object's cells within reach count. Beams ending short of the
    object (people, other things in front) say nothing."""
    pts = obj.cells_world(pose_xytheta, dense=True)
    support = contradict = 0
    for lp, angles, ranges, reach in views:
        if len(angles) < 2:
            continue
        rk, bk, j = points_to_beams(pts, lp, angles)
        near = rk <= reach
        if not near.any():
            continue
        rk, bk, j = rk[near], bk[near], j[near]
        half = 0.5 * np.abs(np.diff(angles)).mean() + 0.5 * obj.resolution_m / rk
        ok = np.abs(angles[j] - bk) <= half
        if not ok.any():
            continue
        pred = np.full(len(angles), np.inf)
        np.minimum.at(pred, j[ok], rk[ok])
        # only beams inside the object's silhouette (both neighbours would hit it too): its
        # edge cells hold its surface and some free space beside it (a map built from scans),
        # so a beam grazing its outline may pass and say nothing
        hit = np.isfinite(pred)
        m = hit.copy()
        m[1:] &= hit[:-1]
        m[:-1] &= hit[1:]
        m[0] = m[-1] = False
        r = np.where(np.isfinite(ranges), ranges, np.inf)[m]
        support += int(np.sum(np.abs(r - pred[m]) <= hit_tolerance_m))
        contradict += int(np.sum(r > pred[m] + through_m))
    return support, contradict


LOOKALIKE_MIN_CELLS = 20


def lookalike(a: MapObject, b: MapObject, tol: float) -> bool:
    """Same size and proportions (cell count and principal extents within ``tol``)."""
    na, nb = len(a.shape_xy), len(b.shape_xy)
    if min(na, nb) < LOOKALIKE_MIN_CELLS or abs(na - nb) > tol * max(na, nb):
        return False  # specks of clutter all look alike: too small to call a shape
    ea = np.sort(np.linalg.eigvalsh(np.cov(a.shape_xy.T)))
    eb = np.sort(np.linalg.eigvalsh(np.cov(b.shape_xy.T)))
    return bool(np.all(np.abs(np.sqrt(ea) - np.sqrt(eb)) <= tol * np.sqrt(np.maximum(ea, eb))
                       + 0.02))


def min_rect(points_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rectangle of least perimeter around points (P, 2) (one side on an edge of their
    convex hull): (centre (2,), axes (2, 2) whose rows are its unit side directions, extents
    (2,) along them) [m]. A square's axes follow its sides, which principal axes cannot give;
    and the two sides of a box seen from a corner (an L, whose hull is a right triangle) fit
    it along them, where the least area would as well lie along the hypotenuse."""
    from scipy.spatial import ConvexHull, QhullError

    pts = np.asarray(points_xy, dtype=float)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):  # collinear or too few points
        hull = pts
    best = None
    edges = np.roll(hull, -1, axis=0) - hull
    for e in edges:
        n = np.hypot(e[0], e[1])
        if n < 1e-9:
            continue
        axes = np.array([[e[0], e[1]], [-e[1], e[0]]]) / n
        q = hull @ axes.T
        lo, hi = q.min(axis=0), q.max(axis=0)
        size = float(np.sum(hi - lo))
        if best is None or size < best[0] - 1e-12:
            best = (size, axes, lo, hi)
    if best is None:
        return pts.mean(axis=0), np.eye(2), np.zeros(2)
    _, axes, lo, hi = best
    return ((lo + hi) / 2) @ axes, axes, hi - lo


def side_spans(obj: MapObject, pose_xytheta: np.ndarray, points_xy: np.ndarray,
               near_m: float = 0.15, min_points: int = 3, turn_deg: float = 10.0,
               rect: tuple | None = None) -> np.ndarray | None:
    """The sides (shorter, longer) [m] of one scan's returns ``points_xy`` (K, 2, map frame)
    within ``near_m`` of the object ``obj`` placed at ``pose_xytheta``: their smallest
    rectangle turned at most ``turn_deg`` from the object's own (:func:`min_rect` of its
    cells). The match's yaw is a few degrees off, and the least rectangle of a noisy L (a box
    seen from a corner) may lie along its hypotenuse. ``rect``: the object's
    :func:`min_rect`, if known. None: fewer than ``min_points`` near."""
    from gatmo.geometry import inverse, transform_points

    if len(points_xy) < min_points:
        return None
    centre, axes, ext = min_rect(obj.shape_xy) if rect is None else rect
    q = (transform_points(inverse(np.asarray(pose_xytheta, dtype=float)), points_xy)
         - centre) @ axes.T
    q = q[np.all(np.abs(q) <= ext / 2 + near_m, axis=1)]
    if len(q) < min_points:
        return None
    turns = np.radians(np.arange(-turn_deg, turn_deg + 1e-9, 1.0))
    c, s = np.cos(turns), np.sin(turns)
    u = q[None, :, 0] * c[:, None] + q[None, :, 1] * s[:, None]
    v = -q[None, :, 0] * s[:, None] + q[None, :, 1] * c[:, None]
    ext_u = u.max(axis=1) - u.min(axis=1)
    ext_v = v.max(axis=1) - v.min(axis=1)
    k = int(np.argmin(ext_u + ext_v))
    return np.sort([ext_u[k], ext_v[k]])


def longest_sides(spans: list) -> np.ndarray | None:
    """The sides (shorter, longer) [m] single scans saw of a thing, from their
    :func:`side_spans` (S, 2): per side the longest, or the second longest once three scans
    count (one scan's stray return). None: no scan."""
    if not spans:
        return None
    s = np.sort(np.asarray(spans, dtype=float), axis=0)
    return s[-2] if len(s) >= 3 else s[-1]


def extent_excess(obj: MapObject, pose_xytheta: np.ndarray, scan_points: list,
                  rect: tuple | None = None) -> float | None:
    """How far what single scans saw of a chair reaches past the object ``obj`` placed at
    ``pose_xytheta`` (map frame) [m]: the chair's :func:`longest_sides` of the
    :func:`side_spans` of each scan's returns ``scan_points`` ((K, 2) per scan, map frame)
    less the sides of the object's cells' smallest rectangle, the larger difference. Beyond
    the paper: one scan's returns are not smeared by the pose's error from scan to scan, so
    a 0.50 m box reaches past a 0.45 m footstool's outline, which the blurred edge score
    cannot tell (both fit within a cell). How far the cells reach past the surfaces hangs on
    how the map was drawn (0 to a cell in the simulator's maps, by where the grid falls).
    ``rect``: the object's :func:`min_rect`, if known (:attr:`EdgeField.rect`). None: no
    scan had 3 returns near the object."""
    rect = min_rect(obj.shape_xy) if rect is None else rect
    spans = [sp for p in scan_points
             if (sp := side_spans(obj, pose_xytheta, np.asarray(p, dtype=float), rect=rect))
             is not None]
    seen = longest_sides(spans)
    if seen is None:
        return None
    return float(np.max(seen - np.sort(rect[2])))
