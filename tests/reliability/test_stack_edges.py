"""Input edge cases fed straight to the full stack (localizer + scan matcher + GATMO), each with
what the stack does. Readers refuse or skip most of these (see test_hostile_bags.py and
tests/datasets); library users can still hand them to ``LocalizationStack.step``.

The world does not change in any of these runs, so every test also checks that GATMO marks
nothing absent or relocated.
"""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.datasets.carmen import CarmenLog, write_carmen
from gatmo.datasets.sim import SimConfig, make_world, rasterize, simulate_run
from gatmo.errors import DataError
from gatmo.geometry import compose, relative
from gatmo.objects import GatmoMapper
from gatmo.pipeline.config import sim_stack_config
from gatmo.pipeline.runs import make_localizer, make_matcher
from gatmo.pipeline.stack import LocalizationStack

N = 260


@pytest.fixture(scope="module")
def hall():
    rng = np.random.default_rng(33)
    sim = SimConfig.for_preset("hall")
    sim.robot.duration_s = N / sim.robot.scan_rate_hz
    sim.people.count_per_run = 0
    world, route = make_world("hall", rng)
    return rasterize(world, 0.05), simulate_run(world, route, sim, rng)


def _run(grid, scans, cfg=None):
    cfg = sim_stack_config() if cfg is None else cfg
    mapper = GatmoMapper.from_config(cfg.gatmo, grid)
    stack = LocalizationStack(make_localizer(cfg, grid, 0, scans[0].gt_pose_xytheta, False),
                              make_matcher(cfg), mapper, cfg.fusion)
    stack.begin_run(1)
    steps = [stack.step(s) for s in scans]
    err = np.array([np.hypot(*(st.pose_xytheta[:2] - s.gt_pose_xytheta[:2]))
                    for st, s in zip(steps, scans, strict=True)])
    kinds = [e.kind for st in steps for e in st.events]
    return stack, err, kinds


def _copy(scans):
    from dataclasses import replace

    return [replace(s, ranges_m=s.ranges_m.copy(), angles_rad=s.angles_rad.copy(),
                    odom_pose_xytheta=s.odom_pose_xytheta.copy()) for s in scans]


@pytest.fixture(scope="module")
def reference(hall):
    grid, scans = hall
    _, err, kinds = _run(grid, _copy(scans))
    assert np.median(err) < 0.1 and "absent" not in kinds
    return err


def _no_map_change(kinds):
    assert "absent" not in kinds and "relocated" not in kinds


def test_beam_count_changes_mid_run(hall, reference):
    """Every 2nd beam dropped from scan 80 to 159, then a 3-beam scan: the stack uses what each
    scan has (beams are weighed and matched per scan), tracking is unchanged."""
    grid, scans = hall
    ss = _copy(scans)
    for s in ss[80:160]:
        s.ranges_m, s.angles_rad = s.ranges_m[::2], s.angles_rad[::2]
    ss[200].ranges_m, ss[200].angles_rad = ss[200].ranges_m[::90], ss[200].angles_rad[::90]
    assert {s.num_beams for s in ss} == {181, 91, 3}
    stack, err, kinds = _run(grid, ss)
    assert np.median(err[80:160]) < 0.1 and err[200] < 0.3 and np.median(err[200:]) < 0.1
    _no_map_change(kinds)


def test_carmen_beam_count_change_is_read_and_counted(tmp_path, hall):
    _, scans = hall
    ss = _copy(scans[:6])
    ss[3].ranges_m, ss[3].angles_rad = ss[3].ranges_m[::2], ss[3].angles_rad[::2]
    log = CarmenLog(write_carmen(tmp_path / "b.clf", ss))
    back = list(log)
    assert [s.num_beams for s in back] == [181, 181, 181, 91, 181, 181]
    assert log.stats.skipped == 1 and "beam count changed" in log.stats.skipped_reasons[0]


@pytest.mark.parametrize("case", ["duplicate", "backwards"])
def test_duplicate_and_backwards_stamps(hall, reference, case):
    """Readers refuse these (DataError) or skip them (skip_bad). Handed to the stack directly, a
    repeated scan (same stamp, same odometry) or one stamped 1 s in the past is processed like
    any other: tracking and the object map are unchanged (object tracks never predict backwards
    in time)."""
    grid, scans = hall
    ss = _copy(scans)
    extra = _copy([ss[120]])[0]
    if case == "backwards":
        extra.stamp_s -= 1.0
    ss.insert(121, extra)
    stack, err, kinds = _run(grid, ss)
    assert stack.n_scans == len(ss)
    assert np.median(err[110:140]) < 0.1 and np.median(err[140:]) < 0.1
    _no_map_change(kinds)


def test_carmen_duplicate_stamp_is_refused_or_skipped(tmp_path, hall):
    _, scans = hall
    ss = _copy(scans[:5])
    ss[3].stamp_s = ss[2].stamp_s
    p = write_carmen(tmp_path / "d.clf", ss)
    with pytest.raises(DataError) as e:
        list(CarmenLog(p))
    assert e.value.file == str(p) and "does not increase" in str(e.value)
    log = CarmenLog(p, skip_bad=True)
    assert len(list(log)) == 4 and log.stats.skipped == 1


@pytest.mark.parametrize("weight", [0.5, 0.0])
def test_wheels_stall_in_a_turn_and_catch_up(hall, weight):
    """The wheels stall for 15 scans in the hall route's sharpest turn (from scan 81), then
    catch up 1.09 rad in one step, an odometry jump. With the step held as motion too
    (``amcl.odom_jump_motion_weight`` 0.5, the default) the stack tracks through it (0.15 m at
    worst after, median 1 cm); restarting around the last estimate alone (0) loses the robot
    on this run (8.5 m; MIT CSAIL's full stack was 1.8 m off so)."""
    grid, scans = hall
    ss = _copy(scans)
    a, k = 81, 15
    for s in ss[a:a + k]:
        s.odom_pose_xytheta = ss[a - 1].odom_pose_xytheta.copy()
    assert abs(relative(ss[a + k - 1].odom_pose_xytheta, ss[a + k].odom_pose_xytheta)[2]) > 1.0
    cfg = sim_stack_config()
    cfg.amcl.odom_jump_motion_weight = weight
    stack, err, kinds = _run(grid, ss, cfg)
    assert stack.localizer.stats.odom_resets == 1
    if weight > 0:
        assert err[a + k:].max() < 0.3 and np.median(err[a + k:]) < 0.05
        _no_map_change(kinds)
    else:
        assert err[a + k:].max() > 1.0


@pytest.mark.parametrize("on", [True, False])
def test_published_pose_follows_the_matcher_through_a_stall(hall, on):
    """The wheels stall for 15 scans on a straight (from scan 150): the filter updates on their
    travel and stands still. With ``fusion.publish_through_stalls`` (on in the real logs'
    preset) the published pose moves by the scan matcher's steps meanwhile: 0.16 m off at
    worst in the stall on this run against 0.61 m without. Either way the pose carried by the
    wheels' and the matcher's steps (``carry_matcher_inflation``, on here) takes the wheels'
    through the stall and their catch-up, where the matcher falls back on them: counting the
    stall's motion twice put the pose 0.44 m ahead after the catch-up."""
    grid, scans = hall
    ss = _copy(scans)
    a, k = 150, 15
    for s in ss[a:a + k]:
        s.odom_pose_xytheta = ss[a - 1].odom_pose_xytheta.copy()
    cfg = sim_stack_config()
    cfg.fusion.publish_through_stalls = on
    stack, err, kinds = _run(grid, ss, cfg)
    if on:
        assert err[a:a + k].max() < 0.3
    else:
        assert err[a:a + k].max() > 0.5
    assert err[a + k:].max() < 0.3
    _no_map_change(kinds)


@pytest.mark.parametrize("case", ["jump", "reset"])
def test_odometry_jump_or_reset(hall, reference, case):
    """From scan 120 on the odometry is offset by 3 m and 90 degrees (a jump) or restarts at
    the origin (a reset). The localizer sees a step above ``odom_jump_m`` (``odom_resets`` == 1):
    of its two hypotheses the scans keep the cloud around the last estimate, the step taken
    as no motion (the other, the step as motion, lands metres off); the published pose stays
    within 0.3 m of the truth throughout (0.07 m at worst on this run) and GATMO marks nothing
    absent."""
    grid, scans = hall
    ss = _copy(scans)
    o120 = ss[120].odom_pose_xytheta.copy()
    for s in ss[120:]:
        rel = relative(o120, s.odom_pose_xytheta)
        base = compose(o120, [3.0, 0.0, np.pi / 2]) if case == "jump" else np.zeros(3)
        s.odom_pose_xytheta = compose(base, rel)
    stack, err, kinds = _run(grid, ss)
    assert stack.localizer.stats.odom_resets == 1
    assert err[120:].max() < 0.3 and np.median(err[160:]) < 0.1
    _no_map_change(kinds)
