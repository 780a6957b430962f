"""KISS-ICP (Vizzo et al. 2023, the ``kiss-icp`` package) behind gatmo's odometry interface:
2D scans lifted to z = 0; the pose is read back as (x, y, yaw)."""

from __future__ import annotations

import numpy as np

from gatmo.datasets.types import Scan
from gatmo.scanmatch.odometry import MatchResult


class KissIcpBackend:
    """``register(scan) -> MatchResult`` like :class:`ScanMatchOdometry`, using KISS-ICP.

    KISS-ICP ignores wheel odometry (its prediction is constant velocity) and deskewing needs
    per-point stamps that 2D logs lack, so deskew is off.
    """

    def __init__(self, voxel_m: float = 0.1, max_range_m: float = 30.0,
                 min_range_m: float = 0.1) -> None:
        from kiss_icp.config import KISSConfig
        from kiss_icp.kiss_icp import KissICP

        cfg = KISSConfig()
        cfg.data.max_range = max_range_m
        cfg.data.min_range = min_range_m
        cfg.data.deskew = False
        cfg.mapping.voxel_size = voxel_m
        cfg.adaptive_threshold.min_motion_th = 0.01
        self._icp = KissICP(cfg)
        self.stats = {"scans": 0}

    def register(self, scan: Scan) -> MatchResult:
        self.stats["scans"] += 1
        pts = scan.points_base_xy()
        xyz = np.column_stack([pts, np.zeros(len(pts))]).astype(np.float64)
        if len(xyz) >= 3:
            self._icp.register_frame(xyz, np.zeros(len(xyz)))
        T = self._icp.last_pose
        pose = np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])
        return MatchResult(pose, np.diag([0.02, 0.02, 0.01]) ** 2, 1.0, len(xyz) >= 3)
