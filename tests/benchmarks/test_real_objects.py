"""``bench_real_objects``: whether what GATMO found absent or relocated still stood where it
was, from scans at reference poses (a hand-made room)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_real_objects import absence_rows, relocation_rows
from gatmo.objects import GatmoConfig, ObjectMap
from tests.helpers import make_scan, room_grid

BOX = (5.0, 2.5, 5.5, 3.0)
MOVED = (5.0, 4.5, 5.5, 5.0)


def _scene(world_after):
    """(object map of a room with BOX, the box, scans: 10 of the room with the box, then 10
    of ``world_after``, stamps 0-1.9 s; the robot 3 m off, looking at both places)."""
    omap = ObjectMap.from_grid(room_grid(10, 7, 0.05, boxes=[BOX]), GatmoConfig())
    box = next(o for o in omap.objects if not o.structure)
    before = room_grid(10, 7, 0.05, boxes=[BOX])
    scans = [make_scan(before if i < 10 else world_after, (2.0, 3.5 + 0.02 * i, 0.0),
                       n_beams=361, max_range_m=8.0, stamp_s=0.1 * i) for i in range(20)]
    return omap, box, scans, np.array([s.stamp_s for s in scans])


@pytest.mark.parametrize("after, stood", [((BOX,), True), ((), False)])
def test_an_absence_is_false_when_the_thing_stood_there_after(after, stood):
    omap, box, scans, stamps = _scene(room_grid(10, 7, 0.05, boxes=list(after)))
    events = [{"kind": "absent", "object_id": box.id, "stamp_s": 0.95, "run": 1,
               "pose_old": box.pose_xytheta.tolist()}]
    (row,) = absence_rows(omap, events, scans, stamps)
    assert row["before"]["there"] >= 5 and row["before"]["gone"] == 0
    assert row["stood_after"] == stood
    assert (row["after"]["gone"] >= 5) == (not stood)


def test_an_absence_undone_by_a_relocation_in_the_same_step_is_left_to_the_relocations():
    omap, box, scans, stamps = _scene(room_grid(10, 7, 0.05, boxes=[MOVED]))
    old, new = box.pose_xytheta.tolist(), (box.pose_xytheta + [0.0, 2.0, 0.0]).tolist()
    events = [{"kind": "absent", "object_id": box.id, "stamp_s": 0.95, "run": 1,
               "pose_old": old},
              {"kind": "relocated", "object_id": box.id, "stamp_s": 0.95, "run": 1,
               "pose_old": old, "pose_new": new}]
    assert absence_rows(omap, events, scans, stamps) == []
    (row,) = relocation_rows(omap, events, scans, stamps)
    assert row["moved_m"] == 2.0 and not row["stood_at_old"]
    assert row["new_after"]["there"] >= 5 and row["old_after"]["gone"] >= 5
