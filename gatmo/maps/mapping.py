"""Occupancy grid mapping with known poses (log-odds, Thrun et al., Probabilistic Robotics 9.2)."""

from __future__ import annotations

import numpy as np
from pydantic import Field, model_validator

from gatmo.config import GatmoModel
from gatmo.geometry import compose, transform_points
from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from gatmo.maps.raycast import traverse_rays


class RenderConfig(GatmoModel):
    """How scans at known poses become an occupancy grid (:func:`render_map`)."""

    resolution_m: float = Field(0.05, gt=0, description="cell size of the map")
    max_range_m: float = Field(
        20.0, gt=0, description="returns up to this range mark their cell occupied; longer and "
        "max-range beams clear space up to this range without an endpoint")
    l_occ: float = Field(0.85, gt=0, description="log-odds added to a beam's endpoint cell")
    l_free: float = Field(-0.4, lt=0, description="log-odds added to each cell a beam crosses")
    l_clamp: float = Field(
        5.0, gt=0, description="log-odds are clamped to +-this after each scan, so a cell "
        "can change its mind (a door opened)")
    margin_m: float = Field(1.0, ge=0, description="room left around the reach of the scans")
    occupied_thresh: float = Field(
        0.65, gt=0, lt=1, description="a cell is occupied above this probability (map_server's "
        "occupied_thresh)")
    free_thresh: float = Field(
        0.196, gt=0, lt=1, description="a cell is free below this probability (map_server's "
        "free_thresh); between the two it is unknown")

    @model_validator(mode="after")
    def _thresholds_ordered(self) -> RenderConfig:
        if self.free_thresh >= self.occupied_thresh:
            raise ValueError(f"free_thresh ({self.free_thresh}) must be below occupied_thresh "
                             f"({self.occupied_thresh})")
        return self


def render_map(scans, poses_xytheta: np.ndarray,
               cfg: RenderConfig | None = None) -> OccupancyGrid:
    """Log-odds grid from scans (sequence of Scan) at base poses (N, 3) in the map frame.

    Cells crossed by a beam get ``cfg.l_free``, the endpoint cell ``cfg.l_occ``; max-range and
    invalid beams clear space up to ``cfg.max_range_m`` without an endpoint. The result is
    thresholded as map_server would (p > ``occupied_thresh`` occupied, p < ``free_thresh``
    free, else unknown). ``cfg``: :class:`RenderConfig` (defaults when None).
    """
    cfg = cfg or RenderConfig()
    resolution_m, max_range_m, margin_m = cfg.resolution_m, cfg.max_range_m, cfg.margin_m
    l_occ, l_free, l_clamp = cfg.l_occ, cfg.l_free, cfg.l_clamp
    poses = np.asarray(poses_xytheta, dtype=float)
    lo = poses[:, :2].min(axis=0) - max_range_m - margin_m
    hi = poses[:, :2].max(axis=0) + max_range_m + margin_m
    shape = np.ceil((hi - lo) / resolution_m).astype(int)
    probe = OccupancyGrid(np.zeros((shape[1], shape[0]), np.int8), resolution_m,
                          (lo[0], lo[1], 0.0))
    logodds = np.zeros((shape[1], shape[0]))
    touched = np.zeros(logodds.shape, dtype=bool)
    for scan, pose in zip(scans, poses, strict=True):
        lp = compose(pose, scan.laser_pose_xytheta)
        r = scan.ranges_m
        with np.errstate(invalid="ignore"):
            hit = scan.valid & (r <= max_range_m)
            clear = np.isfinite(r) & ~hit & (r > scan.range_min_m)
        pts = transform_points(lp, scan.points_laser_xy(only_valid=False))
        ends = pts[hit]
        a = lp[2] + scan.angles_rad[clear]
        far = lp[:2] + np.minimum(r[clear], max_range_m)[:, None] * np.stack(
            [np.cos(a), np.sin(a)], axis=1)
        cells, _ = traverse_rays(probe, lp[:2], np.vstack([ends, far]))
        np.add.at(logodds, (cells[:, 1], cells[:, 0]), l_free)
        touched[cells[:, 1], cells[:, 0]] = True
        c = probe.world_to_cell(ends)
        ok = probe.in_bounds(c)
        np.add.at(logodds, (c[ok, 1], c[ok, 0]), l_occ - l_free)  # cancel a crossing, add hit
        touched[c[ok, 1], c[ok, 0]] = True
        np.clip(logodds, -l_clamp, l_clamp, out=logodds)
    p = 1.0 - 1.0 / (1.0 + np.exp(logodds))
    cells = np.full(logodds.shape, UNKNOWN, dtype=np.int8)
    cells[touched & (p > cfg.occupied_thresh)] = OCCUPIED
    cells[touched & (p < cfg.free_thresh)] = FREE
    return OccupancyGrid(cells, resolution_m, (lo[0], lo[1], 0.0))
