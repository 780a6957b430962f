"""The pictures' choices that can be checked without looking at them."""

from __future__ import annotations

from gatmo.pipeline.plots import shown_moves


def test_the_map_picture_draws_relocations_and_additions_with_a_new_pose_in_order():
    ev = [
        {"kind": "relocated", "object_id": 3, "pose_old": [0, 0, 0], "pose_new": [1, 1, 0]},
        {"kind": "absent", "object_id": 2, "pose_old": [5, 5, 0], "pose_new": None},
        {"kind": "movable", "object_id": 4, "pose_old": [2, 2, 0], "pose_new": [2, 2, 0]},
        {"kind": "relocated", "object_id": 2, "pose_old": [5, 5, 0], "pose_new": [1, 2, 0]},
        {"kind": "added", "object_id": 9, "pose_old": None, "pose_new": [4, 4, 0]},
        {"kind": "added", "object_id": 10, "pose_old": None, "pose_new": None},
    ]
    assert [(e["kind"], e["object_id"]) for e in shown_moves(ev)] == [
        ("relocated", 3), ("relocated", 2), ("added", 9)]
