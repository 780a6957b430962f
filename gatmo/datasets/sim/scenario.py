"""Rearranged-room scenarios: runs of a differential-drive robot through a world whose furniture
is rearranged between runs, with people walking and drifting odometry; written in the formats
users have (map_server map, CARMEN logs, TUM ground truth, optional ROS 2 bags)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_text
from gatmo.datasets.sim.config import SimConfig
from gatmo.datasets.sim.presets import make_world, place, placement_ok
from gatmo.datasets.sim.world import SHAPES, Piece, World, cast, rasterize
from gatmo.datasets.types import Scan
from gatmo.geometry import compose, wrap_angle

LEG_RADIUS_M = 0.06


# ------------------------------------------------------------------------------- robot
def drive(route: np.ndarray, cfg: SimConfig, rng: np.random.Generator) -> np.ndarray:
    """True poses (N, 3) at the scan rate: a unicycle steering to a lookahead point."""
    dt = 1.0 / cfg.robot.scan_rate_hz
    n = int(cfg.robot.duration_s * cfg.robot.scan_rate_hz)
    k0 = int(rng.integers(len(route)))
    pts = np.roll(route, -k0, axis=0)
    first = np.arctan2(*(pts[1] - pts[0])[::-1])
    pose = np.array([pts[0, 0], pts[0, 1], first])
    target = 1
    out = np.empty((n, 3))
    for i in range(n):
        out[i] = pose
        goal = pts[target % len(pts)]
        if np.hypot(*(goal - pose[:2])) < 0.3:
            target += 1
            goal = pts[target % len(pts)]
        err = wrap_angle(np.arctan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2])
        w = np.clip(2.0 * err, -cfg.robot.max_turn_rate_rps, cfg.robot.max_turn_rate_rps)
        v = cfg.robot.speed_mps * max(0.0, np.cos(err)) ** 4
        pose = pose + np.array([v * np.cos(pose[2]) * dt, v * np.sin(pose[2]) * dt, w * dt])
        pose[2] = wrap_angle(pose[2])
    return out


def odometry(true_xytheta: np.ndarray, cfg: SimConfig, rng: np.random.Generator) -> np.ndarray:
    """Odometry poses (N, 3) in an odom frame starting at (0, 0, 0): Thrun's odometry motion
    model (Probabilistic Robotics, Table 5.6) with a per-run scale bias on translation and
    rotation."""
    a = cfg.odom
    s_t = 1.0 + rng.normal(0, a.scale_bias_std)
    s_r = 1.0 + rng.normal(0, a.scale_bias_std)
    out = np.zeros_like(true_xytheta)
    for i in range(1, len(true_xytheta)):
        p0, p1 = true_xytheta[i - 1], true_xytheta[i]
        trans = np.hypot(*(p1[:2] - p0[:2]))
        rot1 = wrap_angle(np.arctan2(p1[1] - p0[1], p1[0] - p0[0]) - p0[2]) if trans > 1e-6 \
            else 0.0
        rot2 = wrap_angle(p1[2] - p0[2] - rot1)
        sd1 = np.sqrt(a.alpha1 * rot1**2 + a.alpha2 * trans**2)
        sdt = np.sqrt(a.alpha3 * trans**2 + a.alpha4 * (rot1**2 + rot2**2))
        sd2 = np.sqrt(a.alpha1 * rot2**2 + a.alpha2 * trans**2)
        r1 = s_r * (rot1 + rng.normal(0, sd1) if sd1 > 0 else rot1)
        tr = s_t * (trans + rng.normal(0, sdt) if sdt > 0 else trans)
        r2 = s_r * (rot2 + rng.normal(0, sd2) if sd2 > 0 else rot2)
        q = out[i - 1]
        out[i] = [q[0] + tr * np.cos(q[2] + r1), q[1] + tr * np.sin(q[2] + r1),
                  wrap_angle(q[2] + r1 + r2)]
    return out


# ------------------------------------------------------------------------------ people
@dataclass
class Person:
    waypoints: np.ndarray
    speed_mps: float
    phase: float


def _segment_clear(a, b, world: World, margin: float) -> bool:
    ts = np.linspace(0, 1, max(2, int(np.hypot(*(b - a)) / 0.1)))
    pts = a + ts[:, None] * (b - a)
    for p in world.pieces:
        if np.min(np.hypot(*(pts - p.pose_xytheta[:2]).T)) < p.radius_m + margin:
            return False
    for poly in world.static_polys:
        lo, hi = poly.min(axis=0) - margin, poly.max(axis=0) + margin
        if np.any(np.all((pts >= lo) & (pts <= hi), axis=1)):
            return False
    return True


def make_people(world: World, cfg: SimConfig, rng: np.random.Generator,
                route: np.ndarray | None = None) -> list[Person]:
    from gatmo.datasets.sim.presets import random_pose

    people = []
    for _ in range(cfg.people.count_per_run):
        pts = [random_pose(world, rng, route, (0.8, 2.0))[:2]]
        tries = 0
        while len(pts) < 6 and tries < 500:
            tries += 1
            q = random_pose(world, rng, route, (0.8, 2.0))[:2]
            if _segment_clear(pts[-1], q, world, 0.35):
                pts.append(q)
        if len(pts) >= 2 and _segment_clear(pts[0], pts[0], world, 0.35):
            people.append(Person(np.array(pts), rng.uniform(cfg.people.min_speed_mps,
                                                            cfg.people.max_speed_mps),
                                 rng.uniform(0, 2 * np.pi)))
    return people


def person_state(person: Person, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre (2,) and the two leg circles (2, 3) at time ``t`` (ping-pong along waypoints)."""
    seg = np.diff(person.waypoints, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    total = lengths.sum()
    s = (person.speed_mps * t) % (2 * total)
    forward = s <= total
    s = s if forward else 2 * total - s
    k = int(np.searchsorted(np.cumsum(lengths), s, side="right"))
    k = min(k, len(seg) - 1)
    s0 = np.concatenate([[0.0], np.cumsum(lengths)])[k]
    u = seg[k] / max(lengths[k], 1e-9)
    centre = person.waypoints[k] + u * (s - s0)
    heading = u if forward else -u
    side = np.array([-heading[1], heading[0]])
    swing = 0.15 * np.sin(2 * np.pi * 1.6 * t + person.phase)
    legs = np.array([[*(centre + 0.12 * side + swing * heading), LEG_RADIUS_M],
                     [*(centre - 0.12 * side - swing * heading), LEG_RADIUS_M]])
    return centre, legs


# ------------------------------------------------------------------------------- scans
def simulate_run(world: World, route: np.ndarray, cfg: SimConfig, rng: np.random.Generator,
                 *, t0_s: float = 0.0, people: list[Person] | None = None) -> list[Scan]:
    """Scans of one run in memory (odometry, ground truth, people as leg pairs)."""
    true = drive(route, cfg, rng)
    odom = odometry(true, cfg, rng)
    people = make_people(world, cfg, rng, route) if people is None else people
    L = cfg.laser
    angles = np.radians(np.linspace(-L.fov_deg / 2, L.fov_deg / 2, L.beams))
    laser_pose = np.array([L.forward_offset_m, 0.0, 0.0])
    segs, circles = world.segments_and_circles()
    dt = 1.0 / cfg.robot.scan_rate_hz
    scans = []
    for i, pose in enumerate(true):
        t = i * dt
        legs = [person_state(p, t)[1] for p in people]
        c = np.vstack([circles] + legs) if legs else circles
        lp = compose(pose, laser_pose)
        r = cast(lp[:2], lp[2] + angles, segs, c, L.max_range_m)
        hit = r < L.max_range_m
        if L.noise_std_m > 0:
            r = np.where(hit, r + rng.normal(0, L.noise_std_m, r.shape), r)
        spurious = rng.random(r.shape) < L.spurious_short_prob
        r = np.where(spurious, rng.uniform(0.05, 1.0, r.shape) * r, r)
        r = np.clip(r, 0.0, L.max_range_m)
        scans.append(Scan(stamp_s=t0_s + t, ranges_m=r, angles_rad=angles, range_min_m=0.02,
                          range_max_m=L.max_range_m, odom_pose_xytheta=odom[i],
                          laser_pose_xytheta=laser_pose.copy(), gt_pose_xytheta=pose.copy()))
    return scans


# ------------------------------------------------------------------------- rearranging
def rearrange(world: World, route: np.ndarray, cfg: SimConfig, rng: np.random.Generator,
              next_id: int) -> tuple[World, list[dict], int]:
    """A new layout and the list of changes (id, label, kind, old_pose, new_pose)."""
    R = cfg.rearrange
    new = world.copy()
    changes = []
    for piece in list(new.pieces):
        old = piece.pose_xytheta.copy()
        u = rng.random()
        if u < R.remove_prob:
            new.pieces.remove(piece)
            changes.append({"id": piece.id, "label": piece.label, "kind": "removed",
                            "old_pose": old.tolist(), "new_pose": None})
            continue
        if u < R.remove_prob + R.move_prob:
            kind, ok = "moved", place(new, piece, route, rng)
        elif u < R.remove_prob + R.move_prob + R.shift_prob:
            kind, ok = "shifted", False
            for _ in range(100):
                d = rng.uniform(R.shift_min_m, R.shift_max_m)
                a = rng.uniform(-np.pi, np.pi)
                piece.pose_xytheta = old + [d * np.cos(a), d * np.sin(a),
                                            rng.uniform(-np.pi / 3, np.pi / 3)]
                piece.pose_xytheta[2] = wrap_angle(piece.pose_xytheta[2])
                if placement_ok(piece, new.pieces, new, route):
                    ok = True
                    break
        else:
            continue
        if not ok:
            piece.pose_xytheta = old
            continue
        changes.append({"id": piece.id, "label": piece.label, "kind": kind,
                        "old_pose": old.tolist(), "new_pose": piece.pose_xytheta.tolist()})
    labels = sorted(SHAPES)
    for _ in range(R.add_count):
        piece = Piece(next_id, labels[rng.integers(len(labels))], np.zeros(3))
        if place(new, piece, route, rng):
            new.pieces.append(piece)
            changes.append({"id": piece.id, "label": piece.label, "kind": "added",
                            "old_pose": None, "new_pose": piece.pose_xytheta.tolist()})
            next_id += 1
    return new, changes, next_id


# --------------------------------------------------------------------------- scenario
@dataclass
class ScenarioResult:
    out_dir: Path
    map_yaml: Path
    logs: list[Path]
    gt: list[Path]
    scenario_json: Path
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return dict(self.info, map=str(self.map_yaml), logs=[str(p) for p in self.logs])


def simulate_scenario(out_dir: str | Path, *, preset: str = "hall", runs: int = 4,
                      seed: int = 3, bag: bool = False,
                      config: SimConfig | None = None) -> ScenarioResult:
    """Write a scenario: ``map.yaml`` + ``map.pgm`` (layout L0), per run K the layout
    L_K = rearrange(L_{K-1}) driven through as ``run_K.clf`` (+ ``run_K.bag/``) with
    ``run_K.gt.tum``, and ``scenario.json`` (objects per run, changes, people). Deterministic for a
    seed."""
    from gatmo.datasets.carmen import write_carmen
    from gatmo.datasets.tum import write_tum
    from gatmo.maps.io import save_map

    cfg = config or SimConfig.for_preset(preset)
    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    world, route = make_world(cfg.preset, rng)
    grid0 = rasterize(world, cfg.resolution_m)
    map_yaml = save_map(grid0, out / "map.yaml")
    next_id = max((p.id for p in world.pieces), default=0) + 1
    layout0 = [p.as_dict() for p in world.pieces]
    logs, gts, run_docs = [], [], []
    n_scans = []
    for k in range(1, runs + 1):
        world, changes, next_id = rearrange(world, route, cfg, rng, next_id)
        people = make_people(world, cfg, rng, route)
        scans = simulate_run(world, route, cfg, rng, t0_s=1000.0 * k, people=people)
        log = write_carmen(out / f"run_{k}.clf", scans)
        gt = write_tum(out / f"run_{k}.gt.tum", [s.stamp_s for s in scans],
                       np.array([s.gt_pose_xytheta for s in scans]))
        if bag:
            import shutil

            from gatmo.datasets.rosbag import write_ros2_bag

            shutil.rmtree(out / f"run_{k}.bag", ignore_errors=True)
            write_ros2_bag(out / f"run_{k}.bag", scans, gt_topic="/base_pose_ground_truth")
        logs.append(log)
        gts.append(gt)
        n_scans.append(len(scans))
        run_docs.append({
            "run": k,
            "log": log.name,
            "ground_truth": gt.name,
            "initial_pose": scans[0].gt_pose_xytheta.tolist(),
            "objects": [p.as_dict() for p in world.pieces],
            "changes": changes,
            "people": [{"waypoints": p.waypoints.tolist(), "speed_mps": p.speed_mps}
                       for p in people],
        })
    doc = {
        "format": "gatmo-scenario", "version": 1, "preset": cfg.preset, "seed": seed,
        "config": cfg.model_dump(mode="json"), "resolution_m": cfg.resolution_m,
        "map": map_yaml.name,
        "note": "the map is layout L0; run K drives through L_K = rearrange(L_{K-1})",
        "map_objects": layout0, "runs": run_docs,
    }
    sj = atomic_write_text(out / "scenario.json", json.dumps(doc, indent=1))
    info = {"preset": cfg.preset, "seed": seed, "runs": runs, "scans_per_run": n_scans,
            "objects": len(layout0),
            "changed_per_run": [len(r["changes"]) for r in run_docs],
            "people_per_run": [len(r["people"]) for r in run_docs]}
    return ScenarioResult(out, map_yaml, logs, gts, sj, info)


def load_scenario(path: str | Path) -> dict:
    from gatmo.errors import FormatError

    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise FormatError(f"cannot read scenario: {exc}", file=path) from None
    if doc.get("format") != "gatmo-scenario":
        raise FormatError("not a gatmo scenario.json", file=path, field="format")
    return doc


__all__ = ["ScenarioResult", "load_scenario", "simulate_run", "simulate_scenario"]
