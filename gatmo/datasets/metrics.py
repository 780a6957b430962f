"""Trajectory metrics (pure numpy): absolute error in a fixed map frame, and the relations
metric of Kümmerle et al. 2009."""

from __future__ import annotations

import numpy as np

from gatmo.geometry import interpolate_poses, relative, wrap_angle


def ate(
    stamps_s: np.ndarray,
    est_xytheta: np.ndarray,
    gt_stamps_s: np.ndarray,
    gt_xytheta: np.ndarray,
    *,
    max_dt_s: float = 0.05,
    lost_m: float = 0.5,
) -> dict:
    """Position error without alignment (the map frame is fixed).

    Ground truth is interpolated at the estimate's stamps; estimates outside the ground truth's
    time span (by more than ``max_dt_s``) are not scored. Returns rmse_m, median_m, max_m,
    mean_rot_deg, lost_fraction (error > ``lost_m``) and n.
    """
    t = np.asarray(stamps_s, dtype=float)
    est = np.asarray(est_xytheta, dtype=float)
    gt_t = np.asarray(gt_stamps_s, dtype=float)
    ok = (t >= gt_t[0] - max_dt_s) & (t <= gt_t[-1] + max_dt_s)
    if not ok.any():
        nan = float("nan")
        return dict(rmse_m=nan, median_m=nan, max_m=nan, mean_rot_deg=nan, lost_fraction=nan,
                    n=0)
    g = interpolate_poses(gt_t, gt_xytheta, t[ok])
    e = np.hypot(*(est[ok, :2] - g[:, :2]).T)
    r = np.abs(wrap_angle(est[ok, 2] - g[:, 2]))
    return dict(
        rmse_m=float(np.sqrt(np.mean(e**2))),
        median_m=float(np.median(e)),
        max_m=float(np.max(e)),
        mean_rot_deg=float(np.degrees(np.mean(r))),
        lost_fraction=float(np.mean(e > lost_m)),
        n=int(ok.sum()),
    )


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
        i = np.clip(np.searchsorted(t, q), 1, len(t) - 1)
        j = np.where(np.abs(t[i - 1] - q) <= np.abs(t[i] - q), i - 1, i)
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
