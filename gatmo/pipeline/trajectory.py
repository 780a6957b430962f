"""``gatmo eval``: a trajectory file scored against ground truth and/or relations, as evo's
``evo_ape`` and the SLAM benchmark's relations metric (Kümmerle et al. 2009) do."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo.errors import DataError, GatmoError


def evaluate_trajectory(
    poses_path: str | Path,
    *,
    gt_path: str | Path | None = None,
    relations_path: str | Path | None = None,
    align: bool = False,
    correct_scale: bool = False,
    stamp_offset_s: float = 0.0,
    rpe_delta_m: float | None = None,
    max_dt_s: float = 0.05,
    relations_max_dt_s: float = 0.002,
) -> dict:
    """Score the TUM trajectory ``poses_path`` (what ``localize``, ``run`` and ``map build
    --poses-out`` write).

    Against a TUM ground truth ``gt_path``: position error at the estimate's stamps (ground
    truth interpolated, within ``max_dt_s`` of its span); ``align``: after the rigid fit of
    the estimate onto it, for a trajectory in a frame of its own such as a built map's;
    ``correct_scale``: a scale fitted too (implies ``align``). Against a relations file
    ``relations_path`` (no common frame needed): a relation is used when the estimate has a
    pose within ``relations_max_dt_s`` of both its stamps. ``stamp_offset_s`` is added to the
    estimate's stamps first (e.g. radish's ``intel-corrected`` log runs 976052857.33753 s
    behind the Intel bag). Returns a flat dict: ``poses``; ``ate_*`` with ground truth;
    ``rel_*`` with relations; ``rpe_*``, with ground truth and ``rpe_delta_m``, the relative
    pose error over that much travel (:func:`gatmo.datasets.metrics.rpe`, frame-free)."""
    from gatmo.datasets.metrics import ate, relations_error, rpe
    from gatmo.datasets.tum import read_tum

    if gt_path is None and relations_path is None:
        raise GatmoError("nothing to score against: give --ground-truth and/or --relations")
    t, p = read_tum(poses_path)
    if len(t) == 0:
        raise DataError("no poses", file=poses_path)
    t = np.asarray(t, dtype=float) + stamp_offset_s
    out: dict = {"poses": int(len(t))}
    if gt_path is not None:
        gt_t, gt_p = read_tum(gt_path)
        if len(gt_t) == 0:
            raise DataError("ground truth is empty", file=gt_path)
        a = ate(t, p, gt_t, gt_p, max_dt_s=max_dt_s, align=align or correct_scale,
                with_scale=correct_scale)
        if a["n"] == 0:
            raise DataError(
                f"ground-truth stamps [{gt_t[0]:.3f}, {gt_t[-1]:.3f}] s do not cover any of the "
                f"estimate's [{t[0]:.3f}, {t[-1]:.3f}] s (--stamp-offset shifts the estimate's)",
                file=gt_path)
        out.update(ate_poses=a["n"], ate_rmse_m=a["rmse_m"], ate_median_m=a["median_m"],
                   ate_max_m=a["max_m"], ate_mean_rot_deg=a["mean_rot_deg"],
                   lost_fraction=a["lost_fraction"])
        if "T_gt_est" in a:
            out["T_gt_est"] = [round(v, 6) for v in a["T_gt_est"]]
        if correct_scale:
            out["scale"] = round(a["scale"], 6)
        if rpe_delta_m is not None:
            e = rpe(t, p, gt_t, gt_p, delta_m=rpe_delta_m, max_dt_s=max_dt_s)
            out.update(rpe_delta_m=rpe_delta_m, rpe_pairs=e["n"],
                       rpe_trans_rmse_m=e["trans_rmse_m"], rpe_trans_median_m=e["trans_median_m"],
                       rpe_rot_mean_deg=e["rot_mean_deg"])
    if relations_path is not None:
        from gatmo.datasets.relations import read_relations

        rel = read_relations(relations_path)
        r = relations_error(t, p, rel, max_dt_s=relations_max_dt_s)
        if r["n_used"] == 0:
            raise DataError(
                f"none of the {r['n_total']} relations has a pose of the estimate within "
                f"{relations_max_dt_s * 1e3:g} ms of both its stamps (--stamp-offset shifts the "
                "estimate's)", file=relations_path)
        out.update(rel_used=r["n_used"], rel_total=r["n_total"],
                   rel_trans_mean_m=r["trans_mean_m"], rel_trans_std_m=r["trans_std_m"],
                   rel_rot_mean_deg=r["rot_mean_deg"], rel_rot_std_deg=r["rot_std_deg"])
    return out
