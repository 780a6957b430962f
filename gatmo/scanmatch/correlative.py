"""Correlative scan matching (exhaustive search over x, y, theta on a likelihood field, Olson
2009 style) followed by point-to-line ICP, with a strict acceptance test. Used to find loop
closures when drift makes the odometry guess too poor for ICP alone.

Frames: the target (a submap) is in its own frame ``a``; the result ``T_target_source`` is the
pose of the source scan's base frame in ``a``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from gatmo.config import GatmoModel
from gatmo.geometry import relative, transform_points, wrap_angle
from gatmo.scanmatch.icp import IcpResult, icp_2d, normals_of, voxel_downsample


@dataclass
class LikelihoodField:
    """``values`` (H, W) in [0, 1]: exp(-d^2 / 2 sigma^2) of the distance d [m] from each cell
    centre to the nearest target point; cell (0, 0) has its corner at ``origin_xy`` [m]."""

    values: np.ndarray
    origin_xy: np.ndarray
    resolution_m: float


def likelihood_field(points_xy: np.ndarray, *, resolution_m: float = 0.05,
                     sigma_m: float = 0.1, pad_m: float = 1.0) -> LikelihoodField:
    """The likelihood field of target points (N, 2) [m], padded by ``pad_m`` on every side."""
    lo = points_xy.min(axis=0) - pad_m
    hi = points_xy.max(axis=0) + pad_m
    shape = np.ceil((hi - lo) / resolution_m).astype(int) + 1
    occ = np.zeros((shape[1], shape[0]), dtype=bool)
    c = np.floor((points_xy - lo) / resolution_m).astype(int)
    occ[c[:, 1], c[:, 0]] = True
    d = distance_transform_edt(~occ) * resolution_m
    return LikelihoodField(np.exp(-0.5 * (d / sigma_m) ** 2), lo, resolution_m)


def correlative_scores_reference(field, cells_x, cells_y, offsets_x, offsets_y) -> np.ndarray:
    """Plain-numpy twin of :func:`gatmo.scanmatch._kernels.correlative_scores_kernel`."""
    h, w = field.shape
    n_a, n = cells_x.shape
    out = np.zeros((n_a, len(offsets_y), len(offsets_x)))
    if n == 0:
        return out
    for a in range(n_a):
        x = cells_x[a][None, None, :] + offsets_x[None, :, None]  # (1, NX, N)
        y = cells_y[a][None, None, :] + offsets_y[:, None, None]  # (NY, 1, N)
        x, y = np.broadcast_arrays(x, y)
        ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        v = np.zeros(x.shape)
        v[ok] = field[y[ok], x[ok]]
        out[a] = v.sum(axis=2) / n
    return out


def block_scores_reference(field, cells_x, cells_y, block_a, block_x0, block_y0, k, n_max):
    """Plain-numpy twin of :func:`gatmo.scanmatch._kernels.block_scores_kernel`."""
    out = np.zeros((len(block_a), k, k))
    for m in range(len(block_a)):
        a = block_a[m]
        ox = block_x0[m] + np.arange(k)
        oy = block_y0[m] + np.arange(k)
        out[m] = correlative_scores_reference(field, cells_x[a:a + 1], cells_y[a:a + 1], ox,
                                              oy)[0]
        out[m][:, ox > n_max] = -1.0
        out[m][oy > n_max, :] = -1.0
    return out


@dataclass
class SearchResult:
    """Best pose (3,) of the source in the target frame and its score (mean likelihood, 0..1);
    ``second_score``: the best score of a pose farther than the ambiguity radius from it (high
    in a corridor or between look-alike places); ``refined``: coarse cells searched finely."""

    T_target_source: np.ndarray
    score: float
    second_score: float
    refined: int
    exhausted: bool  # the refinement budget ran out before the bound settled the search


def _block_max(values: np.ndarray, k: int) -> np.ndarray:
    """out[y, x] = max(values[y:y+k, x:x+k]) (zero beyond the edges)."""
    from scipy.ndimage import maximum_filter

    return maximum_filter(values, size=k, origin=-(k // 2), mode="constant", cval=0.0)


def correlative_search(source_xy: np.ndarray, field: LikelihoodField, guess_xytheta, *,
                       window_xy_m: float, window_theta_rad: float,
                       step_theta_rad: float = np.radians(0.7), coarse_cells: int = 6,
                       ambiguity_ratio: float = 0.9, ambiguity_radius_m: float = 0.3,
                       ambiguity_theta_rad: float = np.radians(5.0), max_refine: int = 400,
                       use_kernel: bool = True) -> SearchResult:
    """Search of x, y in ``guess`` +- ``window_xy_m`` (on the field's cells) and theta in +-
    ``window_theta_rad`` (steps ``step_theta_rad``) for the source points (N, 2) (source
    frame) on ``field``. Two-level branch and bound: scores on a block-max field over blocks
    of ``coarse_cells`` cells bound the scores inside each block; blocks are refined best
    first until no bound reaches ``ambiguity_ratio`` times the best score, so every pose
    scoring that high is seen and the second-best peak is exact."""
    if use_kernel:
        from gatmo.scanmatch._kernels import block_scores_kernel as blocks_of
        from gatmo.scanmatch._kernels import correlative_scores_kernel as scores_of
    else:
        blocks_of = block_scores_reference
        scores_of = correlative_scores_reference
    guess = np.asarray(guess_xytheta, dtype=float)
    res = field.resolution_m
    k = max(1, int(coarse_cells))
    n = int(np.ceil(window_xy_m / res))
    coarse_offs = np.arange(-n, n + 1, k)
    n_th = int(np.ceil(window_theta_rad / step_theta_rad))
    thetas = guess[2] + np.arange(-n_th, n_th + 1) * step_theta_rad
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    px = c * source_xy[None, :, 0] - s * source_xy[None, :, 1] + guess[0]
    py = s * source_xy[None, :, 0] + c * source_xy[None, :, 1] + guess[1]
    cx = np.floor((px - field.origin_xy[0]) / res).astype(np.int64)
    cy = np.floor((py - field.origin_xy[1]) / res).astype(np.int64)
    bounds = scores_of(_block_max(field.values, k), cx, cy, coarse_offs, coarse_offs)
    flat = bounds.ravel()
    cand = np.nonzero(flat > 0)[0]
    order = cand[np.argsort(flat[cand])[::-1]]
    found = []  # (score, theta index, x offset, y offset)
    best = 0.0
    refined = 0
    exhausted = False
    batch = 32
    pos = 0
    while pos < len(order):
        idx = order[pos:pos + batch]
        idx = idx[flat[idx] >= ambiguity_ratio * best]
        if len(idx) == 0:
            break
        if refined >= max_refine:
            exhausted = True
            break
        pos += batch
        refined += len(idx)
        ia, iy, ix = np.unravel_index(idx, bounds.shape)
        x0 = coarse_offs[ix]
        y0 = coarse_offs[iy]
        sc = blocks_of(field.values, cx, cy, ia.astype(np.int64), x0.astype(np.int64),
                       y0.astype(np.int64), k, n)
        best = max(best, float(sc.max()))
        mm, jj, ii = np.nonzero(sc >= ambiguity_ratio * best)
        found.append(np.column_stack([sc[mm, jj, ii], ia[mm], x0[mm] + ii, y0[mm] + jj]))
        if len(idx) < batch:  # the rest of this batch fell below the bound
            break
    f = np.vstack(found) if found else np.zeros((0, 4))
    f = f[f[:, 0] >= ambiguity_ratio * best]
    if len(f) == 0 or best <= 0:
        return SearchResult(guess.copy(), 0.0, 0.0, refined, exhausted)
    top = int(np.argmax(f[:, 0]))
    sb, ia, ox, oy = f[top]
    ia = int(ia)
    pose = np.array([guess[0] + ox * res, guess[1] + oy * res, float(wrap_angle(thetas[ia]))])
    far = ((np.hypot(f[:, 2] - ox, f[:, 3] - oy) * res > ambiguity_radius_m)
           | (np.abs(thetas[f[:, 1].astype(int)] - thetas[ia]) > ambiguity_theta_rad))
    second = float(f[far, 0].max()) if far.any() else 0.0
    return SearchResult(pose, float(sb), second, refined, exhausted)


class MatchConfig(GatmoModel):
    """Search window, grid and the strict acceptance test of a loop closure."""

    field_resolution_m: float = Field(
        0.05, gt=0, description="cell size of the likelihood field the search scores on")
    field_sigma_m: float = Field(
        0.1, gt=0, description="std of the gaussian around each target point in that field")
    search_voxel_m: float = Field(
        0.1, gt=0, description="the source points are thinned to one per voxel this size for "
        "the search (ICP afterwards takes them all)")
    step_theta_rad: float = Field(
        float(np.radians(0.7)), gt=0, description="heading step of the search")
    coarse_cells: int = Field(
        6, ge=1, description="branch-and-bound: the coarse level's blocks are this many field "
        "cells wide")
    min_score: float = Field(
        0.4, ge=0, le=1, description="a closure is refused unless the mean likelihood of the "
        "source points at the best pose reaches this")
    ambiguity_ratio: float = Field(
        0.9, gt=0, le=1, description="a second peak scoring this close to the best (and "
        "ambiguity_radius_m or ambiguity_theta_rad away from it) makes the match ambiguous: "
        "refused (corridors)")
    ambiguity_radius_m: float = Field(
        0.3, gt=0, description="a second peak this far from the best is a rival place")
    ambiguity_theta_rad: float = Field(
        float(np.radians(5.0)), gt=0,
        description="a second peak turned this far from the best is a rival too")
    max_refine: int = Field(
        400, ge=1, description="most coarse blocks refined before the search gives up "
        "(exhausted: refused as ambiguous)")
    min_fitness: float = Field(
        0.5, ge=0, le=1, description="ICP's inliers over the source points, at least")
    max_rmse_m: float = Field(0.05, gt=0, description="ICP's residual, at most")
    max_icp_shift_m: float = Field(
        0.2, gt=0, description="ICP's refinement may move the search's pose this far, at most")
    max_icp_shift_rad: float = Field(
        float(np.radians(3.0)), gt=0,
        description="... and turn it this far, at most")
    max_range_m: float = Field(
        15.0, gt=0, description="source points farther than this from the robot are left out")


@dataclass
class ClosureMatch:
    """Outcome of one closure attempt: the pose of the source in the target frame, the search
    and ICP figures, ICP's covariance (3, 3), whether it passed and why not."""

    T_target_source: np.ndarray
    search: SearchResult | None
    icp: IcpResult | None
    accepted: bool
    reason: str


def match_to_submap(source_xy: np.ndarray, target_xy: np.ndarray, guess_xytheta, *,
                    window_xy_m: float, window_theta_rad: float,
                    cfg: MatchConfig | None = None, field: LikelihoodField | None = None,
                    target_tree: cKDTree | None = None,
                    target_normals: np.ndarray | None = None) -> ClosureMatch:
    """Correlative search then ICP of source points (N, 2) (source base frame, m) against
    target points (M, 2) (target frame, m), around ``guess_xytheta``; accepted only if the
    search peak is high and unambiguous and ICP agrees, fits well and is not degenerate."""
    cfg = cfg or MatchConfig()
    guess = np.asarray(guess_xytheta, dtype=float)
    src = source_xy[np.hypot(source_xy[:, 0], source_xy[:, 1]) < cfg.max_range_m]
    if len(src) < 20 or len(target_xy) < 20:
        return ClosureMatch(guess, None, None, False, "few points")
    if field is None:
        field = likelihood_field(target_xy, resolution_m=cfg.field_resolution_m,
                                 sigma_m=cfg.field_sigma_m)
    coarse = voxel_downsample(src, cfg.search_voxel_m)
    sr = correlative_search(coarse, field, guess, window_xy_m=window_xy_m,
                            window_theta_rad=window_theta_rad,
                            step_theta_rad=cfg.step_theta_rad, coarse_cells=cfg.coarse_cells,
                            ambiguity_ratio=cfg.ambiguity_ratio,
                            ambiguity_radius_m=cfg.ambiguity_radius_m,
                            ambiguity_theta_rad=cfg.ambiguity_theta_rad,
                            max_refine=cfg.max_refine)
    if sr.score < cfg.min_score:
        return ClosureMatch(sr.T_target_source, sr, None, False, "low score")
    if sr.exhausted or sr.second_score >= cfg.ambiguity_ratio * sr.score:
        return ClosureMatch(sr.T_target_source, sr, None, False, "ambiguous")
    tree = target_tree if target_tree is not None else cKDTree(target_xy)
    normals = target_normals if target_normals is not None else normals_of(target_xy, tree)[0]
    r1 = icp_2d(src, target_xy, sr.T_target_source, target_tree=tree, target_normals=normals,
                max_corr_dist_m=0.3, max_iter=20)
    r2 = icp_2d(src, target_xy, r1.T_target_source, target_tree=tree, target_normals=normals,
                max_corr_dist_m=0.15, max_iter=30)
    shift = relative(sr.T_target_source, r2.T_target_source)
    if r2.degenerate:
        return ClosureMatch(r2.T_target_source, sr, r2, False, "degenerate")
    if r2.fitness < cfg.min_fitness or r2.rmse_m > cfg.max_rmse_m:
        return ClosureMatch(r2.T_target_source, sr, r2, False, "poor fit")
    if np.hypot(shift[0], shift[1]) > cfg.max_icp_shift_m or abs(shift[2]) > cfg.max_icp_shift_rad:
        return ClosureMatch(r2.T_target_source, sr, r2, False, "icp disagrees")
    return ClosureMatch(r2.T_target_source, sr, r2, True, "ok")


def submap_points(poses_xytheta: np.ndarray, points: list[np.ndarray], center: int,
                  half_width: int, voxel_m: float) -> np.ndarray:
    """Points (M, 2) of keyframes ``center +- half_width`` merged in keyframe ``center``'s
    frame at the given keyframe poses (K, 3)."""
    lo, hi = max(0, center - half_width), min(len(points), center + half_width + 1)
    parts = [transform_points(relative(poses_xytheta[center], poses_xytheta[k]), points[k])
             for k in range(lo, hi) if len(points[k])]
    if not parts:
        return np.zeros((0, 2))
    return voxel_downsample(np.vstack(parts), voxel_m)
