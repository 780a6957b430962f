"""The simulator: deterministic, its scans agree with its own ground truth, its odometry drifts as
configured, its rearrangements keep pieces apart and ids stable, its files read back."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gatmo.datasets.carmen import CarmenLog
from gatmo.datasets.sim import (
    SimConfig,
    load_scenario,
    make_world,
    rasterize,
    simulate_run,
    simulate_run_detailed,
    simulate_scenario,
)
from gatmo.datasets.sim.people import LEG_RADIUS_M
from gatmo.datasets.sim.presets import route_distance
from gatmo.datasets.sim.rearrange import rearrange
from gatmo.datasets.sim.robot import drive, sample_odometry, stall_odometry
from gatmo.datasets.sim.world import Piece, World, cast, points_in_polygon
from gatmo.datasets.tum import read_tum
from gatmo.errors import ConfigError, FormatError
from gatmo.geometry import compose, path_length_m, relative, transform_points, wrap_angle
from gatmo.maps.grid import FREE, OCCUPIED
from gatmo.maps.io import load_map
from tests.helpers import march_ranges


def short_cfg(preset: str = "hall", duration_s: float = 12.0) -> SimConfig:
    cfg = SimConfig.for_preset(preset)
    cfg.robot.duration_s = duration_s
    return cfg


# --------------------------------------------------------------------------- world
def test_cast_known_answers():
    """A beam along +x from the origin: wall segment at x=3, a circle r=0.5 at x=2."""
    segs = np.array([[3.0, -1.0, 3.0, 1.0]])
    circles = np.array([[2.0, 0.0, 0.5]])
    a = np.array([0.0, np.pi, np.pi / 2])
    r = cast(np.zeros(2), a, segs, circles, 10.0)
    np.testing.assert_allclose(r, [1.5, 10.0, 10.0])
    r = cast(np.zeros(2), a, segs, np.zeros((0, 3)), 10.0)
    np.testing.assert_allclose(r, [3.0, 10.0, 10.0])
    # a 45 degree beam to the wall at x=3 hits at y=3 > 1: misses the segment
    assert cast(np.zeros(2), np.array([np.pi / 4]), segs, np.zeros((0, 3)), 10.0)[0] == 10.0


def test_rasterize_fills_pieces_and_marks_outside_unknown():
    sq = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=float)
    w = World((-1, -1, 5, 5), [sq], [], [Piece(1, "desk", np.array([2.0, 2.0, 0.0]))])
    g = rasterize(w, 0.05)
    assert g.value_at(np.array([[2.0, 2.0]]))[0] == OCCUPIED  # interior filled
    assert g.value_at(np.array([[2.65, 2.3]]))[0] == OCCUPIED  # desk is 1.4 x 0.7
    assert g.value_at(np.array([[2.0, 2.45]]))[0] == FREE
    assert g.value_at(np.array([[-0.5, 2.0]]))[0] == -1
    # every cell the desk overlaps is occupied, as a map built from scans has it: the edge
    # cells' centres lie on its surfaces (not half a cell inside)
    area = g.occupied.sum() * 0.05**2
    assert area == pytest.approx((1.4 + 0.05) * (0.7 + 0.05), rel=0.02)
    xy = g.occupied_cells_world()
    assert xy.min(axis=0) == pytest.approx([1.3, 1.65], abs=1e-6)
    assert xy.max(axis=0) == pytest.approx([2.7, 2.35], abs=1e-6)


@pytest.mark.parametrize("preset", ["hall", "office"])
def test_presets_have_expected_content(preset):
    world, route = make_world(preset, np.random.default_rng(0))
    n = len(world.pieces)
    assert (14 <= n <= 18) if preset == "hall" else (6 <= n <= 10)
    # same label, same shape (look-alike objects)
    for p in world.pieces:
        same = [q for q in world.pieces if q.label == p.label]
        assert all(q.as_dict()["shape"] == p.as_dict()["shape"] for q in same)
    grid = rasterize(world)
    # the route runs through free space with margin: no occupied cell within 0.45 m of it
    occ = grid.occupied_cells_world()
    assert route_distance(occ, route).min() > 0.45
    # inside the building every cell is known (doors included), outside everything is unknown
    iy, ix = np.indices(grid.cells.shape)
    xy = grid.cell_to_world(np.stack([ix.ravel(), iy.ravel()], axis=1))
    x0, y0, x1, y1 = world.bounds_xy
    inside = (xy[:, 0] > x0 + 0.5) & (xy[:, 0] < x1 - 0.5) & (xy[:, 1] > y0 + 0.5) & (
        xy[:, 1] < y1 - 0.5)
    cells = grid.cells.ravel()
    assert np.all(cells[inside] != -1)
    assert np.all(cells[(xy[:, 0] < x0 + 0.3) | (xy[:, 1] < y0 + 0.3)] == -1)


# -------------------------------------------------------------------- determinism
def test_deterministic_for_a_seed(tmp_path):
    cfg = short_cfg()
    a = simulate_scenario(tmp_path / "a", runs=2, seed=5, config=cfg)
    simulate_scenario(tmp_path / "b", runs=2, seed=5, config=cfg)
    for name in ("map.pgm", "map.yaml", "run_1.clf", "run_2.clf", "run_2.gt.tum",
                 "scenario.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    # run 1 does not depend on how many runs follow; another seed gives other data
    run1 = (tmp_path / "a" / "run_1.clf").read_bytes()
    simulate_scenario(tmp_path / "c", runs=1, seed=5, config=cfg)
    assert (tmp_path / "c" / "run_1.clf").read_bytes() == run1
    simulate_scenario(tmp_path / "d", runs=1, seed=6, config=cfg)
    assert (tmp_path / "d" / "run_1.clf").read_bytes() != run1
    s = a.summary()
    assert s["runs"] == 2 and s["scans_per_run"] == [120, 120] and s["preset"] == "hall"


# ------------------------------------------------------------ scans vs ground truth
@pytest.mark.parametrize("preset", ["hall", "office"])
def test_scans_agree_with_ground_truth_in_rasterized_world(preset):
    rng = np.random.default_rng(1)
    cfg = short_cfg(preset, 20.0)
    cfg.people.count_per_run = 3
    world, route = make_world(preset, rng)
    run = simulate_run_detailed(world, route, cfg, rng)
    grid = rasterize(world, 0.05)
    errs, agree, n_people = [], [], 0
    for i, s in enumerate(run.scans[::10]):
        lp = compose(s.gt_pose_xytheta, s.laser_pose_xytheta)
        ref = march_ranges(grid, lp, s.angles_rad, s.range_max_m, step_m=0.01)
        # beams ending near a person are people, not the static/furniture world
        ends = lp[:2] + s.ranges_m[:, None] * np.stack(
            [np.cos(lp[2] + s.angles_rad), np.sin(lp[2] + s.angles_rad)], axis=1)
        near = np.zeros(s.num_beams, dtype=bool)
        for xy in run.people_xy[:, i * 10]:
            near |= np.hypot(*(ends - xy).T) < 0.45
        n_people += near.sum()
        both = (ref < s.range_max_m) & s.valid & ~near
        errs.append(np.abs(ref - s.ranges_m)[both])
        agree.append(((ref < s.range_max_m) == s.valid)[~near])
    errs = np.concatenate(errs)
    assert len(errs) > 500
    assert np.median(errs) < 0.05  # within a cell of the 5 cm raster
    assert np.quantile(errs, 0.9) < 0.1
    assert np.concatenate(agree).mean() > 0.97


def test_people_legs_are_seen():
    """With people close in front of the robot, some beams end on legs (r = 6 cm circles)."""
    rng = np.random.default_rng(3)
    cfg = short_cfg("hall", 30.0)
    cfg.people.count_per_run = 4
    cfg.laser.noise_std_m = 0.0
    cfg.laser.spurious_short_prob = 0.0
    world, route = make_world("hall", rng)
    run = simulate_run_detailed(world, route, cfg, rng)
    on_leg = 0
    for i, s in enumerate(run.scans):
        lp = compose(s.gt_pose_xytheta, s.laser_pose_xytheta)
        ends = transform_points(lp, s.points_laser_xy())
        for legs in run.people_legs[:, i]:
            d = np.hypot(*(ends[:, None, :] - legs[None, :, :2]).transpose(2, 0, 1))
            on_leg += int((np.abs(d - LEG_RADIUS_M) < 1e-6).any(axis=1).sum())
    assert on_leg > 20


# ---------------------------------------------------------------------- odometry
def _true_path():
    world, route = make_world("hall", np.random.default_rng(0))
    cfg = short_cfg("hall", 60.0)
    return drive(route, cfg.robot, np.random.default_rng(0), start_index=0), cfg


def test_robot_respects_speed_and_turn_limits():
    true, cfg = _true_path()
    d = np.diff(true, axis=0)
    dt = 1.0 / cfg.robot.scan_rate_hz
    assert np.hypot(d[:, 0], d[:, 1]).max() / dt <= cfg.robot.speed_mps + 1e-9
    assert np.abs(wrap_angle(d[:, 2])).max() / dt <= cfg.robot.max_turn_rate_rps + 1e-9
    assert path_length_m(true) > 0.8 * cfg.robot.speed_mps * cfg.robot.duration_s


def test_odometry_scale_bias_is_applied_exactly_without_noise():
    true, cfg = _true_path()
    quiet = cfg.odom.model_copy(update={"alpha1": 0.0, "alpha2": 0.0, "alpha3": 0.0,
                                        "alpha4": 0.0})
    od = sample_odometry(true, quiet, np.random.default_rng(0), (1.03, 0.97))
    np.testing.assert_allclose(od[0], 0.0)
    assert path_length_m(od) == pytest.approx(1.03 * path_length_m(true), rel=1e-9)
    turn_true = np.abs(wrap_angle(np.diff(true[:, 2]))).sum()
    turn_od = np.abs(wrap_angle(np.diff(od[:, 2]))).sum()
    assert turn_od == pytest.approx(0.97 * turn_true, rel=1e-6)
    # unbiased and noise-free: odometry is the true path moved to the odom origin
    od1 = sample_odometry(true, quiet, np.random.default_rng(0))
    back = np.array([compose(true[0], q) for q in od1])
    np.testing.assert_allclose(back[:, :2], true[:, :2], atol=1e-9)


def test_odometry_stalls_hold_still_then_catch_up():
    """``odom.stall_rate_per_min``: each stall repeats the pose before it for ``stall_s``, and
    the scan after it is the unstalled odometry again (the whole motion in one step)."""
    true, cfg = _true_path()
    od = sample_odometry(true, cfg.odom, np.random.default_rng(0))
    stall = cfg.odom.model_copy(update={"stall_rate_per_min": 6.0, "stall_s": 1.0})
    dt = 1.0 / cfg.robot.scan_rate_hz
    out, starts = stall_odometry(od, stall, dt, np.random.default_rng(1))
    k = int(round(1.0 / dt))
    assert len(starts) >= 1 and np.all(np.diff(starts) > k)
    held = np.zeros(len(od), dtype=bool)
    for i in starts:
        np.testing.assert_array_equal(out[i:i + k], np.repeat(od[i - 1][None], len(out[i:i + k]),
                                                              axis=0))
        held[i:i + k] = True
        if i + k < len(od):
            np.testing.assert_array_equal(out[i + k], od[i + k])
    np.testing.assert_array_equal(out[~held], od[~held])
    # a run with stalls is the run without them but for the odometry
    cfg6 = short_cfg()
    cfg6.odom.stall_rate_per_min = 20.0
    world, route = make_world("hall", np.random.default_rng(4))
    plain = simulate_run(world, route, short_cfg(), np.random.default_rng(5))
    stalled = simulate_run(world, route, cfg6, np.random.default_rng(5))
    assert [s.stamp_s for s in plain] == [s.stamp_s for s in stalled]
    np.testing.assert_array_equal(np.array([s.ranges_m for s in plain]),
                                  np.array([s.ranges_m for s in stalled]))
    a = np.array([s.odom_pose_xytheta for s in plain])
    b = np.array([s.odom_pose_xytheta for s in stalled])
    still = np.all(np.diff(b, axis=0) == 0.0, axis=1)
    assert still.sum() >= 10 and not np.all(a == b)
    assert np.all(np.any(np.diff(a, axis=0) != 0.0, axis=1))  # the robot never stands still


def test_odometry_noise_matches_alpha3_and_drift_grows():
    true, cfg = _true_path()
    only_t = cfg.odom.model_copy(update={"alpha1": 0.0, "alpha2": 0.0, "alpha3": 0.04,
                                         "alpha4": 0.0})
    od = sample_odometry(true, only_t, np.random.default_rng(1))
    trans = np.hypot(*np.diff(true[:, :2], axis=0).T)
    meas = np.hypot(*np.diff(od[:, :2], axis=0).T)
    moving = trans > 0.02
    assert np.std(meas[moving] / trans[moving] - 1.0) == pytest.approx(0.2, rel=0.1)
    # drift of dead reckoning from the true start grows with time (averaged over seeds)
    errs = []
    for seed in range(20):
        o = sample_odometry(true, cfg.odom, np.random.default_rng(seed),
                            (1.0 + 0.02 * np.random.default_rng(100 + seed).standard_normal(),
                             1.0))
        dead = compose(true[0], relative(o[0], o))
        errs.append(np.hypot(*(dead[:, :2] - true[:, :2]).T))
    e = np.mean(errs, axis=0)
    assert e[100] < e[300] < e[-1]
    assert 0.05 < e[-1] < 2.0


# ------------------------------------------------------------------ rearrangement
def _piece_cells(world: World, piece: Piece) -> np.ndarray:
    solo = World(world.bounds_xy, world.interior, [], [piece])
    return rasterize(solo, 0.05).occupied


def test_rearrangement_keeps_ids_and_pieces_apart():
    rng = np.random.default_rng(4)
    cfg = SimConfig.for_preset("hall")
    world, route = make_world("hall", rng)
    next_id = max(p.id for p in world.pieces) + 1
    kinds = set()
    for _ in range(3):
        before = {p.id: p for p in world.pieces}
        new, changes, next_id2 = rearrange(world, route, cfg.rearrange, rng, next_id)
        by_id = {c["id"]: c for c in changes}
        kinds |= {c["kind"] for c in changes}
        removed = {c["id"] for c in changes if c["kind"] == "removed"}
        added = {c["id"] for c in changes if c["kind"] == "added"}
        assert {p.id for p in new.pieces} == (set(before) - removed) | added
        assert all(i >= next_id for i in added) and next_id2 == next_id + len(added)
        for p in new.pieces:
            c = by_id.get(p.id)
            if c is None:  # untouched pieces keep their pose exactly
                np.testing.assert_array_equal(p.pose_xytheta, before[p.id].pose_xytheta)
            else:
                np.testing.assert_allclose(p.pose_xytheta, c["new_pose"], atol=1e-8)
            if c is not None and c["kind"] == "shifted":
                d = np.hypot(*(np.array(c["new_pose"][:2]) - c["old_pose"][:2]))
                assert cfg.rearrange.shift_min_m - 1e-9 <= d <= cfg.rearrange.shift_max_m + 1e-9
            if c is not None and c["kind"] == "moved":
                assert c["new_pose"] != c["old_pose"]
        # no two pieces share a cell; no piece within 0.6 m of the route
        count = sum(_piece_cells(new, p).astype(int) for p in new.pieces)
        assert count.max() == 1
        grid = rasterize(new)
        occ = grid.occupied_cells_world()
        static = rasterize(World(new.bounds_xy, new.interior, new.static_polys, [])).occupied
        furn = grid.occupied & ~static
        iy, ix = np.nonzero(furn)
        furn_xy = grid.cell_to_world(np.stack([ix, iy], axis=1))
        assert len(occ) and route_distance(furn_xy, route).min() > 0.6 - 0.05
        assert world.pieces is not new.pieces
        world, next_id = new, next_id2
    assert {"moved", "shifted", "added"} <= kinds


def test_pieces_put_back_where_they_stood_before(tmp_path):
    # return_prob: a piece goes back to one of its poses in earlier layouts (chairs back at
    # their desks); the scenario keeps those poses per piece and flags the change "returned"
    rng = np.random.default_rng(5)
    cfg = SimConfig.for_preset("hall").rearrange.model_copy(
        update={"move_prob": 0.0, "shift_prob": 0.0, "remove_prob": 0.0, "return_prob": 1.0,
                "add_count": 0})
    world, route = make_world("hall", rng)
    moved = world.copy()
    earlier = {}
    for p in moved.pieces:  # every piece stood 2 m to the side (in free space or not)
        earlier[p.id] = [p.pose_xytheta.copy()]
        p.pose_xytheta = p.pose_xytheta + np.array([0.0, 0.0, 0.3])
    new, changes, _ = rearrange(moved, route, cfg, rng, 1000, earlier={
        pid: [q + np.array([2.0, 0.0, 0.0]), q] for pid, (q,) in earlier.items()})
    assert changes and all(c["kind"] == "moved" and c["returned"] for c in changes)
    for c in changes:
        assert any(np.allclose(c["new_pose"], q + d, atol=1e-8) for q in earlier[c["id"]]
                   for d in (np.zeros(3), np.array([2.0, 0.0, 0.0])))
    # without earlier poses, nothing to go back to: the layout stays
    new, changes, _ = rearrange(moved, route, cfg, rng, 1000)
    assert changes == []
    # a scenario with returns: its changes say which moves went back to an earlier pose
    sim = short_cfg("hall", 5.0)
    sim.rearrange.return_prob = 0.5
    scen = simulate_scenario(tmp_path, runs=4, seed=3, config=sim)
    doc = json.loads(scen.scenario_json.read_text())
    seen = {p["id"]: [p["pose"]] for p in doc["map_objects"]}
    back = 0
    for run in doc["runs"]:
        for c in run["changes"]:
            if c.get("returned"):
                back += 1
                assert any(np.allclose(c["new_pose"], q, atol=1e-6) for q in seen[c["id"]])
        for p in run["objects"]:
            seen.setdefault(p["id"], []).append(p["pose"])
    assert back > 0


def test_people_never_inside_furniture_or_walls():
    rng = np.random.default_rng(6)
    cfg = short_cfg("hall", 40.0)
    cfg.people.count_per_run = 5
    world, route = make_world("hall", rng)
    run = simulate_run_detailed(world, route, cfg, rng)
    assert len(run.people) == 5
    grid = rasterize(world, 0.02)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = LEG_RADIUS_M * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    dt = 1.0 / cfg.robot.scan_rate_hz
    for j, p in enumerate(run.people):
        assert cfg.people.min_speed_mps <= p.speed_mps <= cfg.people.max_speed_mps
        for i in range(0, len(run.scans), 3):
            legs = run.people_legs[j, i]
            pts = (legs[:, None, :2] + rim[None]).reshape(-1, 2)
            assert np.all(grid.value_at(pts) == FREE)
            for piece in world.pieces:
                poly = piece.polygon_world()
                if poly is not None:
                    assert not points_in_polygon(pts, poly).any()
        # steps are the person's speed (or a stop when giving way to the robot)
        step = np.hypot(*np.diff(run.people_xy[j], axis=0).T) / dt
        assert step.max() <= p.speed_mps + 1e-6
        assert np.median(step) == pytest.approx(p.speed_mps, rel=0.02)


def test_people_and_robot_give_way():
    """People do not walk into the robot and the robot stops for people: nobody's legs come
    within the robot's ~0.25 m radius, over several crowded runs."""
    stops = 0
    for seed in (7, 8):
        rng = np.random.default_rng(seed)
        cfg = short_cfg("hall", 60.0)
        cfg.people.count_per_run = 6
        world, route = make_world("hall", rng)
        run = simulate_run_detailed(world, route, cfg, rng)
        robot = np.array([s.gt_pose_xytheta[:2] for s in run.scans])
        legs = run.people_legs[..., :2]  # (P, N, 2, 2)
        d_legs = np.hypot(*(legs - robot[None, :, None]).transpose(3, 0, 1, 2))
        assert d_legs.min() - LEG_RADIUS_M > 0.2
        stops += int((np.hypot(*np.diff(robot, axis=0).T) < 1e-12).sum())
    assert stops > 10  # the robot did wait for people


# ---------------------------------------------------------------------- files
def test_scenario_json_round_trip_and_layout_chain(tmp_path):
    res = simulate_scenario(tmp_path, runs=3, seed=2, config=short_cfg())
    doc = load_scenario(tmp_path)
    assert doc == json.loads(res.scenario_json.read_text())
    assert doc["preset"] == "hall" and doc["seed"] == 2 and doc["map_layout"] == "L0"
    assert SimConfig.model_validate(doc["config"]).robot.duration_s == 12.0
    layout = {o["id"]: o for o in doc["map_objects"]}
    for run in doc["runs"]:
        # L_K = L_{K-1} with this run's changes applied
        for c in run["changes"]:
            if c["kind"] == "removed":
                assert layout.pop(c["id"])["pose"] == pytest.approx(c["old_pose"])
            elif c["kind"] == "added":
                assert c["id"] not in layout
                layout[c["id"]] = {"id": c["id"], "label": c["label"], "pose": c["new_pose"]}
            else:
                assert layout[c["id"]]["pose"] == pytest.approx(c["old_pose"])
                layout[c["id"]]["pose"] = c["new_pose"]
        objs = {o["id"]: o for o in run["objects"]}
        assert set(objs) == set(layout)
        for i, o in objs.items():
            assert o["pose"] == pytest.approx(layout[i]["pose"], abs=1e-8)
            assert o["label"] == layout[i]["label"]
        stamps, poses = read_tum(tmp_path / run["ground_truth"])
        np.testing.assert_allclose(poses[0], run["initial_pose"], atol=1e-8)
        for person in run["people"]:
            assert len(person["xy"]) == len(person["stamps_s"]) == len(stamps)
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "other"}')
    with pytest.raises(FormatError):
        load_scenario(bad)


def test_written_files_read_back(tmp_path):
    cfg = short_cfg()
    res = simulate_scenario(tmp_path, runs=1, seed=2, config=cfg)
    rng_world, _ = np.random.SeedSequence(2).spawn(2)
    world, _ = make_world("hall", np.random.default_rng(rng_world))
    assert load_map(res.map_yaml) == rasterize(world, cfg.resolution_m)  # map = layout L0
    scans = list(CarmenLog(res.logs[0]))
    stamps, poses = read_tum(res.gt[0])
    assert len(scans) == len(stamps) == res.summary()["scans_per_run"][0]
    gt = np.array([s.gt_pose_xytheta for s in scans])
    np.testing.assert_allclose(gt, poses, atol=1e-6)
    np.testing.assert_allclose([s.stamp_s for s in scans], stamps, atol=1e-6)
    od = np.array([s.odom_pose_xytheta for s in scans])
    np.testing.assert_allclose(od[0], 0.0, atol=1e-9)
    assert np.hypot(*(od[-1, :2] - gt[-1, :2])) > 1.0  # odom frame != map frame
    assert scans[0].num_beams == 181 and scans[0].range_max_m == 4.0


def test_bag_written_when_asked(tmp_path):
    pytest.importorskip("rosbags")
    from gatmo.datasets.rosbag import RosBag

    cfg = short_cfg(duration_s=3.0)
    res = simulate_scenario(tmp_path, runs=1, seed=1, bag=True, config=cfg)
    scans = list(RosBag(tmp_path / "run_1_bag"))
    assert len(scans) == 30 and res.bags


def test_config_checks():
    with pytest.raises(ConfigError):
        SimConfig.for_preset("garage")
    with pytest.raises(ValueError):
        SimConfig.model_validate({"rearrange": {"move_prob": 0.7, "shift_prob": 0.5}})
    with pytest.raises(ValueError):
        SimConfig.model_validate({"people": {"min_speed_mps": 2.0, "max_speed_mps": 1.0}})
    assert SimConfig.for_preset("office").laser.max_range_m == 10.0
    assert SimConfig.for_preset("hall").laser.max_range_m == 4.0


def test_simulate_run_in_memory():
    rng = np.random.default_rng(0)
    world, route = make_world("office", rng)
    scans = simulate_run(world, route, short_cfg("office", 2.0), rng)
    assert len(scans) == 20 and all(s.gt_pose_xytheta is not None for s in scans)
    assert np.allclose(np.diff([s.stamp_s for s in scans]), 0.1)


def test_odometry_of_a_robot_standing_still_does_not_spin():
    # heading pi: atan2(0, 0) - pi used to wrap to a 2 pi turn that the rotation scale bias
    # turned into a spurious spin (0.06 rad per scan)
    from gatmo.datasets.sim.config import OdomConfig
    from gatmo.datasets.sim.robot import sample_odometry

    true = np.tile([16.5, 7.0, np.pi], (50, 1))
    od = sample_odometry(true, OdomConfig(), np.random.default_rng(0), scale_bias=(1.02, 1.03))
    assert np.max(np.abs(np.angle(np.exp(1j * od[:, 2])))) < 1e-9
    assert np.max(np.abs(od[:, :2])) < 1e-9
