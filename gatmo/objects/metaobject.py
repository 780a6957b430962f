"""Metaobjects (paper, Sec. IV): a track of unexplained returns with two hypotheses, *person*
(constant-velocity Kalman filter on the centre) and *chair* (an evidence grid that only adds
probability where returns land)."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter

from gatmo.geometry import points_to_beams

# Points scatter around a person's centre (two legs ~0.25 m apart): the person likelihood uses
# the KF's centre covariance plus this spread, or every point but the centre would be
# "impossible" for a walking person.
BODY_SPREAD_M = 0.2


class Metaobject:
    """One tracked cluster. ``points`` are world points (K, 2) of its first observation."""

    def __init__(self, mid: int, points: np.ndarray, stamp_s: float, cfg, res_m: float,
                 verified: bool = True):
        self.id = mid
        self.cfg = cfg
        self.res = res_m
        c = points.mean(axis=0)
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.x = np.array([c[0], c[1], 0.0, 0.0])
        kf.H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
        kf.P = np.diag([0.05, 0.05, 1.0, 1.0])
        kf.R = np.eye(2) * cfg.person_meas_std_m**2
        self.kf = kf
        self.t = stamp_s
        self.first_seen = stamp_s
        self.last_seen = stamp_s
        self.evidence: dict[tuple[int, int], int] = {}
        # per evidence cell, the later scans whose beams went on well beyond it (seen
        # through: what stood there left; :meth:`note_passes`)
        self.passes: dict[tuple[int, int], int] = {}
        # the same grid from the scans whose pose an independent check confirmed only
        self.evidence_verified: dict[tuple[int, int], int] = {}
        self.n_verified = 0  # observations from independently confirmed poses
        self.n_obs = 0
        self.ll_person = 0.0
        self.ll_chair = 0.0
        self.centres: list[np.ndarray] = []
        self.matched_object: int | None = None
        # the nearest this track was seen from: the least, over its scans, of the median range
        # of its returns from the laser [m] (set by the mapper; inf until then)
        self.nearest_view_m = float("inf")
        self.waited = False  # a match was held back as ambiguous (GatmoMapper._ambiguous)
        # the scans that saw it (set by the mapper): laser pose, angles, ranges, reach
        self.views: list[tuple] = []
        # the returns (K, 2) of each scan that fed it, map frame (as views: at most 48, every
        # other dropped past that), for the extent test of a match (matching.extent_excess)
        self.scan_points: list[np.ndarray] = []
        self._add(points, stamp_s, verified)

    # -------------------------------------------------------------- hypotheses
    def predict(self, stamp_s: float) -> None:
        dt = max(0.0, stamp_s - self.t)
        if dt > 0:
            self.kf.F = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1.0]])
            q = self.cfg.person_accel_std**2
            g = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
            self.kf.Q = g @ g.T * q
            self.kf.predict()
            self.t = stamp_s

    def log_p_person(self, points: np.ndarray) -> float:
        """sum_k log P(x_k | p_j): the KF's normal integrated over a 2 delta_R cell."""
        mu = self.kf.x[:2]
        S = self.kf.P[:2, :2] + np.eye(2) * BODY_SPREAD_M**2
        inv = np.linalg.inv(S)
        d = points - mu
        m = np.einsum("ij,jk,ik->i", d, inv, d)
        pdf = np.exp(-0.5 * m) / (2 * np.pi * np.sqrt(np.linalg.det(S)))
        cell = (2 * self.cfg.delta_R_m) ** 2
        return float(np.sum(np.log(np.maximum(pdf * cell, 1e-300))))

    def _keys(self, points: np.ndarray) -> np.ndarray:
        return np.floor(points / self.res).astype(np.int64)

    def log_p_chair(self, points: np.ndarray) -> float:
        """sum_k log P(x_k | chair): how often returns landed near x_k in this track."""
        if self.n_obs == 0:
            return float(len(points) * np.log(self.cfg.beta_min_prob))
        total = 0.0
        for kx, ky in self._keys(points):
            best = 0
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    best = max(best, self.evidence.get((kx + dx, ky + dy), 0))
            total += np.log(max(min(best / self.n_obs, 1.0), 0.01))
        return float(total)

    def log_p(self, points: np.ndarray) -> float:
        """log P(z | m_j) = log (P(z | person) + P(z | chair))."""
        return float(np.logaddexp(self.log_p_person(points), self.log_p_chair(points)))

    # ------------------------------------------------------------------ update
    def update(self, points: np.ndarray, stamp_s: float, verified: bool = True) -> None:
        self.predict(stamp_s)
        # accumulate each hypothesis' predictive likelihood, per point so sizes compare
        n = max(len(points), 1)
        self.ll_person = 0.9 * self.ll_person + self.log_p_person(points) / n
        self.ll_chair = 0.9 * self.ll_chair + self.log_p_chair(points) / n
        self._add(points, stamp_s, verified)

    def _add(self, points: np.ndarray, stamp_s: float, verified: bool = True) -> None:
        c = points.mean(axis=0)
        self.scan_points.append(np.asarray(points, dtype=float).copy())
        if len(self.scan_points) > 48:
            self.scan_points = self.scan_points[::2]
        if self.n_obs:
            self.kf.update(c)
        self.centres.append(c)
        keys = {tuple(k) for k in self._keys(points).tolist()}
        for k in keys:
            self.evidence[k] = self.evidence.get(k, 0) + 1
        if verified:
            for k in keys:
                self.evidence_verified[k] = self.evidence_verified.get(k, 0) + 1
            self.n_verified += 1
        self.n_obs += 1
        self.last_seen = stamp_s

    # ---------------------------------------------------------------- verdicts
    @property
    def speed_mps(self) -> float:
        return float(np.hypot(self.kf.x[2], self.kf.x[3]))

    def travel_m(self) -> float:
        c = np.array(self.centres)
        return float(np.max(np.hypot(*(c - c[0]).T))) if len(c) > 1 else 0.0

    def dominant(self) -> str:
        """"chair", "person" or "unknown" (too few observations)."""
        # the centre of what is seen of a still object wanders as the view changes (up to its
        # size); a person keeps going
        # (the KF's speed is no verdict: the visible part of a still object changes with the
        # viewpoint and its centroid jumps by tenths of a metre between scans)
        if self.moving():
            return "person"
        if self.n_obs < self.cfg.chair_min_scans:
            return "unknown"
        vmin = self.cfg.person_min_vacated
        if vmin is not None and self.vacated() > vmin:
            # beyond the paper: where it stood was seen through since; whatever its chair
            # likelihood (a walker's few returns fit any grid), it left
            return "person"
        if self.ll_chair >= self.ll_person:
            return "chair"
        return "person"

    def moving(self) -> bool:
        """Its centre travelled more than 1.2 m, or the person filter's speed passed 0.8 m/s
        after 5 scans: the person hypothesis keeps going (paper, Sec. IV)."""
        return self.travel_m() > 1.2 or (self.n_obs >= 5 and self.speed_mps > 0.8)

    def concentration(self) -> float:
        """Share of the evidence (hits summed over cells) on cells hit in at least
        ``still_min_hits`` scans. A still thing is hit on the same cells scan after scan (hall
        seeds 100-104, true poses: 0.95-0.99 for tracks on pieces); a walking person leaves a
        trail of cells hit once or twice (at most 0.65)."""
        if not self.evidence:
            return 0.0
        ev = np.fromiter(self.evidence.values(), dtype=np.int64, count=len(self.evidence))
        return float(ev[ev >= self.cfg.still_min_hits].sum() / ev.sum())

    def still_though_moving(self) -> bool:
        """Called a person for its motion only (its centre travelled, :meth:`moving`) while
        its evidence is concentrated (``still_min_concentration``), or with
        ``still_max_vacated`` while nothing saw through where it stood and its cells were hit
        again (``still_vacated_min_concentration``): pieces side by side, or a desk, seen in
        parts from a moving robot."""
        c = self.cfg
        if not (self.n_obs >= c.chair_min_scans and self.moving()
                and self.ll_chair >= self.ll_person):
            return False
        if c.still_max_vacated is None:
            return self.concentration() >= c.still_min_concentration
        # beyond the paper: nothing saw through where it stood, and its cells were hit again
        # (a person walking at the laser hides their trail instead)
        return (self.vacated() <= c.still_max_vacated
                and self.concentration() >= c.still_vacated_min_concentration)

    def note_passes(self, view: tuple, through_m: float) -> None:
        """Count the evidence cells the scan ``view`` (laser pose (3,) map frame, beam angles
        (B,) sorted [rad], ranges (B,) [m], reach [m], as :attr:`views`) saw through: the beam
        nearest the cell and both its neighbours end more than ``through_m`` beyond it. Beyond
        the paper: where a person stood, the next scans see the wall behind; a still thing
        seen in parts from a moving robot is hit or hidden, never seen through. The
        neighbours keep a beam grazing a still thing's outline (pose jitter) from counting."""
        lp, angles, ranges, reach = view
        if not self.evidence or len(angles) < 3:
            return
        keys = np.array(list(self.evidence), dtype=np.int64)
        rk, bk, j = points_to_beams((keys + 0.5) * self.res, lp, angles)
        half = 0.5 * np.abs(np.diff(angles)).mean()
        r = np.where(np.isnan(ranges), -np.inf, ranges)
        jm, jp = np.maximum(j - 1, 0), np.minimum(j + 1, len(angles) - 1)
        past = rk + through_m
        seen = ((rk <= reach) & (np.abs(angles[j] - bk) <= half) & (j > 0)
                & (j < len(angles) - 1) & (r[j] > past) & (r[jm] > past) & (r[jp] > past))
        for k in map(tuple, keys[seen].tolist()):
            self.passes[k] = self.passes.get(k, 0) + 1

    def vacated(self) -> float:
        """Share of the evidence (hits summed over cells) on cells seen through in as many
        later scans as hit them or more (:meth:`note_passes`): near 1 for a walking person's
        trail, near 0 for a still thing however its centre wandered."""
        if not self.evidence:
            return 0.0
        tot = gone = 0
        for k, v in self.evidence.items():
            tot += v
            if self.passes.get(k, 0) >= v:
                gone += v
        return gone / tot

    def chair_points(self, min_count: int = 2, min_fraction: float = 0.05,
                     verified: bool = False) -> np.ndarray:
        """World centres (K, 2) of evidence cells hit in at least ``min_count`` scans and
        ``min_fraction`` of this track's scans. The count is absolute, not a fraction of all
        scans: a robot driving past sees each side of a still object for a part of the time.
        ``verified``: from the scans whose pose was independently confirmed only."""
        ev, n = ((self.evidence_verified, self.n_verified) if verified
                 else (self.evidence, self.n_obs))
        need = max(min_count, int(np.ceil(min_fraction * n)))
        keys = [k for k, v in ev.items() if v >= need]
        if not keys:
            return np.zeros((0, 2))
        return (np.array(keys, dtype=float) + 0.5) * self.res

    def _cells(self) -> np.ndarray:
        if not self.evidence:
            return np.zeros((0, 2))
        return (np.array(list(self.evidence), dtype=float) + 0.5) * self.res

    def near(self, points: np.ndarray, dist_m: float) -> bool:
        """Whether any of ``points`` (N, 2) lies within ``dist_m`` of this track's evidence."""
        cells = self._cells()
        if len(cells) == 0 or len(points) == 0:
            return False
        lo = points.min(axis=0) - dist_m
        hi = points.max(axis=0) + dist_m
        cells = cells[np.all((cells >= lo) & (cells <= hi), axis=1)]
        if len(cells) == 0:
            return False
        d2 = ((points[:, None, :] - cells[None, :, :]) ** 2).sum(-1)
        return bool(d2.min() <= dist_m**2)

    def touches(self, other: Metaobject) -> bool:
        """Evidence cells of the two tracks overlap or are adjacent (8-connectivity)."""
        small, large = sorted((self.evidence, other.evidence), key=len)
        return any((kx + dx, ky + dy) in large for kx, ky in small
                   for dx in (-1, 0, 1) for dy in (-1, 0, 1))

    def add_view(self, view: tuple, max_views: int = 48) -> None:
        """Keep the scan ``view`` that saw this track; past ``max_views``, every other one is
        dropped, so the kept views still span the whole track."""
        self.views.append(view)
        if len(self.views) > max_views:
            self.views = self.views[::2]

    def absorb(self, other: Metaobject) -> None:
        """Merge ``other`` (a part of the same object tracked separately) into this track."""
        for v in other.views:
            if all(v is not w for w in self.views):
                self.add_view(v)
        self.scan_points = (self.scan_points + other.scan_points)[-48:]
        for k, v in other.evidence.items():
            self.evidence[k] = self.evidence.get(k, 0) + v
        for k, v in other.passes.items():
            self.passes[k] = self.passes.get(k, 0) + v
        for k, v in other.evidence_verified.items():
            self.evidence_verified[k] = self.evidence_verified.get(k, 0) + v
        self.n_obs = max(self.n_obs, other.n_obs)
        self.n_verified += other.n_verified
        self.first_seen = min(self.first_seen, other.first_seen)
        self.nearest_view_m = min(self.nearest_view_m, other.nearest_view_m)
        self.last_seen = max(self.last_seen, other.last_seen)
        self.ll_chair = max(self.ll_chair, other.ll_chair)
        self.ll_person = min(self.ll_person, other.ll_person)
        if self.matched_object is None:
            self.matched_object = other.matched_object
