"""Scoring GATMO's object map against a simulated scenario's truth (scenario.json).

Map objects are tied to the scenario's pieces once, by footprint overlap in the static map
(layout L0): that gives each object its label (as a user labelling the map would) and its true
pose in every later layout. An object is *correctly placed* when its footprint at the
estimated pose lies on the piece's true footprint (mean distance < 0.1 m, centre < 0.15 m):
footprints, not yaw, so symmetric pieces are not penalised for an equivalent yaw.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from gatmo.geometry import compose, inverse, points_to_beams, transform_points


def _piece_points(piece: dict, res: float) -> np.ndarray:
    """Filled footprint points (K, 2) of a scenario piece in its own frame."""
    kind = piece["shape"]["kind"]
    dims = piece["shape"]["dims_m"]
    if kind == "circle":
        r = dims[0]
        xs = np.arange(-r, r + 1e-9, res / 2)
        gx, gy = np.meshgrid(xs, xs)
        pts = np.stack([gx.ravel(), gy.ravel()], 1)
        return pts[np.hypot(pts[:, 0], pts[:, 1]) <= r]
    lx, ly = dims[0], dims[1]
    gx, gy = np.meshgrid(np.arange(-lx / 2, lx / 2 + 1e-9, res / 2),
                         np.arange(-ly / 2, ly / 2 + 1e-9, res / 2))
    return np.stack([gx.ravel(), gy.ravel()], 1)


def tie_objects(object_map, scenario: dict) -> dict[int, int]:
    """object id -> piece id by footprint overlap in layout L0; sets the objects' labels."""
    res = scenario.get("resolution_m", 0.05)
    ties: dict[int, int] = {}
    pieces = scenario["map_objects"]
    trees = [(p, cKDTree(transform_points(np.array(p["pose"]), _piece_points(p, res))))
             for p in pieces]
    for o in object_map.objects:
        if o.structure or o.base_pose_xytheta is None:
            continue
        pts = o.cells_world(o.base_pose_xytheta)
        best, best_n = None, 0
        for p, tree in trees:
            d, _ = tree.query(pts, distance_upper_bound=res)
            n = int(np.isfinite(d).sum())
            if n > best_n:
                best, best_n = p, n
        if best is not None and best_n >= 0.5 * len(pts):
            ties[o.id] = best["id"]
            if o.label is None:
                o.label = best["label"]
    return ties


def true_pose_of(piece_id: int, layout: list[dict]) -> np.ndarray | None:
    for p in layout:
        if p["id"] == piece_id:
            return np.array(p["pose"], dtype=float)
    return None


def placement_error(o, expected_pose: np.ndarray,
                    pose_xytheta: np.ndarray | None = None) -> tuple[float, float]:
    """(mean footprint distance, centre distance) [m] of the object at ``pose_xytheta``
    (default its current pose) vs its expected pose."""
    est = o.cells_world(pose_xytheta)
    ref = o.cells_world(expected_pose)
    d, _ = cKDTree(ref).query(est)
    return float(np.mean(d)), float(np.hypot(*(est.mean(0) - ref.mean(0))))


def score_run(object_map, ties: dict[int, int], scenario: dict, run: int,
              events: list[dict]) -> dict:
    """Object figures after run ``run`` (1-based).

    moved: tied pieces that moved in this run (moved/shifted); found: those whose object ends
    the run correctly placed with its id; absent_recall: moved or removed tied pieces whose
    object was taken off its old place (absent or relocated); false_relocations: relocation
    events this run that left an object in the wrong place, and twin_relocations those that
    put it at the true pose of an identical piece instead (the map right, the identity
    swapped; counted among false_relocations until 2026-11-24); false_relocations_carried:
    of the false ones, those of an object that stood for no piece of its own shape (its own
    or an identical one, in this layout or the run before's) before the event: an earlier
    error carried on (an object put on another piece following that piece), not a new one;
    twin_relocations_carried: of the twin swaps, those of an object that did not stand on its
    own piece before the event (in this layout or the run before's): a swap made earlier,
    carried on as the twin piece moves (the map stays right).
    """
    r = scenario["runs"][run - 1]
    layout0 = scenario["map_objects"]
    layout = r["objects"]
    changed = {c["id"]: c["kind"] for c in r["changes"]}
    by_id = object_map.by_id
    piece_to_obj = {v: k for k, v in ties.items()}
    moved = [pid for pid, kind in changed.items() if kind in ("moved", "shifted")
             and pid in piece_to_obj]
    found = 0
    errors = []
    for pid in moved:
        o = by_id[piece_to_obj[pid]]
        exp = expected_pose(o, pid, layout0, layout)
        if exp is None:
            continue
        mean_d, centre_d = placement_error(o, exp)
        if o.status in ("M", "U") and mean_d < 0.1 and centre_d < 0.15:
            found += 1
            errors.append(centre_d)
    gone = [pid for pid, kind in changed.items() if kind in ("moved", "shifted", "removed")
            and pid in piece_to_obj]
    off = sum(1 for pid in gone if by_id[piece_to_obj[pid]].status == "A"
              or any(e.get("object_id") == piece_to_obj[pid] and e.get("kind") == "relocated"
                     for e in events))
    false_reloc = twin_reloc = carried = twin_carried = 0
    layout_before = scenario["runs"][run - 2]["objects"] if run > 1 else layout0
    for e in events:
        if e.get("kind") != "relocated" or e.get("object_id") not in ties:
            continue
        o = by_id[e["object_id"]]
        placed = _placed_as(o, ties[o.id], layout0, layout, np.asarray(e["pose_new"], float))
        before = ([_placed_as(o, ties[o.id], layout0, lay, np.asarray(e["pose_old"], float))
                   for lay in (layout_before, layout)] if e.get("pose_old") is not None
                  else None)
        if placed == "twin":
            twin_reloc += 1  # the map is right, an identical piece's identity swapped
            # it stood on no piece of its own before, or on a twin: a swap made earlier
            twin_carried += int(before is not None and "right" not in before)
        if placed is not None:
            continue
        false_reloc += 1
        if before is not None and not any(before):
            carried += 1  # it stood for no piece of its own shape before: an earlier error
    false_abs = 0
    for e in events:
        if e.get("kind") != "absent" or e.get("object_id") not in ties:
            continue
        o = by_id[e["object_id"]]
        exp = expected_pose(o, ties[o.id], layout0, layout)
        if exp is not None and e.get("pose_old") is not None:
            d, _ = cKDTree(o.cells_world(exp)).query(o.cells_world(np.asarray(e["pose_old"])))
            false_abs += int(np.mean(d) < 0.1)  # the piece was still where the map had it
    correct = total = 0
    for oid, pid in ties.items():
        o = by_id.get(oid)
        exp = expected_pose(o, pid, layout0, layout) if o is not None else None
        total += 1
        if exp is None:
            correct += int(o is not None and o.status in ("A", "Gamma"))  # removed: absent
            continue
        mean_d, _ = placement_error(o, exp)
        correct += int(o.status in ("U", "M") and mean_d < 0.1)
    return {
        "run": run, "moved": len(moved), "found": found,
        "found_fraction": found / len(moved) if moved else float("nan"),
        "placement_error_m": float(np.mean(errors)) if errors else float("nan"),
        "gone": len(gone), "absent_recall": off / len(gone) if gone else float("nan"),
        "false_relocations": false_reloc, "twin_relocations": twin_reloc,
        "false_relocations_carried": carried, "twin_relocations_carried": twin_carried,
        "false_absences": false_abs,
        "map_correct_fraction": correct / total if total else float("nan"),
    }


#: the counts :func:`map_census` returns
CENSUS_KEYS = ("pieces", "on_piece", "duplicate", "stale", "fixed", "pieces_unmapped")


def objects_on_pieces(object_map, scenario: dict, run: int,
                      near_m: float = 0.1) -> tuple[dict[int, list[int]], list]:
    """Which objects placed in the map (U, M; walls left out) stand on which piece of run
    ``run``'s layout (1-based): an object stands on a piece when at least half of its cells
    lie within ``near_m`` of the piece's footprint (the piece it covers most). Returns piece
    id -> the ids of the objects on it, and the objects on no piece."""
    res = scenario.get("resolution_m", 0.05)
    layout = scenario["runs"][run - 1]["objects"]
    trees = {p["id"]: cKDTree(transform_points(np.array(p["pose"], dtype=float),
                                               _piece_points(p, res)))
             for p in layout}
    on: dict[int, list[int]] = {}
    off = []
    for o in object_map.placed():
        if o.structure:
            continue
        pts = o.cells_world()
        best, best_n = None, 0.5 * len(pts)
        for pid, tree in trees.items():
            d, _ = tree.query(pts, distance_upper_bound=near_m)
            n = int(np.isfinite(d).sum())
            if n >= best_n:
                best, best_n = pid, n
        if best is not None:
            on.setdefault(best, []).append(o.id)
        else:
            off.append(o)
    return on, off


def map_census(object_map, ties: dict[int, int], scenario: dict, run: int,
               near_m: float = 0.1) -> dict:
    """What the objects placed in the map (U, M; walls left out) stand on after run ``run``
    (1-based), against the pieces of that run's layout (:func:`objects_on_pieces`). Per piece
    one object on it counts as ``on_piece`` and the rest as ``duplicate``
    (which object, its own or another's, is not asked); an object on no piece is ``fixed``
    when it is tied to none and its footprint is still within ``near_m`` (mean distance) of
    where the static map drew it (a column), else
    ``stale`` (left where a piece stood, or made of nothing). ``pieces_unmapped``: pieces no
    object stands on; ``stale_ids``: the stale objects' ids."""
    layout = scenario["runs"][run - 1]["objects"]
    on, off = objects_on_pieces(object_map, scenario, run, near_m)
    out = {"on_piece": 0, "duplicate": 0, "stale": 0, "fixed": 0}
    stale_ids = []
    for o in off:
        if (o.id not in ties and o.base_pose_xytheta is not None
                and placement_error(o, o.base_pose_xytheta)[0] < near_m):
            # a column or clutter of the static map, where the map has it: a match that
            # "restored" it a few cm (the chair seen there was its own surface) moves nothing
            out["fixed"] += 1
        else:
            out["stale"] += 1
            stale_ids.append(o.id)
    for ids in on.values():
        out["on_piece"] += 1
        out["duplicate"] += len(ids) - 1
    out["pieces"] = len(layout)
    out["pieces_unmapped"] = len(layout) - len(on)
    out["stale_ids"] = stale_ids
    return out


def seen_through(points_xy: np.ndarray, scans, max_range_m: float,
                 beyond_m: float = 0.2) -> tuple[np.ndarray, int]:
    """How well the true poses saw through ``points_xy`` (N, 2, map frame). Returns (N,) bool,
    whether any scan's beam passed the point by more than ``beyond_m`` within ``max_range_m``
    of the laser, and the number of scans that saw through at least 30 % of the points. Scans
    carry ``gt_pose_xytheta`` and ``laser_pose_xytheta``; the beam nearest each point's
    bearing stands for it."""
    union = np.zeros(len(points_xy), dtype=bool)
    n = 0
    for s in scans:
        lp = compose(np.asarray(s.gt_pose_xytheta, dtype=float), s.laser_pose_xytheta)
        r, b, i = points_to_beams(points_xy, lp, s.angles_rad)
        a = s.angles_rad
        inside = (b >= a[0]) & (b <= a[-1]) & (r <= max_range_m)
        rng = np.nan_to_num(s.ranges_m[i], nan=0.0, posinf=np.inf)  # inf: no return, passed
        through = inside & (rng > r + beyond_m)
        union |= through
        n += int(through.mean() >= 0.3) if len(through) else 0
    return union, n


def expected_pose(o, piece_id: int, layout0: list[dict], layout: list[dict]):
    """Where the object's frame must be if it followed its piece from L0 to this layout."""
    p0 = true_pose_of(piece_id, layout0)
    pk = true_pose_of(piece_id, layout)
    if p0 is None or pk is None or o.base_pose_xytheta is None:
        return None
    return compose(pk, compose(inverse(p0), o.base_pose_xytheta))


def twin_of(o, piece_id: int, layout0: list[dict], layout: list[dict],
            pose_xytheta: np.ndarray | None = None) -> int | None:
    """The id of another piece with the same label whose true pose in ``layout`` the object
    (tied to ``piece_id``) occupies at ``pose_xytheta`` (default: now), or None: identical
    pieces that swapped places look the same to a laser, so the map is right while the
    identity is not."""
    p0 = true_pose_of(piece_id, layout0)
    label = next((p["label"] for p in layout0 if p["id"] == piece_id), None)
    if p0 is None or o.base_pose_xytheta is None:
        return None
    rel = compose(inverse(p0), o.base_pose_xytheta)
    for p in layout:
        if p["id"] == piece_id or p["label"] != label:
            continue
        md, cd = placement_error(o, compose(np.array(p["pose"], dtype=float), rel),
                                 pose_xytheta)
        if md < 0.1 and cd < 0.15:
            return int(p["id"])
    return None


def _placed_as(o, piece_id: int, layout0: list[dict], layout: list[dict],
               pose_xytheta: np.ndarray) -> str | None:
    """Whose footprint in ``layout`` the object at ``pose_xytheta`` lies on (0.1 m mean
    distance): "right" (its piece's), "twin" (an identical piece's, :func:`twin_of`) or
    None."""
    exp = expected_pose(o, piece_id, layout0, layout)
    if exp is not None and placement_error(o, exp, pose_xytheta)[0] < 0.1:
        return "right"
    return "twin" if twin_of(o, piece_id, layout0, layout, pose_xytheta) is not None else None


def piece_outcome(o, piece_id: int, layout0: list[dict], layout: list[dict],
                  events: list[dict]) -> str:
    """What became of a moved piece's object by the end of a run (paper, Table II): "found"
    (placed at the piece's true pose: 0.1 m mean footprint, 0.15 m centre), "twin" (at an
    identical piece's true pose, :func:`twin_of`), "wrong" (relocated elsewhere), "absent"
    (noticed gone only) or "missed". ``events``: the run's events as dicts."""
    state = object_state(o, piece_id, layout0, layout)
    if state in ("right", "twin"):
        return "found" if state == "right" else "twin"
    kinds = {e["kind"] for e in events if e.get("object_id") == o.id}
    return "wrong" if "relocated" in kinds else "absent" if "absent" in kinds else "missed"


def object_state(o, piece_id: int, layout0: list[dict], layout: list[dict]) -> str:
    """Where a piece's object stands against the piece's pose in ``layout`` (e.g. the layout
    of the run before, for the object map a run starts from): "right" (at the piece: 0.1 m
    mean footprint, 0.15 m centre, as :func:`piece_outcome`), "twin" (at an identical
    piece's pose, :func:`twin_of`), "absent" (not placed), "elsewhere" (placed anywhere
    else) or "unknown" (the piece or the object's base pose is not known)."""
    if o.status not in ("U", "M"):
        return "absent"
    exp = expected_pose(o, piece_id, layout0, layout)
    if exp is not None:
        md, cd = placement_error(o, exp)
        if md < 0.1 and cd < 0.15:
            return "right"
    if twin_of(o, piece_id, layout0, layout) is not None:
        return "twin"
    return "unknown" if exp is None else "elsewhere"


def piece_views(scans, piece_old: dict, piece_new: dict | None,
                res: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Which scans of a run saw a piece that moved, from the simulator's truth: ((N,) bool,
    scans with >= 5 rays through its old footprint; (N,) bool, scans with >= 8 returns on its
    new one). ``scans``: the run's scans with ground-truth poses; pieces as in scenario.json
    (``piece_new`` None: it was removed)."""
    old_xy = transform_points(np.array(piece_old["pose"]), _piece_points(piece_old, res))
    told = cKDTree(old_xy)
    # only rays that pass within the old footprint's bounding circle (plus the query's 0.03 m)
    # can cross it: the rest are skipped, which leaves the answer as it was and saves most of
    # the work (a piece is seen through by a few of a scan's rays at most)
    centre = old_xy.mean(axis=0)
    reach = float(np.max(np.hypot(*(old_xy - centre).T))) + 0.03 + 1e-9
    n = len(scans)
    new = scans_seeing(scans, piece_new, res) if piece_new is not None else np.zeros(n, bool)
    old = np.zeros(n, dtype=bool)
    for i, s in enumerate(scans):
        lp = compose(s.gt_pose_xytheta, s.laser_pose_xytheta)
        r = s.ranges_m
        a = lp[2] + s.angles_rad
        u = np.stack([np.cos(a), np.sin(a)], 1)
        valid = r < s.range_max_m
        rr = np.where(valid, r, s.range_max_m) - 0.1
        along = np.clip((centre - lp[:2]) @ u.T, 0.0, np.maximum(rr, 0.0))
        near = np.hypot(*(lp[:2] + along[:, None] * u - centre).T) <= reach
        if near.sum() < 5:
            continue
        old[i] = _rays_crossing(told, lp[:2], u[near], rr[near], s.range_max_m) >= 5
    return old, new


def scans_seeing(scans, piece: dict, res: float = 0.05, min_returns: int = 8) -> np.ndarray:
    """(N,) bool: the scans of a run (with ground-truth poses) that saw a piece standing as in
    scenario.json, at least ``min_returns`` returns within 0.06 m of its footprint."""
    tree = cKDTree(transform_points(np.array(piece["pose"]), _piece_points(piece, res)))
    out = np.zeros(len(scans), dtype=bool)
    for i, s in enumerate(scans):
        lp = compose(s.gt_pose_xytheta, s.laser_pose_xytheta)
        r = s.ranges_m
        valid = r < s.range_max_m
        a = lp[2] + s.angles_rad[valid]
        pts = lp[:2] + r[valid, None] * np.stack([np.cos(a), np.sin(a)], 1)
        d, _ = tree.query(pts, distance_upper_bound=0.06)
        out[i] = np.isfinite(d).sum() >= min_returns
    return out


def unmapped_seen(object_map, scenario: dict, run: int, scans, min_scans: int = 5,
                  near_m: float = 0.1) -> int:
    """Of the pieces of run ``run``'s layout that no placed object stands on
    (:func:`map_census`' ``pieces_unmapped``), how many the run's ``scans`` saw
    (:func:`scans_seeing` in ``min_scans`` scans, as :func:`observed` counts a new place
    seen): the unmapped pieces GATMO had a chance at in the run, the rest it never saw."""
    res = scenario.get("resolution_m", 0.05)
    on, _ = objects_on_pieces(object_map, scenario, run, near_m)
    return sum(int(scans_seeing(scans, p, res).sum() >= min_scans)
               for p in scenario["runs"][run - 1]["objects"] if p["id"] not in on)


def _rays_crossing(tree: cKDTree, origin_xy: np.ndarray, u: np.ndarray, free_m: np.ndarray,
                   range_max_m: float) -> int:
    """How many rays from ``origin_xy`` along the unit directions ``u`` (R, 2), each free up
    to ``free_m`` (R,) [m], pass within 3 cm of a point of ``tree`` (sampled every 5 cm)."""
    ts = np.arange(0.05, range_max_m, 0.05)
    pts = origin_xy[None, None] + ts[None, :, None] * u[:, None, :]
    m = ts[None, :] < free_m[:, None]
    d, _ = tree.query(pts[m], distance_upper_bound=0.03)
    inside = np.zeros(m.shape, bool)
    inside[m] = np.isfinite(d)
    return int(inside.any(axis=1).sum())


def observed(scans, piece_old: dict, piece_new: dict | None, min_scans: int = 5,
             views: tuple[np.ndarray, np.ndarray] | None = None) -> str:
    """"both" (old place seen through and new place seen, each in ``min_scans`` scans), "old",
    "new" or "none": whether GATMO could have found the piece in this run at all. ``views``:
    :func:`piece_views` of the same arguments, if already at hand."""
    if views is None:
        views = piece_views(scans, piece_old, piece_new)
    n_old, n_new = int(views[0].sum()), int(views[1].sum())
    if n_old >= min_scans and n_new >= min_scans:
        return "both"
    return "new" if n_new >= min_scans else "old" if n_old >= min_scans else "none"
