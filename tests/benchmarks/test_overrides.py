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


def test_static_overrides_change_a_copy_of_the_localizers_section_only():
    from benchmarks._overrides import static_amcl
    from gatmo.pipeline.config import sim_stack_config

    ap = argparse.ArgumentParser()
    add_override_args(ap, static=True)
    args = ap.parse_args(["--static-set", "amcl.laser_model=likelihood_field",
                          "--static-set", "amcl.sigma_hit_m=0.2"])
    cfg = sim_stack_config()
    amcl = static_amcl(cfg, args.static_set)
    assert (amcl.laser_model, amcl.sigma_hit_m) == ("likelihood_field", 0.2)
    assert amcl.alpha2 == cfg.amcl.alpha2  # the rest as the stack's
    assert cfg.amcl.laser_model == "likelihood_field_prob" and cfg.amcl.sigma_hit_m == 0.1
    assert static_amcl(cfg, []) is None
    with pytest.raises(ConfigError, match="only amcl"):
        static_amcl(cfg, ["gatmo.beta_thresh=0.5"])
    with pytest.raises(ConfigError, match="sigma_hit_m"):
        static_amcl(cfg, ["amcl.sigma_hit_m=-1"])
    plain = argparse.ArgumentParser()
    add_override_args(plain)
    with pytest.raises(SystemExit):  # benchmarks without a static side do not take it
        plain.parse_args(["--static-set", "amcl.sigma_hit_m=0.2"])
