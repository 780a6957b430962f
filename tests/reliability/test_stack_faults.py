"""Faults for the whole stack: while the pose is wrong or the laser is blocked, GATMO must not
empty the map."""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.datasets.sim import SimConfig, make_world, rasterize, simulate_run
from gatmo.geometry import compose, relative
from gatmo.objects import GatmoMapper
from gatmo.pipeline.config import sim_stack_config
from gatmo.pipeline.runs import make_localizer, make_matcher
from gatmo.pipeline.stack import LocalizationStack


@pytest.fixture(scope="module")
def hall():
    rng = np.random.default_rng(21)
    sim = SimConfig.for_preset("hall")
    sim.robot.duration_s = 50.0
    world, route = make_world("hall", rng)
    return rasterize(world, 0.05), simulate_run(world, route, sim, rng)


def _stack(grid, pose0):
    cfg = sim_stack_config()
    cfg.amcl.recovery_alpha_slow = 0.001
    cfg.amcl.recovery_alpha_fast = 0.1
    mapper = GatmoMapper.from_config(cfg.gatmo, grid)
    stack = LocalizationStack(make_localizer(cfg, grid, 0, pose0, False), make_matcher(cfg),
                              mapper, cfg.fusion)
    stack.begin_run(1)
    return stack, mapper


def test_kidnapped_robot_does_not_empty_the_map(hall):
    grid, scans = hall
    stack, mapper = _stack(grid, scans[0].gt_pose_xytheta)
    for s in scans[:100]:
        stack.step(s)
    # teleport: scans from 300 on, odometry continuing smoothly from scan 99
    o99, o300 = scans[99].odom_pose_xytheta, scans[300].odom_pose_xytheta
    events = []
    for s in scans[300:]:
        s.odom_pose_xytheta = compose(o99, relative(o300, s.odom_pose_xytheta))
        events += stack.step(s).events
    absent = [e for e in events if e.kind == "absent"]
    placed = [o for o in mapper.object_map.placed() if not o.structure]
    # the world did not change: whatever the filter believes, few objects may go
    assert len(absent) <= 2
    assert len(placed) >= len([o for o in mapper.object_map.objects if not o.structure]) - 2


def test_blocked_laser_changes_nothing(hall):
    grid, scans = hall
    stack, mapper = _stack(grid, scans[0].gt_pose_xytheta)
    events = []
    for i, s in enumerate(scans[:200]):
        if 50 <= i < 150:  # people stand around the robot: every beam ends at 0.3-0.5 m
            s.ranges_m = np.random.default_rng(i).uniform(0.3, 0.5, s.ranges_m.shape)
        events += stack.step(s).events
    assert not [e for e in events if e.kind in ("absent", "relocated")]
    assert mapper.object_map.Gamma == [] or all(
        len(o.shape_xy) < 200 for o in mapper.object_map.Gamma)  # no wall of people added
