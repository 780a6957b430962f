"""``gatmo localize`` end to end on a simulated log, through the CLI."""

from __future__ import annotations

import numpy as np

from gatmo.cli import main
from gatmo.datasets.sim import SimConfig, simulate_scenario
from gatmo.datasets.tum import read_tum


def test_localize_cli_on_simulated_office(tmp_path, capsys):
    cfg = SimConfig.for_preset("office")
    cfg.robot.duration_s = 20.0
    cfg.rearrange.move_prob = 0.0
    cfg.rearrange.shift_prob = 0.0
    cfg.rearrange.add_count = 0
    cfg.rearrange.remove_prob = 0.0
    scen = simulate_scenario(tmp_path / "s", preset="office", runs=1, seed=1, config=cfg)
    params = tmp_path / "amcl.yaml"
    params.write_text("amcl:\n  ros__parameters:\n    z_hit: 0.95\n    z_rand: 0.05\n"
                      "    alpha1: 0.05\n    alpha2: 0.05\n    alpha3: 0.05\n    alpha4: 0.05\n"
                      "    update_min_d: 0.1\n")
    out = tmp_path / "poses.tum"
    rc = main(["localize", "--map", str(scen.map_yaml), "--log", str(scen.logs[0]),
               "--params", str(params), "--out", str(out)])
    assert rc == 0
    t, p = read_tum(out)
    gt_t, gt = read_tum(scen.gt[0])
    assert len(t) == len(gt_t)
    err = np.hypot(*(p[:, :2] - gt[:, :2]).T)
    assert np.median(err) < 0.1
    assert "ate_rmse_m" in capsys.readouterr().out


def test_localize_refuses_pose_in_a_wall(tmp_path, capsys):
    scen = simulate_scenario(tmp_path / "s", preset="office", runs=1, seed=1)
    rc = main(["localize", "--map", str(scen.map_yaml), "--log", str(scen.logs[0]),
               "--initial-pose", "-0.1,-0.1,0", "--out", str(tmp_path / "p.tum")])
    assert rc == 1
    err = capsys.readouterr().err
    assert "initial pose" in err and "Traceback" not in err
