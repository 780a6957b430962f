"""Odometry motion models of nav2_amcl (``DifferentialMotionModel``, ``OmniMotionModel``) and
ROS 1 AMCL's originals, which pass a variance where a standard deviation belongs (kept under
their ROS 1 names ``diff`` and ``omni`` for parity; the ``-corrected`` ones are the default)."""

from __future__ import annotations

import numpy as np

from gatmo.geometry import wrap_angle


def _angle_diff(a, b):
    return wrap_angle(np.asarray(a) - np.asarray(b))


def sample_motion(particles: np.ndarray, odom_prev: np.ndarray, odom_now: np.ndarray,
                  model: str, alphas: tuple[float, ...], rng: np.random.Generator) -> np.ndarray:
    """Move particles (N, 3) by the odometry step ``odom_prev -> odom_now`` (odom frame) with
    noise; returns new particles (N, 3). ``alphas`` = (alpha1..alpha5)."""
    a1, a2, a3, a4, a5 = alphas
    n = len(particles)
    dx, dy = odom_now[0] - odom_prev[0], odom_now[1] - odom_prev[1]
    dth = float(_angle_diff(odom_now[2], odom_prev[2]))
    trans = float(np.hypot(dx, dy))
    corrected = model.endswith("-corrected")
    sd = np.sqrt if corrected else (lambda v: v)  # ROS 1: variance used as a std
    out = particles.copy()
    if model.startswith("diff"):
        rot1 = 0.0 if trans < 0.01 else float(_angle_diff(np.arctan2(dy, dx), odom_prev[2]))
        rot2 = float(_angle_diff(dth, rot1))
        r1n = min(abs(_angle_diff(rot1, 0.0)), abs(_angle_diff(rot1, np.pi)))
        r2n = min(abs(_angle_diff(rot2, 0.0)), abs(_angle_diff(rot2, np.pi)))
        s1 = sd(a1 * r1n**2 + a2 * trans**2)
        st = sd(a3 * trans**2 + a4 * r1n**2 + a4 * r2n**2)
        s2 = sd(a1 * r2n**2 + a2 * trans**2)
        rot1_hat = _angle_diff(rot1, rng.normal(0.0, 1.0, n) * s1)
        trans_hat = trans - rng.normal(0.0, 1.0, n) * st
        rot2_hat = _angle_diff(rot2, rng.normal(0.0, 1.0, n) * s2)
        out[:, 0] += trans_hat * np.cos(particles[:, 2] + rot1_hat)
        out[:, 1] += trans_hat * np.sin(particles[:, 2] + rot1_hat)
        out[:, 2] = wrap_angle(particles[:, 2] + rot1_hat + rot2_hat)
        return out
    if model.startswith("omni"):
        st = sd(a3 * trans**2 + a1 * dth**2)
        sr = sd(a4 * dth**2 + a2 * trans**2)
        ss = sd(a1 * dth**2 + a5 * trans**2)
        bearing = float(_angle_diff(np.arctan2(dy, dx), odom_prev[2])) + particles[:, 2]
        cb, sb = np.cos(bearing), np.sin(bearing)
        t_hat = trans + rng.normal(0.0, 1.0, n) * st
        r_hat = dth + rng.normal(0.0, 1.0, n) * sr
        s_hat = rng.normal(0.0, 1.0, n) * ss
        out[:, 0] += t_hat * cb + s_hat * sb
        out[:, 1] += t_hat * sb - s_hat * cb
        out[:, 2] = wrap_angle(particles[:, 2] + r_hat)
        return out
    raise ValueError(f"unknown odometry model {model!r}")
