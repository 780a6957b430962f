"""Rearranged-room scenarios: runs of a differential-drive robot through a world whose furniture
is rearranged between runs, with people walking and drifting odometry; written in the formats
users have (map_server map, CARMEN logs, TUM ground truth, optional ROS 2 bags).

Layouts: the map is layout L0; run K (1-based) drives through L_K = rearrange(L_{K-1}), so run 1
already differs from the map. Randomness: one ``np.random.SeedSequence(seed)`` spawns a stream
for the world and one per run (itself split into rearrangement, people, route, odometry and laser
streams), so run K of a 2-run and of a 4-run scenario with the same seed are identical.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_text
from gatmo.datasets.sim.config import SimConfig
from gatmo.datasets.sim.people import Person, Walker, make_people, person_in_front
from gatmo.datasets.sim.presets import make_world
from gatmo.datasets.sim.rearrange import rearrange
from gatmo.datasets.sim.robot import (
    RouteFollower,
    draw_scale_bias,
    sample_odometry,
    stall_odometry,
)
from gatmo.datasets.sim.world import World, cast, rasterize
from gatmo.datasets.types import Scan
from gatmo.errors import FormatError
from gatmo.geometry import compose, path_length_m

RANGE_MIN_M = 0.02
ROBOT_PATIENCE_S = 3.0  # after standing this long for a person, the robot creeps past them
RUN_T0_S = 1000.0  # run K starts at K * RUN_T0_S [s], so stamps never repeat across runs


@dataclass
class SimRun:
    """One simulated run in memory: scans (odometry and ground truth set), people, odom bias."""

    scans: list[Scan]
    people: list[Person]
    people_xy: np.ndarray  # (P, N, 2) centre of each person at each scan stamp [m]
    people_legs: np.ndarray  # (P, N, 2, 3) leg circles (x, y, r) [m] at each scan stamp
    scale_bias: tuple[float, float]  # odometry (translation, rotation) multipliers
    start_index: int  # route waypoint the robot started at


def _rngs(rng: np.random.Generator, n: int) -> list[np.random.Generator]:
    """``n`` independent streams seeded from ``rng`` (so adding draws to one part of the
    simulation does not shift the others)."""
    return [np.random.default_rng(int(s)) for s in rng.integers(0, 2**63 - 1, size=n)]


def simulate_run_detailed(world: World, route: np.ndarray, cfg: SimConfig,
                          rng: np.random.Generator, *, t0_s: float = 0.0,
                          people: list[Person] | None = None) -> SimRun:
    """Drive ``route`` (closed polyline (K, 2) [m]) through ``world`` for ``cfg.robot.duration_s``
    and scan at ``cfg.robot.scan_rate_hz``. Beams are cast analytically from the true laser pose
    against walls, columns, furniture and people's legs, then get Gaussian noise on returns and
    rare spurious short readings; no return = ``max_range_m`` (invalid in :class:`Scan`)."""
    r_people, r_drive, r_odom, r_laser = _rngs(rng, 4)
    start = int(r_drive.integers(len(route)))
    bot = RouteFollower(route, cfg.robot, start)
    if people is None:
        people = make_people(world, cfg.people, r_people, route, avoid_xy=bot.pose[:2])
    # robot and people move together: people give way, the robot stops for a person in front
    walkers = [Walker(p) for p in people]
    dt = 1.0 / cfg.robot.scan_rate_hz
    n = int(round(cfg.robot.duration_s * cfg.robot.scan_rate_hz))
    true = np.zeros((n, 3))
    people_xy = np.zeros((len(people), n, 2))
    people_legs = np.zeros((len(people), n, 2, 3))
    blocked_s = 0.0
    for i in range(n):
        true[i] = bot.pose
        for j, w in enumerate(walkers):
            people_xy[j, i], people_legs[j, i] = w.state()
        near = person_in_front(true[i], people_xy[:, i])
        blocked_s = blocked_s + dt if near else 0.0
        # a stand-off: after ROBOT_PATIENCE_S creep past unless someone is right ahead
        blocked = near and (blocked_s < ROBOT_PATIENCE_S or person_in_front(
            true[i], people_xy[:, i], stop_m=0.5, half_angle_rad=0.6))
        bot.step(dt, blocked=blocked)
        for w in walkers:
            w.step(dt, np.array([bot.x, bot.y]))
    bias = draw_scale_bias(cfg.odom, r_odom)
    odom = sample_odometry(true, cfg.odom, r_odom, bias)
    if cfg.odom.stall_rate_per_min > 0:  # drawn after: runs without stalls stay the same
        odom, _ = stall_odometry(odom, cfg.odom, dt, r_odom)
    L = cfg.laser
    angles = np.radians(np.linspace(-L.fov_deg / 2, L.fov_deg / 2, L.beams))
    laser_pose = np.array([L.forward_offset_m, 0.0, 0.0])
    segs, circles = world.segments_and_circles()
    scans = []
    for i, pose in enumerate(true):
        t = i * dt
        c = np.vstack([circles, *people_legs[:, i]]) if len(people) else circles
        lp = compose(pose, laser_pose)
        r = cast(lp[:2], lp[2] + angles, segs, c, L.max_range_m)
        hit = r < L.max_range_m
        if L.noise_std_m > 0:
            r = np.where(hit, r + r_laser.normal(0.0, L.noise_std_m, r.shape), r)
        if L.spurious_short_prob > 0:
            spurious = r_laser.random(r.shape) < L.spurious_short_prob
            r = np.where(spurious, r_laser.uniform(0.05, 1.0, r.shape) * r, r)
        r = np.clip(r, RANGE_MIN_M, L.max_range_m)
        scans.append(Scan(stamp_s=t0_s + t, ranges_m=r, angles_rad=angles,
                          range_min_m=RANGE_MIN_M, range_max_m=L.max_range_m,
                          odom_pose_xytheta=odom[i], laser_pose_xytheta=laser_pose.copy(),
                          gt_pose_xytheta=pose.copy()))
    return SimRun(scans, people, people_xy, people_legs, bias, start)


def simulate_run(world: World, route: np.ndarray, cfg: SimConfig,
                 rng: np.random.Generator) -> list[Scan]:
    """Scans of one run in memory (see :func:`simulate_run_detailed`), stamps from 0 s."""
    return simulate_run_detailed(world, route, cfg, rng).scans


# --------------------------------------------------------------------------- scenario
@dataclass
class ScenarioResult:
    """What :func:`simulate_scenario` wrote (paths) and its summary figures (``info``)."""

    out_dir: Path
    map_yaml: Path
    logs: list[Path]
    gt: list[Path]
    scenario_json: Path
    bags: list[Path] = field(default_factory=list)
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """preset, seed, runs, scans per run, objects, changes per run, people, path lengths."""
        return dict(self.info)


def _r(a, nd: int = 6):
    return np.round(np.asarray(a, dtype=float), nd).tolist()


def simulate_scenario(out_dir: str | Path, *, preset: str = "hall", runs: int = 4,
                      seed: int = 3, bag: bool = False, bag_storage: str = "sqlite3",
                      config: SimConfig | None = None) -> ScenarioResult:
    """Write a scenario into ``out_dir``: ``map.yaml`` + ``map.pgm`` (layout L0), per run K the
    layout L_K = rearrange(L_{K-1}) driven through as ``run_K.clf`` (+ ``run_K_bag/``) with
    ``run_K.gt.tum``, and ``scenario.json`` (objects per run, changes, people tracks, initial
    poses). Deterministic for a seed. ``preset`` chooses the world; ``config`` (default
    ``SimConfig.for_preset(preset)``) the parameters; ``bag_storage`` the ROS 2 bags' storage
    (sqlite3 or mcap)."""
    from gatmo.datasets.carmen import write_carmen
    from gatmo.datasets.tum import write_tum
    from gatmo.errors import ConfigError
    from gatmo.maps.io import save_map

    if bag:
        from gatmo.datasets.rosbag import check_ros2_storage

        check_ros2_storage(bag_storage, field="--bag-storage")  # before anything is written

    if runs < 1:
        raise ConfigError(f"runs must be >= 1, got {runs}", field="runs")
    cfg = SimConfig.for_preset(preset) if config is None else config
    if cfg.preset != preset:
        cfg = cfg.model_copy(update={"preset": preset})
    ss = np.random.SeedSequence(seed)
    world_ss, *run_ss = ss.spawn(1 + runs)
    world, route = make_world(preset, np.random.default_rng(world_ss))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    map_yaml = save_map(rasterize(world, cfg.resolution_m), out / "map.yaml")
    next_id = max((p.id for p in world.pieces), default=0) + 1
    layout0 = [p.as_dict() for p in world.pieces]
    earlier = {p.id: [p.pose_xytheta.copy()] for p in world.pieces}
    logs, gts, bags, run_docs = [], [], [], []
    for k in range(1, runs + 1):
        r_rearr, r_run = (np.random.default_rng(s) for s in run_ss[k - 1].spawn(2))
        world, changes, next_id = rearrange(world, route, cfg.rearrange, r_rearr, next_id,
                                            earlier)
        for p in world.pieces:
            poses = earlier.setdefault(p.id, [])
            if not any(np.allclose(p.pose_xytheta, q) for q in poses):
                poses.append(p.pose_xytheta.copy())
        t0 = RUN_T0_S * k
        sim = simulate_run_detailed(world, route, cfg, r_run, t0_s=t0)
        scans = sim.scans
        stamps = np.array([s.stamp_s for s in scans])
        gt_poses = np.array([s.gt_pose_xytheta for s in scans])
        logs.append(write_carmen(out / f"run_{k}.clf", scans))
        gts.append(write_tum(out / f"run_{k}.gt.tum", stamps, gt_poses))
        if bag:
            from gatmo.datasets.rosbag import write_ros2_bag

            # not "run_K.bag": rosbags' AnyReader takes any *.bag path for a ROS 1 file
            shutil.rmtree(out / f"run_{k}_bag", ignore_errors=True)
            bags.append(write_ros2_bag(out / f"run_{k}_bag", scans,
                                       gt_topic="/base_pose_ground_truth",
                                       storage=bag_storage))
        run_docs.append({
            "run": k,
            "layout": f"L{k}",
            "log": logs[-1].name,
            "ground_truth": gts[-1].name,
            "bag": bags[-1].name if bag else None,
            "t0_s": t0,
            "scans": len(scans),
            "initial_pose": _r(gt_poses[0], 9),
            "path_length_m": round(path_length_m(gt_poses), 6),
            "odom_scale_bias": _r(sim.scale_bias, 9),
            "objects": [p.as_dict() for p in world.pieces],
            "changes": changes,
            "people": [dict(p.as_dict(), id=j, stamps_s=_r(stamps, 6), xy=_r(sim.people_xy[j], 4))
                       for j, p in enumerate(sim.people)],
        })
    doc = {
        "format": "gatmo-scenario", "version": 1, "preset": preset, "seed": seed,
        "config": cfg.model_dump(mode="json"), "resolution_m": cfg.resolution_m,
        "map": map_yaml.name, "map_layout": "L0",
        "layouts": "the map is layout L0 (before any rearrangement); run K (1-based) drives "
                   "through layout L_K = rearrange(L_{K-1}), so run 1 already differs from the "
                   "map; changes of run K are relative to L_{K-1}",
        "route_xy": _r(route, 6),
        "map_objects": layout0, "runs": run_docs,
    }
    sj = atomic_write_text(out / "scenario.json", json.dumps(doc, indent=1) + "\n")
    info = {"preset": preset, "seed": seed, "runs": runs,
            "scans_per_run": [r["scans"] for r in run_docs],
            "objects": len(layout0),
            "objects_per_run": [len(r["objects"]) for r in run_docs],
            "changed_per_run": [len(r["changes"]) for r in run_docs],
            "people_per_run": [len(r["people"]) for r in run_docs],
            "path_length_m": [round(r["path_length_m"], 2) for r in run_docs]}
    return ScenarioResult(out, map_yaml, logs, gts, sj, bags, info)


def load_scenario(path: str | Path) -> dict:
    """Read a ``scenario.json`` (or the folder holding it); FormatError if it is not one."""
    path = Path(path)
    if path.is_dir():
        path = path / "scenario.json"
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise FormatError(f"cannot read scenario: {exc.strerror}", file=path) from None
    except ValueError as exc:
        raise FormatError(f"not JSON: {exc}", file=path) from None
    if not isinstance(doc, dict) or doc.get("format") != "gatmo-scenario":
        raise FormatError("not a gatmo scenario.json", file=path, field="format")
    if "runs" not in doc or "map_objects" not in doc:
        raise FormatError("scenario.json lacks 'runs' or 'map_objects'", file=path)
    return doc


__all__ = ["ScenarioResult", "SimRun", "load_scenario", "simulate_run", "simulate_run_detailed",
           "simulate_scenario"]
