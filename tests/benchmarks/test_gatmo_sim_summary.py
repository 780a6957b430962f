"""The totals of the hall benchmark (benchmarks.bench_gatmo_sim.summarize) over seed rows as
one_seed returns them, per-seed lists included."""

import math

import pytest

from benchmarks.bench_gatmo_sim import summarize
from gatmo.pipeline.evaluate import CENSUS_KEYS


def _row(seed, gatmo_ate_m, static_ate_m, found, moved, stale_ids):
    row = {"seed": seed, "static_ate_m": static_ate_m, "gatmo_ate_m": gatmo_ate_m,
           "before_ate_m": math.nan, "static_lost": 0.2, "gatmo_lost": 0.05,
           "moved": moved, "found": found, "absent_events": 3, "gone": 8, "gone_noticed": 4,
           "false_relocations": 1, "twin_relocations": 0, "false_absences": 0,
           **{f"last_{k}": 2 for k in CENSUS_KEYS}, "last_stale_ids": stale_ids,
           "gatmo_ms_per_scan": 20.0, "static_ms_per_scan": 2.0,
           "outcomes": [{"label": "box", "outcome": "found", "observed": "both"}] * found
           + [{"label": "desk", "outcome": "missed", "observed": "old"}] * (moved - found)}
    return row


def test_totals_over_seeds_leave_the_per_seed_lists_to_the_rows():
    rows = [_row(1, 0.1, 1.0, 3, 10, [4, 7]), _row(2, 0.3, 0.2, 1, 10, [])]
    t = summarize(rows, preset="hall", runs=4, overrides=["gatmo.nudge=false"], before=False)
    assert t["seeds"] == 2 and t["gatmo_over_before_ate_median"] is None
    assert t["gatmo_over_static_ate_median"] == pytest.approx((0.1 + 1.5) / 2)
    assert t["seeds_gatmo_not_worse"] == 1
    assert t["found_over_moved"] == pytest.approx(0.2)
    assert t["false_relocations_per_run"] == pytest.approx(2 / 8)
    assert t["found_over_seen_both"] == 1.0 and t["seen_both_over_moved"] == pytest.approx(0.2)
    assert t["table_ii"] == {"box": {"found": 4, "twin": 0, "wrong": 0, "absent": 0, "missed": 0},
                             "desk": {"found": 0, "twin": 0, "wrong": 0, "absent": 0,
                                      "missed": 16}}
    assert "last_stale_ids" not in t["last_run_census_per_seed"]
