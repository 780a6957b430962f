"""Occupancy grid mapping with known poses (log-odds, Thrun et al., Probabilistic Robotics 9.2)."""

from __future__ import annotations

import numpy as np

from gatmo.geometry import compose, transform_points
from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from gatmo.maps.raycast import traverse_rays


def render_map(scans, poses_xytheta: np.ndarray, *, resolution_m: float = 0.05,
               max_range_m: float = 20.0, l_occ: float = 0.85, l_free: float = -0.4,
               l_clamp: float = 5.0, margin_m: float = 1.0) -> OccupancyGrid:
    """Log-odds grid from scans (sequence of Scan) at base poses (N, 3) in the map frame.

    Cells crossed by a beam get ``l_free``, the endpoint cell ``l_occ``; max-range and invalid
    beams clear space up to ``max_range_m`` without an endpoint. The result is thresholded as
    map_server would (p > 0.65 occupied, p < 0.196 free, else unknown).
    """
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
    cells[touched & (p > 0.65)] = OCCUPIED
    cells[touched & (p < 0.196)] = FREE
    return OccupancyGrid(cells, resolution_m, (lo[0], lo[1], 0.0))
