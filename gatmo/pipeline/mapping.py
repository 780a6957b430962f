"""``gatmo map render``: an occupancy map from a log whose poses are known (a SLAM-corrected
CARMEN log such as the radish ``*-corrected`` logs, or a log with ground truth).
``gatmo map build``: a map from a raw log, the poses estimated by scan matching and a pose
graph with loop closures."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gatmo.errors import DataError


@dataclass
class RenderSummary:
    scans: int
    skipped: int
    size_cells: str
    resolution_m: float
    occupied_cells: int
    out: str

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def render_reference_map(log: str | Path, out_yaml: str | Path, *,
                         resolution_m: float | None = None, max_range_m: float | None = None,
                         fmt: str | None = None, image_format: str = "pgm",
                         cfg=None) -> RenderSummary:
    """Render ``log`` at its reference poses (CARMEN pose fields, or ground truth) into a
    map_server map. Records that are bad or out of order are skipped and counted.

    ``cfg``: a :class:`~gatmo.maps.mapping.RenderConfig` (defaults when None);
    ``resolution_m`` / ``max_range_m`` replace its fields."""
    from gatmo.datasets.open import open_log, sniff_format
    from gatmo.maps.io import save_map
    from gatmo.maps.mapping import render_map

    fmt = fmt or sniff_format(log)
    kw = {"pose_is_reference": True} if fmt == "carmen" else {}
    src = open_log(log, fmt=fmt, skip_bad=True, **kw)
    scans = [s for s in src if s.gt_pose_xytheta is not None]
    if not scans:
        raise DataError("no scan carries a reference pose to map with", file=log)
    poses = np.array([s.gt_pose_xytheta for s in scans])
    cfg = _render_config(cfg, resolution_m, max_range_m)
    grid = render_map(scans, poses, cfg)
    save_map(grid, out_yaml, image_format=image_format)
    return RenderSummary(len(scans), src.stats.skipped, f"{grid.width} x {grid.height}",
                         cfg.resolution_m, int(grid.occupied.sum()), str(out_yaml))


def _render_config(cfg, resolution_m: float | None, max_range_m: float | None):
    """A copy of ``cfg`` (a RenderConfig, defaults when None) with the given fields replaced."""
    from gatmo.maps.mapping import RenderConfig

    cfg = (cfg or RenderConfig()).model_copy(deep=True)
    if resolution_m is not None:
        cfg.resolution_m = resolution_m
    if max_range_m is not None:
        cfg.max_range_m = max_range_m
    return cfg


@dataclass
class BuildSummary:
    scans: int
    skipped_records: int  # bad records the reader skipped
    odometry: str  # what guided scan matching: wheels, or constant velocity (and why)
    few_points: int  # scans with too few valid points (odometry used instead of ICP)
    rescued: int  # scans ICP failed on from every guess, placed by a correlative search
    keyframes: int
    closures_accepted: int
    closures_rejected: int  # failed the acceptance test
    closures_unconfirmed: int  # passed it but no agreeing closures followed
    closures_pruned: int  # accepted, then dropped: they disagreed with the optimized graph
    size_cells: str
    resolution_m: float
    seconds: float
    out: str
    config_out: str  # the configuration the map was built with (MAP.build.yaml)
    poses_out: str | None
    odometry_out: str | None

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def build_trajectory(scans, *, icp_cfg=None, graph_cfg=None,
                     progress: Callable[[int, int], None] | None = None):
    """Scan-matching odometry then the pose graph with loop closures over ``scans``.

    ``icp_cfg``: :class:`~gatmo.scanmatch.odometry.IcpConfig`; ``graph_cfg``:
    :class:`~gatmo.scanmatch.posegraph.GraphConfig` (defaults when None).
    Returns (ICP odometry poses (N, 3), optimized poses (N, 3), GraphResult, odometry stats).
    Poses are the base in the frame of the first scan.
    """
    from gatmo.scanmatch.odometry import IcpConfig, ScanMatchOdometry
    from gatmo.scanmatch.posegraph import build_graph

    n = len(scans)
    total = 2 * n
    odo = ScanMatchOdometry(icp_cfg or IcpConfig())
    poses = np.empty((n, 3))
    for i, s in enumerate(scans):
        poses[i] = odo.register(s).pose_xytheta
        if progress is not None and (i % 100 == 0 or i == n - 1):
            progress(i + 1, total)

    def graph_progress(k: int, kk: int) -> None:
        if progress is not None:
            progress(n + int(n * k / max(kk, 1)), total)

    corrected, res = build_graph(scans, poses, graph_cfg, progress=graph_progress)
    return poses, corrected, res, dict(odo.stats)


def build_config_path(out_yaml: str | Path) -> Path:
    """Where ``gatmo map build`` saves the configuration a map was built with: beside the map's
    YAML, ``MAP.yaml`` -> ``MAP.build.yaml``."""
    out_yaml = Path(out_yaml)
    return out_yaml.with_name(out_yaml.stem + ".build.yaml")


def build_map(log: str | Path, out_yaml: str | Path, *, poses_out: str | Path | None = None,
              odometry_out: str | Path | None = None, cfg=None,
              resolution_m: float | None = None, max_range_m: float | None = None,
              fmt: str | None = None, image_format: str = "pgm", max_scans: int | None = None,
              progress: Callable[[int, int], None] | None = None) -> BuildSummary:
    """``gatmo map build``: a map_server map from a raw log (scans, and odometry where the log
    has it): scan-matching odometry, loop closures, a gtsam pose graph, then log-odds ray
    tracing at the optimized poses. A bag without odometry (or ``cfg.icp.use_odometry``
    False) is matched from constant velocity alone, as KISS-ICP.

    ``cfg``: a :class:`~gatmo.pipeline.config.MapBuildConfig` (defaults when None);
    ``resolution_m`` / ``max_range_m`` replace its ``render`` section's. The configuration used
    is saved beside the map (:func:`build_config_path`), so the map can be built again.
    ``poses_out`` gets the optimized pose of every scan, ``odometry_out`` the scan-matching
    odometry's (before loop closure); TUM, in the first scan's frame."""
    from gatmo._io import atomic_write_text
    from gatmo.config import dump_model
    from gatmo.datasets.open import open_log
    from gatmo.datasets.tum import write_tum
    from gatmo.maps.io import save_map
    from gatmo.maps.mapping import render_map
    from gatmo.pipeline.config import MapBuildConfig

    t0 = time.perf_counter()
    cfg = cfg or MapBuildConfig()
    cfg = cfg.model_copy(update={"render": _render_config(cfg.render, resolution_m, max_range_m)})
    src = open_log(log, fmt=fmt, skip_bad=True, odometry_optional=True)  # laser-only bags too
    scans = []
    for s in src:
        scans.append(s)
        if max_scans is not None and len(scans) >= max_scans:
            break
    if len(scans) < 2:
        raise DataError(f"{len(scans)} scans: too few to build a map", file=log)
    odometry, poses, res, odo_stats = build_trajectory(scans, icp_cfg=cfg.icp,
                                                       graph_cfg=cfg.graph, progress=progress)
    grid = render_map(scans, poses, cfg.render)
    save_map(grid, out_yaml, image_format=image_format)
    config_out = build_config_path(out_yaml)
    atomic_write_text(config_out, dump_model(cfg, comments=True))
    stamps = np.array([s.stamp_s for s in scans])
    if poses_out is not None:
        write_tum(poses_out, stamps, poses)
    if odometry_out is not None:
        write_tum(odometry_out, stamps, odometry)
    if progress is not None:
        progress(2 * len(scans), 2 * len(scans))
    st = res.stats
    if getattr(src, "has_odometry", True) is False:
        guided = "none in the log: constant velocity"
    elif not cfg.icp.use_odometry:
        guided = "constant velocity (icp.use_odometry false)"
    else:
        guided = "wheels"
    return BuildSummary(
        scans=len(scans), skipped_records=src.stats.skipped, odometry=guided,
        few_points=int(odo_stats.get("fallback_few_points", 0)),
        rescued=int(odo_stats.get("rescued", 0)), keyframes=len(res.keyframes),
        closures_accepted=len(res.closures), closures_rejected=int(st.get("rejected", 0)),
        closures_unconfirmed=int(st.get("unconfirmed", 0)), closures_pruned=res.pruned,
        size_cells=f"{grid.width} x {grid.height}", resolution_m=cfg.render.resolution_m,
        seconds=round(time.perf_counter() - t0, 1), out=str(out_yaml),
        config_out=str(config_out),
        poses_out=None if poses_out is None else str(poses_out),
        odometry_out=None if odometry_out is None else str(odometry_out))
