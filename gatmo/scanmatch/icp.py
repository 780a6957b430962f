"""2D point-to-line ICP: KD-tree correspondences, normals from neighbours, Huber or
Geman-McClure weights, Gauss-Newton on SE(2), covariance from the Hessian and a degeneracy flag."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial import cKDTree

from gatmo.geometry import transform_points, wrap_angle


@dataclass
class IcpResult:
    """``T_target_source`` (3,): pose of the source frame in the target frame."""

    T_target_source: np.ndarray
    cov: np.ndarray
    fitness: float
    rmse_m: float
    n_inliers: int
    iterations: int
    converged: bool
    degenerate: bool


def voxel_downsample(points_xy: np.ndarray, voxel_m: float) -> np.ndarray:
    """One point (the first) per voxel."""
    if len(points_xy) == 0:
        return points_xy
    keys = np.floor(points_xy / voxel_m).astype(np.int64)
    _, idx = np.unique(keys, axis=0, return_index=True)
    return points_xy[np.sort(idx)]


def normals_of(points_xy: np.ndarray, tree: cKDTree, k: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N, 2) from the PCA of k neighbours, and a planarity flag (N,)."""
    k = min(k, len(points_xy))
    _, idx = tree.query(points_xy, k=k)
    nb = points_xy[idx]  # (N, k, 2)
    d = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", d, d) / k
    w, v = np.linalg.eigh(cov)
    normals = v[:, :, 0]  # smallest eigenvalue's vector
    good = w[:, 0] < 0.1 * np.maximum(w[:, 1], 1e-12)
    return normals, good


def icp_2d(source_xy: np.ndarray, target_xy: np.ndarray, init_xytheta=(0.0, 0.0, 0.0), *,
           target_tree: cKDTree | None = None, target_normals: np.ndarray | None = None,
           max_corr_dist_m: float = 0.5, max_iter: int = 30, kernel_scale_m: float = 0.05,
           tol_xy_m: float = 1e-4, tol_theta_rad: float = 1e-5,
           degenerate_ratio: float = 1e-3,
           kernel: Literal["huber", "geman_mcclure"] = "huber") -> IcpResult:
    """Align ``source_xy`` (N, 2) to ``target_xy`` (M, 2) from ``init_xytheta``.

    ``kernel``: ``huber`` (a residual beyond ``kernel_scale_m`` pulls with a constant force) or
    ``geman_mcclure`` (redescending, as kiss-icp: a residual several ``kernel_scale_m`` long
    pulls almost not at all, so points on something that moved by less than
    ``max_corr_dist_m`` do not drag the alignment towards where it stood)."""
    if kernel not in ("huber", "geman_mcclure"):
        raise ValueError(f"kernel must be 'huber' or 'geman_mcclure', not {kernel!r}")
    T = np.asarray(init_xytheta, dtype=float).copy()
    tree = target_tree or cKDTree(target_xy)
    if target_normals is None:
        target_normals, good = normals_of(target_xy, tree)
    else:
        good = np.ones(len(target_xy), dtype=bool)
    converged = False
    H = np.eye(3)
    it = 0
    r = np.zeros(0)
    inl = np.zeros(0, dtype=bool)
    for it in range(1, max_iter + 1):  # noqa: B007 - reported
        p = transform_points(T, source_xy)
        dist, j = tree.query(p, distance_upper_bound=max_corr_dist_m)
        inl = np.isfinite(dist)
        jj = j[inl]
        inl_idx = np.nonzero(inl)[0][good[jj]]
        jj = j[inl_idx]
        if len(inl_idx) < 6:
            break
        n = target_normals[jj]
        q = target_xy[jj]
        pi = p[inl_idx]
        r = np.einsum("ij,ij->i", pi - q, n)
        # d(p)/d(theta) for p = R(theta) s + t, about the current estimate
        c, s = np.cos(T[2]), np.sin(T[2])
        src = source_xy[inl_idx]
        dp = np.stack([-s * src[:, 0] - c * src[:, 1], c * src[:, 0] - s * src[:, 1]], axis=1)
        J = np.column_stack([n[:, 0], n[:, 1], np.einsum("ij,ij->i", n, dp)])
        if kernel == "huber":
            w = kernel_scale_m / np.maximum(np.abs(r), kernel_scale_m)
        else:
            w = (kernel_scale_m**2 / (kernel_scale_m**2 + r**2)) ** 2
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ r
        try:
            dx = -np.linalg.solve(H + np.eye(3) * 1e-9, g)
        except np.linalg.LinAlgError:
            break
        T = T + dx
        T[2] = float(wrap_angle(T[2]))
        if np.hypot(dx[0], dx[1]) < tol_xy_m and abs(dx[2]) < tol_theta_rad:
            converged = True
            break
    n_in = int(len(r))
    rmse = float(np.sqrt(np.mean(r**2))) if n_in else float("inf")
    sigma2 = max(rmse**2, 1e-6)
    ev = np.linalg.eigvalsh(H) if n_in else np.zeros(3)
    degenerate = bool(n_in < 6 or ev[0] < degenerate_ratio * max(ev[-1], 1e-12))
    cov = np.eye(3) * 1e6
    if n_in and np.all(np.isfinite(H)):  # no inliers: nothing known (inf * 0 would be NaN)
        try:
            cov = sigma2 * np.linalg.inv(H + np.eye(3) * 1e-9)
        except np.linalg.LinAlgError:
            pass
    return IcpResult(T, cov, n_in / max(len(source_xy), 1), rmse, n_in, it, converged,
                     degenerate)
