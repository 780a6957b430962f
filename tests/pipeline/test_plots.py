"""The pictures' choices that can be checked without looking at them."""

from __future__ import annotations

from gatmo.pipeline.plots import shown_moves


def test_a_withdrawn_relocation_gets_no_arrow_and_the_one_after_it_does():
    ev = [
        {"kind": "relocated", "object_id": 3, "pose_old": [0, 0, 0], "pose_new": [1, 1, 0]},
        {"kind": "absent", "object_id": 2, "pose_old": [5, 5, 0], "pose_new": None},
        {"kind": "withdrawn", "object_id": 3, "pose_old": [1, 1, 0], "pose_new": None},
        {"kind": "relocated", "object_id": 2, "pose_old": [5, 5, 0], "pose_new": [1, 1, 0]},
        {"kind": "added", "object_id": 9, "pose_old": None, "pose_new": [4, 4, 0]},
        {"kind": "withdrawn", "object_id": 9, "pose_old": [4, 4, 0], "pose_new": None},
    ]
    assert [(e["kind"], e["object_id"]) for e in shown_moves(ev)] == [
        ("relocated", 2), ("added", 9)]
