"""``gatmo localize``: the Monte Carlo localizer alone over one log, poses written as TUM."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class LocalizeSummary:
    scans: int
    sensor_updates: int
    mean_particles: float
    ms_per_update: float
    ms_per_scan: float
    skipped: int
    out_path: str
    # median over the log's second half of the share of each scan's returns the map explains
    # at the estimate (:func:`map_explained`): near 1 where the localizer follows the map
    map_explained: float = float("nan")
    errors: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)  # runs.vet_ground_truth, a lost localizer

    def as_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k not in ("errors", "warnings")}
        d.update(self.errors)
        return d


#: a return within this of an occupied map cell is explained by the map (:func:`map_explained`)
EXPLAINED_WITHIN_M = 0.2
#: below this median share over a log's second half, ``localize`` warns that the localizer is
#: likely lost (or the map is not this place's)
EXPLAINED_WARN_BELOW = 0.5


def map_explained(grid, scans: list, poses_xytheta: np.ndarray,
                  within_m: float = EXPLAINED_WITHIN_M, field=None) -> np.ndarray:
    """Per scan, the share (N,) of its returns that lie within ``within_m`` of an occupied cell
    of ``grid`` when laid at the estimate ``poses_xytheta`` (N, 3), map frame; NaN for a scan
    without returns. What a user sees in rviz as the scan lying on the map, without ground
    truth: a localizer that follows the map explains most of them (clutter and people aside).
    ``field``: a :class:`gatmo.maps.likelihood.LikelihoodField` of ``grid`` already built (the
    localizer's), used if it reaches ``within_m``."""
    from gatmo.geometry import compose, transform_points
    from gatmo.maps.likelihood import LikelihoodField

    if field is None or field.max_dist_m <= within_m:
        field = LikelihoodField(grid, 2.0 * within_m)
    out = np.full(len(scans), np.nan)
    for i, (s, p) in enumerate(zip(scans, poses_xytheta, strict=True)):
        pts = transform_points(compose(p, s.laser_pose_xytheta), s.points_laser_xy())
        if len(pts):
            out[i] = float(np.mean(field.distance_at(pts) < within_m))
    return out


def run_localize(
    map_yaml: str | Path,
    log: str | Path,
    *,
    out_path: str | Path,
    params_path: str | Path | None = None,
    config_path: str | Path | None = None,
    preset: str | None = None,
    fmt: str | None = None,
    initial_pose=None,
    global_localization: bool = False,
    max_scans: int | None = None,
    progress: Callable[[int, int | None], None] | None = None,
    seed: int = 0,
    config=None,
    gt_path: str | Path | None = None,
) -> LocalizeSummary:
    """Localize ``log`` in the map; the initial pose comes from the argument, else the params
    file, else the log's first ground-truth pose, else global localization. The localizer's
    configuration: ``config`` (an :class:`AmclConfig`), else the ROS AMCL YAML
    ``params_path``, else the ``amcl`` section of the gatmo stack YAML ``config_path`` (what
    ``gatmo run --config`` takes, e.g. a simulated scenario's ``stack.yaml``) or of the named
    stack configuration ``preset``, else AMCL's defaults. Scored against ``gt_path`` (TUM, map
    frame) if given, else the log's own ground truth."""
    from gatmo.datasets.open import open_map
    from gatmo.datasets.tum import write_tum
    from gatmo.localization.mcl import MonteCarloLocalizer
    from gatmo.pipeline.config import load_amcl_config
    from gatmo.pipeline.runs import (
        check_overlap,
        ground_truth_of,
        initial_pose_for,
        initial_pose_origin,
        load_scans,
        score,
        vet_ground_truth,
    )

    grid = open_map(map_yaml)
    cfg = config if config is not None else load_amcl_config(params_path, config_path, preset)
    scans = load_scans(log, fmt, max_scans)
    loc = MonteCarloLocalizer.from_config(cfg, grid, np.random.default_rng(seed))
    pose0 = initial_pose_for(scans, initial_pose, global_localization, cfg.initial_pose_xytheta)
    if pose0 is not None:
        check_overlap(grid, scans[0], pose0, log,
                      initial_pose_origin(initial_pose, cfg.initial_pose_xytheta))
        loc.set_initial_pose(pose0)
    else:
        loc.global_localization()
    n = len(scans)
    stamps = np.empty(n)
    poses = np.empty((n, 3))
    parts = np.empty(n)
    t0 = time.perf_counter()
    for i, s in enumerate(scans):
        e = loc.update(s.odom_pose_xytheta, s)
        stamps[i] = s.stamp_s
        poses[i] = e.pose_xytheta
        parts[i] = e.n_particles
        if progress is not None and (i % 50 == 0 or i == n - 1):
            progress(i + 1, n)
    elapsed = time.perf_counter() - t0
    write_tum(out_path, stamps, poses)
    st = loc.stats.as_dict()
    summary = LocalizeSummary(
        scans=n, sensor_updates=st["sensor_updates"], mean_particles=float(parts.mean()),
        ms_per_update=st["ms_per_update_median"], ms_per_scan=elapsed * 1e3 / n,
        skipped=st["skipped_no_valid_beams"], out_path=str(out_path),
    )
    gt, summary.warnings = vet_ground_truth(grid, scans, ground_truth_of(scans, log, gt_path),
                                            log)
    second = map_explained(grid, scans[n // 2:], poses[n // 2:], field=loc.field)
    if np.isfinite(second).any():
        summary.map_explained = float(np.nanmedian(second))
        if summary.map_explained < EXPLAINED_WARN_BELOW:
            summary.warnings.append(
                f"{log}: over the log's second half the map explains a median of "
                f"{summary.map_explained:.0%} of a scan's returns at the estimate (within "
                f"{EXPLAINED_WITHIN_M:g} m of a wall): the localizer is likely lost, or the map "
                "is not this place's. Give the start (--initial-pose X,Y,YAW); global "
                "localization needs particles for the whole map (amcl.max_particles)")
    if gt is not None:
        from gatmo.pipeline.runs import RunTrace

        tr = RunTrace(str(log), "static", stamps, poses, poses, np.zeros(n, bool), np.zeros(n))
        row = score(tr, gt)
        summary.errors = {k: row[k] for k in ("ate_rmse_m", "ate_median_m", "ate_max_m",
                                               "lost_fraction") if k in row}
    return summary
