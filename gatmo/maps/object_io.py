"""``objects.json``: the object map across runs.

Schema (version 1)::

    {"format": "gatmo-objects", "version": 1, "resolution_m": 0.05, "next_id": 23,
     "runs": 4,     # the number of the last run laid on it (optional; else the largest
                    # run in any history); a run started from this file is run 5
     "base_map": {...},                      # the static map the objects were cut from
     "objects": [{"id": 3, "label": "lounge_chair", "status": "M",
                  "pose": [x, y, yaw],       # p_i: object frame -> map frame
                  "base_pose": [x, y, yaw] | null,   # where the static map draws it
                  "structure": false,
                  "shape_cells_xy": [[x, y], ...],   # I_i, object frame [m]
                  "edge_xy": [[x, y], ...],          # E_i, object frame [m]
                  "seen_count": 120, "moved_count": 2,
                  "unseen_runs": 0,  # runs since seen standing (optional, 0)
                  "history": [{"run": 1, "stamp_s": 12.3, "pose": [...], "status": "A"}]}]}
                  # every pose in history with status U or M, and base_pose, is a prior
                  # for matching (gatmo.prior_earlier_poses)

Written atomically (temp file, fsync, rename): an interrupted run never leaves half a file.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_text
from gatmo.errors import FormatError
from gatmo.objects.objectmap import STATUSES, MapObject, ObjectMap

FORMAT = "gatmo-objects"
VERSION = 1


def _f(v) -> float:
    return round(float(v), 6)


def save_objects(path: str | Path, object_map: ObjectMap, *, base_grid_meta: dict | None = None):
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "resolution_m": object_map.resolution_m,
        "next_id": object_map.next_id,
        "runs": int(object_map.runs),
        "base_map": base_grid_meta or {},
        "objects": [
            {
                "id": o.id,
                "label": o.label,
                "status": o.status,
                "pose": [_f(v) for v in o.pose_xytheta],
                "base_pose": None if o.base_pose_xytheta is None
                else [_f(v) for v in o.base_pose_xytheta],
                "structure": bool(o.structure),
                "shape_cells_xy": [[_f(x), _f(y)] for x, y in o.shape_xy],
                "edge_xy": [[_f(x), _f(y)] for x, y in o.edge_xy],
                "seen_count": int(o.seen_count),
                "moved_count": int(o.moved_count),
                "unseen_runs": int(o.unseen_runs),
                "history": o.history,
            }
            for o in object_map.objects
        ],
    }
    return atomic_write_text(path, json.dumps(doc, separators=(",", ":")))


def _check_base_map(meta, grid, path: Path) -> None:
    """Refuse an object map made on another map than ``grid``: ``meta`` is the file's
    ``base_map`` (resolution_m, origin_xytheta, shape [rows, columns]); a file without it (or
    with an empty one) is taken as it is."""
    if not meta:
        return
    if not isinstance(meta, dict):
        raise FormatError("base_map must be an object", file=path, field="base_map")
    here = {"resolution_m": grid.resolution_m, "origin_xytheta": list(grid.origin_xytheta),
            "shape": [grid.height, grid.width]}
    for key, value in here.items():
        if key not in meta:
            continue
        try:
            same = np.allclose(np.asarray(meta[key], dtype=float), value, rtol=0, atol=1e-6)
        except (TypeError, ValueError):
            raise FormatError(f"bad value {meta[key]!r}", file=path,
                              field=f"base_map.{key}") from None
        if not same:
            raise FormatError(f"made on another map: {key} {meta[key]} there, {value} in the "
                              "map given", file=path, field=f"base_map.{key}")


def _pose(v, path, where) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float) if isinstance(v, list) else None
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise FormatError(f"expected [x, y, yaw], got {v!r}", file=path, field=where)
    return a


def _count(v, path, where) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise FormatError(f"expected a count (an integer >= 0), got {v!r}", file=path,
                          field=where)
    return v


def _points(v, path, where) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float).reshape(-1, 2)
    except (TypeError, ValueError):
        raise FormatError("expected a list of [x, y]", file=path, field=where) from None
    if not np.all(np.isfinite(a)):
        raise FormatError("non-finite coordinate", file=path, field=where)
    return a


def load_objects(path: str | Path, grid=None) -> ObjectMap:
    """Read objects.json; any schema problem is a FormatError naming the JSON path. With
    ``grid`` (an OccupancyGrid, the static map a run is given), a file whose ``base_map`` records
    another map (resolution, origin or size) is refused: its objects' poses and cells are in
    that map's frame."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror}", file=path) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise FormatError(f"not JSON: {exc}", file=path) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise FormatError(f"not a {FORMAT} file", file=path, field="format")
    if doc.get("version") != VERSION:
        raise FormatError(f"unsupported version {doc.get('version')!r} (this gatmo reads "
                          f"{VERSION})", file=path, field="version")
    try:
        res = float(doc["resolution_m"])
        next_id = int(doc["next_id"])
        items = doc["objects"]
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"missing or bad top-level field: {exc}", file=path) from None
    if not isinstance(items, list) or not (res > 0):
        raise FormatError("bad objects list or resolution", file=path, field="objects")
    if grid is not None:
        _check_base_map(doc.get("base_map"), grid, path)
    objects, ids = [], set()
    for i, d in enumerate(items):
        where = f"objects[{i}]"
        if not isinstance(d, dict):
            raise FormatError("expected an object", file=path, field=where)
        try:
            oid = d["id"]
            if not isinstance(oid, int) or isinstance(oid, bool):
                raise FormatError(f"id must be an integer, got {oid!r}", file=path,
                                  field=f"{where}.id")
            if oid in ids:
                raise FormatError(f"id {oid} used twice", file=path, field=f"{where}.id")
            ids.add(oid)
            status = d["status"]
            if status not in STATUSES:
                raise FormatError(f"status must be one of {STATUSES}, got {status!r}",
                                  file=path, field=f"{where}.status")
            label = d.get("label")
            if label is not None and not isinstance(label, str):
                raise FormatError("label must be a string or null", file=path,
                                  field=f"{where}.label")
            bp = d.get("base_pose")
            hist = d.get("history", [])
            if not isinstance(hist, list):
                raise FormatError("history must be a list", file=path, field=f"{where}.history")
            for j, h in enumerate(hist):  # earlier poses are priors for matching: checked
                hw = f"{where}.history[{j}]"
                if not isinstance(h, dict) or h.get("status") not in STATUSES:
                    raise FormatError(f"history entries need a status in {STATUSES}",
                                      file=path, field=hw)
                h["pose"] = [float(v) for v in _pose(h.get("pose"), path, f"{hw}.pose")]
                if "run" in h:
                    _count(h["run"], path, f"{hw}.run")
            o = MapObject(
                id=oid, label=label, status=status,
                pose_xytheta=_pose(d["pose"], path, f"{where}.pose"),
                shape_xy=_points(d["shape_cells_xy"], path, f"{where}.shape_cells_xy"),
                edge_xy=_points(d.get("edge_xy", []), path, f"{where}.edge_xy"),
                structure=bool(d.get("structure", False)),
                base_pose_xytheta=None if bp is None else _pose(bp, path, f"{where}.base_pose"),
                resolution_m=res,
                seen_count=_count(d.get("seen_count", 0), path, f"{where}.seen_count"),
                moved_count=_count(d.get("moved_count", 0), path, f"{where}.moved_count"),
                unseen_runs=_count(d.get("unseen_runs", 0), path, f"{where}.unseen_runs"),
                history=hist,
            )
        except KeyError as exc:
            raise FormatError(f"missing field {exc}", file=path, field=where) from None
        except (TypeError, ValueError) as exc:
            raise FormatError(f"bad value: {exc}", file=path, field=where) from None
        objects.append(o)
    if ids and next_id <= max(ids):
        next_id = max(ids) + 1
    # files written before "runs": the largest run in any history
    runs = max((h["run"] for o in objects for h in o.history if "run" in h), default=0)
    if "runs" in doc:
        runs = max(runs, _count(doc["runs"], path, "runs"))
    return ObjectMap(objects, res, next_id, runs)
