"""People walking through the scene, seen by the laser as two swinging legs.

A person follows a polyline of random waypoints (straight legs between them) back and forth at a
constant speed drawn from the config range. Every segment keeps ``PERSON_CLEARANCE_M`` from walls,
columns and the bounding circles of furniture, so legs never enter an obstacle. People and the
robot give way to each other (:class:`Walker`, :func:`person_in_front`): nobody walks through the
robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gatmo.datasets.sim.config import PeopleConfig
from gatmo.datasets.sim.presets import random_pose
from gatmo.datasets.sim.world import World

LEG_RADIUS_M = 0.06
LEG_SPACING_M = 0.25  # between leg centres, sideways
SWING_M = 0.15  # fore/aft amplitude of each leg
STEP_HZ = 1.6  # stride frequency
PERSON_CLEARANCE_M = 0.35  # > reach of a leg edge from the walking line (~0.26 m)
ROBOT_KEEP_AWAY_M = 0.8  # people do not step closer than this to the robot's centre
ROBOT_STOP_M = 0.9  # the robot stands while a person is this close in front of it


@dataclass
class Person:
    """``waypoints`` (K, 2) [m] in the world, walked back and forth at ``speed_mps``."""

    waypoints: np.ndarray
    speed_mps: float
    phase: float

    def as_dict(self) -> dict:
        return {"waypoints": np.round(self.waypoints, 6).tolist(),
                "speed_mps": round(float(self.speed_mps), 6)}


def segment_clear(a: np.ndarray, b: np.ndarray, world: World, margin_m: float) -> bool:
    """True when the segment a-b keeps ``margin_m`` from furniture (bounding circles) and from the
    bounding boxes of walls/columns, and stays inside a room."""
    n = max(2, int(np.hypot(*(b - a)) / 0.1) + 1)
    pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    for p in world.pieces:
        if np.min(np.hypot(*(pts - p.pose_xytheta[:2]).T)) < p.radius_m + margin_m:
            return False
    for poly in world.static_polys:
        lo, hi = poly.min(axis=0) - margin_m, poly.max(axis=0) + margin_m
        if np.any(np.all((pts >= lo) & (pts <= hi), axis=1)):
            return False
    inside = np.zeros(len(pts), dtype=bool)
    for poly in world.interior:
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        inside |= np.all((pts >= lo) & (pts <= hi), axis=1)
    return bool(inside.all())


def make_people(world: World, cfg: PeopleConfig, rng: np.random.Generator,
                route: np.ndarray | None = None, waypoints: int = 6,
                avoid_xy: np.ndarray | None = None) -> list[Person]:
    """``cfg.count_per_run`` people with up to ``waypoints`` clear waypoints each, mostly near the
    route (where the robot sees them), starting >= 1.5 m from ``avoid_xy`` (the robot's start).
    A person without a clear start is dropped."""
    people = []
    for _ in range(cfg.count_per_run):
        start = None
        for _ in range(200):
            q = random_pose(world, rng, route, (0.8, 2.0))[:2]
            far = avoid_xy is None or np.hypot(*(q - avoid_xy)) >= 1.5
            if far and segment_clear(q, q, world, PERSON_CLEARANCE_M):
                start = q
                break
        if start is None:
            continue
        pts = [start]
        tries = 0
        while len(pts) < waypoints and tries < 500:
            tries += 1
            q = random_pose(world, rng, route, (0.8, 2.0))[:2]
            if np.hypot(*(q - pts[-1])) > 1.0 and segment_clear(pts[-1], q, world,
                                                                  PERSON_CLEARANCE_M):
                pts.append(q)
        if len(pts) >= 2:
            lo, hi = sorted((cfg.min_speed_mps, cfg.max_speed_mps))
            people.append(Person(np.array(pts), float(rng.uniform(lo, hi)),
                                 float(rng.uniform(0, 2 * np.pi))))
    return people


def position_along(person: Person, s_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre (2,) [m] and unit walking direction (2,) after walking ``s_m`` metres along the
    waypoints, forth and back."""
    seg = np.diff(person.waypoints, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    total = cum[-1]
    s = s_m % (2 * total)
    forward = s <= total
    s = s if forward else 2 * total - s
    k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
    u = seg[k] / max(lengths[k], 1e-9)
    return person.waypoints[k] + u * (s - cum[k]), (u if forward else -u)


def legs_at(centre: np.ndarray, heading: np.ndarray, swing_m: float) -> np.ndarray:
    """The two leg circles (2, 3) as (x, y, r): ``LEG_SPACING_M`` apart sideways, one
    ``swing_m`` ahead of the centre and the other as much behind."""
    side = np.array([-heading[1], heading[0]])
    half = LEG_SPACING_M / 2
    return np.array([[*(centre + half * side + swing_m * heading), LEG_RADIUS_M],
                     [*(centre - half * side - swing_m * heading), LEG_RADIUS_M]])


def person_state(person: Person, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre (2,) [m] and legs (2, 3) at ``t_s`` [s] after the run start, walking without
    pause (:class:`Walker` gives way to the robot)."""
    centre, heading = position_along(person, person.speed_mps * t_s)
    swing = SWING_M * np.sin(2 * np.pi * STEP_HZ * t_s + person.phase)
    return centre, legs_at(centre, heading, swing)


class Walker:
    """A person walking their waypoints, giving way to the robot.

    They do not take a step that would bring them closer than ``keep_away_m`` to the robot *and*
    closer than they are; they wait instead (legs still), after ``patience_s`` of waiting turn
    round and walk their path the other way, and after twice that squeeze past the (then
    stopped) robot at ``squeeze_m`` from its centre, as people do.
    """

    def __init__(self, person: Person, keep_away_m: float = ROBOT_KEEP_AWAY_M,
                 patience_s: float = 1.5, squeeze_m: float = 0.6) -> None:
        self.person = person
        self.keep_away_m = keep_away_m
        self.squeeze_m = squeeze_m
        self.patience_s = patience_s
        self.s_m = 0.0
        self.direction = 1.0
        self.swing_t = 0.0
        self.waited_s = 0.0

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre (2,) and legs (2, 3) now."""
        centre, heading = position_along(self.person, self.s_m)
        swing = SWING_M * np.sin(2 * np.pi * STEP_HZ * self.swing_t + self.person.phase)
        return centre, legs_at(centre, heading * self.direction, swing)

    def step(self, dt_s: float, robot_xy: np.ndarray) -> None:
        centre, _ = position_along(self.person, self.s_m)
        ds = self.direction * self.person.speed_mps * dt_s
        nxt, _ = position_along(self.person, self.s_m + ds)
        d_now = np.hypot(*(centre - robot_xy))
        d_next = np.hypot(*(nxt - robot_xy))
        keep = self.keep_away_m if self.waited_s < 2 * self.patience_s else self.squeeze_m
        if d_next >= keep or d_next >= d_now:
            self.s_m += ds
            self.swing_t += dt_s
            self.waited_s = 0.0
            return
        self.waited_s += dt_s
        if abs(self.waited_s - self.patience_s) < dt_s / 2:
            self.direction = -self.direction


def person_in_front(robot_pose: np.ndarray, centres_xy: np.ndarray,
                    stop_m: float = ROBOT_STOP_M, half_angle_rad: float = 1.2) -> bool:
    """True when a person's centre is within ``stop_m`` of the robot and within
    ``half_angle_rad`` of its heading: the robot's safety stop."""
    if len(centres_xy) == 0:
        return False
    d = centres_xy - robot_pose[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    bearing = np.abs(np.arctan2(d[:, 1], d[:, 0]) - robot_pose[2])
    bearing = np.minimum(bearing, 2 * np.pi - bearing)
    return bool(np.any((r < stop_m) & (bearing < half_angle_rad)))


__all__ = ["LEG_RADIUS_M", "Person", "legs_at", "make_people", "person_state", "position_along",
           "person_in_front", "segment_clear", "Walker"]
