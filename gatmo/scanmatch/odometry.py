"""Scan-matching odometry: each scan registered to a local map of recent keyframes, odometry as
the initial guess. Poses are in the matcher's own frame (its origin is the first scan)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from gatmo.config import GatmoModel
from gatmo.datasets.types import Scan
from gatmo.geometry import compose, relative, transform_points
from gatmo.scanmatch.icp import icp_2d, normals_of, voxel_downsample


class IcpConfig(GatmoModel):
    voxel_m: float = Field(0.05, gt=0)
    max_corr_dist_m: float = Field(0.3, gt=0)
    max_iter: int = Field(20, ge=1)
    kernel_scale_m: float = Field(0.05, gt=0)
    keyframe_dist_m: float = Field(0.3, gt=0)
    keyframe_angle_rad: float = Field(0.2, gt=0)
    local_map_keyframes: int = Field(8, ge=1)
    min_points: int = Field(30, ge=3)
    min_fitness: float = Field(0.5, ge=0, le=1)
    max_correction_m: float = Field(0.3, gt=0, description="ICP vs odometry; more -> odometry")
    max_range_m: float = Field(30.0, gt=0)
    odom_jump_m: float = Field(
        0.2, gt=0, description="odometry step this far from constant velocity: try both guesses")
    odom_jump_rad: float = Field(0.2, gt=0)


@dataclass
class MatchResult:
    pose_xytheta: np.ndarray  # base pose in the matcher frame
    cov: np.ndarray
    fitness: float
    used_icp: bool


class ScanMatchOdometry:
    """Our ICP against a rolling local map; falls back to odometry when ICP cannot be trusted
    (too few points, poor fitness, degenerate geometry, implausible correction)."""

    def __init__(self, cfg: IcpConfig) -> None:
        self.cfg = cfg
        self.pose = np.zeros(3)
        self._odom_prev: np.ndarray | None = None
        self._keyframes: deque = deque(maxlen=cfg.local_map_keyframes)
        self._kf_pose: np.ndarray | None = None
        self._tree = None
        self._normals = None
        self._map = None
        self._last_step = np.zeros(3)  # last scan-to-scan motion (constant-velocity guess)
        self.stats = {"scans": 0, "icp": 0, "fallback_few_points": 0, "fallback_bad_fit": 0,
                      "degenerate": 0, "odom_jumps": 0}

    @classmethod
    def from_config(cls, cfg: IcpConfig) -> ScanMatchOdometry:
        return cls(cfg)

    def _points_base(self, scan: Scan) -> np.ndarray:
        pts = scan.points_base_xy()
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) < self.cfg.max_range_m]
        return voxel_downsample(pts, self.cfg.voxel_m)

    def _rebuild(self) -> None:
        self._map = np.vstack([transform_points(p, s) for p, s in self._keyframes])
        self._map = voxel_downsample(self._map, self.cfg.voxel_m)
        self._tree = cKDTree(self._map)
        self._normals, _ = normals_of(self._map, self._tree)

    def register(self, scan: Scan) -> MatchResult:
        c = self.cfg
        self.stats["scans"] += 1
        odom = np.asarray(scan.odom_pose_xytheta, dtype=float)
        pts = self._points_base(scan)
        if self._odom_prev is None:
            self._odom_prev = odom
            if len(pts) >= c.min_points:
                self._keyframes.append((self.pose.copy(), pts))
                self._kf_pose = self.pose.copy()
                self._rebuild()
            return MatchResult(self.pose.copy(), np.eye(3) * 1e-6, 1.0, False)
        prev_pose = self.pose.copy()
        guess = compose(self.pose, relative(self._odom_prev, odom))
        self._odom_prev = odom
        used = False
        fitness = 0.0
        cov = np.diag([0.05, 0.05, 0.02]) ** 2
        if len(pts) < c.min_points or self._tree is None or len(self._map) < c.min_points:
            self.stats["fallback_few_points"] += 1
            self.pose = guess
        else:
            # Logged wheel odometry stalls and then jumps (MIT CSAIL: four zero steps, then
            # 0.85 m / 50 deg at once). When its step disagrees with constant velocity, ICP
            # also starts from the constant-velocity guess and the better fit wins.
            guesses = [guess]
            cv = compose(self.pose, self._last_step)
            jump = relative(guess, cv)
            if np.hypot(jump[0], jump[1]) > c.odom_jump_m or abs(jump[2]) > c.odom_jump_rad:
                guesses.append(cv)
                self.stats["odom_jumps"] += 1
            best = None
            for g in guesses:
                res = icp_2d(pts, self._map, g, target_tree=self._tree,
                             target_normals=self._normals, max_corr_dist_m=c.max_corr_dist_m,
                             max_iter=c.max_iter, kernel_scale_m=c.kernel_scale_m)
                corr = relative(g, res.T_target_source)
                if res.degenerate:
                    self.stats["degenerate"] += 1
                ok = not (res.fitness < c.min_fitness or res.degenerate
                          or np.hypot(corr[0], corr[1]) > c.max_correction_m)
                if ok and (best is None or res.fitness > best.fitness):
                    best = res
            if best is None:
                self.stats["fallback_bad_fit"] += 1
                self.pose = guess
            else:
                self.pose = best.T_target_source
                used = True
                fitness = best.fitness
                cov = best.cov
                self.stats["icp"] += 1
        self._last_step = relative(prev_pose, self.pose)
        if len(pts) >= c.min_points:
            d = relative(self._kf_pose if self._kf_pose is not None else self.pose, self.pose)
            if (self._kf_pose is None or np.hypot(d[0], d[1]) > c.keyframe_dist_m
                    or abs(d[2]) > c.keyframe_angle_rad):
                self._keyframes.append((self.pose.copy(), pts))
                self._kf_pose = self.pose.copy()
                self._rebuild()
        return MatchResult(self.pose.copy(), cov, fitness, used)
