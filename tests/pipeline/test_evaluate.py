"""Scoring GATMO's object map against a scenario's truth (gatmo.pipeline.evaluate)."""

import numpy as np

from gatmo.objects.objectmap import MapObject
from gatmo.pipeline.evaluate import expected_pose, observed, placement_error, twin_of
from tests.helpers import make_scan, room_grid


def _box_object(pose, label="box"):
    xs = np.arange(-0.225, 0.226, 0.05)
    gx, gy = np.meshgrid(xs, xs)
    shape = np.stack([gx.ravel(), gy.ravel()], 1)
    return MapObject(1, label, "M", np.array(pose, float), shape, shape,
                     base_pose_xytheta=np.array([2.0, 1.0, 0.0]))


def _piece(pid, pose, label="box"):
    return {"id": pid, "label": label, "pose": list(pose),
            "shape": {"kind": "box", "dims_m": [0.5, 0.5]}}


def test_expected_pose_follows_the_piece_and_placement_error_is_zero_there():
    o = _box_object([5.0, 3.0, 0.3])
    layout0 = [_piece(7, [2.0, 1.0, 0.0])]
    layout = [_piece(7, [5.0, 3.0, 0.3])]
    exp = expected_pose(o, 7, layout0, layout)
    np.testing.assert_allclose(exp, [5.0, 3.0, 0.3], atol=1e-9)
    md, cd = placement_error(o, exp)
    assert md < 1e-9 and cd < 1e-9
    md, cd = placement_error(o, exp + np.array([0.3, 0.0, 0.0]))
    assert cd > 0.29


def test_twin_of_names_the_identical_piece_the_object_now_sits_on():
    layout0 = [_piece(7, [2.0, 1.0, 0.0]), _piece(8, [6.0, 1.0, 0.0]),
               _piece(9, [9.0, 1.0, 0.0], label="footstool")]
    layout = [_piece(7, [2.0, 4.0, 0.0]), _piece(8, [5.0, 3.0, 0.0]),
              _piece(9, [9.0, 4.0, 0.0], label="footstool")]
    assert twin_of(_box_object([5.0, 3.0, 0.0]), 7, layout0, layout) == 8
    assert twin_of(_box_object([2.0, 4.0, 0.0]), 7, layout0, layout) is None  # its own place
    assert twin_of(_box_object([9.0, 4.0, 0.0]), 7, layout0, layout) is None  # other label
    assert twin_of(_box_object([7.0, 7.0, 0.0]), 7, layout0, layout) is None  # nowhere


def test_piece_outcome_names_what_became_of_a_moved_piece():
    from gatmo.pipeline.evaluate import piece_outcome

    layout0 = [_piece(7, [2.0, 1.0, 0.0]), _piece(8, [6.0, 1.0, 0.0])]
    layout = [_piece(7, [2.0, 4.0, 0.0]), _piece(8, [5.0, 3.0, 0.0])]
    reloc = [{"kind": "relocated", "object_id": 1}]
    absent = [{"kind": "absent", "object_id": 1}]
    assert piece_outcome(_box_object([2.0, 4.0, 0.0]), 7, layout0, layout, reloc) == "found"
    assert piece_outcome(_box_object([5.0, 3.0, 0.0]), 7, layout0, layout, reloc) == "twin"
    assert piece_outcome(_box_object([8.0, 8.0, 0.0]), 7, layout0, layout, reloc) == "wrong"
    gone = _box_object([2.0, 1.0, 0.0])
    gone.status = "A"
    assert piece_outcome(gone, 7, layout0, layout, absent) == "absent"
    assert piece_outcome(_box_object([2.0, 1.0, 0.0]), 7, layout0, layout, []) == "missed"


def test_score_run_tells_twin_swaps_from_false_relocations():
    from gatmo.objects.objectmap import ObjectMap
    from gatmo.pipeline.evaluate import score_run

    o = _box_object([2.0, 4.0, 0.0])
    om = ObjectMap([o], 0.05)
    layout0 = [_piece(7, [2.0, 1.0, 0.0]), _piece(8, [6.0, 1.0, 0.0])]
    layout = [_piece(7, [2.0, 4.0, 0.0]), _piece(8, [5.0, 3.0, 0.0])]
    scen = {"map_objects": layout0,
            "runs": [{"objects": layout, "changes": [{"id": 7, "kind": "moved"},
                                                     {"id": 8, "kind": "moved"}]}]}

    def reloc(x, y):
        return {"kind": "relocated", "object_id": 1, "pose_new": [x, y, 0.0]}

    events = [reloc(2.0, 4.0), reloc(5.0, 3.0), reloc(5.0, 3.0), reloc(8.0, 8.0)]
    r = score_run(om, {1: 7}, scen, 1, events)
    assert (r["false_relocations"], r["twin_relocations"]) == (1, 2)
    assert r["found"] == 1  # it ends the run at its own piece's true pose


def test_score_run_tells_a_false_relocation_that_carries_an_earlier_error():
    """Run 2: the box (piece 7) moved from (2, 4) to (3, 5); its object was put on the
    footstool (piece 9) in an earlier run. Moving the object along with the footstool to
    (9, 6) is another false relocation, carried; moving it onto the footstool from its own
    piece's place, in this layout or the run before's, is a new one."""
    from gatmo.objects.objectmap import ObjectMap
    from gatmo.pipeline.evaluate import score_run

    o = _box_object([9.0, 6.0, 0.0])
    om = ObjectMap([o], 0.05)
    layout0 = [_piece(7, [2.0, 1.0, 0.0]), _piece(9, [9.0, 1.0, 0.0], label="footstool")]
    layout1 = [_piece(7, [2.0, 4.0, 0.0]), _piece(9, [9.0, 4.0, 0.0], label="footstool")]
    layout2 = [_piece(7, [3.0, 5.0, 0.0]), _piece(9, [9.0, 6.0, 0.0], label="footstool")]
    scen = {"map_objects": layout0,
            "runs": [{"objects": layout1, "changes": []},
                     {"objects": layout2, "changes": [{"id": 7, "kind": "moved"},
                                                      {"id": 9, "kind": "moved"}]}]}

    def reloc(old_xy, new_xy):
        return {"kind": "relocated", "object_id": 1, "pose_old": [*old_xy, 0.0],
                "pose_new": [*new_xy, 0.0]}

    carried = score_run(om, {1: 7}, scen, 2, [reloc((9.0, 4.0), (9.0, 6.0))])
    assert (carried["false_relocations"], carried["false_relocations_carried"]) == (1, 1)
    for old_xy in ((3.0, 5.0), (2.0, 4.0)):
        fresh = score_run(om, {1: 7}, scen, 2, [reloc(old_xy, (9.0, 6.0))])
        assert (fresh["false_relocations"], fresh["false_relocations_carried"]) == (1, 0)


def test_score_run_tells_a_twin_swap_that_carries_an_earlier_one():
    """Run 2: box 7's object stood on its twin, box 8, after run 1 (a swap made then). Box 8
    moved from (9, 4) to (9, 6): moving the object along with it is a twin swap carried on;
    moving it onto box 8 from box 7's own place, in this layout or the run before's, or from
    a place no box stood, is a new swap or a carried error as the false relocations count."""
    from gatmo.objects.objectmap import ObjectMap
    from gatmo.pipeline.evaluate import score_run

    o = _box_object([9.0, 6.0, 0.0])
    om = ObjectMap([o], 0.05)
    layout0 = [_piece(7, [2.0, 1.0, 0.0]), _piece(8, [9.0, 1.0, 0.0])]
    layout1 = [_piece(7, [2.0, 4.0, 0.0]), _piece(8, [9.0, 4.0, 0.0])]
    layout2 = [_piece(7, [3.0, 5.0, 0.0]), _piece(8, [9.0, 6.0, 0.0])]
    scen = {"map_objects": layout0,
            "runs": [{"objects": layout1, "changes": []},
                     {"objects": layout2, "changes": [{"id": 7, "kind": "moved"},
                                                      {"id": 8, "kind": "moved"}]}]}

    def twin_counts(old_xy):
        ev = {"kind": "relocated", "object_id": 1, "pose_old": [*old_xy, 0.0],
              "pose_new": [9.0, 6.0, 0.0]}
        r = score_run(om, {1: 7}, scen, 2, [ev])
        assert r["false_relocations"] == 0
        return r["twin_relocations"], r["twin_relocations_carried"]

    assert twin_counts((9.0, 4.0)) == (1, 1)  # on the twin before: the old swap, carried
    assert twin_counts((6.0, 8.0)) == (1, 1)  # on no box before: an earlier error
    for own_xy in ((3.0, 5.0), (2.0, 4.0)):
        assert twin_counts(own_xy) == (1, 0)  # from its own piece: a new swap


def test_observed_tells_whether_the_old_place_was_seen_through_and_the_new_one_seen():
    # the box stood at (3, 4) and now stands at (5.5, 4); the robot at (1, 4) looks along +x
    old, new = _piece(1, (3.0, 4.0, 0.0)), _piece(1, (5.5, 4.0, 0.0))
    world = room_grid(10.0, 8.0, boxes=[(5.25, 3.75, 5.75, 4.25)])
    scans = [make_scan(world, (1.0, 4.0, 0.0), n_beams=361, max_range_m=8.0)
             for _ in range(5)]
    assert observed(scans, old, new) == "both"
    assert observed(scans[:4], old, new) == "none"  # 5 scans needed
    # facing away: its old place behind the laser, the new one not in view
    away = [make_scan(world, (1.0, 4.0, np.pi), n_beams=361, max_range_m=8.0)
            for _ in range(5)]
    assert observed(away, old, new) == "none"
    # with a 4 m laser the new place (4.25 m off) is out of reach: only the old one is seen
    short = [make_scan(world, (1.0, 4.0, 0.0), n_beams=361, max_range_m=4.0)
             for _ in range(5)]
    assert observed(short, old, new) == "old"
    assert observed(scans, old, None) == "old"  # removed


def test_map_census_counts_duplicates_stale_objects_and_unmapped_pieces():
    from gatmo.objects.objectmap import ObjectMap
    from gatmo.pipeline.evaluate import map_census, objects_on_pieces

    def obj(oid, pose, base):
        o = _box_object(pose)
        o.id, o.base_pose_xytheta = oid, np.array(base, float)
        return o

    layout = [_piece(7, [2.0, 4.0, 0.0]), _piece(8, [5.0, 3.0, 0.0]), _piece(9, [8.0, 1.0, 0.0])]
    om = ObjectMap([obj(1, [2.0, 4.0, 0.0], [2.0, 1.0, 0.0]),  # its piece 7, moved there
                    obj(2, [2.02, 4.0, 0.0], [0.0, 0.0, 0.0]),  # added again on piece 7
                    obj(3, [5.0, 3.0, 0.0], [6.0, 1.0, 0.0]),  # on piece 8
                    obj(4, [6.0, 1.0, 0.0], [6.0, 1.0, 0.0]),  # tied, left where 8 stood
                    obj(5, [3.0, 6.0, 0.0], [3.0, 6.0, 0.0]),  # untied, never moved
                    # untied, "restored" 3 cm by a match: still where the map has it
                    obj(10, [8.03, 6.0, 0.0], [8.0, 6.0, 0.0]),
                    obj(11, [5.0, 6.3, 0.0], [5.0, 6.0, 0.0])],  # untied, shifted 0.3 m
                   0.05)
    om.objects[3].status = "U"
    gone = obj(6, [8.0, 1.0, 0.0], [8.0, 1.0, 0.0])
    gone.status = "A"  # absent: not in the map, piece 9 is unmapped
    om.objects.append(gone)
    scen = {"runs": [{"objects": layout}]}
    c = map_census(om, {1: 7, 3: 8, 4: 8, 6: 9}, scen, 1)
    assert c == {"on_piece": 2, "duplicate": 1, "stale": 2, "fixed": 2, "pieces": 3,
                 "pieces_unmapped": 1, "stale_ids": [4, 11]}
    on, off = objects_on_pieces(om, scen, 1)
    assert on == {7: [1, 2], 8: [3]}
    assert [o.id for o in off] == [4, 5, 10, 11]


def test_unmapped_seen_counts_the_unmapped_pieces_the_run_saw():
    """Two boxes stand, neither in the object map; the robot at (1, 4) looking along +x sees
    the one in front of it and not the one behind it. A piece with an object on it is not
    unmapped, seen or not."""
    from gatmo.objects.objectmap import ObjectMap
    from gatmo.pipeline.evaluate import scans_seeing, unmapped_seen

    ahead, behind = _piece(1, (3.0, 4.0, 0.0)), _piece(2, (0.4, 1.0, 0.0))
    world = room_grid(10.0, 8.0, boxes=[(2.75, 3.75, 3.25, 4.25), (0.15, 0.75, 0.65, 1.25)])
    scans = [make_scan(world, (1.0, 4.0, 0.0), n_beams=361, max_range_m=8.0)
             for _ in range(5)]
    assert scans_seeing(scans, ahead).all() and not scans_seeing(scans, behind).any()
    scen = {"runs": [{"objects": [ahead, behind]}]}
    assert unmapped_seen(ObjectMap([], 0.05), scen, 1, scans) == 1
    assert unmapped_seen(ObjectMap([], 0.05), scen, 1, scans[:4]) == 0  # 5 scans needed
    mapped = ObjectMap([_box_object([3.0, 4.0, 0.0])], 0.05)  # the box ahead is mapped
    assert unmapped_seen(mapped, scen, 1, scans) == 0


def test_seen_through_counts_points_a_true_beam_passed():
    """Points between the laser and a wall are seen through, points behind the wall or
    beyond the range limit are not; a scan counts when it saw through 30 % of them."""
    from gatmo.pipeline.evaluate import seen_through
    from tests.helpers import make_scan, room_grid

    world = room_grid(10, 6, 0.05)
    scan = make_scan(world, (2.0, 3.0, 0.0), n_beams=361, max_range_m=9.0)
    pts = np.array([[4.0, 3.0], [6.0, 3.5], [9.95, 3.0], [11.0, 3.0], [8.0, 2.0]])
    union, n = seen_through(pts, [scan], max_range_m=5.0)
    assert union.tolist() == [True, True, False, False, False]  # in, behind the wall; 6 m off
    assert n == 1
    union, n = seen_through(pts, [scan], max_range_m=9.0)
    assert union.tolist() == [True, True, False, False, True]


def test_object_state_tells_where_an_object_stands_against_its_piece():
    from gatmo.pipeline.evaluate import object_state

    layout0 = [_piece(7, [2.0, 1.0, 0.0]), _piece(8, [6.0, 1.0, 0.0])]
    layout = [_piece(7, [2.0, 4.0, 0.0]), _piece(8, [5.0, 3.0, 0.0])]
    assert object_state(_box_object([2.0, 4.05, 0.0]), 7, layout0, layout) == "right"
    assert object_state(_box_object([5.0, 3.0, 0.0]), 7, layout0, layout) == "twin"
    assert object_state(_box_object([2.0, 4.3, 0.0]), 7, layout0, layout) == "elsewhere"
    gone = _box_object([2.0, 4.0, 0.0])
    gone.status = "A"
    assert object_state(gone, 7, layout0, layout) == "absent"
    assert object_state(_box_object([2.0, 4.0, 0.0]), 9, layout0, layout) == "unknown"


def _piece_views_every_ray(scans, piece_old, piece_new, res=0.05):
    """piece_views as first written: every ray of every scan sampled (the reference the
    bounding-circle cull must agree with)."""
    from scipy.spatial import cKDTree

    from gatmo.geometry import compose, transform_points
    from gatmo.pipeline.evaluate import _piece_points, _rays_crossing

    told = cKDTree(transform_points(np.array(piece_old["pose"]), _piece_points(piece_old, res)))
    tnew = cKDTree(transform_points(np.array(piece_new["pose"]), _piece_points(piece_new, res)))
    old, new = np.zeros(len(scans), bool), np.zeros(len(scans), bool)
    for i, s in enumerate(scans):
        lp = compose(s.gt_pose_xytheta, s.laser_pose_xytheta)
        a = lp[2] + s.angles_rad
        u = np.stack([np.cos(a), np.sin(a)], 1)
        valid = s.ranges_m < s.range_max_m
        d, _ = tnew.query(lp[:2] + s.ranges_m[valid, None] * u[valid], distance_upper_bound=0.06)
        new[i] = np.isfinite(d).sum() >= 8
        rr = np.where(valid, s.ranges_m, s.range_max_m) - 0.1
        old[i] = _rays_crossing(told, lp[:2], u, rr, s.range_max_m) >= 5
    return old, new


def test_piece_views_agrees_with_sampling_every_ray():
    from gatmo.pipeline.evaluate import piece_views

    rng = np.random.default_rng(7)
    world = room_grid(10.0, 8.0, boxes=[(6.0, 2.0, 6.6, 2.5)])
    new_piece = {"id": 1, "label": "desk", "pose": [6.3, 2.25, 0.0],
                 "shape": {"kind": "box", "dims_m": [0.6, 0.5]}}
    scans = []
    for _ in range(60):
        pose = (rng.uniform(0.5, 9.5), rng.uniform(0.5, 7.5), rng.uniform(-np.pi, np.pi))
        scans.append(make_scan(world, pose, n_beams=181, max_range_m=4.0))
    for pose in ([3.0, 4.0, 0.3], [5.0, 2.0, 1.2], [8.0, 6.0, -0.7]):
        old_piece = {"id": 1, "label": "desk", "pose": pose,
                     "shape": {"kind": "box", "dims_m": [0.6, 0.5]}}
        got = piece_views(scans, old_piece, new_piece)
        want = _piece_views_every_ray(scans, old_piece, new_piece)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        assert 0 < want[0].sum() < len(scans)  # the case tells something
