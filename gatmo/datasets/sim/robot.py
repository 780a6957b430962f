"""The robot: a differential-drive base following a waypoint loop, and its odometry.

Poses are ``(x_m, y_m, theta_rad)``: true poses in the map (world) frame, odometry poses in an odom
frame that starts at (0, 0, 0), so ``odom != map`` as on a real robot.
"""

from __future__ import annotations

import numpy as np

from gatmo.datasets.sim.config import OdomConfig, RobotConfig
from gatmo.geometry import wrap_angle

WAYPOINT_REACHED_M = 0.3


class RouteFollower:
    """A unicycle steering at the next waypoint of a closed route (K, 2) [m].

    Turn rate ``2 * heading_error`` clipped to ``max_turn_rate_rps``; speed
    ``speed_mps * cos(err)^4`` (so it turns nearly in place at sharp corners). Starts on waypoint
    ``start_index`` facing the next one. :meth:`step` integrates one scan period in 5 sub-steps;
    ``blocked`` makes it stand still (a safety stop for a person in front).
    """

    def __init__(self, route: np.ndarray, cfg: RobotConfig, start_index: int = 0) -> None:
        self.cfg = cfg
        self.pts = np.roll(np.asarray(route, dtype=float), -int(start_index), axis=0)
        first = np.arctan2(self.pts[1, 1] - self.pts[0, 1], self.pts[1, 0] - self.pts[0, 0])
        self.x, self.y, self.th = float(self.pts[0, 0]), float(self.pts[0, 1]), float(first)
        self.target = 1

    @property
    def pose(self) -> np.ndarray:
        """True base pose (3,) in the world."""
        return np.array([self.x, self.y, self.th])

    def step(self, dt_s: float, blocked: bool = False, sub: int = 5) -> None:
        if blocked:
            return
        c = self.cfg
        h = dt_s / sub
        for _ in range(sub):
            goal = self.pts[self.target % len(self.pts)]
            if np.hypot(goal[0] - self.x, goal[1] - self.y) < WAYPOINT_REACHED_M:
                self.target += 1
                goal = self.pts[self.target % len(self.pts)]
            err = float(wrap_angle(np.arctan2(goal[1] - self.y, goal[0] - self.x) - self.th))
            w = float(np.clip(2.0 * err, -c.max_turn_rate_rps, c.max_turn_rate_rps))
            v = c.speed_mps * max(0.0, np.cos(err)) ** 4
            self.x += v * np.cos(self.th) * h
            self.y += v * np.sin(self.th) * h
            self.th = float(wrap_angle(self.th + w * h))


def drive(route: np.ndarray, cfg: RobotConfig, rng: np.random.Generator,
          start_index: int | None = None) -> np.ndarray:
    """True base poses (N, 3) in the world at the scan rate, N = duration_s * scan_rate_hz, with
    nothing in the way (see :class:`RouteFollower`); a random start waypoint unless given."""
    dt = 1.0 / cfg.scan_rate_hz
    n = int(round(cfg.duration_s * cfg.scan_rate_hz))
    k0 = int(rng.integers(len(route))) if start_index is None else int(start_index)
    bot = RouteFollower(route, cfg, k0)
    out = np.empty((n, 3))
    for i in range(n):
        out[i] = bot.pose
        bot.step(dt)
    return out


def draw_scale_bias(cfg: OdomConfig, rng: np.random.Generator) -> tuple[float, float]:
    """Per-run multiplicative odometry biases (translation, rotation), each ``1 + N(0, std)``."""
    return (1.0 + float(rng.normal(0.0, cfg.scale_bias_std)),
            1.0 + float(rng.normal(0.0, cfg.scale_bias_std)))


def sample_odometry(true_xytheta: np.ndarray, cfg: OdomConfig, rng: np.random.Generator,
                    scale_bias: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Odometry poses (N, 3) in an odom frame starting at (0, 0, 0).

    Each step between true poses is decomposed into (rot1, trans, rot2) and perturbed as in
    Thrun's ``sample_motion_model_odometry`` (Probabilistic Robotics, Table 5.6, with standard
    deviations ``sqrt(alpha1 rot1^2 + alpha2 trans^2)`` etc., as AMCL reads them), then scaled by
    ``scale_bias`` = (translation, rotation): a wheel-radius / wheel-base calibration error that
    makes the drift systematic, not just a random walk.
    """
    a = cfg
    s_t, s_r = scale_bias
    true_xytheta = np.asarray(true_xytheta, dtype=float)
    n = len(true_xytheta)
    d = np.diff(true_xytheta, axis=0)
    trans = np.hypot(d[:, 0], d[:, 1])
    rot1 = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - true_xytheta[:-1, 2])
    rot2 = wrap_angle(d[:, 2] - rot1)
    # below 1 cm the direction of travel is ill-defined: the decomposition stays exact, but the
    # noise is sized as for a pure turn (AMCL makes the same choice when it samples)
    moving = trans > 0.01
    # standing still, atan2(0, 0) gives rot1 = -theta and rot1 + rot2 may wrap to -2 pi, which
    # the rotation scale bias then turns into a spurious spin: decompose as a pure turn
    still = trans < 1e-9
    rot1 = np.where(still, 0.0, rot1)
    rot2 = np.where(still, wrap_angle(d[:, 2]), rot2)
    n1 = np.where(moving, rot1, 0.0)
    n2 = np.where(moving, rot2, wrap_angle(d[:, 2]))
    # driving backwards is rot1 = pi, not a half turn: size the noise on the angle to the
    # nearer of forward and backward (AMCL's delta_rot_noise), or reversing would throw the
    # odometry heading by tens of degrees
    n1 = np.minimum(np.abs(n1), np.abs(wrap_angle(n1 - np.pi)))
    n2 = np.where(moving, np.minimum(np.abs(n2), np.abs(wrap_angle(n2 - np.pi))), n2)
    sd1 = np.sqrt(a.alpha1 * n1**2 + a.alpha2 * trans**2)
    sdt = np.sqrt(a.alpha3 * trans**2 + a.alpha4 * (n1**2 + n2**2))
    sd2 = np.sqrt(a.alpha1 * n2**2 + a.alpha2 * trans**2)
    z = rng.standard_normal((max(n - 1, 0), 3))
    r1 = s_r * (rot1 + sd1 * z[:, 0])
    tr = s_t * (trans + sdt * z[:, 1])
    r2 = s_r * (rot2 + sd2 * z[:, 2])
    out = np.zeros((n, 3))
    th = np.concatenate([[0.0], np.cumsum(r1 + r2)])  # heading after each step
    heading_travel = th[:-1] + r1
    out[1:, 0] = np.cumsum(tr * np.cos(heading_travel))
    out[1:, 1] = np.cumsum(tr * np.sin(heading_travel))
    out[:, 2] = wrap_angle(th)
    return out


def stall_odometry(odom_xytheta: np.ndarray, cfg: OdomConfig, dt_s: float,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``odom_xytheta`` (N, 3) with stalls: starts drawn at ``cfg.stall_rate_per_min`` (a
    Poisson process over the scans, ``dt_s`` apart), each holding the reported pose at the
    one before for ``cfg.stall_s``; the scan after a stall reports the true odometry again,
    the whole motion in one step. Returns (stalled poses (N, 3), stall start indices (S,))."""
    out = np.array(odom_xytheta, dtype=float, copy=True)
    n = len(out)
    k = max(1, int(round(cfg.stall_s / dt_s)))
    p = cfg.stall_rate_per_min / 60.0 * dt_s
    starts = []
    i = 1
    draws = rng.random(n)
    while i < n:
        if draws[i] < p:
            out[i:i + k] = out[i - 1]
            starts.append(i)
            i += k + 1  # stalls do not overlap, and a catch-up step comes between
        else:
            i += 1
    return out, np.array(starts, dtype=int)


__all__ = ["RouteFollower", "draw_scale_bias", "drive", "sample_odometry", "stall_odometry"]
