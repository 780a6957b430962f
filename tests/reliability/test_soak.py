"""Short soak: consecutive runs with the object map carried over stay bounded."""

from __future__ import annotations

from benchmarks.bench_soak import soak


def test_short_soak_keeps_objects_memory_and_time_bounded(tmp_path):
    rows = soak(runs=3, seconds=10.0, seed=11, tmp=tmp_path)
    assert [r["run"] for r in rows] == [1, 2, 3]
    first = rows[0]
    for r in rows:
        # no duplicates piling up: never more objects than pieces + static structure + a few
        assert r["objects_total"] <= first["objects_total"] + 2 * r["run"]
        assert r["peak_rss_mb"] < first["peak_rss_mb"] + 100
        assert 0.0 <= r["map_correct_fraction"] <= 1.0 and r["found"] <= r["moved"]
    # relocations scored per run (time per scan is the benchmark's business, not a test's)
    assert sum(r["false_relocations"] for r in rows) <= 1
