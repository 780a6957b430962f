"""Paired comparison of two benchmark runs over the same seeds (benchmarks.paired)."""

import numpy as np
import pytest

from benchmarks.paired import ORACLE_FIGURES, SIM_FIGURES, paired, per_seed, pooled


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


def _doc(draw, found):
    """A bench_gatmo_sim output with filter seed ``draw``: ``found`` per hall seed 0, 1, ..."""
    rows = [_sim_row(s, f) for s, f in enumerate(found)]
    return {"rows": rows, "total": {"overrides": [f"seed={draw}"] if draw else []}}


def test_filter_draws_pool_into_rows_per_seed_and_draw_resampled_by_whole_seeds():
    a, b, figures = pooled([(_doc(0, [2, 3]), _doc(0, [3, 3])),
                            (_doc(10, [2, 4]), _doc(10, [4, 4]))])
    assert sorted(a) == [(0, 0), (0, 10), (1, 0), (1, 10)] and figures is SIM_FIGURES
    found = paired(a, b, figures)[0]
    assert abs(found["b_minus_a"] - 3 / 40) < 1e-12  # 11 -> 14 found of 40 moved
    assert found["seeds_higher"] == 2 and found["seeds_lower"] == 0 and found["seeds"] == 4
    # one seed whose two draws differ by +1 and -1: resampling whole seeds always takes both
    # (B - A = 0 every time); resampling rows alone would give -0.1 to +0.1
    a, b, _ = pooled([(_doc(0, [2]), _doc(0, [3])), (_doc(10, [2]), _doc(10, [1]))])
    assert paired(a, b, figures)[0]["ci95"] == [0.0, 0.0]


def test_pairs_of_runs_with_different_filter_seeds_are_refused():
    with pytest.raises(ValueError, match="different filter seeds"):
        pooled([(_doc(0, [2]), _doc(0, [2])), (_doc(10, [2]), _doc(20, [2]))])
