"""Odometry motion models of nav2_amcl (``DifferentialMotionModel``, ``OmniMotionModel``) and
ROS 1 AMCL's originals, which pass a variance where a standard deviation belongs (kept under
their ROS 1 names ``diff`` and ``omni`` for parity; the ``-corrected`` ones are the default).

:func:`sample_motion` draws the noise as standard normals (3, N) and moves the particles with a
numba kernel; :func:`sample_motion_reference` is the same in numpy on given normals.
"""

from __future__ import annotations

import math

import numpy as np

from gatmo.geometry import wrap_angle


def _angle_diff(a: float, b: float) -> float:
    """wrap_angle(a - b) of scalars (Python's float % has numpy's sign convention)."""
    return (a - b + math.pi) % (2.0 * math.pi) - math.pi


def motion_terms(odom_prev: np.ndarray, odom_now: np.ndarray, model: str,
                 alphas: tuple[float, ...]) -> tuple[str, tuple[float, ...]]:
    """The odometry step's decomposition and noise standard deviations.

    ``("diff", (rot1, trans, rot2, sd_rot1, sd_trans, sd_rot2))`` or
    ``("omni", (bearing, trans, dtheta, sd_trans, sd_rot, sd_strafe))``; bearing relative to the
    heading."""
    a1, a2, a3, a4, a5 = (float(a) for a in alphas)
    p0, p1, p2 = (float(v) for v in odom_prev[:3])
    dx, dy = float(odom_now[0]) - p0, float(odom_now[1]) - p1
    dth = _angle_diff(float(odom_now[2]), p2)
    trans = math.hypot(dx, dy)
    sd = math.sqrt if model.endswith("-corrected") else (lambda v: v)  # ROS 1: variance as std
    if model.startswith("diff"):
        rot1 = 0.0 if trans < 0.01 else _angle_diff(math.atan2(dy, dx), p2)
        rot2 = _angle_diff(dth, rot1)
        r1n = min(abs(_angle_diff(rot1, 0.0)), abs(_angle_diff(rot1, math.pi)))
        r2n = min(abs(_angle_diff(rot2, 0.0)), abs(_angle_diff(rot2, math.pi)))
        s1 = sd(a1 * r1n**2 + a2 * trans**2)
        st = sd(a3 * trans**2 + a4 * r1n**2 + a4 * r2n**2)
        s2 = sd(a1 * r2n**2 + a2 * trans**2)
        return "diff", (rot1, trans, rot2, s1, st, s2)
    if model.startswith("omni"):
        st = sd(a3 * trans**2 + a1 * dth**2)
        sr = sd(a4 * dth**2 + a2 * trans**2)
        ss = sd(a1 * dth**2 + a5 * trans**2)
        bearing = _angle_diff(math.atan2(dy, dx), p2)
        return "omni", (bearing, trans, dth, st, sr, ss)
    raise ValueError(f"unknown odometry model {model!r}")


def sample_motion(particles: np.ndarray, odom_prev: np.ndarray, odom_now: np.ndarray,
                  model: str, alphas: tuple[float, ...], rng: np.random.Generator,
                  normals: np.ndarray | None = None) -> np.ndarray:
    """Move particles (N, 3) by the odometry step ``odom_prev -> odom_now`` (odom frame) with
    noise; returns new particles (N, 3). ``alphas`` = (alpha1..alpha5). ``normals`` (3, N):
    the standard normals to use (default: drawn from ``rng``)."""
    from gatmo.localization import _kernels as K

    kind, terms = motion_terms(odom_prev, odom_now, model, alphas)
    if normals is None:
        normals = rng.standard_normal((3, len(particles)))
    parts = np.ascontiguousarray(particles, dtype=np.float64)
    kern = K.motion_diff_kernel if kind == "diff" else K.motion_omni_kernel
    return kern(parts, *terms, np.ascontiguousarray(normals, dtype=np.float64))


def sample_motion_reference(particles: np.ndarray, odom_prev: np.ndarray, odom_now: np.ndarray,
                            model: str, alphas: tuple[float, ...],
                            normals: np.ndarray) -> np.ndarray:
    """numpy reference of :func:`sample_motion` on the given standard normals (3, N)."""
    kind, terms = motion_terms(odom_prev, odom_now, model, alphas)
    out = particles.copy()
    th = particles[:, 2]
    if kind == "diff":
        rot1, trans, rot2, s1, st, s2 = terms
        rot1_hat = wrap_angle(rot1 - normals[0] * s1)
        trans_hat = trans - normals[1] * st
        rot2_hat = wrap_angle(rot2 - normals[2] * s2)
        out[:, 0] += trans_hat * np.cos(th + rot1_hat)
        out[:, 1] += trans_hat * np.sin(th + rot1_hat)
        out[:, 2] = wrap_angle(th + rot1_hat + rot2_hat)
        return out
    bearing, trans, dth, st, sr, ss = terms
    cb, sb = np.cos(bearing + th), np.sin(bearing + th)
    t_hat = trans + normals[0] * st
    r_hat = dth + normals[1] * sr
    s_hat = normals[2] * ss
    out[:, 0] += t_hat * cb + s_hat * sb
    out[:, 1] += t_hat * sb - s_hat * cb
    out[:, 2] = wrap_angle(th + r_hat)
    return out
