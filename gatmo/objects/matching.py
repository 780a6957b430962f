"""Matching a chair hypothesis to a map object (paper, Sec. V): principal axes by SVD give
candidate alignments (four per axis pair: the 2- and 4-fold ambiguity of boxes), each scored on
a gaussian-blurred grid of the object's edge points with a local search around it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from gatmo.geometry import wrap_angle
from gatmo.objects.objectmap import MapObject


@dataclass
class Match:
    object_id: int
    score: float
    pose_xytheta: np.ndarray  # new p_i (object frame -> map)


class EdgeField:
    """exp(-d^2 / 2 sigma^2) of the distance to the object's edge points, in its own frame."""

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
        self.lo, self.res = lo, res

    def score(self, q_xy: np.ndarray) -> np.ndarray:
        """Mean field value of point sets q (..., P, 2) in the object frame -> (...)."""
        idx = np.floor((q_xy - self.lo) / self.res).astype(np.int64)
        h, w = self.val.shape
        ok = (idx[..., 0] >= 0) & (idx[..., 0] < w) & (idx[..., 1] >= 0) & (idx[..., 1] < h)
        v = np.where(ok, self.val[np.clip(idx[..., 1], 0, h - 1), np.clip(idx[..., 0], 0, w - 1)],
                     0.0)
        return v.mean(axis=-1)


def principal_angle(points_xy: np.ndarray) -> float:
    d = points_xy - points_xy.mean(axis=0)
    if len(d) < 2:
        return 0.0
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    return float(np.arctan2(vt[0, 1], vt[0, 0]))


def match_points(points_xy: np.ndarray, obj: MapObject, cfg, field: EdgeField | None = None,
                 prior_yaw: float | None = None) -> Match:
    """Best pose of ``obj`` explaining world points (P, 2), with its score in [0, 1]."""
    field = field or EdgeField(obj, cfg.match_edge_sigma_m)
    c_p = points_xy.mean(axis=0)
    a_p = principal_angle(points_xy)
    a_o = principal_angle(obj.edge_xy if len(obj.edge_xy) > 2 else obj.shape_xy)
    best = (-1.0, None)
    step = max(obj.resolution_m, 0.025)
    offs = np.arange(-cfg.match_search_m, cfg.match_search_m + 1e-9, step)
    dth = np.radians(np.arange(-cfg.match_search_deg, cfg.match_search_deg + 1e-9, 3.0))
    for k in range(4):
        th0 = wrap_angle(a_p - a_o + k * np.pi / 2)
        for th in th0 + dth:
            # the object's centroid (0 in its frame) goes to the points' centroid + offset
            R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            base = (points_xy - c_p) @ R  # = R^T (p - c_p)
            ox, oy = np.meshgrid(offs, offs, indexing="ij")
            t = np.stack([ox.ravel(), oy.ravel()], axis=1)  # translation in the map frame
            tl = t @ R  # R^T t
            q = base[None, :, :] - tl[:, None, :]
            s = field.score(q)
            i = int(np.argmax(s))
            if s[i] > best[0] + 1e-9 or (
                abs(s[i] - best[0]) <= 1e-9 and prior_yaw is not None and best[1] is not None
                and abs(wrap_angle(th - prior_yaw)) < abs(wrap_angle(best[1][2] - prior_yaw))
            ):
                best = (float(s[i]), np.array([c_p[0] + t[i, 0], c_p[1] + t[i, 1], th]))
    score, pose = best
    # refine: finer local search around the best
    fine = np.arange(-step, step + 1e-9, step / 4)
    for th in pose[2] + np.radians(np.arange(-3.0, 3.01, 0.5)):
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        ox, oy = np.meshgrid(fine, fine, indexing="ij")
        t = np.stack([ox.ravel(), oy.ravel()], axis=1) + pose[:2]
        q = (points_xy[None, :, :] - t[:, None, :]) @ R
        s = field.score(q)
        i = int(np.argmax(s))
        if s[i] > score:
            score, pose = float(s[i]), np.array([t[i, 0], t[i, 1], th])
    if prior_yaw is not None:
        pose[2] = _closest_symmetric_yaw(obj, field, points_xy, pose, prior_yaw, score)
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
