"""``gatmo calibrate``: AMCL's odometry alphas fitted to a log against reference poses.

The reference is a TUM trajectory (ground truth, or what ``gatmo map build --poses-out`` writes
for a raw log: only relative motions are used, so any fixed frame will do) or the log's own
ground truth. The fit (:func:`gatmo.localization.calibration.fit_odometry_noise`) is made at the
update thresholds and odometry model of the AMCL configuration given (else AMCL's defaults),
checked on held-out data (fitted on the log's first half, scored on its second), and the
current alphas are scored on the same steps, so a user sees how far off they are. A reference
at every scan has its own noise measured (a pose graph jitters by about a centimetre, a tenth of
a radian of direction over a 0.1 m step) and taken out, so the alphas do not carry it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from gatmo.errors import DataError, GatmoError
from gatmo.geometry import relative

#: a scan has a reference when one of the reference's samples is this close in time
MAX_REFERENCE_DT_S = 0.05
#: ... or when the reference's samples either side are at most this far apart (interpolated)
MAX_REFERENCE_GAP_S = 1.0
#: steps longer on average than this many times the filter's: the fit is for them
COARSE_STEPS = 1.5
#: a fitted alpha below this is reported as none of that noise
NEGLIGIBLE_ALPHA = 1e-4


def reference_at(stamps_s: np.ndarray, ref_stamps_s: np.ndarray, ref_xytheta: np.ndarray,
                 max_dt_s: float = MAX_REFERENCE_DT_S,
                 max_gap_s: float = MAX_REFERENCE_GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """(valid (N,), poses (N, 3)): the reference at ``stamps_s``, interpolated, where it has a
    sample within ``max_dt_s`` or samples at most ``max_gap_s`` apart either side (NaN
    elsewhere). A sparse reference (a SLAM's keyframes) thus counts only at its own stamps."""
    from gatmo.geometry import interpolate_poses

    t = np.asarray(ref_stamps_s, dtype=float)
    order = np.argsort(t, kind="stable")
    t, p = t[order], np.asarray(ref_xytheta, dtype=float)[order]
    q = np.asarray(stamps_s, dtype=float)
    j = np.searchsorted(t, q)
    lo, hi = np.clip(j - 1, 0, len(t) - 1), np.clip(j, 0, len(t) - 1)
    near = np.minimum(np.abs(t[hi] - q), np.abs(t[lo] - q)) <= max_dt_s
    inside = (q >= t[0]) & (q <= t[-1])
    valid = near | (inside & (t[hi] - t[lo] <= max_gap_s))
    out = np.full((len(q), 3), np.nan)
    if valid.any():
        out[valid] = interpolate_poses(t, p, q[valid])
    return valid, out


def calibrate_odometry(
    log: str | Path | Sequence[str | Path],
    *,
    reference_path: str | Path | Sequence[str | Path] | None = None,
    stamp_offset_s: float = 0.0,
    params_path: str | Path | None = None,
    config_path: str | Path | None = None,
    preset: str | None = None,
    fmt: str | None = None,
    max_scans: int | None = None,
    out_path: str | Path | None = None,
    config=None,
    min_alpha: float = 0.0,
    report_path: str | Path | None = None,
) -> dict:
    """Fit AMCL's odometry alphas to ``log``'s odometry against the reference.

    Args:
        log: a log or bag with scans and odometry (the odometry at the scans' stamps is used),
            or several of one robot, pooled (no step spans two).
        reference_path: TUM reference poses of the robot base, one per log; else the logs'
            own ground truth.
        stamp_offset_s: added to the reference's stamps (radish's ``intel-corrected`` runs
            976052857.33753 s behind the Intel bag).
        params_path / config_path / preset: the AMCL configuration whose odometry model and
            update thresholds the fit is made at, and whose alphas are scored (as ``localize``).
        out_path: write the fitted alphas, model and thresholds as AMCL YAML here (Nav2's
            layout, or ROS 1's when ``params_path`` is a ROS 1 file).
        config: an :class:`AmclConfig` instead of the files.
        min_alpha: the least alpha written to ``out_path`` (the fit may find none of a kind of
            noise, and a filter given none cannot spread its particles that way).
        report_path: write the returned dict here as JSON (NaN as null, ``"format":
            "gatmo-calibration"``; ``gatmo info`` reads it).

    Returns:
        a flat dict: ``model``, ``update_min_d_m``, ``update_min_a_rad``, ``steps``,
        ``rejected``, ``alphas`` (fitted), ``current_alphas``, ``z_std_*`` (RMS of the
        normalized errors per component: 1 when the alphas predict the errors; ``fitted``
        in-sample, ``holdout`` fitted on the first half of the steps (in the order of the
        logs) and scored on the second,
        ``current`` the configuration's alphas), ``trans_scale``, ``rot_scale`` and
        ``mean_error`` (biases the alphas absorb), ``reference_noise_std`` (the reference's own
        scan-to-scan noise, along / across the robot [m] and heading [rad], taken out of the
        errors first: :func:`gatmo.localization.calibration.reference_noise`), ``reference``,
        ``out``.

    Raises:
        DataError: no reference, or too few steps with one.
    """
    from gatmo._io import atomic_write_text
    from gatmo.localization.calibration import (
        fit_odometry_noise,
        reference_noise,
        step_z_std,
        update_steps,
    )
    from gatmo.localization.params import amcl_yaml_dialect, amcl_yaml_text
    from gatmo.pipeline.config import load_amcl_config
    from gatmo.pipeline.runs import ground_truth_of, load_scans

    cfg = config if config is not None else load_amcl_config(params_path, config_path, preset)
    logs = [log] if isinstance(log, str | Path) else list(log)
    if reference_path is None or isinstance(reference_path, str | Path):
        refs = [reference_path] * len(logs) if reference_path is None or len(logs) == 1 else None
    else:
        refs = list(reference_path)
    if not logs or refs is None or len(refs) != len(logs):
        raise GatmoError(f"{len(logs)} logs and {1 if refs is None else len(refs)} references: "
                         "give one --reference per log, or none")
    model = cfg.odom_model
    d, a = cfg.update_min_d_m, cfg.update_min_a_rad
    odoms, poses, valids, pairs, filter_pairs, sources = [], [], [], [], [], []
    n0 = 0
    for lg, rp in zip(logs, refs, strict=True):
        scans = load_scans(lg, fmt, max_scans)
        gt = ground_truth_of(scans, lg, rp, stamp_offset_s=stamp_offset_s)
        if gt is None:
            raise DataError("no reference poses: the log has no ground truth; give --reference "
                            "(e.g. gatmo map build LOG --poses-out POSES.tum)", file=lg)
        stamps = np.array([s.stamp_s for s in scans])
        odom = np.array([s.odom_pose_xytheta for s in scans])
        valid, ref = reference_at(stamps, gt.stamps_s, gt.poses_xytheta)
        # the filter's update steps among the scans with a reference: a reference sparser
        # than the updates gives steps as long as its spacing
        have = np.flatnonzero(valid)
        steps = have[update_steps(odom[have], d, a)] if len(have) else have
        every = update_steps(odom, d, a)
        pairs.append(np.c_[steps[:-1], steps[1:]] + n0)
        filter_pairs.append(np.c_[every[:-1], every[1:]] + n0)
        odoms.append(odom)
        poses.append(ref)
        valids.append(valid)
        sources.append(gt.source)
        n0 += len(scans)
    odom, ref, valid = np.vstack(odoms), np.vstack(poses), np.concatenate(valids)
    seq = np.concatenate([np.full(len(o), k) for k, o in enumerate(odoms)])
    steps = np.vstack(pairs)
    current = (cfg.alpha1, cfg.alpha2, cfg.alpha3, cfg.alpha4, cfg.alpha5)
    half = len(steps) // 2
    # the reference's own scan-to-scan noise (a pose graph's jitter) is not the odometry's
    rv = reference_noise(odom, ref, valid, seq)
    kw = {"model": model, "update_min_d_m": d, "update_min_a_rad": a, "valid": valid,
          "sequence": seq, "reference_var": rv}
    try:
        fit = fit_odometry_noise(odom, ref, pairs=steps, **kw)
    except ValueError as exc:
        raise DataError(f"{exc} (the reference covers {valid.mean():.0%} of the scans; "
                        f"{len(steps)} odometry steps of {d:g} m / {a:g} rad)",
                        file=refs[0] or logs[0]) from None
    try:  # the held-out check: fitted on the first half, scored on the second
        first = fit_odometry_noise(odom, ref, pairs=steps[:half], **kw)
        holdout = step_z_std(odom, ref, first.alphas, model=model, pairs=steps[half:],
                             reference_var=rv)
    except ValueError:  # too few steps for a half
        holdout = (float("nan"),) * 3
    terms = ("rot1", "trans", "rot2") if model.startswith("diff") else ("trans", "rot", "strafe")
    n_alphas = 5 if model.startswith("omni") else 4
    out = {
        "log": ", ".join(str(x) for x in logs), "reference": ", ".join(sources),
        "scans": len(odom),
        "reference_coverage": round(float(valid.mean()), 4), "model": model,
        "update_min_d_m": d, "update_min_a_rad": a, "steps": fit.steps,
        "rejected": fit.rejected, "alphas": [round(v, 6) for v in fit.alphas[:n_alphas]],
        "current_alphas": [float(v) for v in current[:n_alphas]], "terms": list(terms),
        "z_std_fitted": [round(v, 3) for v in fit.z_std],
        "z_std_holdout": [round(v, 3) for v in holdout],
        "z_std_current": [round(v, 3) for v in step_z_std(
            odom, ref, current, model=model, pairs=steps, reference_var=rv)],
        "trans_scale": round(fit.trans_scale, 5), "rot_scale": round(fit.rot_scale, 5),
        "mean_error": [round(v, 6) for v in fit.mean_error],
        "reference_noise_std": [round(v, 5) for v in fit.reference_std],
        "step_mean_m": round(fit.step_mean_m, 4), "step_mean_rad": round(fit.step_mean_rad, 4),
        "warnings": [],
    }
    # the steps the filter takes on this odometry, all scans counted
    every = np.vstack(filter_pairs)
    filt = relative(odom[every[:, 0]], odom[every[:, 1]]) if len(every) else None
    if filt is not None:
        f_m, f_rad = float(np.hypot(filt[:, 0], filt[:, 1]).mean()), float(
            np.abs(filt[:, 2]).mean())
        out.update(filter_step_mean_m=round(f_m, 4), filter_step_mean_rad=round(f_rad, 4))
        if fit.step_mean_m > COARSE_STEPS * f_m or fit.step_mean_rad > COARSE_STEPS * f_rad:
            out["warnings"].append(
                f"the reference is sparser than the filter's updates: the steps fitted average "
                f"{fit.step_mean_m:.2f} m / {fit.step_mean_rad:.2f} rad, the filter's "
                f"{f_m:.2f} m / {f_rad:.2f} rad, and alphas fitted to longer steps are not the "
                "filter's (a reference at every scan: gatmo map build LOG --poses-out "
                "POSES.tum)")
    zero = [f"alpha{i + 1}" for i, v in enumerate(out["alphas"]) if v < NEGLIGIBLE_ALPHA]
    if zero:
        out["warnings"].append(
            f"{', '.join(zero)} fitted to about 0: these steps show no such noise, and a filter "
            "given none cannot spread its particles that way; --min-alpha floors what is "
            "written")
    if out_path is not None:
        if params_path is not None:
            dialect = amcl_yaml_dialect(params_path)
        else:  # Nav2 has only the corrected models
            dialect = "nav2" if model.endswith("-corrected") else "ros1"
        values = {"odom_model": model, "update_min_d_m": d, "update_min_a_rad": a}
        values.update({f"alpha{i + 1}": max(out["alphas"][i], min_alpha)
                       for i in range(n_alphas)})
        header = (f"# AMCL odometry noise fitted by gatmo calibrate to "
                  f"{', '.join(Path(x).name for x in logs)} against {out['reference']}\n"
                  f"# over {fit.steps} steps of {d:g} m / {a:g} rad "
                  f"({fit.rejected} outliers trimmed)"
                  + (f"; alphas floored at {min_alpha:g}" if min_alpha > 0 else "") + "\n")
        atomic_write_text(out_path, header + amcl_yaml_text(values, dialect))
        out["out"] = str(out_path)
    if report_path is not None:
        import json

        def finite(v):
            if isinstance(v, list):
                return [finite(x) for x in v]
            return None if isinstance(v, float) and not np.isfinite(v) else v

        doc = {"format": "gatmo-calibration"} | {k: finite(v) for k, v in out.items()}
        atomic_write_text(report_path, json.dumps(doc, indent=1) + "\n")
    return out


__all__ = ["COARSE_STEPS", "MAX_REFERENCE_DT_S", "MAX_REFERENCE_GAP_S", "NEGLIGIBLE_ALPHA",
           "calibrate_odometry", "reference_at"]
