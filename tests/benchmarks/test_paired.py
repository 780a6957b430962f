"""Paired comparison of two benchmark runs over the same seeds (benchmarks.paired)."""

import numpy as np

from benchmarks.paired import ORACLE_FIGURES, SIM_FIGURES, paired, per_seed


def _sim_row(seed, found, moved=10, frel=0):
    return {"seed": seed, "found": found, "moved": moved, "false_relocations": frel,
            "twin_relocations": 0, "gone_noticed": 5, "gone": 10, "gatmo_lost": 0.1,
            "gatmo_ate_m": 0.2}


def test_a_gain_on_every_seed_is_told_from_noise_and_noise_is_not():
    rng = np.random.default_rng(3)
    a = {s: _sim_row(s, int(rng.integers(2, 6))) for s in range(12)}
    better = {s: _sim_row(s, a[s]["found"] + 2) for s in range(12)}
    noisy = {s: _sim_row(s, a[s]["found"] + int(rng.integers(-2, 3))) for s in range(12)}
    (gain, *_), (swing, *_) = paired(a, better, SIM_FIGURES), paired(a, noisy, SIM_FIGURES)
    assert gain["figure"] == "found of moved" and abs(gain["b_minus_a"] - 0.2) < 1e-12
    assert gain["ci95"][0] > 0.0 and gain["seeds_higher"] == 12 and gain["seeds_lower"] == 0
    assert swing["ci95"][0] < 0.0 < swing["ci95"][1]


def test_oracle_rows_are_summed_per_seed_over_the_pieces_seen_at_both_places():
    rows = [{"seed": 1, "observed": "both", "outcome": "found"},
            {"seed": 1, "observed": "both", "outcome": "twin"},
            {"seed": 1, "observed": "old", "outcome": "found"},  # not seen at both: left out
            {"seed": 2, "observed": "both", "outcome": "wrong"}]
    by_seed, figures = per_seed({"rows": rows})
    assert figures is ORACLE_FIGURES
    assert by_seed[1] == {"found": 1, "found_or_twin": 2, "wrong": 0, "missed": 0, "both": 2}
    assert by_seed[2]["wrong"] == 1 and by_seed[2]["both"] == 1
    (found, *_) = paired(by_seed, by_seed, figures)
    assert found["b_minus_a"] == 0.0 and found["ci95"] == [0.0, 0.0]
