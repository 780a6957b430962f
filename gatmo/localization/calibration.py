"""Odometry noise fitted to data: AMCL's alphas from odometry beside reference poses.

AMCL's odometry models (:mod:`gatmo.localization.motion`) draw each filter update's motion
error from normals whose variance is a weighted sum of the step's squared rotations and
translation, the weights being alpha1..alpha5. Given the robot's odometry and a reference
trajectory (ground truth, or the poses of a built map) at the same stamps, this module cuts the
odometry into the steps the filter would update on (``update_min_d`` / ``update_min_a``),
measures each step's error in the model's own terms (rot1 / trans / rot2 for ``diff``,
trans / rot / strafe for ``omni``) and fits the alphas by maximum likelihood (heteroscedastic
normals, alphas >= 0, steps beyond 4 sigma trimmed as outliers: a reference's jumps, an odometry
reset).

The alphas are per update: the variance a model grows by is quadratic in the step, while a
random walk's grows with its length, so the fit depends on the update thresholds and is made at
the ones the filter will run with.

:func:`fit_linear_calibration` is the systematic part instead (least squares of the reference's
relative motions on the odometry's, the 3 x 3 matrix of the Freiburg robot-mapping course's
odometry calibration).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gatmo.geometry import compose, relative, wrap_angle

#: a step whose error is beyond this many predicted standard deviations is an outlier
OUTLIER_SIGMA = 4.0
#: odometry translation under which AMCL's diff model takes rot1 = 0 (motion.py)
_MIN_TRANS_M = 0.01
# the least variance of a component [rad^2 | m^2]: keeps a step with no motion (all features
# zero) from an infinite likelihood; far below any error a reference resolves
_VAR_FLOOR = 1e-12


def update_steps(odom_xytheta: np.ndarray, update_min_d_m: float,
                 update_min_a_rad: float) -> np.ndarray:
    """Indices (K + 1,) of the poses the filter updates at: the first, then each one whose
    odometry since the last update exceeds ``update_min_d_m`` in x or y (odom frame) or
    ``update_min_a_rad`` in heading, as AMCL's trigger (mcl.py). ``odom_xytheta`` (N, 3)."""
    odom = np.asarray(odom_xytheta, dtype=float)
    if len(odom) == 0:
        return np.zeros(0, dtype=np.int64)
    idx = [0]
    last = odom[0]
    for i in range(1, len(odom)):
        d = odom[i] - last
        if (abs(d[0]) > update_min_d_m or abs(d[1]) > update_min_d_m
                or abs(wrap_angle(d[2])) > update_min_a_rad):
            idx.append(i)
            last = odom[i]
    return np.asarray(idx, dtype=np.int64)


def _rot_noise(rot: np.ndarray) -> np.ndarray:
    """AMCL's rotation for the noise: the smaller of |rot| and |rot - pi| (backwards driving)."""
    return np.minimum(np.abs(wrap_angle(rot)), np.abs(wrap_angle(rot - math.pi)))


def motion_errors(odom_prev: np.ndarray, odom_now: np.ndarray, ref_prev: np.ndarray,
                  ref_now: np.ndarray, model: str) -> tuple[np.ndarray, np.ndarray]:
    """Each step's error in the model's terms and the model's features.

    Args:
        odom_prev, odom_now: (K, 3) odometry at the step's ends (odom frame).
        ref_prev, ref_now: (K, 3) reference poses at the same stamps (any fixed frame).
        model: ``diff[-corrected]`` or ``omni[-corrected]``.

    Returns:
        errors (K, 3): ``diff``: (rot1, trans, rot2) of the odometry minus those of the
        reference [rad, m, rad], rot1 NaN where the odometry's translation is under 1 cm (AMCL
        takes rot1 = 0 there); ``omni``: the reference's motion minus the odometry's along the
        odometry's direction, its heading change, and across [m, rad, m].
        features (K, 3, 5): the component's variance is ``features[k, c] @ alphas``
        (``-corrected`` models; ROS 1's ``diff`` / ``omni`` use it as the standard deviation).
    """
    op, on = np.atleast_2d(odom_prev), np.atleast_2d(odom_now)
    rp, rn = np.atleast_2d(ref_prev), np.atleast_2d(ref_now)
    k = len(op)
    feats = np.zeros((k, 3, 5))
    errs = np.zeros((k, 3))
    d_o = on[:, :2] - op[:, :2]
    d_r = rn[:, :2] - rp[:, :2]
    trans_o = np.hypot(d_o[:, 0], d_o[:, 1])
    dth_o = wrap_angle(on[:, 2] - op[:, 2])
    dth_r = wrap_angle(rn[:, 2] - rp[:, 2])
    if model.startswith("diff"):
        moving = trans_o >= _MIN_TRANS_M
        rot1_o = np.where(moving, wrap_angle(np.arctan2(d_o[:, 1], d_o[:, 0]) - op[:, 2]), 0.0)
        rot1_r = wrap_angle(np.arctan2(d_r[:, 1], d_r[:, 0]) - rp[:, 2])
        rot1_r = np.where(moving, rot1_r, 0.0)
        rot2_o = wrap_angle(dth_o - rot1_o)
        rot2_r = wrap_angle(dth_r - rot1_r)
        errs[:, 0] = np.where(moving, wrap_angle(rot1_o - rot1_r), np.nan)
        errs[:, 1] = trans_o - np.hypot(d_r[:, 0], d_r[:, 1])
        errs[:, 2] = wrap_angle(rot2_o - rot2_r)
        r1n, r2n, t2 = _rot_noise(rot1_o) ** 2, _rot_noise(rot2_o) ** 2, trans_o**2
        feats[:, 0, 0], feats[:, 0, 1] = r1n, t2  # rot1: a1 rot1^2 + a2 trans^2
        feats[:, 1, 2], feats[:, 1, 3] = t2, r1n + r2n  # trans: a3 trans^2 + a4 (rot1^2+rot2^2)
        feats[:, 2, 0], feats[:, 2, 1] = r2n, t2  # rot2: a1 rot2^2 + a2 trans^2
        return errs, feats
    if model.startswith("omni"):
        # the particle (at the reference's pose) moves along the odometry's bearing
        bearing = np.arctan2(d_o[:, 1], d_o[:, 0]) - op[:, 2]
        c, s = np.cos(bearing + rp[:, 2]), np.sin(bearing + rp[:, 2])
        errs[:, 0] = d_r[:, 0] * c + d_r[:, 1] * s - trans_o
        errs[:, 1] = wrap_angle(dth_r - dth_o)
        errs[:, 2] = d_r[:, 0] * s - d_r[:, 1] * c
        t2, r2 = trans_o**2, dth_o**2
        feats[:, 0, 2], feats[:, 0, 0] = t2, r2  # trans: a3 trans^2 + a1 dtheta^2
        feats[:, 1, 3], feats[:, 1, 1] = r2, t2  # rot: a4 dtheta^2 + a2 trans^2
        feats[:, 2, 0], feats[:, 2, 4] = r2, t2  # strafe: a1 dtheta^2 + a5 trans^2
        return errs, feats
    raise ValueError(f"unknown odometry model {model!r}")


def _nanmean(values: np.ndarray) -> np.ndarray:
    """Column means (3,) over the finite entries; NaN for a column with none (rot1 where the
    robot only turned in place)."""
    fin = np.isfinite(values)
    n = fin.sum(axis=0)
    total = np.where(fin, values, 0.0).sum(axis=0)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def reference_noise(odom_xytheta: np.ndarray, ref_xytheta: np.ndarray,
                    valid: np.ndarray | None = None,
                    sequence: np.ndarray | None = None) -> np.ndarray:
    """The reference's own white noise (3,): variances along and across the robot [m^2] and of
    its heading [rad^2], from scan to scan.

    Between consecutive scans the odometry is all but exact, so the reference's motion minus
    the odometry's is the reference's noise at both ends: white noise of variance s^2 gives
    consecutive differences a lag-one covariance of -s^2, which the odometry's own errors
    (independent from step to step) and slow drift (positive) do not fake. A pose graph's
    scans jitter by about a centimetre; at the filter's 0.1 m steps that is a tenth of a radian
    of heading between two poses, which the alphas must not be made to carry. Where no pair of
    consecutive scans has a reference (a SLAM's keyframes only), zeros. ``sequence`` (N,):
    which log each pose is from, for several logs laid end to end (default one)."""
    odom = np.asarray(odom_xytheta, dtype=float)
    ref = np.asarray(ref_xytheta, dtype=float)
    ok = np.ones(len(odom), bool) if valid is None else np.asarray(valid, bool)
    pair = ok[:-1] & ok[1:] & _same(sequence, len(odom))
    if pair.sum() < 20:
        return np.zeros(3)
    r = np.full((len(odom) - 1, 3), np.nan)
    i = np.flatnonzero(pair)
    r[i] = relative(ref[i], ref[i + 1]) - relative(odom[i], odom[i + 1])
    r[:, 2] = wrap_angle(r[:, 2])
    med = np.nanmedian(r, axis=0)
    mad = 1.4826 * np.nanmedian(np.abs(r - med), axis=0)
    good = np.all(np.abs(r - med) <= 6.0 * np.maximum(mad, 1e-12), axis=1) & pair
    both = good[:-1] & good[1:]
    if both.sum() < 20:
        return np.zeros(3)
    a, b = r[:-1][both], r[1:][both]
    cov = np.mean((a - a.mean(axis=0)) * (b - b.mean(axis=0)), axis=0)
    return np.maximum(-cov, 0.0)


def reference_variance(odom_prev: np.ndarray, odom_now: np.ndarray, model: str,
                       ref_var) -> np.ndarray:
    """What the reference's white noise ``ref_var`` (3,) (along, across [m^2], heading
    [rad^2]; :func:`reference_noise`) adds to each step's error variance (K, 3), in the terms
    of :func:`motion_errors`: the direction of travel between two noisy positions t apart is
    off by 2 s_across^2 / t^2, a heading difference by 2 s_heading^2."""
    vx, vy, vth = (float(v) for v in ref_var)
    op, on = np.atleast_2d(odom_prev), np.atleast_2d(odom_now)
    d = on[:, :2] - op[:, :2]
    t = np.hypot(d[:, 0], d[:, 1])
    out = np.zeros((len(op), 3))
    if model.startswith("diff"):
        moving = t >= _MIN_TRANS_M
        direction = 2.0 * vy / np.maximum(t, _MIN_TRANS_M) ** 2
        # rot1 = direction - theta0; rot2 = theta1 - direction (theta0 cancels), or a turn
        out[:, 0] = np.where(moving, direction + vth, 0.0)
        out[:, 1] = 2.0 * vx
        out[:, 2] = np.where(moving, direction + vth, 2.0 * vth)
        return out
    out[:, 0] = 2.0 * vx
    out[:, 1] = 2.0 * vth
    out[:, 2] = 2.0 * vy + t**2 * vth  # the start's heading turns the across axis
    return out


#: :func:`odometry_scales` compares the two over stretches of this much reference travel [m] ...
SCALE_STRETCH_M = 1.0
#: ... or of this much reference turn [rad]
SCALE_STRETCH_RAD = 0.5


def _same(sequence: np.ndarray | None, n: int) -> np.ndarray:
    """(n - 1,) whether poses i and i + 1 are from the same log."""
    if sequence is None:
        return np.ones(max(n - 1, 0), bool)
    seq = np.asarray(sequence)
    return seq[:-1] == seq[1:]


def odometry_scales(odom_xytheta: np.ndarray, ref_xytheta: np.ndarray,
                    valid: np.ndarray | None = None,
                    sequence: np.ndarray | None = None) -> tuple[float, float]:
    """(travel scale, turn scale): the reference's travel over the odometry's, and 1 / k of
    the odometry's heading changes regressed on the reference's (``dtheta_odom = k
    dtheta_ref``; above 1: the odometry under-reports turns); NaN where there is nothing to
    compare.

    Over stretches cut where the *reference* has travelled :data:`SCALE_STRETCH_M` or turned
    :data:`SCALE_STRETCH_RAD`. Not over the filter's steps: those are cut where the odometry
    crosses a threshold, which biases any ratio taken over them; not from scan to scan, where
    a reference's jitter adds travel and dilutes turns; and not a ratio of summed |turns|,
    which reads straight driving's heading noise as turning. ``sequence``: as
    :func:`reference_noise` (no stretch spans two logs)."""
    odom = np.asarray(odom_xytheta, dtype=float)
    ref = np.asarray(ref_xytheta, dtype=float)
    ok = np.ones(len(odom), bool) if valid is None else np.asarray(valid, bool)
    seq = np.zeros(len(odom), np.int64) if sequence is None else np.asarray(sequence)
    stretches = []
    start = None
    for j in np.flatnonzero(ok):
        if start is None or seq[j] != seq[start]:
            start = j
            continue
        d = ref[j] - ref[start]
        if math.hypot(d[0], d[1]) >= SCALE_STRETCH_M or abs(wrap_angle(d[2])) >= SCALE_STRETCH_RAD:
            stretches.append((start, j))
            start = j
    if len(stretches) < 2:
        return float("nan"), float("nan")
    c0, c1 = np.asarray(stretches).T
    d_o, d_r = relative(odom[c0], odom[c1]), relative(ref[c0], ref[c1])
    t_o, t_r = np.hypot(d_o[:, 0], d_o[:, 1]).sum(), np.hypot(d_r[:, 0], d_r[:, 1]).sum()
    a_o, a_r = wrap_angle(d_o[:, 2]), wrap_angle(d_r[:, 2])
    xx = float(np.dot(a_r, a_r))
    k = float(np.dot(a_r, a_o)) / xx if xx > 0 else float("nan")
    return (float(t_r / t_o) if t_o > 0 else float("nan"),
            1.0 / k if k > 0 else float("nan"))


def _variance_of(lin: np.ndarray, model: str, extra=0.0) -> np.ndarray:
    """The variance from the features' weighted sum ``lin`` (K, 3)."""
    if not model.endswith("-corrected"):  # ROS 1: the weighted sum is the standard deviation
        lin = lin * lin
    return lin + extra + _VAR_FLOOR


def _variance(feats: np.ndarray, alphas: np.ndarray, model: str, extra=0.0) -> np.ndarray:
    return _variance_of(feats @ alphas, model, extra)


def normalized_errors(errors: np.ndarray, features: np.ndarray, alphas, model: str,
                      extra=0.0) -> np.ndarray:
    """Errors (K, 3) over the standard deviation the alphas predict (plus ``extra`` (K, 3)
    variance, the reference's: :func:`reference_variance`): unit normals when the alphas fit
    (NaN where the error is)."""
    a = np.zeros(5)
    a[: len(alphas)] = np.asarray(alphas, dtype=float)
    return errors / np.sqrt(_variance(features, a, model, extra))


def _nll(alphas: np.ndarray, e2: np.ndarray, feats: np.ndarray, mask: np.ndarray,
         model: str, extra) -> tuple[float, np.ndarray]:
    """Negative log-likelihood (constant dropped) and its gradient in the alphas."""
    lin = feats @ alphas  # (K, 3)
    var = _variance_of(lin, model, extra)
    r = np.where(mask, 0.5 * (np.log(var) + e2 / var), 0.0)
    dv = np.where(mask, 0.5 * (1.0 / var - e2 / var**2), 0.0)  # d nll / d var
    if not model.endswith("-corrected"):
        dv = dv * 2.0 * lin
    grad = np.einsum("kc,kcj->j", dv, feats)
    return float(r.sum()), grad


@dataclass(frozen=True)
class OdometryNoiseFit:
    """AMCL's alphas fitted to a log's odometry against reference poses.

    Attributes:
        model: the odometry model the alphas are for.
        alphas: (alpha1, ..., alpha5); alpha5 (strafe) only fitted for ``omni``, else 0.
        update_min_d_m, update_min_a_rad: the update thresholds the steps were cut at.
        steps: steps used; ``rejected``: steps trimmed beyond :data:`OUTLIER_SIGMA`.
        z_std: (3,) standard deviation of the used steps' normalized errors at the fit (1 when
            the model's shape fits; per component: rot1 / trans / rot2 or trans / rot / strafe).
        mean_error: (3,) the used steps' mean error (a bias the alphas absorb).
        trans_scale, rot_scale: the reference's travel over the odometry's, and its turns
            over the odometry's (above 1: the odometry under-reports them;
            :func:`odometry_scales`).
        step_mean_m, step_mean_rad: the used steps' mean odometry translation and |rotation|.
        reference_std: (3,) the reference's noise taken out (along, across [m], heading
            [rad]; :func:`reference_noise`).
    """

    model: str
    alphas: tuple[float, float, float, float, float]
    update_min_d_m: float
    update_min_a_rad: float
    steps: int
    rejected: int
    z_std: tuple[float, float, float]
    mean_error: tuple[float, float, float]
    trans_scale: float
    rot_scale: float
    step_mean_m: float
    step_mean_rad: float
    reference_std: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _fit_alphas(errors: np.ndarray, feats: np.ndarray, model: str,
                keep: np.ndarray, extra: np.ndarray) -> np.ndarray:
    from scipy.optimize import minimize, nnls

    omni = model.startswith("omni")
    n_par = 5 if omni else 4
    f = feats[..., :n_par]
    mask = np.isfinite(errors) & keep[:, None]
    e = np.where(mask, errors, 0.0)
    e2 = e * e
    # a start from least squares of the squared (or absolute) errors on the features
    if model.endswith("-corrected"):
        target = np.maximum(e2 - extra, 0.0)
    else:
        target = np.sqrt(np.maximum(e2 - extra, 0.0))
    rows = mask.reshape(-1)
    x0, _ = nnls(f.reshape(-1, n_par)[rows], target.reshape(-1)[rows])
    x0 = np.maximum(x0, 1e-6)
    res = minimize(_nll, x0, args=(e2, f, mask, model, extra), jac=True, method="L-BFGS-B",
                   bounds=[(0.0, None)] * n_par)
    a = np.zeros(5)
    a[:n_par] = res.x
    return a


def fit_odometry_noise(odom_xytheta: np.ndarray, ref_xytheta: np.ndarray, *,
                       model: str = "diff-corrected", update_min_d_m: float = 0.25,
                       update_min_a_rad: float = 0.2, valid: np.ndarray | None = None,
                       steps: np.ndarray | None = None,
                       pairs: np.ndarray | None = None,
                       sequence: np.ndarray | None = None,
                       reference_var=(0.0, 0.0, 0.0)) -> OdometryNoiseFit:
    """Fit AMCL's alphas to odometry beside reference poses at the same stamps.

    Args:
        odom_xytheta: (N, 3) odometry poses (odom frame).
        ref_xytheta: (N, 3) reference poses at the same stamps (any fixed frame: only their
            relative motions are used).
        model: AMCL odometry model (``diff-corrected`` | ``omni-corrected`` | ``diff`` |
            ``omni``).
        update_min_d_m, update_min_a_rad: the filter's update thresholds.
        valid: (N,) bool, poses with a reference (default all); a step is used when both its
            ends have one.
        steps: (K + 1,) update indices to use instead of cutting them here (:func:`update_steps`).
        pairs: (K, 2) the steps' (start, end) indices instead: several logs laid end to end.
        sequence: (N,) which log each pose is from, with ``pairs`` (for the scales).
        reference_var: (3,) the reference's own noise (:func:`reference_noise`), added to
            each step's predicted variance so the alphas do not carry it.

    Raises:
        ValueError: shapes differ, or fewer than 10 steps to fit on.
    """
    odom = np.asarray(odom_xytheta, dtype=float)
    ref = np.asarray(ref_xytheta, dtype=float)
    if odom.shape != ref.shape or odom.ndim != 2 or odom.shape[1] != 3:
        raise ValueError(f"odometry {odom.shape} and reference {ref.shape} must both be (N, 3)")
    ok = np.ones(len(odom), bool) if valid is None else np.asarray(valid, bool)
    i0, i1 = _step_pairs(odom, update_min_d_m, update_min_a_rad, steps, pairs)
    use = ok[i0] & ok[i1]
    i0, i1 = i0[use], i1[use]
    if len(i0) < 10:
        raise ValueError(f"{len(i0)} steps with a reference at both ends: need at least 10")
    errors, feats = motion_errors(odom[i0], odom[i1], ref[i0], ref[i1], model)
    extra = reference_variance(odom[i0], odom[i1], model, reference_var)
    keep = np.ones(len(i0), bool)
    alphas = _fit_alphas(errors, feats, model, keep, extra)
    for _ in range(10):  # trim the outliers, refit, until the kept set stands
        z = normalized_errors(errors, feats, alphas, model, extra)
        new = ~np.any(np.abs(np.nan_to_num(z)) > OUTLIER_SIGMA, axis=1)
        if np.array_equal(new, keep):
            break
        keep = new
        alphas = _fit_alphas(errors, feats, model, keep, extra)
    z = normalized_errors(errors[keep], feats[keep], alphas, model, extra[keep])
    d_o = relative(odom[i0[keep]], odom[i1[keep]])
    trans_scale, rot_scale = odometry_scales(odom, ref, ok, sequence)
    return OdometryNoiseFit(
        model=model, alphas=tuple(float(a) for a in alphas), update_min_d_m=update_min_d_m,
        update_min_a_rad=update_min_a_rad, steps=int(keep.sum()), rejected=int((~keep).sum()),
        z_std=tuple(float(v) for v in np.sqrt(_nanmean(z**2))),
        mean_error=tuple(float(v) for v in _nanmean(errors[keep])),
        trans_scale=trans_scale, rot_scale=rot_scale,
        step_mean_m=float(np.hypot(d_o[:, 0], d_o[:, 1]).mean()),
        step_mean_rad=float(np.abs(d_o[:, 2]).mean()),
        reference_std=tuple(float(v) for v in np.sqrt(np.asarray(reference_var, float))))


def _step_pairs(odom: np.ndarray, update_min_d_m: float, update_min_a_rad: float,
                steps: np.ndarray | None, pairs: np.ndarray | None):
    """(i0, i1): the steps' start and end indices, from ``pairs`` (K, 2), else ``steps``
    (K + 1,), else cut at the thresholds."""
    if pairs is not None:
        p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        return p[:, 0], p[:, 1]
    idx = update_steps(odom, update_min_d_m, update_min_a_rad) if steps is None else steps
    return np.asarray(idx[:-1]), np.asarray(idx[1:])


def step_z_std(odom_xytheta: np.ndarray, ref_xytheta: np.ndarray, alphas, *, model: str,
               steps: np.ndarray | None = None, pairs: np.ndarray | None = None,
               valid: np.ndarray | None = None,
               reference_var=(0.0, 0.0, 0.0)) -> tuple[float, float, float]:
    """RMS of the normalized errors (3,) of the given alphas (and the reference's noise
    ``reference_var``) over the update ``steps``, outliers beyond :data:`OUTLIER_SIGMA` of the
    alphas dropped: about 1 when they predict these steps' errors, above when they are too
    small, below when too large."""
    odom = np.asarray(odom_xytheta, dtype=float)
    ref = np.asarray(ref_xytheta, dtype=float)
    ok = np.ones(len(odom), bool) if valid is None else np.asarray(valid, bool)
    if steps is None and pairs is None:
        raise ValueError("step_z_std needs steps or pairs")
    i0, i1 = _step_pairs(odom, 0.0, 0.0, steps, pairs)
    use = ok[i0] & ok[i1]
    errors, feats = motion_errors(odom[i0[use]], odom[i1[use]], ref[i0[use]], ref[i1[use]],
                                  model)
    extra = reference_variance(odom[i0[use]], odom[i1[use]], model, reference_var)
    z = normalized_errors(errors, feats, alphas, model, extra)
    z = z[~np.any(np.abs(np.nan_to_num(z)) > OUTLIER_SIGMA, axis=1)]
    return tuple(float(v) for v in np.sqrt(_nanmean(z**2)))


def fit_linear_calibration(odom_motions_xytheta: np.ndarray,
                           ref_motions_xytheta: np.ndarray) -> np.ndarray:
    """The 3 x 3 matrix ``K`` with ``ref_motion ~ K @ odom_motion`` by least squares.

    Args:
        odom_motions_xytheta: (K, 3) relative motions by odometry (dx, dy [m], dtheta [rad],
            in the robot frame at the step's start).
        ref_motions_xytheta: (K, 3) the same steps' reference motions.
    """
    u = np.asarray(odom_motions_xytheta, dtype=float)
    r = np.asarray(ref_motions_xytheta, dtype=float)
    if u.shape != r.shape or u.ndim != 2 or u.shape[1] != 3:
        raise ValueError(f"motions {u.shape} and {r.shape} must both be (K, 3)")
    k, *_ = np.linalg.lstsq(u, r, rcond=None)
    return k.T


def apply_linear_calibration(odom_xytheta: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Odometry poses (N, 3) re-chained with each relative motion corrected by ``K`` (3, 3);
    starts at the first pose."""
    odom = np.asarray(odom_xytheta, dtype=float)
    if len(odom) < 2:
        return odom.copy()
    steps = relative(odom[:-1], odom[1:]) @ np.asarray(K, dtype=float).T
    out = np.empty_like(odom)
    out[0] = odom[0]
    for i, s in enumerate(steps):
        out[i + 1] = compose(out[i], s)
    return out


__all__ = ["OUTLIER_SIGMA", "SCALE_STRETCH_M", "SCALE_STRETCH_RAD", "OdometryNoiseFit",
           "apply_linear_calibration", "fit_linear_calibration", "fit_odometry_noise",
           "motion_errors", "normalized_errors", "odometry_scales", "reference_noise",
           "reference_variance", "step_z_std", "update_steps"]
