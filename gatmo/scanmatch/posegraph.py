"""A Pose2 pose graph on gtsam: scan-matching odometry between keyframes, loop closures found by
scan-to-scan ICP with a strict acceptance test, robust (Cauchy) noise so that a wrong closure
is down-weighted, Levenberg-Marquardt."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from gatmo.geometry import compose, inverse, relative
from gatmo.scanmatch.icp import icp_2d, voxel_downsample


@dataclass
class GraphConfig:
    keyframe_dist_m: float = 0.5
    keyframe_angle_rad: float = 0.35
    closure_radius_m: float = 3.0
    closure_min_separation: int = 30  # keyframes apart
    closure_every: int = 3  # try closures from every n-th keyframe
    closure_max_per_keyframe: int = 2
    closure_min_fitness: float = 0.8
    closure_max_rmse_m: float = 0.06
    odom_sigma_xy_m: float = 0.05
    odom_sigma_theta_rad: float = 0.02
    closure_sigma_xy_m: float = 0.05
    closure_sigma_theta_rad: float = 0.02
    robust_scale: float = 1.0


@dataclass
class GraphResult:
    keyframes: list[int]  # scan indices
    poses_xytheta: np.ndarray  # optimized keyframe poses (K, 3)
    closures: list[tuple[int, int, np.ndarray]] = field(default_factory=list)
    rejected: int = 0


def select_keyframes(poses_xytheta: np.ndarray, cfg: GraphConfig) -> list[int]:
    keys = [0]
    for i in range(1, len(poses_xytheta)):
        d = relative(poses_xytheta[keys[-1]], poses_xytheta[i])
        if np.hypot(d[0], d[1]) > cfg.keyframe_dist_m or abs(d[2]) > cfg.keyframe_angle_rad:
            keys.append(i)
    return keys


def optimize(poses_xytheta: np.ndarray, points: list[np.ndarray], cfg: GraphConfig,
             extra_closures: list[tuple[int, int, np.ndarray]] | None = None) -> GraphResult:
    """Optimize keyframe poses (K, 3) (odometry chain) with loop closures between keyframes.

    ``points[k]`` are keyframe k's scan points in its base frame. ``extra_closures`` (a, b,
    T_a_b) are added as given (tests use them to inject a wrong closure).
    """
    import gtsam

    K = len(poses_xytheta)
    closures: list[tuple[int, int, np.ndarray]] = []
    rejected = 0
    tree = cKDTree(poses_xytheta[:, :2])
    for b in range(0, K, cfg.closure_every):
        found = 0
        for a in sorted(tree.query_ball_point(poses_xytheta[b, :2], cfg.closure_radius_m)):
            if b - a < cfg.closure_min_separation or found >= cfg.closure_max_per_keyframe:
                continue
            if len(points[a]) < 30 or len(points[b]) < 30:
                continue
            guess = relative(poses_xytheta[a], poses_xytheta[b])
            res = None
            # drift makes the odometry guess poor on loops: coarse-to-fine from a few headings
            for dth in (0.0, -0.15, 0.15):
                g = guess + np.array([0.0, 0.0, dth])
                r1 = icp_2d(points[b], points[a], g, max_corr_dist_m=1.5, max_iter=20)
                r2 = icp_2d(points[b], points[a], r1.T_target_source, max_corr_dist_m=0.3,
                            max_iter=30)
                if res is None or r2.fitness > res.fitness:
                    res = r2
            if (not res.degenerate and res.fitness >= cfg.closure_min_fitness
                    and res.rmse_m <= cfg.closure_max_rmse_m):
                closures.append((a, b, res.T_target_source))
                found += 1
            else:
                rejected += 1
    closures += list(extra_closures or [])
    graph = gtsam.NonlinearFactorGraph()
    prior = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 1e-3, 1e-4]))
    graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*poses_xytheta[0]), prior))
    odo = gtsam.noiseModel.Diagonal.Sigmas(
        np.array([cfg.odom_sigma_xy_m, cfg.odom_sigma_xy_m, cfg.odom_sigma_theta_rad]))
    for k in range(1, K):
        d = relative(poses_xytheta[k - 1], poses_xytheta[k])
        graph.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(*d), odo))
    base = gtsam.noiseModel.Diagonal.Sigmas(
        np.array([cfg.closure_sigma_xy_m, cfg.closure_sigma_xy_m, cfg.closure_sigma_theta_rad]))
    robust = gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Cauchy.Create(cfg.robust_scale), base)
    for a, b, T in closures:
        graph.add(gtsam.BetweenFactorPose2(int(a), int(b), gtsam.Pose2(*T), robust))
    init = gtsam.Values()
    for k in range(K):
        init.insert(k, gtsam.Pose2(*poses_xytheta[k]))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    result = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    out = np.array([[result.atPose2(k).x(), result.atPose2(k).y(), result.atPose2(k).theta()]
                    for k in range(K)])
    return GraphResult(list(range(K)), out, closures, rejected)


def correct_all(poses_xytheta: np.ndarray, keyframes: list[int],
                optimized_xytheta: np.ndarray) -> np.ndarray:
    """Carry each keyframe's correction to the scans after it (N, 3)."""
    out = np.empty_like(poses_xytheta)
    kf = np.asarray(keyframes)
    owner = np.searchsorted(kf, np.arange(len(poses_xytheta)), side="right") - 1
    for i, k in enumerate(owner):
        corr = compose(optimized_xytheta[k], inverse(poses_xytheta[kf[k]]))
        out[i] = compose(corr, poses_xytheta[i])
    return out


def build_graph(scans, odometry_poses_xytheta: np.ndarray, cfg: GraphConfig | None = None,
                voxel_m: float = 0.05):
    """Keyframes from scan-matching odometry (N, 3), loop closures, optimization; returns
    (all scan poses (N, 3) after optimization, GraphResult)."""
    cfg = cfg or GraphConfig()
    keys = select_keyframes(odometry_poses_xytheta, cfg)
    pts = [voxel_downsample(scans[i].points_base_xy(), voxel_m) for i in keys]
    res = optimize(odometry_poses_xytheta[keys], pts, cfg)
    res.keyframes = keys
    return correct_all(odometry_poses_xytheta, keys, res.poses_xytheta), res
