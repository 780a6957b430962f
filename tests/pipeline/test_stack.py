"""The fusion of localizer and scan matcher (offset reset on a confident covariance), with
stand-ins whose answers are known exactly."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from gatmo.geometry import compose, relative, transform_points
from gatmo.maps.grid import OCCUPIED, OccupancyGrid
from gatmo.pipeline.stack import FusionConfig, LocalizationStack, is_confident
from tests.helpers import make_scan, room_grid


@dataclass
class Est:
    pose_xytheta: np.ndarray
    cov: np.ndarray
    updated: bool = True


class ScriptedLocalizer:
    """Returns the true pose plus a fixed bias, confident only on scripted scans."""

    def __init__(self, truth, confident_at, bias=(0.0, 0.0, 0.0)):
        self.truth, self.confident_at, self.bias = truth, set(confident_at), np.array(bias)
        self.i = 0
        self.regions = []

    def update(self, odom, scan, withheld=None):
        i = self.i
        self.i += 1
        std = 0.05 if i in self.confident_at else 0.6
        return Est(self.truth[i] + self.bias, np.diag([std**2, std**2, 0.01**2]))

    def update_map_region(self, cells, ix0, iy0):
        self.regions.append((cells.shape, ix0, iy0))


class DriftingMatcher:
    """Registers each scan exactly in its own frame: T_match_base = T_match_map * truth."""

    def __init__(self, truth, T_match_map):
        self.truth, self.T = truth, np.asarray(T_match_map, dtype=float)
        self.i = 0

    def register(self, scan):
        p = compose(self.T, self.truth[self.i])
        self.i += 1

        @dataclass
        class M:
            pose_xytheta: np.ndarray

        return M(p)


def _truth(n=30):
    t = np.linspace(0, 1, n)
    return np.stack([1 + 3 * t, 2 + np.sin(3 * t), 0.5 * t], axis=1)


def _scans(n):
    grid = room_grid()
    return [make_scan(grid, (2.0, 2.0, 0.0), n_beams=5, stamp_s=float(i)) for i in range(n)]


def test_offset_reset_makes_matcher_pose_land_on_map_frame():
    truth = _truth()
    n = len(truth)
    loc = ScriptedLocalizer(truth, confident_at=[5], bias=(0.3, 0.0, 0.0))
    matcher = DriftingMatcher(truth, T_match_map=(10.0, -4.0, 1.0))
    fusion = FusionConfig(max_travel_without_reset_m=100, publish_pose="fused")
    stack = LocalizationStack(loc, matcher, None, fusion)
    stack.begin_run(1)
    out = [stack.step(s) for s in _scans(n)]
    # before the first confident update the stack publishes the (biased) localizer; from scan
    # 5 on the offset equals the localizer's confident estimate, so every later pose is
    # truth + the bias seen at the reset, carried exactly by the matcher.
    for i in range(5, n):
        expected = compose(compose(truth[5] + [0.3, 0, 0], relative(truth[5], truth[5])),
                           relative(truth[5], truth[i]))
        np.testing.assert_allclose(out[i].pose_xytheta, expected, atol=1e-9)
    resets = [i for i, o in enumerate(out) if o.reset]
    assert resets == [0, 1, 2, 3, 4, 5]  # before any confident update: the localizer's pose
    assert [r[1] for r in stack.resets] == ["start", "confident"]


def test_unaligned_stack_publishes_the_localizer_pose_and_gives_gatmo_the_fused_one():
    # the localizer is biased (0.3 m, 0.05 rad) and confident once; the matcher is exact in
    # its own frame; without the scan-to-map alignment no pose is confirmed, so the default
    # publish_pose (aligned) publishes the localizer's
    truth = _truth()
    n = len(truth)
    b = np.array([0.3, 0.0, 0.05])
    loc = ScriptedLocalizer(truth, confident_at=[5], bias=b)

    class Recorder:
        def __init__(self):
            self.poses = []

        def begin_run(self, run_id):
            pass

        def update(self, pose, scan, *, pose_confident, stamp_s, pose_verified=True, track=True):
            self.poses.append(np.asarray(pose, dtype=float))
            return []

        def pop_map_changes(self):
            return []

    rec = Recorder()
    fusion = FusionConfig(max_travel_without_reset_m=100, absence_max_std_xy_m=1.0,
                          absence_max_std_theta_deg=90.0, align_to_map=False)
    stack = LocalizationStack(loc, DriftingMatcher(truth, (10.0, -4.0, 1.0)), rec, fusion)
    stack.begin_run(1)
    out = [stack.step(s) for s in _scans(n)]
    published = np.array([o.pose_xytheta for o in out])
    np.testing.assert_allclose(published, truth + b, atol=1e-9)
    # GATMO got the matcher's pose anchored at the reset (scan 5), which differs from it
    fused = np.array(rec.poses)
    for i in range(5, n):
        np.testing.assert_allclose(fused[i], compose(truth[5] + b, relative(truth[5], truth[i])),
                                   atol=1e-9)
    assert np.abs(fused[-1, :2] - published[-1, :2]).max() > 0.01


def test_unconfident_localizer_never_moves_the_offset():
    truth = _truth()
    loc = ScriptedLocalizer(truth, confident_at=[0])
    matcher = DriftingMatcher(truth, T_match_map=(0.0, 0.0, 0.0))
    fusion = FusionConfig(max_travel_without_reset_m=100, publish_pose="fused")
    stack = LocalizationStack(loc, matcher, None, fusion)
    stack.begin_run(1)
    out = [stack.step(s) for s in _scans(len(truth))]
    err = np.hypot(*(np.array([o.pose_xytheta for o in out])[:, :2] - truth[:, :2]).T)
    assert err.max() < 1e-9  # exact matcher + confident start -> exact everywhere


def test_diverged_matcher_falls_back_to_localizer():
    truth = _truth()
    loc = ScriptedLocalizer(truth, confident_at=[0])

    class Jumpy(DriftingMatcher):
        def register(self, scan):
            m = super().register(scan)
            if self.i > 11:  # from scan index 11 on
                m.pose_xytheta = m.pose_xytheta + np.array([5.0, 0.0, 0.0])
            return m

    stack = LocalizationStack(loc, Jumpy(truth, (0, 0, 0)), None,
                              FusionConfig(max_travel_without_reset_m=100, publish_pose="fused"))
    stack.begin_run(1)
    out = [stack.step(s) for s in _scans(len(truth))]
    assert np.hypot(*(out[11].pose_xytheta[:2] - truth[11][:2])) < 1e-9
    assert out[11].reset


def test_is_confident_thresholds():
    f = FusionConfig(reset_max_std_xy_m=0.1, reset_max_std_theta_deg=2.0)
    assert is_confident(Est(np.zeros(3), np.diag([0.09**2, 0.05**2, np.radians(1.9) ** 2])), f)
    assert not is_confident(Est(np.zeros(3), np.diag([0.11**2, 0.05**2, 0.0])), f)
    assert not is_confident(Est(np.zeros(3), np.diag([0.0, 0.0, np.radians(2.1) ** 2])), f)
    assert not is_confident(Est(np.zeros(3), np.eye(3) * 1e-6, updated=False), f)
    assert not is_confident(Est(np.zeros(3), np.full((3, 3), np.nan)), f)


def test_offset_not_confirmed_for_a_while_falls_back_to_the_localizer():
    truth = _truth()
    loc = ScriptedLocalizer(truth, confident_at=[0], bias=(0.2, 0.0, 0.0))
    matcher = DriftingMatcher(truth, T_match_map=(0.0, 0.0, 0.0))
    fusion = FusionConfig(max_travel_without_reset_m=1.0, publish_pose="fused")
    stack = LocalizationStack(loc, matcher, None, fusion)
    stack.begin_run(1)
    out = [stack.step(s) for s in _scans(len(truth))]
    travel = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(truth[:, :2], axis=0).T))])
    late = np.nonzero(travel > 1.2)[0]
    for i in late:  # beyond 1 m without a confident update: the localizer's own pose
        np.testing.assert_allclose(out[i].pose_xytheta, truth[i] + [0.2, 0, 0], atol=1e-9)


class RecordingMapper:
    """Records whether the stack trusted each pose enough for GATMO."""

    def __init__(self, grid=None):
        self.trusted = []
        self.verified = []
        self._grid = grid if grid is not None else room_grid(12, 6, 0.05)

    def begin_run(self, run_id):
        pass

    def update(self, pose, scan, *, pose_confident, stamp_s, pose_verified=True, track=True):
        self.trusted.append(pose_confident)
        self.verified.append(pose_verified)
        return []

    def pop_map_changes(self):
        return []

    def grid(self):
        return self._grid


_STRAIGHT = np.array([[1.0 + 0.1 * i, 3.0, 0.0] for i in range(80)])  # 8 m, odometry exact


def _trusted_along_straight(estimates_xytheta, fusion) -> np.ndarray:
    """(80,) bool: which scans of the drive along ``_STRAIGHT`` the stack trusted enough for
    GATMO, the filter confident at every scan but reporting ``estimates_xytheta`` (80, 3)."""
    grid = room_grid(12, 6, 0.05)
    scans = [make_scan(grid, p, odom_pose_xytheta=p, stamp_s=0.1 * i)
             for i, p in enumerate(_STRAIGHT)]
    mapper = RecordingMapper()
    stack = LocalizationStack(ScriptedLocalizer(estimates_xytheta, confident_at=range(80)),
                              None, mapper, fusion)
    stack.begin_run(1)
    for s in scans:
        stack.step(s)
    return np.array(mapper.trusted)


def test_gatmo_waits_after_the_localizer_jumps():
    """A confident filter that has just jumped (recovery, kidnapping) may sit on a look-alike
    place: GATMO gets no trusted pose for settle_after_jump_m of travel."""
    jumped = _STRAIGHT.copy()
    jumped[20:, 1] += 2.0  # the estimate jumps 2 m sideways at scan 20, odometry does not
    t = _trusted_along_straight(jumped, FusionConfig(align_to_map=False,
                                                     settle_after_jump_m=3.0))
    assert t[:20].all()
    assert not t[20:50].any()  # 3 m at 0.1 m per scan
    assert t[52:].all()


def test_gatmo_trusts_poses_from_a_runs_start():
    """A confident filter from the run's first scan: GATMO gets trusted poses from there on
    (the paper), counted from each run's start (``begin_run``)."""
    t = _trusted_along_straight(_STRAIGHT, FusionConfig(align_to_map=False))
    assert t[1:].all()


def test_gatmo_trusts_a_confident_filter_sliding_away_from_odometry():
    """A confident filter sliding onto a look-alike place 3 cm per scan (no single jump):
    every pose is trusted."""
    slid = _STRAIGHT.copy()
    slid[30:, 1] += 0.03 * np.arange(1, 51)  # 3 cm sideways per scan from scan 30 on
    t = _trusted_along_straight(slid, FusionConfig(align_to_map=False))
    assert t[:30].all()  # odometry-consistent, and legitimate jitter below 0.4 m
    assert t.all()


def _aligner(grid, **kw):
    from gatmo.pipeline.stack import MapAligner

    a = MapAligner(FusionConfig(**kw))
    a.set_grid(grid)
    return a


def test_inconclusive_alignment_hands_gatmo_the_filter_pose_or_skips():
    """Most returns on furniture the map does not have (a rearranged room): the alignment
    matches too few points to say anything; by default GATMO gets the filter's pose, with
    ``align_inconclusive: skip`` the scan is skipped."""
    boxes = [(2.6, y, 2.9, y + 0.3) for y in np.arange(0.4, 5.5, 0.45)]
    boxes += [(x, 4.6, x + 0.3, 4.9) for x in np.arange(0.4, 2.4, 0.45)]
    world = room_grid(10, 6, 0.05, boxes=boxes)
    pose = np.array([1.5, 3.0, 0.0])
    scan = make_scan(world, pose, n_beams=361, fov_rad=2 * np.pi, max_range_m=4.0)
    empty = room_grid(10, 6, 0.05)
    got, trusted = _aligner(empty).refine(pose, scan)
    assert trusted and np.array_equal(got, pose)
    got, trusted = _aligner(empty, align_inconclusive="skip").refine(pose, scan)
    assert not trusted and np.array_equal(got, pose)


def test_alignment_that_moves_the_pose_far_contradicts_the_filter():
    """The map explains the scan well from 0.3 m away from the filter's pose: the filter is off
    and GATMO skips the scan whatever align_inconclusive says; near the truth it refines."""
    grid = room_grid(6, 4, 0.05, boxes=[(2.0, 1.0, 2.5, 1.5), (4.0, 2.5, 4.3, 3.2)])
    truth = np.array([3.0, 2.0, 0.1])
    scan = make_scan(grid, truth, n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0)
    for mode in ("filter_pose", "skip"):
        a = _aligner(grid, align_inconclusive=mode)
        _, trusted = a.refine(truth + [0.3, 0.0, 0.0], scan)
        assert not trusted
        got, trusted = a.refine(truth + [0.04, -0.03, 0.01], scan)
        assert trusted and np.hypot(*(got[:2] - truth[:2])) < 0.02


class RecordingLocalizer(ScriptedLocalizer):
    def __init__(self, truth):
        super().__init__(truth, confident_at=range(len(truth)))
        self.scans = []
        self.withheld = []

    def update(self, odom, scan, withheld=None):
        self.scans.append(scan)
        self.withheld.append(withheld)
        return super().update(odom, scan)


def _what_the_localizer_got(loc, grid, fusion, truth, scans, mapper=None):
    """Runs the stack (``loc``, no matcher, GATMO on ``grid`` or ``mapper``) over ``scans``
    taken at ``truth``: (the stack, per scan its endpoints (B, 2) placed from the true pose
    and the ranges the localizer was handed (B,))."""
    from gatmo.objects import GatmoConfig, GatmoMapper

    mapper = mapper or GatmoMapper.from_config(GatmoConfig(), grid)
    stack = LocalizationStack(loc, None, mapper, fusion)
    stack.begin_run(1)
    for s in scans:
        stack.step(s)
    return stack, [(p[:2] + orig.ranges_m[:, None] * np.stack(
        [np.cos(orig.angles_rad), np.sin(orig.angles_rad)], axis=1), seen.ranges_m)
        for p, orig, seen in zip(truth, scans, loc.scans, strict=True)]


def test_returns_gatmo_cannot_explain_are_withheld_from_the_localizer():
    """A box the map does not have: once GATMO has seen its returns unexplained, the stack
    hands the localizer scans with those returns masked (NaN); the walls' returns stay."""
    from gatmo.objects import GatmoConfig, GatmoMapper

    grid = room_grid(8, 5, 0.05)
    world = room_grid(8, 5, 0.05, boxes=[(4.0, 2.2, 4.4, 2.6)])
    truth = np.array([[1.5 + 0.02 * i, 2.4, 0.0] for i in range(12)])
    scans = [make_scan(world, p, n_beams=181, max_range_m=6.0, odom_pose_xytheta=p,
                       stamp_s=0.1 * i) for i, p in enumerate(truth)]
    s = scans[-1]
    ends = truth[-1, :2] + s.ranges_m[:, None] * np.stack([np.cos(s.angles_rad),
                                                           np.sin(s.angles_rad)], axis=1)
    on_box = (np.abs(ends[:, 0] - 4.2) < 0.25) & (np.abs(ends[:, 1] - 2.4) < 0.25)
    assert on_box.sum() >= 8
    for mask, expect in ((True, True), (False, False)):
        loc = RecordingLocalizer(truth)
        # without provisional landmarks: with them the box's outline joins the localizer's
        # map once its track is a still chair, and its returns are no longer withheld
        # (tests/objects/test_objects.py, test_a_still_chair_not_in_the_map_holds_...)
        mapper = GatmoMapper.from_config(GatmoConfig(provisional_landmarks=False), grid)
        stack = LocalizationStack(loc, None, mapper,
                                  FusionConfig(align_to_map=False, mask_unexplained=mask))
        stack.begin_run(1)
        for s in scans:
            stack.step(s)
        last = loc.scans[-1].ranges_m
        assert bool(np.isnan(last[on_box]).all()) == expect
        assert not np.isnan(last[~on_box]).any()
        assert (stack.n_masked > 0) == expect
        # the localizer is told which beams were withheld (its unexplained-scan gate counts
        # them as unexplained: amcl.min_explained_beam_fraction)
        if expect:
            assert np.array_equal(loc.withheld[-1], on_box)
        else:
            assert all(w is None for w in loc.withheld)


def test_a_localizer_without_the_withheld_argument_gets_the_masked_scan():
    """A stand-in localizer written before ``update`` took ``withheld`` still works: it is
    handed the masked scan alone."""
    from gatmo.objects import GatmoConfig, GatmoMapper

    grid = room_grid(8, 5, 0.05)
    world = room_grid(8, 5, 0.05, boxes=[(4.0, 2.2, 4.4, 2.6)])
    truth = np.array([[1.5 + 0.02 * i, 2.4, 0.0] for i in range(12)])
    scans = [make_scan(world, p, n_beams=181, max_range_m=6.0, odom_pose_xytheta=p,
                       stamp_s=0.1 * i) for i, p in enumerate(truth)]

    class OldLocalizer(ScriptedLocalizer):
        def __init__(self, truth):
            super().__init__(truth, confident_at=range(len(truth)))
            self.scans = []

        def update(self, odom, scan):  # no withheld
            self.scans.append(scan)
            return super().update(odom, scan)

    loc = OldLocalizer(truth)
    mapper = GatmoMapper.from_config(GatmoConfig(provisional_landmarks=False), grid)
    stack = LocalizationStack(loc, None, mapper, FusionConfig(align_to_map=False))
    stack.begin_run(1)
    for s in scans:
        stack.step(s)
    assert stack.n_masked > 0 and np.isnan(loc.scans[-1].ranges_m).any()


def test_returns_near_a_doubted_object_leave_the_walls_alone():
    """A box shifted 0.3 m: once beams pass through its old place GATMO doubts it; the walls'
    returns are never withheld from the localizer."""

    grid = room_grid(10, 6, 0.05, boxes=[(5, 2.6, 5.15, 2.8)])
    world = room_grid(10, 6, 0.05, boxes=[(5, 2.9, 5.15, 3.1)])
    truth = np.array([[x, 2.75, 0.0] for x in np.linspace(2.0, 3.0, 30)])
    scans = [make_scan(world, p, n_beams=181, max_range_m=8.0, odom_pose_xytheta=p,
                       stamp_s=0.1 * i) for i, p in enumerate(truth)]
    fusion = FusionConfig(align_to_map=False, mask_offset_objects=False)
    _, got = _what_the_localizer_got(RecordingLocalizer(truth), grid, fusion, truth, scans)
    for ends, seen in got:
        near_box = np.hypot(ends[:, 0] - 5.075, ends[:, 1] - 2.85) < 0.45
        assert not np.isnan(seen[~near_box]).any()  # walls: never withheld


@pytest.mark.parametrize("flag, confident", [(False, False), (True, False), (True, True)])
def test_returns_of_a_withheld_piece_still_standing_are_withheld_with_mask_withheld(
        flag, confident):
    """A box left out of the localizer's map (unseen for two runs, ``withhold_unseen_runs``)
    that still stands: with ``mask_withheld`` its returns reach the localizer as NaN (the
    localizer's map has nothing there to explain them) on every scan after the first (the
    stack places a scan from the last pose) while the filter is too broad for GATMO to see
    the box standing; a confident filter's first scan shows GATMO the box standing, it goes
    back into the localizer's map, and nothing is withheld; the walls' returns never."""
    from gatmo.objects import GatmoConfig, GatmoMapper, ObjectMap

    box = (4.0, 2.2, 4.4, 2.6)
    grid = room_grid(8, 5, 0.05, boxes=[box])
    cfg = GatmoConfig(withhold_unseen_runs=2)
    om = ObjectMap.from_grid(grid, cfg)
    for o in om.objects:
        o.unseen_runs = 0 if o.structure else 2
    mapper = GatmoMapper(om, grid, cfg)
    truth = np.array([[1.5 + 0.02 * i, 2.4, 0.0] for i in range(12)])
    scans = [make_scan(grid, p, n_beams=181, max_range_m=6.0, odom_pose_xytheta=p,
                       stamp_s=0.1 * i) for i, p in enumerate(truth)]
    loc = RecordingLocalizer(truth)
    if not confident:
        loc.confident_at = set()
    _, got = _what_the_localizer_got(loc, grid, FusionConfig(align_to_map=False,
                                                             mask_withheld=flag),
                                     truth, scans, mapper=mapper)
    for k, (ends, seen) in enumerate(got):
        on_box = (np.abs(ends[:, 0] - 4.2) < 0.25) & (np.abs(ends[:, 1] - 2.4) < 0.25)
        assert on_box.sum() >= 8
        assert not np.isnan(seen[~on_box]).any()  # walls: never withheld
        expect = flag and not confident and k > 0
        assert np.isnan(seen[on_box]).all() == expect, k
        assert not np.isnan(seen[on_box]).any() or expect, k


def test_gatmo_is_told_which_poses_the_alignment_confirmed():
    """In a room full of furniture the map lacks, the alignment is inconclusive: GATMO gets the
    filter's pose (trusted) but not as verified; in the room as mapped, verified."""
    boxes = [(2.6, y, 2.9, y + 0.3) for y in np.arange(0.4, 5.5, 0.45)]
    boxes += [(x, 4.6, x + 0.3, 4.9) for x in np.arange(0.4, 2.4, 0.45)]
    full = room_grid(10, 6, 0.05, boxes=boxes)
    truth = np.array([[1.5 + 0.01 * i, 3.0, 0.0] for i in range(5)])
    for grid, verified in ((room_grid(10, 6, 0.05), False), (full, True)):
        scans = [make_scan(full, p, n_beams=361, fov_rad=2 * np.pi, max_range_m=4.0,
                           odom_pose_xytheta=p, stamp_s=0.1 * i) for i, p in enumerate(truth)]
        mapper = RecordingMapper(grid)
        stack = LocalizationStack(ScriptedLocalizer(truth, confident_at=range(5)), None,
                                  mapper, FusionConfig(mask_unexplained=False))
        stack.begin_run(1)
        for sc in scans:
            stack.step(sc)
        assert all(mapper.trusted)
        assert mapper.verified == [verified] * 5


class LooselyConfidentLocalizer(ScriptedLocalizer):
    """Position std 0.12 m: confident enough to reset the matcher (0.15 m), not for GATMO's
    strict test (0.1 m)."""

    def update(self, odom, scan, withheld=None):
        i = self.i
        self.i += 1
        return Est(self.truth[i] + self.bias, np.diag([0.12**2, 0.12**2, 0.01**2]))


def test_a_pose_the_filter_is_not_strictly_sure_of_is_not_trusted():
    # the filter alone is not confident enough, though the alignment would confirm the pose
    grid = room_grid(12, 6, 0.05, boxes=[(4.0, 1.0, 4.5, 1.5), (7.0, 4.0, 7.4, 4.6)])
    truth = np.array([[3.0 + 0.1 * i, 3.0, 0.2] for i in range(10)])
    scans = [make_scan(grid, p, n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0,
                       odom_pose_xytheta=p, stamp_s=0.1 * i) for i, p in enumerate(truth)]
    mapper = RecordingMapper(grid)
    stack = LocalizationStack(LooselyConfidentLocalizer(truth, (), bias=(0.0, 0.0, 0.0)), None,
                              mapper, FusionConfig())
    stack.begin_run(1)
    for s in scans:
        stack.step(s)
    # (the first scan, which resets the matcher's offset, counts as confident_for_m)
    assert mapper.trusted[1:] == [False] * (len(scans) - 1)
    assert mapper.verified[1:] == [False] * (len(scans) - 1)


def test_an_alignment_loose_everywhere_is_confirmed():
    """Every box stands 0.12 m east of where the map has it: most points match within the
    0.3 m gate (fitness passes) and the walls pin the pose, though a quarter of the returns
    lie 0.12 m from any map edge: the alignment confirms the pose."""
    boxes = [(x, y, x + 0.4, y + 0.4) for x in (1.0, 2.2, 3.4, 4.6) for y in (0.8, 2.6)]
    grid = room_grid(6, 4, 0.05, boxes=boxes)
    world = room_grid(6, 4, 0.05, boxes=[(a + 0.12, b, c + 0.12, d) for a, b, c, d in boxes])
    truth = np.array([3.0, 1.9, 0.0])
    scan = make_scan(world, truth, n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0)
    a = _aligner(grid)
    got, trusted = a.refine(truth, scan)
    assert trusted and a.last_verified
    assert a.last_outcome == "confirmed"


@pytest.mark.parametrize("offset_xy_m, kw, outcome", [
    ((0.0, 0.0), {}, "confirmed"),
    ((0.08, 0.06), {"align_max_iter": 1}, "not_converged"),
    ((0.08, 0.06), {"align_max_correction_m": 0.05}, "contradicts"),
])
def test_the_alignment_says_why_it_confirmed_a_pose_or_not(offset_xy_m, kw, outcome):
    """``MapAligner.last_outcome``: a scan from the true pose is confirmed there; from 10 cm off
    one Gauss-Newton step does not converge, and a converged correction larger than
    ``align_max_correction_m`` contradicts the pose it started from."""
    from gatmo.pipeline.stack import ALIGN_OUTCOMES, MapAligner

    boxes = [(x, y, x + 0.4, y + 0.4) for x in (1.0, 2.2, 3.4, 4.6) for y in (0.8, 2.6)]
    grid = room_grid(6, 4, 0.05, boxes=boxes)
    truth = np.array([3.0, 1.9, 0.0])
    scan = make_scan(grid, truth, n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0)
    blank = MapAligner(FusionConfig(**kw))
    blank.refine(truth, scan)
    assert blank.last_outcome == "no_map" and not blank.last_verified
    a = _aligner(grid, **kw)
    start = truth + [*offset_xy_m, 0.0]
    got, _ = a.refine(start, scan)
    assert a.last_outcome == outcome and outcome in ALIGN_OUTCOMES
    assert a.last_verified == (outcome == "confirmed")
    if outcome == "confirmed":
        assert np.hypot(*(got[:2] - truth[:2])) < 0.01
    else:  # the pose it was handed comes back
        np.testing.assert_allclose(got, start)


def test_returns_of_a_box_shifted_a_decimetre_are_withheld_with_mask_offset_objects():
    """A box shifted 0.1 m towards the robot: its returns land within delta_W of its old
    place (explained, so ``mask_unexplained`` keeps most of them) but all miss it by the
    shift; with ``mask_offset_objects`` and a filter strictly confident (0.05 m std) the
    localizer gets them all as NaN from the second scan on; with a broad cloud (0.6 m) none,
    and the walls' returns never."""

    grid = room_grid(10, 6, 0.05, boxes=[(5.0, 2.4, 5.6, 3.2)])
    world = room_grid(10, 6, 0.05, boxes=[(4.9, 2.4, 5.5, 3.2)])
    truth = np.array([[x, 2.8, 0.0] for x in np.linspace(2.0, 2.5, 10)])
    scans = [make_scan(world, p, n_beams=181, max_range_m=8.0, odom_pose_xytheta=p,
                       stamp_s=0.1 * i) for i, p in enumerate(truth)]
    for flag, confident in ((False, True), (True, True), (True, False)):
        loc = RecordingLocalizer(truth)
        if not confident:
            loc.confident_at = set()
        _, got = _what_the_localizer_got(
            loc, grid, FusionConfig(align_to_map=False, mask_offset_objects=flag), truth, scans)
        for k, (ends, seen) in enumerate(got):
            on_box = (np.abs(ends[:, 0] - 5.2) < 0.35) & (np.abs(ends[:, 1] - 2.8) < 0.45)
            assert on_box.sum() >= 8
            assert not np.isnan(seen[~on_box]).any()  # walls: never withheld
            withheld = np.isnan(seen[on_box]).mean()
            if flag and confident and k > 0:
                assert withheld == 1.0, k
            else:  # only the few that mask_unexplained withholds (beyond delta_W)
                assert withheld < 0.3, (flag, confident, k, withheld)


class CloudLocalizer(RecordingLocalizer):
    """A recording localizer whose cloud is ``std_m`` wide on every scan."""

    def __init__(self, truth, std_m):
        super().__init__(truth)
        self.std_m = std_m

    def update(self, odom, scan, withheld=None):
        est = super().update(odom, scan)
        return Est(est.pose_xytheta, np.diag([self.std_m**2, self.std_m**2, 0.01**2]))


def test_returns_of_a_piece_turned_within_its_outline_are_mostly_kept():
    """A 1.6 x 0.6 m sofa turned 30 deg about its centre and shifted 0.15 m: a third of its
    returns land inside its old outline, and with a filter that passes the reset test (0.12 m
    std: not the strict one ``mask_offset_objects`` needs) only the few ``mask_unexplained``
    withholds reach the localizer as NaN; the walls' returns never."""
    from tests.helpers import with_rotated_box

    empty = room_grid(8, 6, 0.05)
    grid = with_rotated_box(empty, (4.5, 3.0), 1.6, 0.6, 0.0)
    world = with_rotated_box(empty, (4.5, 3.15), 1.6, 0.6, np.radians(30.0))
    truth = np.array([[x, 3.0, 0.0] for x in np.linspace(2.3, 2.7, 8)])
    scans = [make_scan(world, p, n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0,
                       odom_pose_xytheta=p, stamp_s=0.1 * i) for i, p in enumerate(truth)]
    fusion = FusionConfig(align_to_map=False)
    _, got = _what_the_localizer_got(CloudLocalizer(truth, 0.12), grid, fusion, truth, scans)
    for k, (ends, seen) in enumerate(got):
        on_sofa = np.hypot(ends[:, 0] - 4.5, ends[:, 1] - 3.15) < 1.0
        assert on_sofa.sum() >= 10
        assert not np.isnan(seen[~on_sofa]).any()  # walls: never withheld
        withheld = np.isnan(seen[on_sofa]).mean()
        assert withheld < 0.3, (k, withheld)


class OdomRecordingLocalizer(ScriptedLocalizer):
    """A scripted localizer that keeps the odometry poses it was handed."""

    def __init__(self, truth):
        super().__init__(truth, confident_at=[])
        self.odom = []

    def update(self, odom, scan, withheld=None):
        self.odom.append(np.asarray(odom, dtype=float))
        return super().update(odom, scan)


class SlippingMatcher(DriftingMatcher):
    """Exact in its own frame but for one scan, where it slips by 1 m and comes back."""

    def __init__(self, truth, T_match_map, slip_at):
        super().__init__(truth, T_match_map)
        self.slip_at = slip_at

    def register(self, scan):
        m = super().register(scan)
        if self.i - 1 == self.slip_at:
            m.pose_xytheta = m.pose_xytheta + np.array([1.0, 0.0, 0.0])
        return m


def test_the_localizer_takes_its_motion_from_the_wheels():
    """Wheel odometry 5 % long (a run's scale bias) against a scan matcher exact in its own
    frame, which slips by 1 m on scan 12: the localizer is handed the wheels' odometry as
    is."""
    truth = _truth()
    n = len(truth)
    wheels = [compose(truth[0], relative(truth[0], t) * [1.05, 1.05, 1.0]) for t in truth]
    scans = [make_scan(room_grid(), (2.0, 2.0, 0.0), n_beams=5, stamp_s=float(i),
                       odom_pose_xytheta=wheels[i]) for i in range(n)]
    loc = OdomRecordingLocalizer(truth)
    stack = LocalizationStack(loc, SlippingMatcher(truth, (10.0, -4.0, 1.0), slip_at=12), None,
                              FusionConfig())
    stack.begin_run(1)
    for s in scans:
        stack.step(s)
    for i in range(1, n):
        got = relative(loc.odom[i - 1], loc.odom[i])
        wheel = relative(wheels[i - 1], wheels[i])
        np.testing.assert_allclose(got, wheel, atol=1e-9)


def _coast_world():
    """(map, world, truth): a 20 x 10 m hall whose walls are beyond a 3 m laser's reach from
    the route (y 5, heading east), a partition the map has 1.5 m north of it and a long
    cabinet it does not have straight ahead: most of what the robot sees is furniture the map
    does not explain."""
    partition = (6.0, 6.5, 13.0, 6.6)
    grid = room_grid(20, 10, 0.05, boxes=[partition])
    world = room_grid(20, 10, 0.05, boxes=[partition, (9.6, 2.5, 10.0, 6.3)])
    truth = np.array([[7.0 + 0.04 * i, 5.0, 0.0] for i in range(30)])
    return grid, world, truth


def test_a_scan_gatmo_withholds_mostly_still_reaches_the_localizer():
    """Once GATMO has seen the box's returns unexplained, they are withheld from the
    localizer; the partition's returns always reach it."""
    from gatmo.objects import GatmoConfig, GatmoMapper

    grid, world, truth = _coast_world()
    scans = [make_scan(world, p, n_beams=181, max_range_m=3.0, odom_pose_xytheta=p,
                       stamp_s=0.1 * i) for i, p in enumerate(truth)]
    box_pt = np.array([[9.6, 5.0]])
    loc = RecordingLocalizer(truth)
    mapper = GatmoMapper.from_config(GatmoConfig(provisional_landmarks=False), grid)
    stack = LocalizationStack(loc, None, mapper, FusionConfig(align_to_map=False))
    stack.begin_run(1)
    for s in scans:
        stack.step(s)
    empty = np.array([not np.isfinite(s.ranges_m).any() for s in loc.scans])
    withheld = np.array([0 if w is None else int(w.sum()) for w in loc.withheld])
    kept = np.array([int(s.valid.sum()) for s in loc.scans])
    assert mapper.unexplained_at(box_pt)[0]
    # the column's returns always reach the localizer, the box's are withheld once seen
    # unexplained
    assert not empty.any() and (kept > 0).all()
    assert (withheld[5:] > kept[5:]).all()


class _MapOnly:
    """A GATMO stand-in that only gives the stack its map (for the scan-to-map alignment)."""

    def __init__(self, grid):
        self._grid = grid

    def grid(self):
        return self._grid

    def begin_run(self, run_id):
        pass

    def update(self, pose, scan, *, pose_confident, stamp_s, pose_verified=True, track=True):
        return []

    def pop_map_changes(self):
        return []


class _OffAtLocalizer(ScriptedLocalizer):
    """A :class:`ScriptedLocalizer` off by a further ``off_at[i]`` (3,) on scan i."""

    def __init__(self, truth, confident_at, bias, off_at):
        super().__init__(truth, confident_at, bias)
        self.off_at = off_at

    def update(self, odom, scan, withheld=None):
        i = self.i
        est = super().update(odom, scan, withheld)
        est.pose_xytheta = est.pose_xytheta + np.asarray(self.off_at.get(i, np.zeros(3)))
        return est


def _publishing_run(fusion: FusionConfig, confident: list[int], off_at: dict | None = None,
                    matcher=None, odom_scale: float = 1.0, **stack_kw):
    """(truth (30, 3), the localizer's bias (3,), the steps): a robot driving 9 cm per scan
    through a room of eight boxes, the scripted localizer off by the bias (and by ``off_at[i]``
    more on scan i) and strictly confident on the scans ``confident``, odometry exact (or its
    travel from the start scaled by ``odom_scale``). ``matcher``: called with the truth, it
    gives the scan matcher (else none)."""
    boxes = [(x, y, x + 0.4, y + 0.4) for x in (1.0, 2.2, 3.4, 4.6) for y in (0.8, 2.6)]
    grid = room_grid(6, 4, 0.05, boxes=boxes)
    n = 30
    truth = np.stack([np.linspace(1.6, 4.2, n), np.full(n, 1.9), np.linspace(0.0, 0.3, n)],
                     axis=1)
    bias = np.array([0.05, -0.03, 0.03])
    loc = _OffAtLocalizer(truth, confident, bias, off_at or {})
    if stack_kw.get("initial_pose_xytheta") == "truth":
        stack_kw["initial_pose_xytheta"] = truth[0]
    observe = stack_kw.pop("observe", None)
    stack = LocalizationStack(loc, None if matcher is None else matcher(truth), _MapOnly(grid),
                              fusion, **stack_kw)
    if observe is not None:
        observe["stack"] = stack
    stack.begin_run(1)
    odom = truth.copy()
    odom[:, :2] = truth[0, :2] + odom_scale * (truth[:, :2] - truth[0, :2])
    scans = [make_scan(grid, truth[i], n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0,
                       odom_pose_xytheta=odom[i], stamp_s=float(i)) for i in range(n)]
    return truth, bias, [stack.step(s) for s in scans]


class _IcpMatcher(DriftingMatcher):
    """:class:`DriftingMatcher` with a result as the ICP matcher's: a covariance (``std_m``
    in translation, a tenth of it in rad) and whether ICP fitted (``used_icp``)."""

    def __init__(self, truth, std_m: float, used_icp: bool = True):
        super().__init__(truth, (0.3, -0.2, 0.4))
        self.cov = np.diag([std_m**2, std_m**2, (0.1 * std_m) ** 2])
        self.used_icp = used_icp

    def register(self, scan):
        return _IcpResult(super().register(scan).pose_xytheta, self.cov, self.used_icp)


@dataclass
class _IcpResult:
    pose_xytheta: np.ndarray
    cov: np.ndarray
    used_icp: bool


@pytest.mark.parametrize("inflation", [None, 10.0])
@pytest.mark.parametrize("std_m,used_icp", [(0.002, True), (0.002, False), (1.0, True)])
def test_the_confirmed_pose_is_carried_by_the_wheels_and_the_matchers_steps(inflation, std_m,
                                                                           used_icp):
    """``carry_matcher_inflation``: the wheels report 10 % too much travel and the scan matcher
    exact steps. Confirmed at scan 0 only, the pose published on the next scans is carried by
    each step's information-weighted average of the wheels' and the matcher's: with a sure ICP
    fit (2 mm, inflated 10x) the wheels' share of each 9 cm step is sm^2 / (sm^2 + sw^2), sw
    the wheels' deviation for their step (7 cm per m, a fifth of 5 cm per rad turned, 2 mm),
    so the error grows by that share of a tenth of the travel; where ICP did not fit, or its
    covariance (1 m) says nothing, and without the option, the wheels carry it: off by a tenth
    of the travel."""
    fusion = FusionConfig(publish_pose="aligned", publish_carry_m=0.5, confident_for_m=0.0,
                          carry_matcher_inflation=inflation, absence_max_std_xy_m=0.1,
                          absence_max_std_theta_deg=3.0)
    truth, _, out = _publishing_run(fusion, [0], matcher=lambda t: _IcpMatcher(t, std_m,
                                                                              used_icp),
                                    odom_scale=1.1)
    assert out[0].gatmo_pose_verified and not any(o.gatmo_pose_verified for o in out[1:])
    published = np.array([o.pose_xytheta for o in out])
    err = np.hypot(*(published[:, :2] - truth[:, :2]).T)
    travel = np.hypot(*(truth[:, :2] - truth[0, :2]).T)
    if inflation is not None and used_icp and std_m < 0.01:
        step = relative(truth[0], truth[1])  # the wheels' step is 1.1x its translation
        sw = 0.07 * 1.1 * np.hypot(step[0], step[1]) + 0.2 * 0.05 * abs(step[2]) + 2e-3
        share = inflation * std_m**2 / (inflation * std_m**2 + sw**2)
        # along the travel (x), from scan 0's confirmation (itself a millimetre or two off)
        ahead = published[:, 0] - truth[:, 0]
        np.testing.assert_allclose(ahead[1:6] - ahead[0], share * 0.1 * travel[1:6], atol=5e-4)
        assert np.all(err[1:6] < 0.5 * 0.1 * travel[1:6])  # half the wheels' error at most
    else:
        np.testing.assert_allclose(err[1:6], 0.1 * travel[1:6], atol=0.004)


class _NoisyIcpMatcher(_IcpMatcher):
    """:class:`_IcpMatcher` whose steps each err by a draw of 1.5 cm along and across (seeded)
    while its covariance still claims ``std_m``."""

    def __init__(self, truth, std_m: float):
        super().__init__(truth, std_m)
        self.walk = np.zeros(3)
        self.rng = np.random.default_rng(4)

    def register(self, scan):
        res = super().register(scan)
        self.walk = compose(self.walk, np.r_[self.rng.normal(0.0, 0.015, 2), 0.0])
        return _IcpResult(compose(res.pose_xytheta, self.walk), res.cov, res.used_icp)


@pytest.mark.parametrize("case", ["long_wheels", "noisy_matcher"])
def test_the_carry_learns_which_of_wheels_and_matcher_to_trust(case):
    """``carry_adapt_inflations``: confirmed every 4 scans (36 cm), each carry's pose carried
    from one confirmation is scored at the next. Wheels 10 % long beside an exact matcher that
    claims 5 mm: the least inflation (the matcher trusted most) wins. Exact wheels beside a
    matcher whose steps err by 1.5 cm while it claims 5 mm: the largest (the wheels). Either
    way the poses published between the later confirmations are nearer the truth than with the
    fixed inflation of 3."""
    confident = list(range(0, 30, 4))
    if case == "long_wheels":
        def matcher(t):
            return _IcpMatcher(t, 0.005)
        odom_scale, want = 1.1, 1.0
    else:
        def matcher(t):
            return _NoisyIcpMatcher(t, 0.005)
        odom_scale, want = 1.0, 100.0
    errs, seen = {}, {}
    for adapt in (None, [1.0, 10.0, 100.0]):
        fusion = FusionConfig(publish_pose="aligned", publish_carry_m=0.5,
                              confident_for_m=0.0, carry_matcher_inflation=3.0,
                              carry_adapt_inflations=adapt, carry_adapt_min_pairs=2,
                              absence_max_std_xy_m=0.1, absence_max_std_theta_deg=3.0)
        truth, _, out = _publishing_run(fusion, confident, matcher=matcher,
                                        odom_scale=odom_scale, observe=seen)
        assert [i for i, o in enumerate(out) if o.gatmo_pose_verified] == confident
        published = np.array([o.pose_xytheta for o in out])
        err = np.hypot(*(published[:, :2] - truth[:, :2]).T)
        between = [i for i in range(13, 30) if i not in confident]
        errs[adapt is not None] = float(np.sqrt(np.mean(err[between] ** 2)))
    assert seen["stack"].carry_inflation == want
    assert errs[True] < 0.8 * errs[False], errs


@pytest.mark.parametrize("publish", ["localizer", "aligned"])
def test_aligned_publishing_reports_the_confirmed_pose_carried_by_odometry(publish):
    """``publish_pose: aligned``: the localizer is 6 cm / 1.7 deg off and strictly confident
    on every fifth scan; there the scan-to-map alignment confirms the true pose, the next
    scans carry it by odometry (here exact) until ``publish_carry_m``, and beyond that the
    localizer's own pose is published again. The default publishes the localizer's pose."""
    confident = [0, 5, 10]  # none after scan 10
    truth, bias, out = _publishing_run(
        FusionConfig(publish_pose=publish, publish_carry_m=0.3, use_scan_matcher=False,
                     absence_max_std_xy_m=0.1, absence_max_std_theta_deg=3.0), confident)
    published = np.array([o.pose_xytheta for o in out])
    err = np.hypot(*(published[:, :2] - truth[:, :2]).T)
    assert [i for i, o in enumerate(out) if o.gatmo_pose_verified] == confident
    if publish == "localizer":
        np.testing.assert_allclose(published, truth + bias, atol=1e-9)
        return
    assert np.all(err[confident] < 0.01)
    # carried: within 0.3 m of travel (3 scans of 9 cm) after each confirmed scan
    for c in confident:
        assert np.all(err[c + 1:c + 4] < 0.01)
        np.testing.assert_allclose(published[c + 4], truth[c + 4] + bias, atol=1e-9)
    np.testing.assert_allclose(published[14:], truth[14:] + bias, atol=1e-9)


@pytest.mark.parametrize("min_tight", [0.0, 0.9])
def test_a_loose_alignment_is_not_published(min_tight):
    """Every box stands 0.12 m east of where the map has it: the alignment confirms most
    scans (the walls pin it), but only 64-77 % of the returns lie within 5 cm of a map edge.
    ``publish_min_tight_fraction`` 0.9 publishes the localizer's pose instead; 0 the
    alignment's."""
    boxes = [(x, y, x + 0.4, y + 0.4) for x in (1.0, 2.2, 3.4, 4.6) for y in (0.8, 2.6)]
    grid = room_grid(6, 4, 0.05, boxes=boxes)
    world = room_grid(6, 4, 0.05, boxes=[(a + 0.12, b, c + 0.12, d) for a, b, c, d in boxes])
    n = 6
    truth = np.stack([np.linspace(2.8, 3.3, n), np.full(n, 1.9), np.zeros(n)], axis=1)
    bias = np.array([0.03, -0.02, 0.01])
    loc = ScriptedLocalizer(truth, confident_at=range(n), bias=bias)
    fusion = FusionConfig(publish_min_tight_fraction=min_tight, use_scan_matcher=False)
    stack = LocalizationStack(loc, None, _MapOnly(grid), fusion)
    stack.begin_run(1)
    out = [stack.step(make_scan(world, truth[i], n_beams=361, fov_rad=2 * np.pi,
                                max_range_m=8.0, odom_pose_xytheta=truth[i], stamp_s=float(i)))
           for i in range(n)]
    confirmed = [i for i, o in enumerate(out) if o.align_outcome == "confirmed"]
    assert len(confirmed) >= 3
    published = np.array([o.pose_xytheta for o in out])
    if min_tight > 0:
        np.testing.assert_allclose(published, truth + bias, atol=1e-9)
    else:
        for i in confirmed:
            np.testing.assert_allclose(published[i], out[i].gatmo_pose_xytheta, atol=1e-9)
        assert np.abs(published - (truth + bias)).max() > 0.02


class StuckLocalizer:
    """A filter locked onto a wrong place: its pose follows odometry and never corrects
    itself; from scan ``slip_at`` on it is ``offset`` off (a slide, all at once); confident
    throughout."""

    def __init__(self, truth, offset, slip_at=0, std_m=0.02):
        self.truth, self.offset, self.slip_at = truth, np.asarray(offset, dtype=float), slip_at
        self.std_m = std_m
        self.i = 0
        self.restarted = None  # (scan index, pose)
        self.restarts = 0

    def set_initial_pose(self, pose_xytheta, cov=None):
        self.restarted = (self.i - 1, np.asarray(pose_xytheta, dtype=float).copy())
        self.restarts += 1

    def update(self, odom, scan, withheld=None):
        i = self.i
        self.i += 1
        if self.restarted is not None:  # from there on odometry (here exact) carries it
            k, p = self.restarted
            pose = compose(p, relative(self.truth[k], self.truth[i]))
        else:
            pose = self.truth[i] + (self.offset if i >= self.slip_at else 0.0)
        return Est(pose, np.diag([self.std_m**2, self.std_m**2, 0.01**2]))


def _reloc_world(n=20, step_m=0.042):
    boxes = [(1.0, 1.0, 1.6, 1.3), (3.0, 4.2, 3.4, 5.0), (5.2, 1.5, 6.2, 1.9),
             (6.8, 3.6, 7.1, 4.4), (2.2, 2.6, 2.5, 2.9)]
    grid = room_grid(8, 6, 0.05, boxes=boxes)
    x = 3.0 + step_m * np.arange(n)
    truth = np.stack([x, 3.0 + 0.3 * np.sin(x), np.full(n, 0.2)], axis=1)
    scans = [make_scan(grid, truth[i], n_beams=361, fov_rad=2 * np.pi, max_range_m=6.0,
                       odom_pose_xytheta=truth[i], stamp_s=0.1 * i) for i in range(n)]
    return grid, truth, scans


def _run_on_map(loc, grid, scans, truth, **fusion):
    """The stack (no scan matcher, ``fusion`` settings) over ``scans`` on the fixed map
    ``grid``: (stack, steps, the localizer's position error per scan [m])."""
    stack = LocalizationStack(loc, None, _MapOnly(grid),
                              FusionConfig(use_scan_matcher=False, **fusion))
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    err = np.hypot(*(np.array([o.localizer_pose_xytheta for o in out])[:, :2]
                     - truth[:, :2]).T)
    return stack, out, err


def _run_stuck(offset, slip_at, relocalize, n, step_m=0.042, std_m=0.02, min_expected=0):
    grid, truth, scans = _reloc_world(n, step_m)
    loc = StuckLocalizer(truth, offset, slip_at, std_m)
    stack, out, err = _run_on_map(loc, grid, scans, truth, relocalize=relocalize,
                                  relocalize_min_expected_beams=min_expected)
    return loc, stack, out, err, truth


@pytest.mark.parametrize("offset, fires", [((0.9, -0.6, 0.1), True), ((0.0, 0.0, 0.0), False),
                                           ((2.5, 0.0, 0.0), False)])
@pytest.mark.parametrize("relocalize", [False, True])
@pytest.mark.parametrize("min_expected", [0, 10])
def test_a_filter_that_slid_onto_a_wrong_place_is_started_again_where_the_scan_fits(
        offset, fires, relocalize, min_expected):
    """``relocalize``: at scan 10 the filter slides 1.1 m / 6 deg off and stays confident,
    explaining little of the scan. A correlative search within 1.5 m finds the true pose on
    every update, but a jump of 1.1 m is only made once the robot has travelled 0.8 m since
    the filter last fitted the map (0.3 m + 1.0 x travel): at scan 28 (19 scans of 4.2 cm),
    onto the truth, and GATMO then waits as after any jump. A filter on the right place is
    never searched from; one 2.5 m off is beyond the window and stays where it is. The same
    with ``relocalize_min_expected_beams``: the map expects plenty of beams to end on its
    boxes from the wrong place."""
    loc, stack, out, err, truth = _run_stuck(offset, 10, relocalize, 40,
                                             min_expected=min_expected)
    if relocalize and fires:
        assert loc.restarts == 1 and len(stack.relocalizations) == 1
        stamp, before, after = stack.relocalizations[0]
        k = round(stamp * 10)
        assert k == 28 and [i for i, o in enumerate(out) if o.relocalized] == [k]
        assert np.hypot(*(after[:2] - truth[k, :2])) < 0.03
        assert abs(after[2] - truth[k, 2]) < np.radians(1.0)
        assert np.all(err[k:] < 0.03) and np.all(err[10:k] > 1.0) and np.all(err[:10] < 1e-9)
        # GATMO is handed no pose for settle_after_jump_m (3 m) after it
        assert all(o.gatmo_pose_xytheta is None for o in out[k:])
    else:
        assert loc.restarts == 0 and stack.relocalizations == []
        assert not any(o.relocalized for o in out)
        np.testing.assert_allclose(err[10:], np.hypot(*offset[:2]), atol=1e-9)


@pytest.mark.parametrize("min_expected", [0, 10])
def test_a_pose_the_map_expects_to_see_nothing_from_is_not_searched_around(min_expected):
    """``relocalize_min_expected_beams``: a U-shaped screen stands 0.6-1.3 m ahead of the
    robot, and the map has it 1 m farther, beyond the laser's 1.4 m. The filter is right but
    explains none of the scan; the search finds where the screen's returns fall on the map's
    screen, 1 m ahead. Without the test the filter is started again there (the jump bound
    widened to allow it); with it nothing is searched, as the map expects no beam to end on
    anything from the filter's pose."""
    screen = [(6.15, 4.4, 6.25, 5.6), (5.55, 5.5, 6.25, 5.6), (5.55, 4.4, 6.25, 4.5)]
    world = room_grid(20, 10, 0.05, boxes=screen)
    grid = room_grid(20, 10, 0.05, boxes=[(a + 1.0, b, c + 1.0, d) for a, b, c, d in screen])
    n = 5
    truth = np.stack([np.full(n, 5.0), 4.9 + 0.04 * np.arange(n), np.zeros(n)], axis=1)
    scans = [make_scan(world, truth[i], n_beams=361, fov_rad=np.pi, max_range_m=1.4,
                       odom_pose_xytheta=truth[i], stamp_s=0.1 * i) for i in range(n)]
    loc = StuckLocalizer(truth, (0.0, 0.0, 0.0))
    _, out, err = _run_on_map(loc, grid, scans, truth, relocalize=True,
                              relocalize_max_jump_m=1.5, relocalize_min_points=10,
                              relocalize_min_expected_beams=min_expected)
    if min_expected == 0:
        assert loc.restarts == 1
        k = [i for i, o in enumerate(out) if o.relocalized][0]
        assert np.all(err[:k] < 1e-9) and np.all(err[k:] > 0.9)
    else:
        assert loc.restarts == 0 and np.all(err < 1e-9)


def test_a_run_started_from_a_given_pose_is_not_moved_farther_than_it_travelled():
    """Off by 1.1 m from the run's first scan (the pose given for it, as pieces moved before
    the run can make a scan fit a wrong place near a right start): within 0.65 m of travel the
    search's pose, right here, is farther than 0.3 m + the travel and is not taken; over 1.6 m
    it is."""
    loc, stack, _, err, _ = _run_stuck((0.9, -0.6, 0.1), 0, True, 15)
    assert loc.restarts == 0 and np.all(err > 1.0)
    loc, stack, _, err, _ = _run_stuck((0.9, -0.6, 0.1), 0, True, 20, step_m=0.084)
    assert loc.restarts == 1 and err[-1] < 0.03


def test_relocalizer_fit_and_search_on_known_poses():
    """The fit is the fraction of the scan's points within 0.1 m of a map edge; the search
    finds the true pose from 1 m / 8 deg off; with a window of 0.85 or 0.95 m (the truth 0.8 m
    away in x: on the window's edge) it finds nothing, nor from 1.75 m off."""
    from gatmo.pipeline.stack import Relocalizer

    grid, truth, scans = _reloc_world()
    r = Relocalizer(FusionConfig())
    r.set_grid(grid)
    pts = scans[0].points_base_xy()
    assert r.fit(truth[0], pts) > 0.95
    off = truth[0] + [0.8, 0.6, np.radians(8.0)]
    assert r.fit(off, pts) < 0.3
    got = r.search(off, pts)
    assert got is not None and np.hypot(*(got[:2] - truth[0, :2])) < 0.03
    assert r.search(truth[0] + [0.0, 1.75, 0.0], pts) is None
    for window_m in (0.85, 0.95):
        r = Relocalizer(FusionConfig(relocalize_window_m=window_m))
        r.set_grid(grid)
        assert r.search(off, pts) is None
    # the search's normals and field are built at the first search after a map change, not
    # on the change (the fit on every update needs neither)
    r.set_grid(grid)
    assert r._field is None and r._normals is None and r.fit(truth[0], pts) > 0.95
    assert r._field is None
    r.search(off, pts)
    assert r._field is not None and r._normals is not None


def test_a_filter_that_is_not_confident_is_left_to_find_its_way():
    """The same slide with a broad cloud (0.3 m std, beyond the reset test's 0.15 m): AMCL's
    own resampling can still reach the right place, so the stack does not restart it."""
    loc, stack, _, err, _ = _run_stuck((0.9, -0.6, 0.1), 10, True, 40, std_m=0.3)
    assert loc.restarts == 0 and np.all(err[10:] > 1.0)


def test_gatmo_is_handed_a_confirmed_pose_that_jumps_against_odometry(monkeypatch):
    """The scan-to-map alignment confirms the truth on every scan but scans 8-10, where it
    confirms a pose 0.2 m off: GATMO is handed those three scans too, and the published pose
    follows them."""
    from gatmo.pipeline import stack as stack_mod

    grid = room_grid(12, 6, 0.05)
    truth = _STRAIGHT[:20]
    scans = [make_scan(grid, p, odom_pose_xytheta=p, stamp_s=0.1 * i)
             for i, p in enumerate(truth)]
    wrong = {8, 9, 10}

    def refine(self, pose, scan):
        i = int(round(scan.stamp_s / 0.1))
        self.last_verified, self.last_outcome, self.last_tight_fraction = True, "confirmed", 1.0
        return truth[i] + ([0.2, 0.0, 0.0] if i in wrong else 0.0), True

    monkeypatch.setattr(stack_mod.MapAligner, "refine", refine)
    mapper = RecordingMapper(grid)
    fusion = FusionConfig(use_scan_matcher=False, mask_unexplained=False,
                          mask_offset_objects=False)
    stack = LocalizationStack(ScriptedLocalizer(truth, confident_at=range(20),
                                                bias=(0.03, 0.0, 0.0)),
                              None, mapper, fusion)
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    handed = [i for i, t in enumerate(mapper.trusted) if t]
    err = np.hypot(*(np.array([o.pose_xytheta for o in out])[:, :2] - truth[:, :2]).T)
    assert handed == list(range(20))
    assert np.all(err[8:11] > 0.19)


@pytest.mark.parametrize("fixed", [False, True])
def test_a_stack_on_a_fixed_map_keeps_it_while_gatmo_changes_its_own(fixed):
    # fusion.passes: a later pass localizes on the map the pass before ended with; GATMO's
    # changes in that pass must not reach its localizer, the alignment or the relocalizer
    truth = _truth()
    loc = ScriptedLocalizer(truth, confident_at=range(len(truth)))
    own, other = room_grid(12, 6, 0.05), room_grid(12, 6, 0.05)
    other.cells[40:60, 40:60] = 100  # a box GATMO's map does not have

    class Changing(RecordingMapper):
        def pop_map_changes(self):  # a region every scan, as a relocation would queue
            return [(np.zeros((3, 3), dtype=np.int8), 10, 10)]

    fusion = FusionConfig(align_to_map=False)
    stack = LocalizationStack(loc, None, Changing(own), fusion,
                              loc_grid=other if fixed else None)
    stack.begin_run(1)
    for s in _scans(len(truth)):
        stack.step(s)
    if fixed:
        assert loc.regions == [] and stack.n_map_updates == 0
        assert stack.current_grid(own) is other and stack._map_grid() is other
    else:
        assert len(loc.regions) == len(truth) == stack.n_map_updates
        assert stack.current_grid(other) is own and stack._map_grid() is own


class AnchorStandIn(ScriptedLocalizer):
    """The anchor filter: the true pose plus ``bias`` on the scans in ``off_at`` until it is
    started again (then the true pose); records the map regions it is handed."""

    def __init__(self, truth, off_at=(), bias=(0.0, 0.0, 0.0)):
        super().__init__(truth, confident_at=range(len(truth)))
        self.off_at, self.off_bias = set(off_at), np.asarray(bias, dtype=float)
        self.restarts = []  # scan indices

    def set_initial_pose(self, pose_xytheta, cov=None):
        self.restarts.append(self.i - 1)

    def update(self, odom, scan, withheld=None):
        est = super().update(odom, scan, withheld)
        if self.i - 1 in self.off_at and not self.restarts:
            est.pose_xytheta = est.pose_xytheta + self.off_bias
        return est


class _OneChange(_MapOnly):
    """A map with one region update queued on the first scan."""

    def __init__(self, grid):
        super().__init__(grid)
        self.queued = [(np.zeros((4, 5), dtype=np.int8), 10, 12)]

    def pop_map_changes(self):
        out, self.queued = self.queued, []
        return out


@pytest.mark.parametrize("offset, anchor_off, restart_at, anchor_restart_at", [
    ((0.9, -0.6, 0.1), (), 14, None),  # the filter slid 1.1 m: started again on its 5th update
    ((0.25, 0.0, 0.0), (), None, None),  # 0.25 m apart: within anchor_gap_m
    ((0.0, 0.0, 0.0), range(10, 14), None, None),  # the anchor strays for 4 updates only
    ((0.0, 0.0, 0.0), range(10, 40), None, 14),  # it strays for good: it is started again
    ((0.9, -0.6, 0.1), range(10, 40), 14, None),  # both stray: the one that strayed more
])
def test_a_filter_that_parts_from_the_anchor_filter_is_started_again_at_its_pose(
        offset, anchor_off, restart_at, anchor_restart_at):
    """``anchor_filter``: a second filter on the same map with a flat sensor model. When the
    localizer and it part by more than ``anchor_gap_m`` (0.3 m) on ``anchor_gap_updates`` (5)
    updates in a row, the one that moved against odometry since they last agreed is started
    again at the other's pose: the localizer (it slid 1.1 m; GATMO then waits as after any
    jump) or the anchor (it strayed 0.67 m). When both strayed, the localizer is started again
    if it strayed more by ``anchor_odom_margin_m``. A shorter or smaller parting changes
    nothing. The anchor gets the map's region updates too."""
    grid, truth, scans = _reloc_world(40)
    loc = StuckLocalizer(truth, offset, slip_at=10)
    loc.update_map_region = lambda cells, ix0, iy0: None
    anchor = AnchorStandIn(truth, anchor_off, bias=(0.6, 0.3, 0.0))
    mapper = _OneChange(grid)
    stack = LocalizationStack(loc, None, mapper,
                              FusionConfig(use_scan_matcher=False, anchor_filter=True),
                              anchor=anchor)
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    assert anchor.regions == [((4, 5), 10, 12)]
    assert anchor.restarts == ([] if anchor_restart_at is None else [anchor_restart_at])
    assert stack.anchor_restarts == len(anchor.restarts)
    restarted = [i for i, o in enumerate(out) if o.relocalized]
    if restart_at is None:
        assert restarted == [] and loc.restarts == 0
        return
    assert restarted == [restart_at] and loc.restarts == 1
    expect = truth[restart_at] + (anchor.off_bias if restart_at in anchor.off_at else 0.0)
    np.testing.assert_allclose(out[restart_at].localizer_pose_xytheta, expect, atol=1e-9)
    assert len(stack.relocalizations) == 1
    assert all(o.gatmo_pose_xytheta is None for o in out[restart_at:restart_at + 20])


@pytest.mark.parametrize("until_confirmed, poses, first_handed", [
    (False, 3, None),  # the full 3 m wait: nothing within the 26 scans left
    (True, 3, 16),  # the restart's scan and the next two confirmed: handed from the third on
    (True, 5, 18),
])
def test_gatmo_waits_after_a_restart_until_the_alignment_confirms_the_new_pose(
        until_confirmed, poses, first_handed):
    """``settle_until_confirmed``: the localizer slid 1.1 m and was started again at the
    anchor filter's (true) pose on scan 14; GATMO's wait after that restart ends once the
    scan-to-map alignment has confirmed the new pose on ``settle_confirmed_poses`` scans,
    instead of after ``settle_after_jump_m`` of travel."""
    grid, truth, scans = _reloc_world(40)
    loc = StuckLocalizer(truth, (0.9, -0.6, 0.1), slip_at=10)
    loc.update_map_region = lambda cells, ix0, iy0: None
    stack = LocalizationStack(loc, None, _OneChange(grid),
                              FusionConfig(use_scan_matcher=False, anchor_filter=True,
                                           settle_until_confirmed=until_confirmed,
                                           settle_confirmed_poses=poses),
                              anchor=AnchorStandIn(truth))
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    assert [i for i, o in enumerate(out) if o.relocalized] == [14]
    handed = [i for i, o in enumerate(out) if i >= 14 and o.gatmo_pose_xytheta is not None]
    assert (handed[:1] or [None])[0] == first_handed
    if first_handed is not None:
        assert handed == list(range(first_handed, 40))
        np.testing.assert_allclose(out[first_handed].gatmo_pose_xytheta[:2],
                                   truth[first_handed, :2], atol=0.02)


def test_a_jump_of_the_filter_itself_keeps_the_full_wait_with_settle_until_confirmed():
    """A jump the filter made by itself (``max_offset_jump_m``; no restart by the stack) is
    no tested pose: GATMO waits the full ``settle_after_jump_m`` whatever the alignment says
    (the scan matcher off, odometry exact: the slid filter's pose fits the map nowhere, the
    returned one everywhere)."""
    grid, truth, scans = _reloc_world(40)
    # the filter jumps 0.5 m at scan 10 and back to the truth at scan 12
    loc = ScriptedLocalizer(truth + np.where(((np.arange(40) >= 10) & (np.arange(40) < 12))
                                             [:, None], (0.5, 0.0, 0.0), 0.0),
                            confident_at=range(40))
    loc.update_map_region = lambda cells, ix0, iy0: None
    stack = LocalizationStack(loc, None, _OneChange(grid),
                              FusionConfig(use_scan_matcher=False, relocalize=False,
                                           settle_until_confirmed=True))
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    assert all(o.gatmo_pose_xytheta is None for o in out[10:])
    assert all(o.gatmo_pose_xytheta is not None for o in out[:10])


class _Started:
    """A stand-in's ``estimate()`` before its first update: the pose it was started at
    (``truth[0]``, a 0.1 m cloud), as ``MonteCarloLocalizer`` gives after set_initial_pose."""

    def estimate(self):
        return self.truth[0].copy(), np.diag([0.1**2, 0.1**2, 0.05**2])


class _StartedStuck(_Started, StuckLocalizer):
    pass


class _StartedAnchor(_Started, AnchorStandIn):
    pass


@pytest.mark.parametrize("knows_start", [True, False])
def test_a_filter_that_slides_on_its_first_update_is_started_again_at_the_anchors_pose(
        knows_start):
    """Both filters start at the run's initial pose; the localizer's first update slides it
    1.08 m off while the anchor stays. They last agreed where they were started, so the
    localizer is the one that moved against the wheels: it is started again at the anchor's
    pose on its 5th update apart. (Measured from where the two stood after their first
    update, as before, neither had moved since "they last agreed", and nothing was done.) A
    stand-in without ``estimate()`` keeps that old behaviour."""
    grid, truth, scans = _reloc_world(40)
    loc = (_StartedStuck if knows_start else StuckLocalizer)(truth, (0.9, -0.6, 0.0), slip_at=0)
    loc.update_map_region = lambda cells, ix0, iy0: None
    anchor = (_StartedAnchor if knows_start else AnchorStandIn)(truth)
    stack = LocalizationStack(loc, None, _MapOnly(grid),
                              FusionConfig(use_scan_matcher=False, anchor_filter=True,
                                           relocalize=False),
                              anchor=anchor)
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    restarted = [i for i, o in enumerate(out) if o.relocalized]
    if not knows_start:
        assert restarted == [] and loc.restarts == 0
        return
    assert restarted == [4] and loc.restarts == 1 and anchor.restarts == []
    np.testing.assert_allclose(out[4].localizer_pose_xytheta, truth[4], atol=1e-9)
    err = np.hypot(*(np.array([o.localizer_pose_xytheta for o in out[5:]])[:, :2]
                     - truth[5:, :2]).T)
    assert err.max() < 1e-6


class _EstimatingAnchor(_StartedAnchor):
    """The anchor stand-in with ``estimate()``: where it was started, then its last pose."""

    def update(self, odom, scan, withheld=None):
        self.last = super().update(odom, scan, withheld)
        return self.last

    def estimate(self):
        if not hasattr(self, "last"):
            return super().estimate()
        return self.last.pose_xytheta.copy(), self.last.cov.copy()


def _run_reporting(loc, anchor, grid, scans, on=True):
    """The stack with the anchor filter and ``publish_anchor_when_apart`` ``on`` (no scan
    matcher, no relocalizer, the localizer's own pose reported otherwise) over ``scans``."""
    loc.update_map_region = lambda cells, ix0, iy0: None
    stack = LocalizationStack(loc, None, _MapOnly(grid),
                              FusionConfig(use_scan_matcher=False, anchor_filter=True,
                                           relocalize=False, publish_pose="localizer",
                                           publish_anchor_when_apart=on),
                              anchor=anchor)
    stack.begin_run(1)
    return [stack.step(s) for s in scans]


@pytest.mark.parametrize("offset, anchor_off, on, anchor_from", [
    ((0.25, 0.0, 0.0), (), True, 10),  # the localizer slid 0.25 m: the anchor is reported
    ((0.25, 0.0, 0.0), (), False, None),  # (off: the localizer's pose, as before)
    ((0.15, 0.0, 0.0), (), True, None),  # 0.15 m: within anchor_agree_m
    ((0.0, 0.0, 0.0), range(10, 40), True, None),  # the anchor strayed: the localizer stays
])
def test_the_anchor_is_reported_while_the_localizer_strays_from_it(
        offset, anchor_off, on, anchor_from):
    """``publish_anchor_when_apart``: from scan 10 the localizer is ``offset`` off, within
    ``anchor_gap_m`` (no restart); while the two are more than ``anchor_agree_m`` apart and the
    localizer is the one that moved against the wheels since they last agreed, the stack
    reports the anchor's pose. The localizer is left as it is."""
    grid, truth, scans = _reloc_world(40)
    loc = _StartedStuck(truth, offset, slip_at=10)
    anchor = _EstimatingAnchor(truth, anchor_off, bias=(0.25, 0.1, 0.0))
    out = _run_reporting(loc, anchor, grid, scans, on=on)
    assert loc.restarts == 0 and anchor.restarts == []
    pub = np.array([o.pose_xytheta for o in out])
    locp = np.array([o.localizer_pose_xytheta for o in out])
    np.testing.assert_allclose(locp, truth + np.where(np.arange(40)[:, None] >= 10, offset, 0.0),
                               atol=1e-9)
    if anchor_from is None:
        np.testing.assert_allclose(pub, locp, atol=1e-9)
    else:
        np.testing.assert_allclose(pub[:anchor_from], locp[:anchor_from], atol=1e-9)
        np.testing.assert_allclose(pub[anchor_from:], truth[anchor_from:], atol=1e-9)


def test_the_anchor_is_not_reported_where_its_pose_explains_the_scan_worse():
    """The wheels slip 0.25 m at scan 10 and the anchor follows them; the localizer stays on
    the true pose, so it is the one that moved against the wheels. The anchor's pose explains
    the scan far less (``anchor_fit_margin``): the localizer's pose is reported, as on MIT
    CSAIL, where every such parting was the localizer correcting itself."""
    grid, truth, _ = _reloc_world(40)
    slip = np.array([0.25, 0.0, 0.0])
    odom = truth + np.where(np.arange(40)[:, None] >= 10, slip, 0.0)
    scans = [make_scan(grid, truth[i], n_beams=361, fov_rad=2 * np.pi, max_range_m=6.0,
                       odom_pose_xytheta=odom[i], stamp_s=0.1 * i) for i in range(40)]
    loc = _StartedStuck(truth, (0.0, 0.0, 0.0))
    out = _run_reporting(loc, _EstimatingAnchor(truth, range(10, 40), bias=slip), grid, scans)
    np.testing.assert_allclose([o.pose_xytheta for o in out], truth, atol=1e-9)
    assert loc.restarts == 0


@pytest.mark.parametrize("bias_m, on, gated", [
    (0.4, True, range(10, 14)),  # 0.4 m apart on 4 updates: GATMO gets none of those scans
    (0.4, False, ()),  # (off: every confident scan, as before)
    (0.25, True, ()),  # within anchor_gate_gap_m (0.3 m)
])
def test_gatmo_gets_no_scan_while_the_two_filters_are_far_apart(bias_m, on, gated):
    """``anchor_gates_gatmo``: on the scans where the anchor filter stands more than
    ``anchor_gate_gap_m`` from the localizer, GATMO is handed no pose (it is in doubt); on the
    others, the localizer's. 4 updates apart start neither filter again."""
    grid, truth, scans = _reloc_world(40)
    loc = StuckLocalizer(truth, (0.0, 0.0, 0.0), slip_at=10)
    loc.update_map_region = lambda cells, ix0, iy0: None
    anchor = AnchorStandIn(truth, range(10, 14), bias=(bias_m, 0.0, 0.0))
    mapper = RecordingMapper(grid)
    stack = LocalizationStack(loc, None, mapper,
                              FusionConfig(use_scan_matcher=False, anchor_filter=True,
                                           relocalize=False, align_to_map=False,
                                           anchor_gates_gatmo=on),
                              anchor=anchor)
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    assert loc.restarts == 0 and anchor.restarts == []
    handed = [o.gatmo_pose_xytheta is not None for o in out]
    assert [i for i, h in enumerate(handed) if not h] == list(gated)
    assert stack.anchor_gated == len(gated)
    np.testing.assert_allclose([o.gatmo_pose_xytheta for o in out if o.gatmo_pose_xytheta
                                is not None], truth[[i for i, h in enumerate(handed) if h]],
                               atol=1e-9)


def test_no_filter_is_started_again_in_a_wall():
    """A filter is not started again at a pose its map has occupied (``set_initial_pose``
    refuses one, and a lost filter's pose can be in a wall): the anchor that strayed for good
    (the case above where it is started again) stays where it is, and the run goes on."""
    grid, truth, scans = _reloc_world(40)
    walled = OccupancyGrid(grid.cells.copy(), grid.resolution_m, grid.origin_xytheta)
    c = walled.world_to_cell(truth[:, :2])
    walled.cells[c[:, 1], c[:, 0]] = OCCUPIED  # the localizer's poses: all in a wall
    loc = StuckLocalizer(truth, (0.0, 0.0, 0.0), slip_at=10)
    loc.update_map_region = lambda cells, ix0, iy0: None
    anchor = AnchorStandIn(truth, range(10, 40), bias=(0.6, 0.3, 0.0))
    # its map has them occupied, as MonteCarloLocalizer.start_refusal would say
    anchor.start_refusal = lambda pose: (
        "in an occupied cell" if walled.value_at(np.asarray(pose)[None, :2])[0] == OCCUPIED
        else None)
    stack = LocalizationStack(loc, None, _OneChange(grid),
                              FusionConfig(use_scan_matcher=False, anchor_filter=True),
                              anchor=anchor)
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    assert len(out) == 40 and anchor.restarts == [] and stack.anchor_restarts == 0


def test_the_anchor_filter_runs_the_localizers_parameters_with_a_flat_sensor_model():
    """``make_full_stack`` builds the anchor from the stack's ``amcl`` section with
    ``anchor_laser_model`` and ``anchor_sigma_hit_m``, and its own random draw."""
    from gatmo.pipeline.config import sim_stack_config
    from gatmo.pipeline.runs import _make_mapper, make_full_stack

    cfg = sim_stack_config()
    assert cfg.fusion.anchor_filter  # on in the simulated halls' configuration
    assert cfg.fusion.publish_anchor_when_apart  # and the anchor reported while they part
    grid, truth, _ = _reloc_world(5)
    cfg.fusion.anchor_filter = False
    assert make_full_stack(cfg, _make_mapper(cfg, grid, None), 3, truth[0]).anchor is None
    cfg.fusion.anchor_filter = True
    stack = make_full_stack(cfg, _make_mapper(cfg, grid, None), 3, truth[0])
    a, loc = stack.anchor.cfg, stack.localizer.cfg
    assert (a.laser_model, a.sigma_hit_m) == ("likelihood_field", 0.2)
    assert (loc.laser_model, loc.sigma_hit_m) == ("likelihood_field_prob", 0.1)
    assert (a.alpha1, a.alpha2, a.max_particles) == (loc.alpha1, loc.alpha2, loc.max_particles)
    assert not np.array_equal(stack.anchor.particles, stack.localizer.particles)
    np.testing.assert_allclose(stack.anchor.particles.mean(axis=0)[:2], truth[0, :2], atol=0.02)


class CorrectingLocalizer(StuckLocalizer):
    """``offset`` off until scan ``slip_at``, then on the true pose: a filter that corrects
    itself, against odometry."""

    def update(self, odom, scan, withheld=None):
        i = self.i
        self.i += 1
        pose = self.truth[i] + (self.offset if i < self.slip_at else 0.0)
        return Est(pose, np.diag([self.std_m**2, self.std_m**2, 0.01**2]))


@pytest.mark.parametrize("fit_margin, restart_at", [(0.1, None), (1.0, 14)])
def test_a_filter_that_corrects_itself_is_not_sent_back_to_a_worse_anchor(fit_margin,
                                                                         restart_at):
    """Both filters start 0.5 m off, on either side of the truth; at scan 10 the localizer
    corrects itself, moving against odometry. It strayed, but the anchor's pose explains the
    scan worse than its own by more than ``anchor_fit_margin``: no restart (with the margin
    at 1, the test off, it is sent to the anchor's wrong pose)."""
    grid, truth, scans = _reloc_world(40)
    loc = CorrectingLocalizer(truth, (0.4, 0.3, 0.0), slip_at=10)
    loc.update_map_region = lambda cells, ix0, iy0: None
    anchor = AnchorStandIn(truth, range(40), bias=(-0.5, 0.0, 0.0))
    stack = LocalizationStack(loc, None, _MapOnly(grid),
                              FusionConfig(use_scan_matcher=False, anchor_filter=True,
                                           anchor_fit_margin=fit_margin), anchor=anchor)
    stack.begin_run(1)
    out = [stack.step(s) for s in scans]
    restarted = [i for i, o in enumerate(out) if o.relocalized]
    assert restarted == ([] if restart_at is None else [restart_at])
    assert anchor.restarts == [] and stack.anchor_restarts == 0
    if restart_at is None:
        err = np.hypot(*(np.array([o.localizer_pose_xytheta for o in out])[10:, :2]
                         - truth[10:, :2]).T)
        assert err.max() < 1e-9


def test_the_alignment_and_the_relocalizer_share_one_edge_extraction_per_map(monkeypatch):
    """The map's edge points are worked out once per version of the map for both the
    scan-to-map alignment and the relocalizer (each eroded the whole map on every change),
    and again after the map may have changed (a new run)."""
    from gatmo.pipeline import stack as stack_mod

    calls = []
    real = stack_mod._edge_points
    monkeypatch.setattr(stack_mod, "_edge_points", lambda g: calls.append(1) or real(g))
    grid = room_grid(12, 6, 0.05)
    st = LocalizationStack(None, fusion=FusionConfig(), loc_grid=grid)
    reloc = st._relocalizer()
    aligner = stack_mod.MapAligner(st.fusion)
    aligner.set_grid(*st._map_edges())
    assert len(calls) == 1 and aligner._pts is reloc._pts
    np.testing.assert_array_equal(reloc._pts, real(grid))
    st.begin_run(2)
    st._relocalizer()
    assert len(calls) == 2


def test_blend_poses_weighs_each_pose_by_the_inverse_of_its_variance():
    """Equal deviations: the midpoint, the heading averaged across +-pi; a pose twice as
    uncertain gets a fifth of the weight (1/4 against 1)."""
    from gatmo.pipeline.stack import blend_poses

    a = np.array([1.0, 2.0, np.pi - 0.1])
    b = np.array([2.0, 0.0, -np.pi + 0.1])
    mid = blend_poses(a, b, 0.1, 0.1)
    np.testing.assert_allclose(mid[:2], [1.5, 1.0], atol=1e-12)
    assert abs(abs(mid[2]) - np.pi) < 1e-9
    np.testing.assert_allclose(blend_poses(a, b, 0.2, 0.1)[:2], [1.8, 0.4], atol=1e-12)
    np.testing.assert_allclose(blend_poses(a, b, 0.1, 0.2)[:2], [1.2, 1.6], atol=1e-12)


def test_blended_publishing_averages_the_carried_pose_with_the_filter_s():
    """``publish_blend``: after each confirmed scan the carried pose (odometry exact here) and
    the filter's (6 cm / 1.7 deg off) are averaged, the filter's weight growing with the
    travel since the confirmation: err = |bias| * w_filter, w_filter = sc^2 / (sc^2 + sf^2)
    with sc = base + per_m * travel; past ``publish_blend_max_m`` the filter's pose alone."""
    confident = [0, 5, 10]
    truth, bias, out = _publishing_run(
        FusionConfig(publish_blend=True, publish_blend_base_std_m=0.02,
                     publish_blend_odom_std_per_m=0.1, publish_blend_filter_std_m=0.05,
                     publish_blend_max_m=1.0, use_scan_matcher=False,
                     absence_max_std_xy_m=0.1, absence_max_std_theta_deg=3.0), confident)
    assert [i for i, o in enumerate(out) if o.gatmo_pose_verified] == confident
    published = np.array([o.pose_xytheta for o in out])
    err = np.hypot(*(published[:, :2] - truth[:, :2]).T)
    assert np.all(err[confident] < 0.01)
    step_m = np.hypot(*(truth[1, :2] - truth[0, :2]))
    for i in range(11, 22):
        sc = 0.02 + 0.1 * step_m * (i - 10)
        w_filter = sc**2 / (sc**2 + 0.05**2)
        # the alignment's pose on scan 10 is within a few mm of the truth
        assert abs(err[i] - np.hypot(*bias[:2]) * w_filter) < 0.006, i
    assert np.all(np.diff(err[11:22]) > 0)  # the filter's weight grows with the travel
    np.testing.assert_allclose(published[22:], truth[22:] + bias, atol=1e-9)


@pytest.mark.parametrize("suspect_std_m", [0.05, 0.2])
def test_the_blend_trusts_the_filter_less_after_the_alignment_contradicted_it(suspect_std_m):
    """``publish_blend_suspect_std_m``: on scan 12 the filter is strictly confident and 0.3 m
    off; the alignment from there moves it back by more than ``align_max_correction_m``
    (contradicts). Until the next confirmation the blend weighs the filter with the suspect
    deviation: err = |bias| * sc^2 / (sc^2 + ss^2); with ss = publish_blend_filter_std_m the
    same as before."""
    truth, bias, out = _publishing_run(
        FusionConfig(publish_blend=True, publish_blend_base_std_m=0.02,
                     publish_blend_odom_std_per_m=0.1, publish_blend_filter_std_m=0.05,
                     publish_blend_suspect_std_m=suspect_std_m, publish_blend_max_m=3.0,
                     use_scan_matcher=False, absence_max_std_xy_m=0.1,
                     absence_max_std_theta_deg=3.0),
        [0, 5, 10, 12], off_at={12: (0.0, 0.3, 0.0)})
    assert out[12].align_outcome in ("contradicts", "not_converged")
    published = np.array([o.pose_xytheta for o in out])
    err = np.hypot(*(published[:, :2] - truth[:, :2]).T)
    step_m = np.hypot(*(truth[1, :2] - truth[0, :2]))
    for i in range(13, 22):
        sc = 0.02 + 0.1 * step_m * (i - 10)
        w_filter = sc**2 / (sc**2 + suspect_std_m**2)
        assert abs(err[i] - np.hypot(*bias[:2]) * w_filter) < 0.006, i


@pytest.mark.parametrize("from_start", [True, False])
def test_a_run_publishes_its_given_start_pose_carried_until_the_first_confirmation(from_start):
    """``publish_blend_from_start``: the stack is handed the run's true start pose with a
    0.1 m deviation; until the first confirmed scan (10) the wheels carry it and the blend
    averages it with the filter's (6 cm / 1.7 deg off): err = |bias| * sc^2 / (sc^2 + sf^2),
    sc = 0.1 + per_m * travel. Without the option the filter's pose is published there."""
    truth, bias, out = _publishing_run(
        FusionConfig(publish_blend=True, publish_blend_base_std_m=0.02,
                     publish_blend_odom_std_per_m=0.1, publish_blend_filter_std_m=0.05,
                     publish_blend_from_start=from_start, use_scan_matcher=False,
                     absence_max_std_xy_m=0.1, absence_max_std_theta_deg=3.0),
        [10], initial_pose_xytheta="truth", initial_std_m=0.1)
    published = np.array([o.pose_xytheta for o in out])
    err = np.hypot(*(published[:, :2] - truth[:, :2]).T)
    assert err[10] < 0.01  # the first confirmation
    if not from_start:
        np.testing.assert_allclose(published[:10], truth[:10] + bias, atol=1e-9)
        return
    step_m = np.hypot(*(truth[1, :2] - truth[0, :2]))
    for i in range(10):
        sc = 0.1 + 0.1 * step_m * i
        w_filter = sc**2 / (sc**2 + 0.05**2)
        assert abs(err[i] - np.hypot(*bias[:2]) * w_filter) < 0.006, i
    assert np.all(err[:4] < np.hypot(*bias[:2]) - 0.007)  # nearer than the filter alone


class _MaskingMapOnly(_MapOnly):
    """:class:`_MapOnly` that calls the returns within 0.15 m of ``unmapped`` boxes (x0, y0,
    x1, y1) unexplained (as GATMO does with furniture its map does not have yet)."""

    def __init__(self, grid, unmapped):
        super().__init__(grid)
        self.unmapped = unmapped

    def unexplained_at(self, points_xy):
        p = np.asarray(points_xy, dtype=float).reshape(-1, 2)
        out = np.zeros(len(p), dtype=bool)
        for x0, y0, x1, y1 in self.unmapped:
            dx = np.maximum(np.maximum(x0 - p[:, 0], p[:, 0] - x1), 0.0)
            dy = np.maximum(np.maximum(y0 - p[:, 1], p[:, 1] - y1), 0.0)
            out |= np.hypot(dx, dy) <= 0.15
        return out


def _masked_run(align_masked, box_m=0.3):
    """(truth (6, 3), the filter's bias (3,), the steps, the poses GATMO was handed, whether
    each was handed as verified): six ``box_m`` boxes stand where the map has none (0.3 m: a
    third of the returns on them)."""
    mapped = [(1.0, 0.6, 1.4, 1.0), (4.6, 2.8, 5.0, 3.2)]
    corners = (((1.8, 3.0, 4.2), (0.9, 2.8)) if box_m <= 0.3 else ((1.6, 2.9, 4.0), (0.7, 2.6)))
    unmapped = [(x, y, x + box_m, y + box_m) for x in corners[0] for y in corners[1]]
    grid = room_grid(6, 4, 0.05, boxes=mapped)
    world = room_grid(6, 4, 0.05, boxes=mapped + unmapped)
    n = 6
    y = 2.0 if box_m <= 0.3 else 1.9
    truth = np.stack([np.linspace(2.3, 2.8, n), np.full(n, y), np.zeros(n)], axis=1)
    bias = np.array([0.03, -0.01, 0.005])
    loc = ScriptedLocalizer(truth, confident_at=range(n), bias=bias)
    handed, verified = [], []

    def update(pose, scan, **kw):
        handed.append(np.array(pose, float))
        verified.append(bool(kw["pose_verified"]))
        return []

    mapper = _MaskingMapOnly(grid, unmapped)
    mapper.update = update
    fusion = FusionConfig(use_scan_matcher=False, align_masked=align_masked,
                          mask_withheld=False, mask_offset_objects=False,
                          publish_min_tight_fraction=0.8)
    stack = LocalizationStack(loc, None, mapper, fusion)
    stack.begin_run(1)
    out = [stack.step(make_scan(world, truth[i], n_beams=361, fov_rad=2 * np.pi,
                                max_range_m=8.0, odom_pose_xytheta=truth[i],
                                stamp_s=float(i))) for i in range(n)]
    return truth, bias, out, np.array(handed), np.array(verified)


@pytest.mark.parametrize("align_masked", ["publish", "all"])
def test_the_masked_scan_s_alignment_gives_the_published_pose(align_masked):
    """The full scan's alignment confirms the filter's pose (3 cm off; the walls and the
    mapped boxes pin it) but loosely (the unmapped boxes), so the filter's pose is published.
    ``align_masked``: aligned without the returns GATMO calls unexplained, the fit is tight
    and its pose (under 1 cm off) is published; with ``publish`` GATMO is handed the full
    scan's poses as without the option, with ``all`` the masked scan's."""
    truth, bias, out, handed, _ = _masked_run(align_masked)
    _, _, out_off, handed_off, _ = _masked_run("off")
    assert all(o.align_outcome == "confirmed" for o in out + out_off)
    # scan 0 is never masked: there is no prediction yet
    published_off = np.array([o.pose_xytheta for o in out_off])
    np.testing.assert_allclose(published_off[1:], truth[1:] + bias, atol=1e-9)
    published = np.array([o.pose_xytheta for o in out])
    assert np.all(np.hypot(*(published[1:, :2] - truth[1:, :2]).T) < 0.01)
    if align_masked == "publish":
        np.testing.assert_array_equal(handed, handed_off)
    else:
        assert np.abs(handed[1:] - handed_off[1:]).max() > 1e-6
        assert np.all(np.hypot(*(handed[1:, :2] - truth[1:, :2]).T) < 0.01)


def test_with_align_masked_all_gatmo_takes_the_masked_scan_s_confirmation():
    """Six 0.6 m boxes the map lacks take so many returns that the full scan's alignment is
    inconclusive (low fitness) from the second scan on: GATMO is handed those poses unverified
    (no evidence of absence from them). ``align_masked: all`` aligns the masked scan, which
    confirms: GATMO takes verified poses under 1 cm off; ``publish`` leaves GATMO's as
    off's."""
    truth, _, out_off, handed_off, verified_off = _masked_run("off", box_m=0.6)
    assert [o.align_outcome for o in out_off[1:]] == ["low_fitness"] * 5
    assert not verified_off[1:].any()
    _, _, _, handed_pub, verified_pub = _masked_run("publish", box_m=0.6)
    np.testing.assert_array_equal(handed_pub, handed_off)
    np.testing.assert_array_equal(verified_pub, verified_off)
    _, _, out, handed, verified = _masked_run("all", box_m=0.6)
    assert [o.align_outcome for o in out[1:]] == ["confirmed"] * 5
    assert verified[1:].all()
    assert np.all(np.hypot(*(handed[1:, :2] - truth[1:, :2]).T) < 0.01)


def test_the_alignment_keeps_the_returns_of_an_object_missing_it_by_an_offset():
    """``align_masked``: the localizer is kept from both the returns GATMO calls unexplained
    and those of an object that misses them by an offset (``offset_at``); the alignment's
    scan lacks only the first (with a right map the second show the pose off)."""
    box, unmapped = (1.0, 0.6, 1.4, 1.0), [(3.0, 2.8, 3.3, 3.1)]
    grid = room_grid(6, 4, 0.05, boxes=[box])
    world = room_grid(6, 4, 0.05, boxes=[box] + unmapped)
    mapper = _MaskingMapOnly(grid, unmapped)
    near_box = _MaskingMapOnly(grid, [box]).unexplained_at
    mapper.offset_at = near_box
    pose = np.array([2.3, 2.0, 0.0])
    stack = LocalizationStack(ScriptedLocalizer(pose[None], confident_at=[0]), None, mapper,
                              FusionConfig(use_scan_matcher=False, mask_withheld=False,
                                           mask_offset_objects=True, align_masked="publish"))
    stack.begin_run(1)
    stack._last_loc, stack._last_odom, stack._last_precise = pose, pose, True
    scan = make_scan(world, pose, n_beams=361, fov_rad=2 * np.pi, max_range_m=8.0,
                     odom_pose_xytheta=pose, stamp_s=0.0)
    masked, withheld = stack._masked(scan)
    aligned = stack._alignment_scan(scan, masked, withheld)
    ends = transform_points(pose, scan.points_base_xy(only_valid=False))
    on_unmapped, on_box = mapper.unexplained_at(ends), near_box(ends)
    assert on_unmapped.sum() >= 5 and on_box.sum() >= 5
    np.testing.assert_array_equal(withheld, on_unmapped | on_box)
    assert np.all(np.isnan(aligned.ranges_m[on_unmapped]))
    np.testing.assert_array_equal(aligned.ranges_m[~on_unmapped], scan.ranges_m[~on_unmapped])
