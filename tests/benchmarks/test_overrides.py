"""The benchmarks' ``--set`` and ``--sim-set`` overrides."""

import argparse

import pytest

from benchmarks._overrides import add_override_args, with_overrides
from gatmo.datasets.sim import SimConfig
from gatmo.errors import ConfigError


def test_sim_overrides_set_the_simulators_config_and_refuse_unknown_keys():
    ap = argparse.ArgumentParser()
    add_override_args(ap)
    args = ap.parse_args(["--sim-set", "laser.max_range_m=8", "--sim-set",
                          "robot.duration_s=30", "--set", "gatmo.track_max_range_m=3.3"])
    sim = with_overrides(SimConfig.for_preset("hall"), args.sim_set)
    assert sim.laser.max_range_m == 8.0 and sim.robot.duration_s == 30.0
    assert sim.laser.beams == SimConfig.for_preset("hall").laser.beams  # the rest untouched
    assert args.set == ["gatmo.track_max_range_m=3.3"]
    with pytest.raises(ConfigError, match="laser.range_m"):
        with_overrides(SimConfig.for_preset("hall"), ["laser.range_m=8"])
    with pytest.raises(ConfigError, match="max_range_m"):
        with_overrides(SimConfig.for_preset("hall"), ["laser.max_range_m=-1"])
