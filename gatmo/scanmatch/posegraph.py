"""A Pose2 pose graph on gtsam with loop closures, for building maps from raw logs.

Keyframes come from scan-matching odometry (between factors, noise growing with the step). Each
new keyframe looks for loop closures against earlier parts of the trajectory: candidates are
earlier keyframes whose current estimate lies within a search radius that grows with the path
driven between the two (drift), one per earlier visit, nearest first. The new keyframe's scan
is matched to a submap (consecutive keyframes merged) by a branch-and-bound correlative x-y-theta
search on a likelihood field, refined by ICP and accepted only by a strict test (score, no
second peak, ICP fit, not degenerate; :mod:`gatmo.scanmatch.correlative`). A match enters the
graph only once ``group_size`` matches found within ``group_span`` keyframes agree with each
other (the loop through two closures and the odometry closes), so one look-alike place cannot
bend the map. Confirmed closures go into iSAM2 at once (Gaussian noise: a robust kernel would
ignore the metres-large first closure of a loop), so later searches start from corrected poses.
A final batch Levenberg-Marquardt pass with Cauchy-robust closures drops closures that still
disagree with the graph (residual above ``prune_xy_m`` / ``prune_theta_rad``) and re-optimizes.

Frames: all poses (x [m], y [m], theta [rad]) are the base frame in the odometry/map frame whose
origin is the first keyframe; keyframe points (N, 2) are in that keyframe's base frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from gatmo.config import GatmoModel
from gatmo.geometry import compose, inverse, relative, wrap_angle
from gatmo.scanmatch.correlative import (
    MatchConfig,
    likelihood_field,
    match_to_submap,
    submap_points,
)
from gatmo.scanmatch.icp import voxel_downsample


class GraphConfig(GatmoModel):
    """Keyframes, loop-closure search and acceptance, and the pose graph's noise models."""

    keyframe_dist_m: float = Field(
        0.5, gt=0, description="a scan becomes a keyframe (a node of the graph) when the "
        "scan-matching odometry has moved this far since the last one, or turned "
        "keyframe_angle_rad")
    keyframe_angle_rad: float = Field(0.35, gt=0, description="see keyframe_dist_m")
    keyframe_voxel_m: float = Field(
        0.05, gt=0, description="each keyframe's scan is thinned to one point per voxel this "
        "size (closure search and submaps)")
    min_points: int = Field(
        30, ge=1, description="keyframes with fewer valid points take no part in closures")
    submap_half_width: int = Field(
        15, ge=0, description="keyframes either side of a candidate merged into the submap a "
        "closure is matched against")
    submap_voxel_m: float = Field(0.05, gt=0, description="the submap is thinned to this")
    closure_min_separation: int = Field(
        20, ge=1, description="a closure joins keyframes at least this many keyframes apart")
    closure_every: int = Field(
        1, ge=1, description="closures are searched from every n-th keyframe")
    closure_max_candidates: int = Field(
        2, ge=1, description="earlier visits tried per keyframe, nearest first")
    closure_skip_after_accept: int = Field(
        1, ge=0, description="keyframes to wait after a confirmed closure before searching "
        "again")
    closure_max_dist_m: float = Field(
        4.0, gt=0, description="a match farther than this from the submap's centre is refused")
    track_span: int = Field(
        3, ge=0, description="a closure confirmed this few keyframes ago narrows the next "
        "search's window to the neighbourhood it found")
    group_size: int = Field(
        3, ge=1, description="a closure enters the graph once this many matches agree with "
        "each other (1: every accepted match at once)")
    group_span: int = Field(
        15, ge=1, description="... matches found within this many keyframes")
    group_xy_m: float = Field(
        0.3, gt=0, description="two matches agree when the loop through both and the "
        "odometry between them closes within this, and group_theta_rad")
    group_theta_rad: float = Field(float(np.radians(3.0)), gt=0, description="see group_xy_m")
    window_base_m: float = Field(
        0.6, gt=0, description="closure search half-width at zero path driven between the two "
        "keyframes")
    window_per_m: float = Field(
        0.05, ge=0, description="... growing by this per metre driven (the odometry's drift)")
    window_max_m: float = Field(12.0, gt=0, description="... up to this")
    window_theta_base_rad: float = Field(
        float(np.radians(6.0)), gt=0, description="heading half-width at zero path driven")
    window_theta_per_m: float = Field(
        float(np.radians(0.5)), ge=0, description="... growing by this per metre driven")
    window_theta_max_rad: float = Field(
        float(np.radians(57.0)), gt=0, description="... up to this")
    match: MatchConfig = Field(
        default_factory=MatchConfig,
        description="the closure match: correlative search, ICP and the acceptance test")
    odom_sigma_xy_m: float = Field(
        0.02, gt=0, description="std of an odometry edge's translation, per keyframe step")
    odom_sigma_xy_per_m: float = Field(0.05, ge=0, description="... plus this per metre")
    odom_sigma_theta_rad: float = Field(
        0.01, gt=0, description="std of an odometry edge's rotation, per keyframe step")
    odom_sigma_theta_per_rad: float = Field(0.05, ge=0, description="... plus this per rad")
    closure_sigma_xy_m: float = Field(0.05, gt=0, description="std of a closure's translation")
    closure_sigma_theta_rad: float = Field(0.02, gt=0,
                                           description="std of a closure's rotation")
    robust_scale: float = Field(
        1.0, gt=0, description="scale of the final pass's Cauchy kernel on the whitened "
        "closure error")
    prune_xy_m: float = Field(
        0.25, gt=0, description="after optimization, closures whose residual is more than "
        "this (or prune_theta_rad) are dropped and the graph is optimized again")
    prune_theta_rad: float = Field(float(np.radians(4.0)), gt=0,
                                   description="see prune_xy_m")


@dataclass
class GraphResult:
    keyframes: list[int]  # scan indices
    poses_xytheta: np.ndarray  # optimized keyframe poses (K, 3)
    closures: list[tuple[int, int, np.ndarray]] = field(default_factory=list)
    rejected: int = 0  # closure attempts that failed the acceptance test
    pruned: int = 0  # accepted closures dropped after optimization (disagree with the graph)
    stats: dict = field(default_factory=dict)


def select_keyframes(poses_xytheta: np.ndarray, cfg: GraphConfig) -> list[int]:
    """Indices of poses (N, 3) at least ``keyframe_dist_m`` or ``keyframe_angle_rad`` apart."""
    keys = [0]
    for i in range(1, len(poses_xytheta)):
        d = relative(poses_xytheta[keys[-1]], poses_xytheta[i])
        if np.hypot(d[0], d[1]) > cfg.keyframe_dist_m or abs(d[2]) > cfg.keyframe_angle_rad:
            keys.append(i)
    return keys


class PoseGraph:
    """Incremental pose graph: ``add_keyframe`` per keyframe (odometry pose, points), then
    ``finish``. Keys are keyframe numbers 0..K-1."""

    def __init__(self, cfg: GraphConfig | None = None) -> None:
        import gtsam

        self.cfg = cfg or GraphConfig()
        self._gtsam = gtsam
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(0.01)
        params.relinearizeSkip = 1
        self._isam = gtsam.ISAM2(params)
        self.odom: list[np.ndarray] = []  # odometry poses of keyframes
        self.points: list[np.ndarray] = []
        self.est = np.zeros((0, 3))  # current estimate (K, 3)
        self.path_m: list[float] = []  # cumulative path length at each keyframe
        self.odom_factors: list[tuple[int, int, np.ndarray, np.ndarray]] = []
        self.closures: list[tuple[int, int, np.ndarray]] = []
        self._pending: list[tuple[int, int, np.ndarray]] = []  # matches awaiting agreement
        self.stats = {"attempts": 0, "matched": 0, "accepted": 0, "rejected": 0,
                      "unconfirmed": 0, "reasons": {}}
        self._last_accept = -(10**9)
        self.attempt_log: list[tuple] = []  # (a, b, window m, window rad, score, reason)
        base = gtsam.noiseModel.Diagonal.Sigmas(np.array(
            [self.cfg.closure_sigma_xy_m, self.cfg.closure_sigma_xy_m,
             self.cfg.closure_sigma_theta_rad]))
        self._closure_gauss = base  # group-confirmed closures in iSAM2
        self._closure_noise = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(self.cfg.robust_scale), base)

    # ------------------------------------------------------------------ building
    def _odom_noise(self, d: np.ndarray):
        c = self.cfg
        sxy = c.odom_sigma_xy_m + c.odom_sigma_xy_per_m * float(np.hypot(d[0], d[1]))
        sth = c.odom_sigma_theta_rad + c.odom_sigma_theta_per_rad * abs(float(d[2]))
        return np.array([sxy, sxy, sth])

    def add_keyframe(self, odom_pose_xytheta: np.ndarray, points_xy: np.ndarray,
                     search: bool = True) -> int:
        """Add a keyframe at its odometry pose (3,) with its points (N, 2) (base frame);
        searches loop closures for it if ``search``. Returns its key."""
        gtsam = self._gtsam
        k = len(self.odom)
        pose = np.asarray(odom_pose_xytheta, dtype=float)
        pts = points_xy if len(points_xy) >= self.cfg.min_points else np.zeros((0, 2))
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        if k == 0:
            prior = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 1e-3, 1e-4]))
            graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*pose), prior))
            guess = pose
            self.path_m.append(0.0)
        else:
            d = relative(self.odom[-1], pose)
            sig = self._odom_noise(d)
            self.odom_factors.append((k - 1, k, d, sig))
            graph.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(*d),
                                               gtsam.noiseModel.Diagonal.Sigmas(sig)))
            guess = compose(self.est[-1], d)
            self.path_m.append(self.path_m[-1] + float(np.hypot(d[0], d[1])))
        values.insert(k, gtsam.Pose2(*guess))
        self.odom.append(pose)
        self.points.append(pts)
        self.est = np.vstack([self.est, guess[None]])
        found = []
        c = self.cfg
        if (search and len(pts) and k % c.closure_every == 0
                and k - self._last_accept >= c.closure_skip_after_accept):
            found = self._confirm(self._search_closures(k), k)
        for a, b, T in found:
            graph.add(gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(*T), self._closure_gauss))
            self.closures.append((a, b, T))
        self._isam.update(graph, values)
        if found:
            for _ in range(3):
                self._isam.update()
            self._refresh()
        else:
            p = self._isam.calculateEstimatePose2(k) if hasattr(
                self._isam, "calculateEstimatePose2") else None
            if p is not None:
                self.est[k] = [p.x(), p.y(), p.theta()]
        return k

    def _refresh(self) -> None:
        vals = self._isam.calculateEstimate()
        self.est = np.array([[vals.atPose2(i).x(), vals.atPose2(i).y(), vals.atPose2(i).theta()]
                             for i in range(len(self.odom))])

    def _windows(self, a: int, b: int) -> tuple[float, float]:
        c = self.cfg
        s = self.path_m
        L = s[b] - s[a]
        # tracking a region closed a moment ago: drift only since that closure
        for ca, cb, _ in reversed(self.closures):
            if b - cb > c.track_span:
                break
            if abs(a - ca) <= c.submap_half_width:
                L = min(L, abs(s[b] - s[cb]) + abs(s[a] - s[ca]))
        wxy = min(c.window_base_m + c.window_per_m * L, c.window_max_m)
        wth = min(c.window_theta_base_rad + c.window_theta_per_m * L, c.window_theta_max_rad)
        return wxy, wth

    def _candidates(self, b: int) -> list[int]:
        c = self.cfg
        last = b - c.closure_min_separation
        if last < 0:
            return []
        d = np.hypot(*(self.est[: last + 1, :2] - self.est[b, :2]).T)
        L = self.path_m[b] - np.asarray(self.path_m[: last + 1])
        radius = np.minimum(c.window_base_m + c.window_per_m * L, c.window_max_m)
        near = np.nonzero((d <= radius) & np.array([len(p) > 0 for p in self.points[: last + 1]]))
        near = near[0]
        if len(near) == 0:
            return []
        # one candidate per visit (a run of consecutive keyframes), the nearest
        splits = np.nonzero(np.diff(near) > 2 * c.submap_half_width)[0] + 1
        visits = [min(run, key=lambda i: d[i]) for run in np.split(near, splits)]
        visits.sort(key=lambda i: d[i])
        return visits[: c.closure_max_candidates]

    def _agree(self, h1, h2) -> bool:
        """Two closures (a, b, T_a_b) agree if the loop a1 -> b1 -> b2 -> a2 -> a1 (closures
        plus the current estimate between a1, a2 and between b1, b2) closes."""
        a1, b1, T1 = h1
        a2, b2, T2 = h2
        lhs = compose(T1, relative(self.est[b1], self.est[b2]))
        rhs = compose(relative(self.est[a1], self.est[a2]), T2)
        e = relative(lhs, rhs)
        return bool(np.hypot(e[0], e[1]) <= self.cfg.group_xy_m
                    and abs(wrap_angle(e[2])) <= self.cfg.group_theta_rad)

    def _confirm(self, new, b: int) -> list[tuple[int, int, np.ndarray]]:
        """Closures to add now: new matches that agree with enough recent matches (pending or
        already in the graph), plus the pending ones they agree with."""
        c = self.cfg
        recent_added = [h for h in self.closures if b - h[1] <= c.group_span]
        kept = []
        for h in self._pending:
            if b - h[1] <= c.group_span:
                kept.append(h)
            else:
                self.stats["unconfirmed"] += 1
        self._pending = kept
        out: list[tuple[int, int, np.ndarray]] = []
        for h in new:
            partners = [p for p in self._pending if p[1] != h[1] and self._agree(p, h)]
            n_added = sum(1 for p in recent_added + out if p[1] != h[1] and self._agree(p, h))
            if len(partners) + n_added + 1 >= c.group_size:
                for p in partners:
                    out.append(p)
                    self._pending.remove(p)
                out.append(h)
            else:
                self._pending.append(h)
        if out:
            self.stats["accepted"] += len(out)
            self._last_accept = b
        return out

    def _search_closures(self, b: int) -> list[tuple[int, int, np.ndarray]]:
        c = self.cfg
        out = []
        for a in self._candidates(b):
            target = submap_points(self.est, self.points, a, c.submap_half_width,
                                   c.submap_voxel_m)
            wxy, wth = self._windows(a, b)
            guess = relative(self.est[a], self.est[b])
            fieldmap = likelihood_field(target, resolution_m=c.match.field_resolution_m,
                                        sigma_m=c.match.field_sigma_m, pad_m=wxy + 1.0)
            m = match_to_submap(self.points[b], target, guess, window_xy_m=wxy,
                                window_theta_rad=wth, cfg=c.match, field=fieldmap,
                                target_tree=cKDTree(target))
            self.stats["attempts"] += 1
            self.attempt_log.append((a, b, wxy, wth, m.search.score if m.search else 0.0,
                                     m.reason))
            if m.accepted and np.hypot(*m.T_target_source[:2]) > c.closure_max_dist_m:
                m.accepted, m.reason = False, "far from submap"
            if m.accepted:
                self.stats["matched"] += 1
                out.append((a, b, m.T_target_source))
            else:
                self.stats["rejected"] += 1
                self.stats["reasons"][m.reason] = self.stats["reasons"].get(m.reason, 0) + 1
        return out

    # ---------------------------------------------------------------- finishing
    def _batch(self, closures, init: np.ndarray) -> np.ndarray:
        gtsam = self._gtsam
        graph = gtsam.NonlinearFactorGraph()
        prior = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 1e-3, 1e-4]))
        graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*self.odom[0]), prior))
        for a, b, d, sig in self.odom_factors:
            graph.add(gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(*d),
                                               gtsam.noiseModel.Diagonal.Sigmas(sig)))
        for a, b, T in closures:
            graph.add(gtsam.BetweenFactorPose2(int(a), int(b), gtsam.Pose2(*T),
                                               self._closure_noise))
        values = gtsam.Values()
        for k in range(len(init)):
            values.insert(k, gtsam.Pose2(*init[k]))
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        res = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        return np.array([[res.atPose2(k).x(), res.atPose2(k).y(), res.atPose2(k).theta()]
                         for k in range(len(init))])

    def finish(self, extra_closures: list[tuple[int, int, np.ndarray]] | None = None
               ) -> GraphResult:
        """Batch optimization with all closures (plus ``extra_closures`` (a, b, T_a_b) as
        given), then closures whose residual exceeds the prune bounds are dropped and the graph
        is optimized again without them."""
        c = self.cfg
        closures = self.closures + list(extra_closures or [])
        if len(self.odom) == 0:
            return GraphResult([], np.zeros((0, 3)), [], 0, 0, dict(self.stats))
        init = self.est if not extra_closures else np.array(self.est)
        poses = self._batch(closures, init)
        keep = []
        for a, b, T in closures:
            e = relative(relative(poses[a], poses[b]), T)
            if np.hypot(e[0], e[1]) <= c.prune_xy_m and abs(wrap_angle(e[2])) <= c.prune_theta_rad:
                keep.append((a, b, T))
        pruned = len(closures) - len(keep)
        if pruned:
            poses = self._batch(keep, poses)
        stats = dict(self.stats, attempt_log=self.attempt_log, pruned=pruned,
                     unconfirmed=self.stats["unconfirmed"] + len(self._pending),
                     keyframes=len(self.odom))
        return GraphResult(list(range(len(poses))), poses, keep, self.stats["rejected"], pruned,
                           stats)


def optimize(poses_xytheta: np.ndarray, points: list[np.ndarray], cfg: GraphConfig,
             extra_closures: list[tuple[int, int, np.ndarray]] | None = None,
             progress: Callable[[int, int], None] | None = None) -> GraphResult:
    """Optimize keyframe poses (K, 3) (odometry chain) with loop closures between keyframes.

    ``points[k]`` are keyframe k's scan points (N, 2) in its base frame. ``extra_closures``
    (a, b, T_a_b) are added as given (tests use them to inject a wrong closure).
    """
    g = PoseGraph(cfg)
    K = len(poses_xytheta)
    for k in range(K):
        g.add_keyframe(poses_xytheta[k], points[k])
        if progress is not None and (k % 20 == 0 or k == K - 1):
            progress(k + 1, K)
    return g.finish(extra_closures)


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
                progress: Callable[[int, int], None] | None = None):
    """Keyframes from scan-matching odometry (N, 3), loop closures, optimization; returns
    (all scan poses (N, 3) after optimization, GraphResult)."""
    cfg = cfg or GraphConfig()
    keys = select_keyframes(odometry_poses_xytheta, cfg)
    pts = [voxel_downsample(scans[i].points_base_xy(), cfg.keyframe_voxel_m) for i in keys]
    res = optimize(odometry_poses_xytheta[keys], pts, cfg, progress=progress)
    res.keyframes = keys
    return correct_all(odometry_poses_xytheta, keys, res.poses_xytheta), res
