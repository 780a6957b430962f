"""SE(2) helpers on poses stored as ``(x_m, y_m, theta_rad)``, vectorised over leading axes.

Conventions: a pose ``T_a_b`` is the pose of frame b expressed in frame a. ``compose(T_a_b, T_b_c)``
gives ``T_a_c``; ``relative(T_w_a, T_w_b)`` gives ``T_a_b``.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(theta_rad):
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(theta_rad) + np.pi) % (2.0 * np.pi) - np.pi


def compose(T_a_b: np.ndarray, T_b_c: np.ndarray) -> np.ndarray:
    """Return ``T_a_c`` for poses of shape (..., 3); broadcasts."""
    T_a_b = np.asarray(T_a_b, dtype=float)
    T_b_c = np.asarray(T_b_c, dtype=float)
    c = np.cos(T_a_b[..., 2])
    s = np.sin(T_a_b[..., 2])
    x = T_a_b[..., 0] + c * T_b_c[..., 0] - s * T_b_c[..., 1]
    y = T_a_b[..., 1] + s * T_b_c[..., 0] + c * T_b_c[..., 1]
    th = wrap_angle(T_a_b[..., 2] + T_b_c[..., 2])
    if T_a_b.ndim == 1 and T_b_c.ndim == 1:  # one pose: the same values, without np.stack's cost
        return np.array([x, y, th])
    return np.stack([x, y, th], axis=-1)


def inverse(T_a_b: np.ndarray) -> np.ndarray:
    """Return ``T_b_a`` for poses of shape (..., 3)."""
    T_a_b = np.asarray(T_a_b, dtype=float)
    c = np.cos(T_a_b[..., 2])
    s = np.sin(T_a_b[..., 2])
    x = -c * T_a_b[..., 0] - s * T_a_b[..., 1]
    y = s * T_a_b[..., 0] - c * T_a_b[..., 1]
    if T_a_b.ndim == 1:
        return np.array([x, y, wrap_angle(-T_a_b[2])])
    return np.stack([x, y, wrap_angle(-T_a_b[..., 2])], axis=-1)


def relative(T_w_a: np.ndarray, T_w_b: np.ndarray) -> np.ndarray:
    """Return ``T_a_b`` = inverse(T_w_a) * T_w_b for poses of shape (..., 3)."""
    return compose(inverse(T_w_a), T_w_b)


def transform_points(T_a_b: np.ndarray, points_b_xy: np.ndarray) -> np.ndarray:
    """Map points (N, 2) given in frame b into frame a, for a single pose ``T_a_b`` (3,)."""
    T_a_b = np.asarray(T_a_b, dtype=float)
    c, s = np.cos(T_a_b[2]), np.sin(T_a_b[2])
    R = np.array([[c, -s], [s, c]])
    return np.asarray(points_b_xy, dtype=float) @ R.T + T_a_b[:2]


def nearest_index(sorted_values: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index (M,) into ``sorted_values`` (N >= 2, ascending) of the value nearest each of
    ``query`` (M,); a tie goes to the lower index."""
    v = np.asarray(sorted_values, dtype=float)
    q = np.asarray(query, dtype=float)
    i = np.clip(np.searchsorted(v, q), 1, len(v) - 1)
    return np.where(np.abs(v[i - 1] - q) <= np.abs(v[i] - q), i - 1, i)


def points_to_beams(points_xy: np.ndarray, laser_pose_xytheta: np.ndarray,
                    angles_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where points (K, 2) of the map frame lie for a laser at ``laser_pose_xytheta`` (3,) with
    beams at ``angles_rad`` (B,, ascending, laser frame): (range_m (K,), bearing_rad (K,) in
    the laser frame, index (K,) of the beam nearest that bearing)."""
    lp = np.asarray(laser_pose_xytheta, dtype=float)
    d = np.asarray(points_xy, dtype=float) - lp[:2]
    rng = np.hypot(d[:, 0], d[:, 1])
    bearing = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - lp[2])
    return rng, bearing, nearest_index(angles_rad, bearing)


def interpolate_poses(stamps_s: np.ndarray, poses_xytheta: np.ndarray, query_s: np.ndarray):
    """Linearly interpolate poses (N, 3) at ``query_s`` (M,), angles along the short arc.

    Queries outside [stamps_s[0], stamps_s[-1]] are clamped to the end poses.
    """
    stamps_s = np.asarray(stamps_s, dtype=float)
    poses_xytheta = np.asarray(poses_xytheta, dtype=float)
    query_s = np.asarray(query_s, dtype=float)
    x = np.interp(query_s, stamps_s, poses_xytheta[:, 0])
    y = np.interp(query_s, stamps_s, poses_xytheta[:, 1])
    th_unwrapped = np.unwrap(poses_xytheta[:, 2])
    th = wrap_angle(np.interp(query_s, stamps_s, th_unwrapped))
    return np.stack([x, y, th], axis=-1)


def path_length_m(poses_xytheta: np.ndarray) -> float:
    """Sum of translation steps along a trajectory (N, 3)."""
    p = np.asarray(poses_xytheta, dtype=float)
    if len(p) < 2:
        return 0.0
    return float(np.hypot(*np.diff(p[:, :2], axis=0).T).sum())
