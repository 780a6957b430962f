"""Trajectory metrics (pure numpy): absolute error in a fixed map frame, and the relations
metric of Kümmerle et al. 2009."""

from __future__ import annotations

import numpy as np

from gatmo.geometry import (
    compose,
    interpolate_poses,
    nearest_index,
    points_to_beams,
    relative,
    wrap_angle,
)


def align_se2(src_xy: np.ndarray, dst_xy: np.ndarray, *, with_scale: bool = False):
    """The rigid 2D transform (x, y, theta), and with ``with_scale`` the scale too, that best
    maps the points ``src_xy`` (N, 2) onto ``dst_xy`` (N, 2) in the least-squares sense
    (Umeyama 1991, as evo's ``--align`` / ``--correct_scale``): dst ~ scale R(theta) src +
    (x, y). Returns (T (3,), scale); scale is 1.0 without ``with_scale``. Needs N >= 2
    distinct points for a rotation."""
    src = np.asarray(src_xy, dtype=float)
    dst = np.asarray(dst_xy, dtype=float)
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    h = (src - ms).T @ (dst - md)  # cross-covariance, (2, 2)
    # the angle maximising trace(R h): atan2 of its antisymmetric over its symmetric part
    theta = np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    c, s = np.cos(theta), np.sin(theta)
    scale = 1.0
    if with_scale:
        var = float(np.sum((src - ms) ** 2))
        scale = float((c * (h[0, 0] + h[1, 1]) + s * (h[0, 1] - h[1, 0])) / var) if var else 1.0
    t = md - scale * (np.array([[c, -s], [s, c]]) @ ms)
    return np.array([t[0], t[1], theta]), scale


def _ground_truth_at(t: np.ndarray, gt_stamps_s, gt_xytheta, max_dt_s: float):
    """(mask (N,) of the stamps ``t`` within ``max_dt_s`` of the ground truth's span, the
    ground truth interpolated at those stamps (M, 3))."""
    gt_t = np.asarray(gt_stamps_s, dtype=float)
    ok = (t >= gt_t[0] - max_dt_s) & (t <= gt_t[-1] + max_dt_s)
    return ok, (interpolate_poses(gt_t, gt_xytheta, t[ok]) if ok.any() else np.zeros((0, 3)))


def ate(
    stamps_s: np.ndarray,
    est_xytheta: np.ndarray,
    gt_stamps_s: np.ndarray,
    gt_xytheta: np.ndarray,
    *,
    max_dt_s: float = 0.05,
    lost_m: float = 0.5,
    align: bool = False,
    with_scale: bool = False,
) -> dict:
    """Position error, without alignment by default (the map frame is fixed).

    Ground truth is interpolated at the estimate's stamps; estimates outside the ground truth's
    time span (by more than ``max_dt_s``) are not scored. With ``align`` the estimate is first
    moved by the rigid transform that fits its positions best onto the ground truth's
    (:func:`align_se2`; for a trajectory in a frame of its own, such as a map built from the
    log), returned as ``T_gt_est`` (x, y, theta); ``with_scale`` fits a scale too (returned
    as ``scale``: a map or a ground truth at another scale). Returns rmse_m, median_m, max_m,
    mean_rot_deg, lost_fraction (error > ``lost_m``) and n.
    """
    t = np.asarray(stamps_s, dtype=float)
    est = np.asarray(est_xytheta, dtype=float)
    ok, g = _ground_truth_at(t, gt_stamps_s, gt_xytheta, max_dt_s)
    if not ok.any():
        nan = float("nan")
        return dict(rmse_m=nan, median_m=nan, max_m=nan, mean_rot_deg=nan, lost_fraction=nan,
                    n=0)
    extra = {}
    if align:
        T, scale = align_se2(est[ok, :2], g[:, :2], with_scale=with_scale)
        est = est.copy()
        est[ok] = compose(T, est[ok] * [scale, scale, 1.0])
        extra["T_gt_est"] = [float(v) for v in T]
        extra["scale"] = scale
    e = np.hypot(*(est[ok, :2] - g[:, :2]).T)
    r = np.abs(wrap_angle(est[ok, 2] - g[:, 2]))
    return dict(
        rmse_m=float(np.sqrt(np.mean(e**2))),
        median_m=float(np.median(e)),
        max_m=float(np.max(e)),
        mean_rot_deg=float(np.degrees(np.mean(r))),
        lost_fraction=float(np.mean(e > lost_m)),
        n=int(ok.sum()),
        **extra,
    )


def rpe(
    stamps_s: np.ndarray,
    est_xytheta: np.ndarray,
    gt_stamps_s: np.ndarray,
    gt_xytheta: np.ndarray,
    *,
    delta_m: float = 1.0,
    max_dt_s: float = 0.05,
) -> dict:
    """Relative pose error over ``delta_m`` of travel (as evo's ``evo_rpe --delta 1 --delta_unit
    m``): for each estimate pose i with ground truth, the first later pose j the ground truth
    has travelled ``delta_m`` to; the error of the estimate's motion i -> j against the ground
    truth's, e = relative(gt_ij, est_ij). Frame-free: no alignment is needed. Returns
    trans_rmse_m, trans_mean_m, trans_median_m, rot_mean_deg and n (pairs)."""
    t = np.asarray(stamps_s, dtype=float)
    est = np.asarray(est_xytheta, dtype=float)
    ok, g = _ground_truth_at(t, gt_stamps_s, gt_xytheta, max_dt_s)
    nan = float("nan")
    if ok.sum() < 2:
        return dict(trans_rmse_m=nan, trans_mean_m=nan, trans_median_m=nan, rot_mean_deg=nan,
                    n=0)
    e_ok = est[ok]
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(g[:, :2], axis=0).T))])
    i = np.arange(len(g))
    j = np.searchsorted(travel, travel + delta_m)  # first pose delta_m of travel on
    keep = j < len(g)
    i, j = i[keep], j[keep]
    if len(i) == 0:
        return dict(trans_rmse_m=nan, trans_mean_m=nan, trans_median_m=nan, rot_mean_deg=nan,
                    n=0)
    err = relative(relative(g[i], g[j]), relative(e_ok[i], e_ok[j]))
    tr = np.hypot(err[:, 0], err[:, 1])
    return dict(trans_rmse_m=float(np.sqrt(np.mean(tr**2))), trans_mean_m=float(tr.mean()),
                trans_median_m=float(np.median(tr)),
                rot_mean_deg=float(np.degrees(np.mean(np.abs(wrap_angle(err[:, 2]))))),
                n=int(len(i)))


def relations_error(stamps_s, poses_xytheta, relations, *, max_dt_s: float = 0.002) -> dict:
    """Kümmerle 2009: for each relation (t1, t2, rel), the error of the estimated relative pose.

    The estimate's pose nearest in time to each relation stamp is used; relations without a pose
    within ``max_dt_s`` are skipped. Error e = relative(rel_est, rel_gt): translation |e_xy|,
    rotation |e_theta|. Returns mean and std of both, n_used, n_total.
    """
    t = np.asarray(stamps_s, dtype=float)
    p = np.asarray(poses_xytheta, dtype=float)
    order = np.argsort(t)
    t, p = t[order], p[order]

    def nearest(q):
        j = nearest_index(t, q)
        return j, np.abs(t[j] - q)

    i1, d1 = nearest(np.asarray(relations.t1_s))
    i2, d2 = nearest(np.asarray(relations.t2_s))
    use = (d1 <= max_dt_s) & (d2 <= max_dt_s)
    n_total = int(len(use))
    if not use.any():
        nan = float("nan")
        return dict(trans_mean_m=nan, trans_std_m=nan, rot_mean_deg=nan, rot_std_deg=nan,
                    n_used=0, n_total=n_total)
    est_rel = relative(p[i1[use]], p[i2[use]])
    e = relative(est_rel, np.asarray(relations.rel_xytheta)[use])
    tr = np.hypot(e[:, 0], e[:, 1])
    rot = np.degrees(np.abs(wrap_angle(e[:, 2])))
    return dict(
        trans_mean_m=float(tr.mean()),
        trans_std_m=float(tr.std()),
        rot_mean_deg=float(rot.mean()),
        rot_std_deg=float(rot.std()),
        n_used=int(use.sum()),
        n_total=n_total,
    )


def object_sightings(
    cells_xy: np.ndarray,
    laser_pose_xytheta: np.ndarray,
    angles_rad: np.ndarray,
    ranges_m: np.ndarray,
    valid: np.ndarray,
    *,
    max_range_m: float,
    cell_m: float = 0.05,
    hit_tol_m: float = 0.1,
    pass_margin_m: float = 0.2,
) -> tuple[int, int]:
    """How one scan saw a thing: (beams ending on it, beams passing through it).

    ``cells_xy`` (M, 2) [m]: the thing's occupied cells in the map frame; ``laser_pose_xytheta``
    (3,): the laser's pose in the map frame (from reference poses, not the estimate under test);
    ``angles_rad``, ``ranges_m``, ``valid`` (B,): the scan. Each cell within ``max_range_m`` is
    assigned the beam nearest its bearing, if that beam passes within half a cell diagonal of
    it. A beam *hits* when its range is within ``hit_tol_m`` of one of its cells' distances,
    *passes* when it is not a hit and ends (or, invalid, returns nothing) more than
    ``pass_margin_m`` beyond its nearest cell: something stood there, or nothing did.
    """
    angles = np.asarray(angles_rad, dtype=float)
    r_c, b_c, j = points_to_beams(cells_xy, laser_pose_xytheta, angles)
    on = ((r_c < max_range_m) & (b_c >= angles[0] - 1e-9) & (b_c <= angles[-1] + 1e-9)
          & (r_c * np.abs(b_c - angles[j]) <= 0.5 * np.sqrt(2.0) * cell_m))
    if not on.any():
        return 0, 0
    j, r_c = j[on], r_c[on]
    ranges = np.where(valid, np.asarray(ranges_m, dtype=float), np.inf)
    hit_cell = np.abs(ranges[j] - r_c) <= hit_tol_m
    beams = np.unique(j)
    hit = np.zeros(len(angles), dtype=bool)
    hit[j[hit_cell]] = True
    nearest = np.full(len(angles), np.inf)
    np.minimum.at(nearest, j, r_c)
    passed = ~hit[beams] & (ranges[beams] > nearest[beams] + pass_margin_m)
    return int(hit[beams].sum()), int(passed.sum())


def visits(stamps_s: np.ndarray, seen: np.ndarray, *, gap_s: float = 30.0) -> list[tuple[int, int]]:
    """Index ranges [first, last] of the scans with ``seen`` (N,) True, split where more than
    ``gap_s`` seconds pass between two of them: the robot's separate visits to a place."""
    idx = np.flatnonzero(np.asarray(seen, dtype=bool))
    if len(idx) == 0:
        return []
    t = np.asarray(stamps_s, dtype=float)[idx]
    cut = np.flatnonzero(np.diff(t) > gap_s)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [len(idx) - 1]])
    return [(int(idx[a]), int(idx[b])) for a, b in zip(starts, ends, strict=True)]
