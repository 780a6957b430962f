"""Faults mid-run: a run killed at random points never leaves a half-written object map."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from gatmo.datasets.sim import SimConfig, simulate_scenario
from gatmo.maps.io import load_map
from gatmo.maps.object_io import load_objects


@pytest.fixture(scope="module")
def scen(tmp_path_factory):
    cfg = SimConfig.for_preset("hall")
    cfg.robot.duration_s = 12.0
    return simulate_scenario(tmp_path_factory.mktemp("s"), runs=3, seed=9, config=cfg)


def _compare(scen, out):
    return [sys.executable, "-m", "gatmo", "compare", *map(str, scen.logs), "--map",
            str(scen.map_yaml), "--out", str(out)]


def test_sigkill_at_random_points_leaves_loadable_object_maps(scen, tmp_path):
    rng = np.random.default_rng(0)
    out = tmp_path / "cmp"
    env = dict(os.environ, COLUMNS="120")
    # warm the numba cache so that kill times fall inside the work
    subprocess.run(_compare(scen, tmp_path / "warm"), check=True, capture_output=True, env=env)
    for _ in range(3):
        p = subprocess.Popen(_compare(scen, out), stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, env=env)
        time.sleep(rng.uniform(1.0, 6.0))
        p.send_signal(signal.SIGKILL)
        p.wait()
        for f in out.glob("gatmo/*/objects.json"):
            load_objects(f)  # complete, or it would not parse
        for f in out.glob("gatmo/*/map.yaml"):
            load_map(f)
    # and a re-run from scratch completes
    done = subprocess.run(_compare(scen, out), capture_output=True, env=env)
    assert done.returncode == 0
    assert len(list(out.glob("gatmo/*/objects.json"))) == 3
