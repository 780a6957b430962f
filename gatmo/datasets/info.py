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


def _scenario_summary(path: Path) -> dict:
    from gatmo.datasets.sim import load_scenario
    from gatmo.errors import FormatError

    def dicts(x) -> bool:
        return isinstance(x, list) and all(isinstance(v, dict) for v in x)

    doc = load_scenario(path)
    runs = doc["runs"]
    ok = (dicts(runs) and isinstance(doc["map_objects"], list)
          and all(dicts(r.get("changes", [])) and isinstance(r.get("people", []), list)
                  for r in runs))
    if not ok:
        raise FormatError("runs must be a list of runs with lists of changes and people, "
                          "map_objects a list", file=path, field="runs")
    changes: dict[str, list[int]] = {}
    for k, run in enumerate(runs):
        for ch in run.get("changes", []):
            changes.setdefault(ch.get("kind", "?"), [0] * len(runs))[k] += 1
    return {"kind": "scenario", "preset": doc.get("preset"), "seed": doc.get("seed"),
            "runs": len(runs), "map_objects": len(doc["map_objects"]),
            "scans_per_run": [r.get("scans") for r in runs],
            **{f"{kind}_per_run": n for kind, n in sorted(changes.items())},
            "people_per_run": [len(r.get("people", [])) for r in runs]}


def _json_summary(path: Path) -> dict:
    """An objects.json, a scenario.json or a calibrate report, told apart by their ``format``
    field."""
    import json

    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        doc = None  # load_objects words the error
    if isinstance(doc, dict) and doc.get("format") == "gatmo-scenario":
        return _scenario_summary(path)
    if isinstance(doc, dict) and doc.get("format") == "gatmo-calibration":
        # gatmo calibrate --report: what was fitted, to what, and how well
        keys = ("log", "reference", "model", "update_min_d_m", "update_min_a_rad", "steps",
                "rejected", "current_alphas", "alphas", "z_std_current", "z_std_fitted",
                "z_std_holdout", "trans_scale", "rot_scale", "warnings")
        return {"kind": "odometry calibration"} | {k: doc[k] for k in keys if k in doc}
    return _objects_summary(path)


def _yaml_summary(path: Path) -> dict:
    """A map_server map YAML, a gatmo stack configuration (``gatmo config dump stack``), a map
    build configuration (``gatmo config dump mapping``, ``MAP.build.yaml``) or a ROS AMCL
    parameter file, told apart by their top-level keys."""
    from gatmo.config import read_yaml

    data, _ = read_yaml(path)
    if isinstance(data, dict) and "image" not in data:
        from gatmo.pipeline.config import StackConfig

        # Nav2 nests its parameters under `<node>: ros__parameters:`; ROS 1 is flat
        nav2 = any(isinstance(v, dict) and "ros__parameters" in v for v in data.values())
        from gatmo.pipeline.config import MapBuildConfig

        if data and not nav2 and set(data) <= set(MapBuildConfig.model_fields) \
                and set(data) & {"graph", "render"}:
            from gatmo.pipeline.config import load_map_build_config, summarize_map_build_config

            return summarize_map_build_config(load_map_build_config(path))
        if data and not nav2 and set(data) <= set(StackConfig.model_fields):
            from gatmo.pipeline.config import load_stack_config, summarize_stack_config

            return summarize_stack_config(load_stack_config(path))
        if nav2 or any(str(k).startswith(("laser_", "odom_")) for k in data):
            from gatmo.localization.params import load_amcl_yaml

            a = load_amcl_yaml(path)
            return {"kind": "AMCL parameters", "laser_model": a.laser_model,
                    "sigma_hit_m": a.sigma_hit_m, "z_hit / z_rand": [a.z_hit, a.z_rand],
                    "alphas": [a.alpha1, a.alpha2, a.alpha3, a.alpha4],
                    "particles": [a.min_particles, a.max_particles],
                    "update_min_d_m / _a_rad": [a.update_min_d_m, a.update_min_a_rad],
                    # where localize / run / compare start without --initial-pose
                    "initial_pose_xytheta": (list(a.initial_pose_xytheta)
                                             if a.initial_pose_xytheta is not None
                                             else "none (the log's ground truth, else global)")}
    from gatmo.datasets.open import open_map

    return _grid_summary(open_map(path))


def _odometry_glitches(odom_xytheta: np.ndarray) -> dict:
    """What the localizer will see of the wheels' glitches, from the odometry poses (N, 3):
    ``odom_jumps``, steps between two scans over its default ``odom_jump_m`` /
    ``odom_jump_rad`` (it holds both "moved" and "did not move" there), and
    ``odom_catch_ups``, steps over 3x the median moving step right after the odometry stood
    exactly still (a stall: MIT CSAIL's wheels stall in turns and catch up in one step)."""
    from gatmo.geometry import relative
    from gatmo.localization.config import AmclConfig

    if len(odom_xytheta) < 2:
        return {"odom_jumps": 0, "odom_catch_ups": 0}
    f = AmclConfig.model_fields
    d = relative(odom_xytheta[:-1], odom_xytheta[1:])  # (N - 1, 3): relative broadcasts
    trans, turn = np.hypot(d[:, 0], d[:, 1]), np.abs(d[:, 2])
    jumps = (trans > f["odom_jump_m"].default) | (turn > f["odom_jump_rad"].default)
    still = ~np.any(np.abs(d) > 1e-9, axis=1)
    size = trans + 0.3 * turn  # a turn of 1 rad weighs as 0.3 m of travel
    if still.all():
        return {"odom_jumps": int(jumps.sum()), "odom_catch_ups": 0}
    big = size > 3.0 * np.median(size[~still])
    catch_ups = big[1:] & still[:-1]
    return {"odom_jumps": int(jumps.sum()), "odom_catch_ups": int(catch_ups.sum())}


def summarize(path: str | Path, fmt: str | None = None) -> dict:
    """A dict describing a log, bag, map YAML, wean.dat, TUM, relations, objects.json or
    scenario.json file, a gatmo stack configuration or a ROS AMCL parameter file."""
    p = Path(path)
    name = p.name
    if name.endswith(".json"):
        return _json_summary(p)
    if name.endswith((".yaml", ".yml")):
        return _yaml_summary(p)
    from gatmo.datasets.wean import is_wean_map, load_wean_map

    if is_wean_map(p):
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
    # report bad records instead of stopping; a laser-only bag is described, not refused
    src = open_log(p, fmt=fmt, skip_bad=True, odometry_optional=True)
    stamps, odom, beams, fov, max_range, gt = [], [], None, None, None, 0
    for s in src:
        stamps.append(s.stamp_s)
        if s.odom_pose_xytheta is not None:
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
        "has_odometry": bool(odom),
        **_odometry_glitches(np.array(odom)),
        "has_ground_truth": gt > 0,
        "skipped": src.stats.skipped,
    }
    if src.stats.skipped_reasons:
        out["first_skipped"] = src.stats.skipped_reasons[:3]
    if fmt == "rosbag":
        out["topics"] = src.topics()
    return out
