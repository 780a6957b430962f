"""``gatmo eval``: a trajectory scored against ground truth (aligned or not) and relations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gatmo.cli import main
from gatmo.datasets.metrics import align_se2, ate
from gatmo.datasets.tum import write_tum
from gatmo.geometry import compose, relative

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def _path(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * 0.1
    th = 0.02 * np.arange(n)
    xy = np.stack([3.0 * np.cos(th) + 0.01 * np.arange(n), 2.0 * np.sin(th)], 1)
    return t, np.column_stack([xy, th + np.pi / 2])


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-50, 50), y=st.floats(-50, 50), th=st.floats(-3.1, 3.1),
       scale=st.floats(0.5, 2.0))
def test_alignment_recovers_a_known_rigid_transform_and_scale(x, y, th, scale):
    _, p = _path()
    T = np.array([x, y, th])
    dst = compose(T, p * [scale, scale, 1.0])[:, :2]
    T_fit, s = align_se2(p[:, :2], dst, with_scale=True)
    np.testing.assert_allclose(T_fit[:2], T[:2], atol=1e-6)
    assert abs(np.angle(np.exp(1j * (T_fit[2] - th)))) < 1e-9 and s == pytest.approx(scale)
    T_rigid, one = align_se2(p[:, :2], compose(T, p)[:, :2])
    assert one == 1.0 and np.allclose(T_rigid[:2], T[:2], atol=1e-6)


def test_ate_is_unaligned_unless_asked():
    t, gt = _path()
    rng = np.random.default_rng(0)
    est = compose([5.0, -2.0, 0.7], gt)  # the estimate in a frame of its own
    est[:, :2] += rng.normal(0.0, 0.01, (len(t), 2))
    assert ate(t, est, t, gt)["median_m"] > 3.0
    a = ate(t, est, t, gt, align=True)
    assert a["rmse_m"] < 0.02 and a["lost_fraction"] == 0.0
    np.testing.assert_allclose(a["T_gt_est"], relative([5.0, -2.0, 0.7], np.zeros(3)),
                               atol=0.01)


def test_eval_cli_scores_against_ground_truth_and_relations(tmp_path, capsys):
    t, gt = _path()
    est = gt.copy()
    est[100:, 0] += 0.3  # a 0.3 m jump half-way
    write_tum(tmp_path / "gt.tum", t, gt)
    write_tum(tmp_path / "est.tum", t + 100.0, est)  # the estimate on another clock
    pairs = [(i, i + 10) for i in range(0, 190, 10)]
    rel = tmp_path / "r.relations"
    rel.write_text("".join(
        f"{t[i]} {t[j]} {r[0]} {r[1]} 0 0 0 {r[2]}\n"
        for (i, j), r in zip(pairs, relative(gt[[i for i, _ in pairs]],
                                             gt[[j for _, j in pairs]]), strict=True)))
    args = ["eval", str(tmp_path / "est.tum"), "--ground-truth", str(tmp_path / "gt.tum"),
            "--relations", str(rel)]
    assert main(args) == 1  # a clock 100 s off covers nothing, and says how to fix it
    assert "--stamp-offset" in capsys.readouterr().err
    from gatmo.pipeline.trajectory import evaluate_trajectory

    r = evaluate_trajectory(tmp_path / "est.tum", gt_path=tmp_path / "gt.tum",
                            relations_path=rel, stamp_offset_s=-100.0)
    assert r["ate_poses"] == 200 and r["ate_median_m"] == pytest.approx(0.15, abs=1e-6)
    assert r["ate_max_m"] == pytest.approx(0.3) and r["lost_fraction"] == 0.0
    # one relation of 19 spans the jump: 0.3 m there, none elsewhere
    assert r["rel_used"] == 19 and r["rel_trans_mean_m"] == pytest.approx(0.3 / 19)
    assert main([*args, "--stamp-offset", "-100"]) == 0
    assert "rel_trans_mean_m" in capsys.readouterr().out
    assert main(["eval", str(tmp_path / "est.tum")]) == 1
    assert "--ground-truth and/or --relations" in capsys.readouterr().err


@pytest.mark.skipif(not (DATA / "radish-corrected" / "intel-corrected.log.gz").exists(),
                    reason="../shared/data (radish's corrected Intel log) not found")
def test_real_intel_corrected_poses_against_the_benchmark_s_relations(tmp_path, capsys):
    # ../shared/data/README.md: the gmapping-corrected log, 976052857.33753 s behind the bag's
    # clock, gives 0.043 m / 0.70 deg on the 40 relations it covers
    from gatmo.datasets.carmen import CarmenLog

    scans = list(CarmenLog(DATA / "radish-corrected" / "intel-corrected.log.gz",
                           pose_is_reference=True, skip_bad=True))
    write_tum(tmp_path / "c.tum", np.array([s.stamp_s for s in scans]),
              np.array([s.gt_pose_xytheta for s in scans]))
    assert main(["eval", str(tmp_path / "c.tum"), "--relations",
                 str(DATA / "slam-benchmark" / "intel.relations"), "--stamp-offset",
                 "976052857.33753"]) == 0
    out = capsys.readouterr().out
    assert "rel_used" in out
    from gatmo.pipeline.trajectory import evaluate_trajectory

    r = evaluate_trajectory(tmp_path / "c.tum",
                            relations_path=DATA / "slam-benchmark" / "intel.relations",
                            stamp_offset_s=976052857.33753)
    assert r["rel_used"] == 40
    assert abs(r["rel_trans_mean_m"] - 0.043) < 0.001 and abs(r["rel_rot_mean_deg"] - 0.70) < 0.01


def test_rpe_is_frame_free_and_measures_a_scale_error():
    from gatmo.datasets.metrics import rpe

    t, gt = _path(300)
    moved = compose([5.0, -2.0, 0.7], gt)  # the same motion in another frame: no error
    e = rpe(t, moved, t, gt, delta_m=1.0)
    assert e["n"] > 200 and e["trans_rmse_m"] < 1e-9 and e["rot_mean_deg"] < 1e-9
    # a straight run at 1.1 x the true speed: 0.1 m of error per metre of travel
    line = np.column_stack([np.arange(300) * 0.05, np.zeros(300), np.zeros(300)])
    e = rpe(t, line * [1.1, 1.0, 1.0], t, line, delta_m=1.0)
    assert e["trans_median_m"] == pytest.approx(0.1, abs=1e-6)
    assert e["n"] == 300 - 20  # pairs 20 poses (1 m) apart


def test_eval_cli_reports_rpe(tmp_path, capsys):
    t, gt = _path()
    write_tum(tmp_path / "gt.tum", t, gt)
    write_tum(tmp_path / "est.tum", t, compose([1.0, 2.0, 0.3], gt))
    assert main(["eval", str(tmp_path / "est.tum"), "--ground-truth", str(tmp_path / "gt.tum"),
                 "--rpe-delta", "1"]) == 0
    out = capsys.readouterr().out
    assert "rpe_trans_rmse_m" in out and "rpe_pairs" in out
