"""``gatmo info``: a summary of any data file gatmo reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo.geometry import path_length_m


def _grid_summary(grid) -> dict:
    n = grid.cells.size
    return {
        "kind": "map",
        "size_cells": f"{grid.width} x {grid.height}",
        "resolution_m": grid.resolution_m,
        "origin": list(grid.origin_xytheta),
        "occupied_fraction": float(grid.occupied.sum() / n),
        "free_fraction": float(grid.free.sum() / n),
        "unknown_fraction": float(grid.unknown.sum() / n),
    }


def _objects_summary(path: Path) -> dict:
    from gatmo.maps.object_io import load_objects

    om = load_objects(path)
    pieces = [o for o in om.objects if not o.structure]
    out = {"kind": "object map", "runs": om.runs, "objects": len(pieces),
           "walls_and_structure": len(om.objects) - len(pieces)}
    for status, name in (("U", "unclassified"), ("M", "movable_placed"), ("A", "absent"),
                         ("Gamma", "seen_never_added")):
        out[name] = sum(o.status == status for o in pieces)
    out["moved_at_least_once"] = sum(o.moved_count > 0 for o in pieces)
    out["pose_history_entries"] = sum(len(o.history) for o in om.objects)
    return out


def summarize(path: str | Path, fmt: str | None = None) -> dict:
    """A dict describing a log, bag, map YAML, wean.dat, TUM, relations or objects.json
    file."""
    p = Path(path)
    name = p.name
    if name.endswith(".json"):
        return _objects_summary(p)
    if name.endswith((".yaml", ".yml")):
        from gatmo.maps.io import load_map

        return _grid_summary(load_map(p))
    if name.startswith("wean.dat"):
        from gatmo.datasets.wean import load_wean_map

        return _grid_summary(load_wean_map(p))
    if name.endswith(".tum"):
        from gatmo.datasets.tum import read_tum

        t, poses = read_tum(p)
        return {"kind": "trajectory", "poses": len(t),
                "duration_s": float(t[-1] - t[0]) if len(t) else 0.0,
                "path_m": path_length_m(poses)}
    if name.endswith(".relations"):
        from gatmo.datasets.relations import read_relations

        r = read_relations(p)
        dt = r.t2_s - r.t1_s
        return {"kind": "relations", "relations": len(r), "dt_min_s": float(dt.min()),
                "dt_max_s": float(dt.max())}
    from gatmo.datasets.open import open_log, sniff_format

    fmt = fmt or sniff_format(p)
    src = open_log(p, fmt=fmt, skip_bad=True)  # report bad records instead of stopping
    stamps, odom, beams, fov, max_range, gt = [], [], None, None, None, 0
    for s in src:
        stamps.append(s.stamp_s)
        odom.append(s.odom_pose_xytheta)
        gt += s.gt_pose_xytheta is not None
        if beams is None:
            beams = s.num_beams
            fov = float(np.degrees(s.angles_rad[-1] - s.angles_rad[0]))
            max_range = s.range_max_m
    out = {
        "kind": "log",
        "format": fmt,
        "scans": len(stamps),
        "beams": beams,
        "fov_deg": fov,
        "max_range_m": max_range,
        "duration_s": float(stamps[-1] - stamps[0]) if stamps else 0.0,
        "odom_path_m": path_length_m(np.array(odom)) if odom else 0.0,
        "has_ground_truth": gt > 0,
        "skipped": src.stats.skipped,
    }
    if src.stats.skipped_reasons:
        out["first_skipped"] = src.stats.skipped_reasons[:3]
    if fmt == "rosbag":
        out["topics"] = src.topics()
    return out
