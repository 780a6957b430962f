"""Run-by-run paired comparison from the same object map (benchmarks.bench_run_paired)."""

import numpy as np

from benchmarks.bench_run_paired import FIGURES, summarize


def _fig(ate, found=1):
    return {"ate_m": ate, "lost": 0.0, "found": found, "false_relocations": 0,
            "twin_relocations": 0}


def test_a_gain_on_every_run_is_told_from_noise_and_noise_is_not():
    rng = np.random.default_rng(5)
    rows, noisy = [], []
    for seed in range(8):
        for run in range(1, 5):
            a = float(rng.uniform(0.05, 0.3))
            rows.append({"seed": seed, "run": run, "a": _fig(a), "b": _fig(a - 0.02, found=2)})
            noisy.append({"seed": seed, "run": run, "a": _fig(a),
                          "b": _fig(a + float(rng.normal(0, 0.05)))})
    gain, swing = summarize(rows), summarize(noisy)
    assert set(gain) == set(FIGURES)
    assert abs(gain["ate_m"]["b_minus_a"] + 0.02) < 1e-12 and gain["ate_m"]["ci95"][1] < 0
    assert gain["ate_m"]["b_lower"] == 32 and gain["found"]["b_higher"] == 32
    assert gain["found"]["ci95"] == [1.0, 1.0]
    assert swing["ate_m"]["ci95"][0] < 0.0 < swing["ate_m"]["ci95"][1]
    assert swing["found"]["b_minus_a"] == 0.0 and swing["found"]["pairs"] == 32
