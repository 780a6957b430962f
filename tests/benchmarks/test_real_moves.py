"""``bench_real_moves``: its summary of trials and its record of why a piece was not found."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from benchmarks.bench_real_moves import _events_of, _refused_near, _totals


def _move(outcome, absent, relocated):
    return {"outcome": outcome, "absent_scan": absent, "relocated_scan": relocated}


def test_totals_count_outcomes_and_subtract_the_unedited_maps_false_events():
    trials = [
        {"moves": 2, "found": 1, "elsewhere": 0, "absent": 1, "unchanged": 0, "untied": 0,
         "false_absent": 3, "false_relocated": 1, "added": 2, "added_on_moved": 1,
         "per_move": [_move("found", 10, 14), _move("absent", 20, None)],
         "static_ate_rmse_m": 0.3, "gatmo_ate_rmse_m": 0.1},
        {"moves": 2, "found": 1, "elsewhere": 1, "absent": 0, "unchanged": 0, "untied": 0,
         "false_absent": 1, "false_relocated": 1, "added": 0, "added_on_moved": 0,
         "per_move": [_move("found", 5, 11), _move("elsewhere", None, 30)],
         "static_ate_rmse_m": 0.5, "gatmo_ate_rmse_m": 0.2}]
    res = {"trials": trials, "before": {"false_absent": 1, "false_relocated": 0, "added": 1},
           "before_ate_rmse_m": 0.09}
    t = _totals(res)
    assert t["moves"] == 4 and t["found"] == 2 and t["elsewhere"] == 1 and t["absent"] == 1
    assert t["found_fraction"] == pytest.approx(0.5)
    assert t["noticed_gone_fraction"] == pytest.approx(0.75)  # 3 of 4 had an absent event
    assert t["false_absent_per_trial_over_unedited"] == pytest.approx(2 - 1)
    assert t["false_relocated_per_trial_over_unedited"] == pytest.approx(1 - 0)
    assert t["median_scans_absent_to_relocated"] == pytest.approx(5.0)  # 4 and 6
    assert t["static_ate_rmse_m_mean"] == pytest.approx(0.4)
    assert t["gatmo_ate_rmse_m_mean"] == pytest.approx(0.15)


def test_refusals_are_counted_near_the_true_place_only():
    trace = SimpleNamespace(refused_at={
        (7, "larger"): {(1.0, 1.0), (1.3, 1.2), (5.0, 5.0)},
        (7, "score"): {(9.0, 9.0)},
        (8, "larger"): {(1.0, 1.0)}})
    assert _refused_near(trace, 7, [1.1, 1.0, 0.0]) == {"larger": 2}
    assert _refused_near(trace, 9, [1.1, 1.0, 0.0]) == {}


def test_events_keep_each_kinds_first_scan_for_the_objects_asked(tmp_path):
    lines = [{"object_id": 3, "kind": "absent", "scan_index": 40},
             {"object_id": 3, "kind": "relocated", "scan_index": 52},
             {"object_id": 3, "kind": "absent", "scan_index": 90},
             {"object_id": 4, "kind": "absent", "scan_index": 10}]
    (tmp_path / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in lines))
    assert _events_of(tmp_path, [3, 5]) == {3: {"absent": 40, "relocated": 52}, 5: {}}
    assert _events_of(tmp_path / "missing", [3]) == {3: {}}


def test_totals_count_the_pieces_put_elsewhere_in_the_scan_they_were_noticed_gone():
    # (40, 40): the absence's own match took it; (50, 61): a track's chair later; (None, 30):
    # relocated without being noticed gone first
    trial = {"moves": 3, "found": 0, "elsewhere": 3, "absent": 0, "unchanged": 0, "untied": 0,
             "false_absent": 0, "false_relocated": 0, "added": 0, "added_on_moved": 0,
             "per_move": [_move("elsewhere", 40, 40), _move("elsewhere", 50, 61),
                          _move("elsewhere", None, 30)],
             "static_ate_rmse_m": 0.3, "gatmo_ate_rmse_m": 0.1}
    res = {"trials": [trial], "before": {"false_absent": 0, "false_relocated": 0, "added": 0},
           "before_ate_rmse_m": 0.09}
    t = _totals(res)
    assert t["elsewhere"] == 3 and t["elsewhere_at_absence"] == 1
