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
        # every object placed is counted once by what it stands on, every piece at most once
        assert r["on_piece"] + r["duplicate"] + r["stale"] + r["fixed"] == r["objects_placed"]
        assert r["pieces"] == r["pieces_in_world"]
        assert r["on_piece"] + r["pieces_unmapped"] == r["pieces"]
        # the unmapped pieces the run saw are some of them; GATMO took some of the scans
        assert 0 <= r["pieces_unmapped_seen"] <= r["pieces_unmapped"]
        assert 0 < r["gatmo_scans"] <= 100  # 10 s at 10 Hz
        # no piece carries two objects (0 measured); objects left where a piece stood (stale:
        # 4, 7, 11 over these 10 s runs, in which the robot sees little) are reported, not bounded
        assert r["duplicate"] <= 1
        # every object stale at the run's start is accounted for once (why it stays or goes)
        assert r["stale_at_start"] == (r["stale_absent"] + r["stale_unseen"]
                                       + r["stale_no_evidence"] + r["stale_partial"])
        assert 0 < r["seen_through_scans"] <= 100  # 10 s at 10 Hz
        # withheld (unseen for withhold_unseen_runs, 2 in the simulated configuration) is a
        # part of stale, and after one run no object can have gone unseen for two
        assert 0 <= r["stale_withheld"] <= r["stale"]
        if r["run"] == 1:
            assert r["stale_withheld"] == 0
    # relocations scored per run (time per scan is the benchmark's business, not a test's)
    assert sum(r["false_relocations"] for r in rows) <= 1


def test_soak_summary_averages_the_maps_census_over_each_window_of_runs():
    from benchmarks.bench_soak import summary
    from gatmo.pipeline.evaluate import CENSUS_KEYS

    def row(run, duplicate, stale):
        r = dict.fromkeys(("median_err_m", "static_median_err_m", "lost_fraction",
                           "static_lost_fraction", "map_correct_fraction", "ms_per_scan",
                           "ms_per_scan_max", "peak_rss_mb"), 0.1)
        r.update(dict.fromkeys(("found", "moved", "false_relocations", "objects_placed",
                                "pieces_in_world", "objects_total", *CENSUS_KEYS), 1))
        r.update(run=run, duplicate=duplicate, stale=stale)
        return r

    # one chain's swing: the last run's 3 duplicates are one draw of 0-3
    rows = [row(1, 0, 2), row(2, 1, 4), row(3, 0, 5), row(4, 3, 7)]
    for r, w in zip(rows, (0, 0, 2, 4), strict=True):
        r["stale_withheld"] = w
    s = summary(rows, first=2)
    assert s["runs 1-2"]["stale_withheld_mean"] == 0.0
    assert s["runs 3-4"]["stale_withheld_mean"] == 3.0
    assert s["runs 1-2"]["duplicate_mean"] == 0.5 and s["runs 1-2"]["stale_mean"] == 3.0
    assert s["runs 3-4"]["duplicate_mean"] == 1.5 and s["runs 3-4"]["stale_mean"] == 6.0
    assert s["duplicate"] == [0, 3] and s["stale"] == [2, 7]  # first and last run
