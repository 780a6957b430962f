"""Furniture moved in a recorded map (gatmo.pipeline.map_moves): the edit, its truth, and GATMO
finding the piece where the log shows it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from gatmo.maps.grid import FREE, OCCUPIED
from gatmo.objects import GatmoConfig, GatmoMapper, ObjectMap
from gatmo.pipeline.evaluate import placement_error
from gatmo.pipeline.map_moves import (
    MapMove,
    apply_moves,
    moved_cells,
    pick_moves,
    score_moves,
    standing_views,
    tie_moves,
)
from tests.helpers import make_scan, room_grid

CFG = GatmoConfig()


@settings(max_examples=50, deadline=None)
@given(st.floats(-np.pi, np.pi), st.floats(-3, 3), st.floats(-3, 3),
       st.floats(-np.pi, np.pi), st.floats(0, 5), st.floats(0, 5))
def test_the_true_pose_carries_the_moved_cells_back_onto_the_recorded_ones(turn, dx, dy, yaw,
                                                                            px, py):
    cells = np.array([[1.0, 1.0], [1.5, 1.0], [1.5, 1.2], [1.0, 1.3]]) + [px, py]
    m = MapMove(1, cells, turn, np.array([dx, dy]))
    np.testing.assert_allclose(m.undone(m.moved(cells)), cells, atol=1e-9)
    # an object frame on the moved cells, anywhere, with any heading
    frame = np.array([px + dx + 0.3, py + dy - 0.2, yaw])
    local = (m.moved(cells) - frame[:2]) @ np.array([[np.cos(yaw), -np.sin(yaw)],
                                                     [np.sin(yaw), np.cos(yaw)]])
    t = m.true_pose(frame)
    back = local @ np.array([[np.cos(t[2]), np.sin(t[2])],
                             [-np.sin(t[2]), np.cos(t[2])]]) + t[:2]
    np.testing.assert_allclose(back, cells, atol=1e-9)


def _recorded_room():
    """(map, scans): a room with a 0.7 x 0.5 m box standing free at (3.85, 4.25) and one
    0.1 m from the bottom wall, and a robot's pass along it (the log: true poses, 6 m laser)."""
    g = room_grid(10, 6, 0.05, boxes=[(3.5, 4.0, 4.2, 4.5), (7.0, 0.2, 7.6, 0.6)])
    path = [(x, 2.9, 0.0) for x in np.linspace(2.0, 5.0, 40)]
    path += [(5.0, 2.9, th) for th in np.linspace(0, 2.6, 20)]
    path += [(5.0 - 0.02 * k, 2.9 + 0.01 * k, 2.6) for k in range(40)]
    scans = [make_scan(g, p, n_beams=361, max_range_m=6.0, stamp_s=0.1 * i)
             for i, p in enumerate(path)]
    return g, scans


def test_a_free_standing_piece_in_view_is_moved_to_free_space_the_log_saw_through():
    g, scans = _recorded_room()
    om = ObjectMap.from_grid(g, CFG)
    box = min(om.objects, key=lambda o: np.hypot(*(o.pose_xytheta[:2] - [3.85, 4.25])))
    views = standing_views(g, om, scans)
    assert views[box.id] >= 50
    moves = pick_moves(g, om, scans, np.random.default_rng(1), 3, shift_range_m=(0.8, 2.0),
                       min_views=10)
    # the piece 0.1 m from the wall is not free standing, the walls are structure: one move
    assert [m.object_id for m in moves] == [box.id]
    m = moves[0]
    assert 0.8 <= np.hypot(*m.shift_xy_m) <= 2.0
    new = moved_cells(g, m)
    assert (g.cells[new[:, 1], new[:, 0]] == FREE).all()
    occ = g.cell_to_world(np.stack(np.nonzero(g.occupied)[::-1], axis=1))
    assert cKDTree(occ).query(g.cell_to_world(new))[0].min() >= 0.2
    poses = np.array([s.gt_pose_xytheta for s in scans])
    assert cKDTree(poses[:, :2]).query(g.cell_to_world(new))[0].min() >= 0.5
    edited = apply_moves(g, moves)
    old = g.world_to_cell(box.cells_world())
    assert (edited.cells[old[:, 1], old[:, 0]] == FREE).all()
    assert (edited.cells[new[:, 1], new[:, 0]] == OCCUPIED).all()
    # the edited map's object on the new place, and where its frame must go
    eom = ObjectMap.from_grid(edited, CFG)
    ties = tie_moves(eom, g, moves)
    assert len(ties) == 1
    (oid, t), = ties.items()
    mean_d, centre_d = placement_error(eom.by_id[oid], t["true_pose"])
    ref = cKDTree(box.cells_world())
    d, _ = ref.query(eom.by_id[oid].cells_world(t["true_pose"]))
    assert d.mean() < 0.04 and mean_d > 0.5 and centre_d > 0.5  # it stands elsewhere now


def test_no_piece_qualifies_when_the_log_never_saw_it():
    g, scans = _recorded_room()
    om = ObjectMap.from_grid(g, CFG)
    assert pick_moves(g, om, scans[:3], np.random.default_rng(1), 2, min_views=10) == []


def test_gatmo_finds_a_piece_moved_in_the_map_where_the_log_shows_it():
    # the map handed to GATMO has the box elsewhere; the log's scans show it where it stood
    g, scans = _recorded_room()
    om = ObjectMap.from_grid(g, CFG)
    moves = pick_moves(g, om, scans, np.random.default_rng(1), 1, shift_range_m=(0.8, 2.0),
                       min_views=10)
    edited = apply_moves(g, moves)
    mapper = GatmoMapper.from_config(CFG, edited)
    ties = tie_moves(mapper.object_map, g, moves)
    before = score_moves(mapper.object_map, ties, len(moves))
    assert before["unchanged"] == 1 and before["found"] == 0
    mapper.begin_run(1)
    events = []
    for s in scans:
        events += mapper.update(s.gt_pose_xytheta, s, pose_confident=True, stamp_s=s.stamp_s)
    events += mapper.end_run()
    (oid,) = ties
    assert [e.kind for e in events if e.object_id == oid][:2] == ["absent", "relocated"]
    res = score_moves(mapper.object_map, ties, len(moves))
    assert res["found"] == 1, res
    assert res["false_absent"] == res["false_relocated"] == res["added"] == 0
    assert res["per_move"][0]["centre_m"] < 0.1


def test_score_moves_tells_a_piece_left_absent_and_one_put_elsewhere():
    g, scans = _recorded_room()
    om = ObjectMap.from_grid(g, CFG)
    moves = pick_moves(g, om, scans, np.random.default_rng(1), 1, shift_range_m=(0.8, 2.0),
                       min_views=10)
    eom = ObjectMap.from_grid(apply_moves(g, moves), CFG)
    ties = tie_moves(eom, g, moves)
    (oid,) = ties
    o = eom.by_id[oid]
    o.status = "A"
    assert score_moves(eom, ties, 1)["absent"] == 1
    o.status, o.pose_xytheta = "M", o.pose_xytheta + [0.5, 0.0, 0.0]
    assert score_moves(eom, ties, 1)["elsewhere"] == 1
    o.pose_xytheta = ties[oid]["true_pose"] + [0.05, 0.0, 0.0]
    assert score_moves(eom, ties, 1)["found"] == 1
    # another object marked absent, or moved, is a false event
    other = next(x for x in eom.objects if not x.structure and x.id != oid)
    other.status = "A"
    assert score_moves(eom, ties, 1)["false_absent"] == 1


DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


@pytest.mark.skipif(not (DATA / "slam-benchmark" / "intel.sort.bag").exists()
                    or not (DATA / "radish-corrected").exists(),
                    reason="../shared/data (the Intel log and its corrected poses) not found")
def test_real_intel_a_piece_moved_in_the_map_is_found_where_the_log_shows_it(tmp_path):
    # the Intel lab's map (rendered from the corrected log) with a 0.6 m piece moved 2.46 m
    # and turned 10.6 deg, as trial 0 of `bench_real_moves --logs intel` drew
    # it; the bag's first 700 scans pass both places
    from gatmo.maps.io import load_map
    from gatmo.pipeline.config import real_stack_config
    from gatmo.pipeline.mapping import render_reference_map
    from gatmo.pipeline.runs import _make_mapper, load_scans, run_full

    render_reference_map(DATA / "radish-corrected" / "intel-corrected.log.gz",
                         tmp_path / "map.yaml")
    grid = load_map(tmp_path / "map.yaml")
    cfg = real_stack_config()
    om = ObjectMap.from_grid(grid, cfg.gatmo)
    piece = min((o for o in om.objects if not o.structure),
                key=lambda o: np.hypot(*(o.cells_world().mean(axis=0) - [10.930, -0.999])))
    assert len(piece.shape_xy) == 71
    move = MapMove(piece.id, piece.cells_world(), np.radians(10.552),
                   np.array([2.1186, -1.2591]))
    edited = apply_moves(grid, [move])
    mapper = _make_mapper(cfg, edited, None)
    ties = tie_moves(mapper.object_map, grid, [move])
    assert len(ties) == 1
    scans = load_scans(DATA / "slam-benchmark" / "intel.sort.bag", None, 700)
    trace = run_full(cfg, mapper, scans, cfg.seed, np.array([0.6, -0.03, -0.35]),
                     log="intel", run_id=1)
    (oid,) = ties
    kinds = [e["kind"] for e in trace.events if e["object_id"] == oid]
    assert kinds[:2] == ["absent", "relocated"], kinds
    res = score_moves(mapper.object_map, ties, 1)
    assert res["found"] == 1, res["per_move"]
    assert res["per_move"][0]["centre_m"] < 0.1
    assert res["false_absent"] == res["false_relocated"] == 0
