"""Furniture moved in a recorded map: GATMO on real scans with a known answer (issue 5).

No public log records furniture moved between runs with object-level truth. A recorded log
with reference poses and the map made from it give one: move some pieces *in the map* (erase
each where it stands, draw it turned and shifted in free space the robot saw through) and
hand gatmo that map with the unchanged log. From GATMO's side the piece moved from the map's
place to the one the scans show: the log's rays pass through the place the map draws it
(absent), and its returns stand where the map is free (a chair to match). The truth is exact:
the place the piece was erased from. The scans are real (their noise, clutter, people and the
robot's odometry); only the map is changed.

Everything here works on arrays; the benchmark ``benchmarks/bench_real_moves.py`` reads the
logs and writes the maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from gatmo.geometry import compose, transform_points, wrap_angle
from gatmo.maps.grid import FREE, OCCUPIED, OccupancyGrid
from gatmo.objects.objectmap import ObjectMap


@dataclass(frozen=True)
class MapMove:
    """One piece moved in the map.

    Attributes:
        object_id: the piece's object id in the object map of the recorded map.
        cells_xy: (K, 2) the piece's cell centres where the recorded map has them [m, map].
        turn_rad: the turn about the cells' centroid.
        shift_xy_m: (2,) then the shift [m, map frame].
    """

    object_id: int
    cells_xy: np.ndarray
    turn_rad: float
    shift_xy_m: np.ndarray

    @property
    def pivot_xy(self) -> np.ndarray:
        return self.cells_xy.mean(axis=0)

    def moved(self, points_xy: np.ndarray) -> np.ndarray:
        """Points (N, 2) of the recorded place carried to the place the edited map draws."""
        p = self.pivot_xy
        return transform_points(np.array([p[0] + self.shift_xy_m[0], p[1] + self.shift_xy_m[1],
                                          self.turn_rad]), np.asarray(points_xy) - p)

    def undone(self, points_xy: np.ndarray) -> np.ndarray:
        """Points (N, 2) of the edited map's place carried back to the recorded place."""
        p = self.pivot_xy
        back = transform_points(np.array([0.0, 0.0, -self.turn_rad]),
                                np.asarray(points_xy) - p - self.shift_xy_m)
        return back + p

    def true_pose(self, pose_xytheta: np.ndarray) -> np.ndarray:
        """Where an object frame standing at ``pose_xytheta`` (3,) on the edited map's place
        must go to stand on the recorded place: the edit undone, composed with the frame."""
        p = self.pivot_xy
        undo = compose(np.array([p[0], p[1], -self.turn_rad]),
                       np.array([-p[0] - self.shift_xy_m[0], -p[1] - self.shift_xy_m[1], 0.0]))
        out = compose(undo, np.asarray(pose_xytheta, dtype=float))
        out[2] = wrap_angle(out[2])
        return out

    def as_dict(self) -> dict:
        return {"recorded_object_id": int(self.object_id), "pivot_xy_m": self.pivot_xy.tolist(),
                "turn_deg": float(np.degrees(self.turn_rad)),
                "shift_xy_m": [float(v) for v in self.shift_xy_m],
                "shift_m": float(np.hypot(*self.shift_xy_m)), "cells": len(self.cells_xy)}


def moved_cells(grid: OccupancyGrid, move: MapMove) -> np.ndarray:
    """(K, 2) the grid cells (ix, iy) the edited map draws the moved piece on (some may lie
    outside the grid): those its cell centres, and the midpoints of neighbouring ones, land on.
    The midpoints keep a turned outline a cell thick in one piece (without them one turn in
    seven split a piece); 4 points per cell, as :meth:`ObjectMap.render` draws a moved object,
    thickened such an outline by half (a 14-cell speck came out at 21 cells, this at 18):
    here the median piece gains 13 % of its cells."""
    src = grid.world_to_cell(move.cells_xy)
    # the piece's cells in a window one cell wider on each side, so every neighbour indexes it
    at = src - src.min(axis=0) + 1
    have = np.zeros(tuple(at.max(axis=0) + 2)[::-1], dtype=bool)
    have[at[:, 1], at[:, 0]] = True
    pts = [move.cells_xy]
    for d in ((1, 0), (0, 1), (1, 1), (1, -1)):
        ok = have[at[:, 1] + d[1], at[:, 0] + d[0]]
        pts.append(move.cells_xy[ok] + 0.5 * grid.resolution_m * np.array(d))
    return np.unique(grid.world_to_cell(move.moved(np.vstack(pts))), axis=0)


def apply_moves(grid: OccupancyGrid, moves: list[MapMove]) -> OccupancyGrid:
    """A copy of ``grid`` with each piece erased (free) where it stands and drawn (occupied)
    where its move puts it."""
    out = grid.copy()
    for m in moves:
        c = grid.world_to_cell(m.cells_xy)
        out.cells[c[:, 1], c[:, 0]] = FREE
    for m in moves:
        c = moved_cells(grid, m)
        c = c[grid.in_bounds(c)]
        out.cells[c[:, 1], c[:, 0]] = OCCUPIED
    return out


def _owners(grid: OccupancyGrid, object_map: ObjectMap) -> np.ndarray:
    """(H, W) the id of the object on each cell at its current pose, 0 where none."""
    label = np.zeros(grid.cells.shape, dtype=np.int64)
    for o in object_map.objects:
        c = grid.world_to_cell(o.cells_world())
        c = c[grid.in_bounds(c)]
        label[c[:, 1], c[:, 0]] = o.id
    return label


def _clear_of_others(occupied: np.ndarray, cells: np.ndarray, clearance_m: float,
                     resolution_m: float) -> bool:
    """Every other occupied cell lies at least ``clearance_m`` from ``cells`` (K, 2) (ix, iy),
    looked for in a window that much wider around them."""
    r = int(np.ceil(clearance_m / resolution_m))
    y0, x0 = max(cells[:, 1].min() - r, 0), max(cells[:, 0].min() - r, 0)
    win = occupied[y0:cells[:, 1].max() + r + 1, x0:cells[:, 0].max() + r + 1].copy()
    win[cells[:, 1] - y0, cells[:, 0] - x0] = False
    if not win.any():
        return True
    d = ndimage.distance_transform_edt(~win) * resolution_m
    return bool(d[cells[:, 1] - y0, cells[:, 0] - x0].min() >= clearance_m)


def standing_views(grid: OccupancyGrid, object_map: ObjectMap, scans,
                   near_m: float = 0.1, min_returns: int = 5) -> dict[int, int]:
    """Object id -> how many of ``scans`` (from their ``gt_pose_xytheta``) put at least
    ``min_returns`` returns within ``near_m`` of its cells: the piece stood there, in view."""
    label = _owners(grid, object_map)
    # a return within near_m of a cell: the labels grown by that many cells (where two
    # grown labels meet, the larger id takes the cell: only pieces near others lose a view)
    grow = max(1, int(np.ceil(near_m / grid.resolution_m)))
    grown = ndimage.grey_dilation(label, size=(2 * grow + 1, 2 * grow + 1))
    views: dict[int, int] = {}
    for s in scans:
        pts = s.points_laser_xy()
        if len(pts) == 0:
            continue
        lp = compose(np.asarray(s.gt_pose_xytheta, dtype=float), s.laser_pose_xytheta)
        c = grid.world_to_cell(transform_points(lp, pts))
        c = c[grid.in_bounds(c)]
        ids, n = np.unique(grown[c[:, 1], c[:, 0]], return_counts=True)
        for i in ids[(ids > 0) & (n >= min_returns)]:
            views[int(i)] = views.get(int(i), 0) + 1
    return views


def pick_moves(
    grid: OccupancyGrid,
    object_map: ObjectMap,
    scans,
    rng: np.random.Generator,
    n_moves: int,
    *,
    min_extent_m: float = 0.3,
    max_extent_m: float = 2.0,
    min_cells: int = 20,
    clearance_m: float = 0.2,
    shift_range_m: tuple[float, float] = (0.5, 3.0),
    path_clearance_m: float = 0.5,
    min_views: int = 20,
    max_range_m: float = 5.0,
    tries: int = 200,
) -> list[MapMove]:
    """Up to ``n_moves`` pieces of the recorded map to move, with where to, at random.

    A piece: an object that is not structure, ``min_extent_m``-``max_extent_m`` across, of at
    least ``min_cells`` cells (20 at 5 cm: not a speck GATMO matches only nearby,
    ``small_object_area_m2``), at least ``clearance_m`` from every other occupied cell (more
    than ``delta_W_m``, 0.15 m, so its returns, once it is erased, are no other object's),
    standing in view of at least ``min_views`` of ``scans`` (:func:`standing_views`).
    Its new place: turned at random, shifted ``shift_range_m`` in a random direction, every
    cell on known free space at least ``clearance_m`` from any occupied cell and any other
    new place, at least ``path_clearance_m`` from every pose the robot took (it never drove
    through it), and seen through by at least ``min_views`` scans within ``max_range_m``
    (:func:`gatmo.pipeline.evaluate.seen_through`): the log holds the evidence that it is not
    there.

    ``scans`` carry ``gt_pose_xytheta`` (the reference poses). Fewer moves come back when
    fewer pieces qualify."""
    from gatmo.pipeline.evaluate import seen_through

    res = grid.resolution_m
    views = standing_views(grid, object_map, scans)
    occ = grid.occupied
    # distance [m] of every cell to the nearest occupied one
    dist_occ = ndimage.distance_transform_edt(~occ) * res
    poses = np.array([s.gt_pose_xytheta for s in scans], dtype=float)
    pose_tree = cKDTree(poses[:, :2])
    candidates = []
    for o in object_map.objects:
        if o.structure or o.base_pose_xytheta is None or len(o.shape_xy) < min_cells:
            continue
        if not (min_extent_m <= o.extent_m() <= max_extent_m):
            continue
        if views.get(o.id, 0) < min_views:
            continue
        c = grid.world_to_cell(o.cells_world())
        if grid.in_bounds(c).all() and _clear_of_others(occ, c, clearance_m, res):
            candidates.append(o)
    order = rng.permutation(len(candidates))
    moves: list[MapMove] = []
    placed = np.zeros((0, 2))
    for k in order:
        if len(moves) >= n_moves:
            break
        o = candidates[k]
        cells = o.cells_world()
        for _ in range(tries):
            turn = float(rng.uniform(-np.pi, np.pi))
            d = float(rng.uniform(*shift_range_m))
            a = float(rng.uniform(-np.pi, np.pi))
            m = MapMove(o.id, cells, turn, np.array([d * np.cos(a), d * np.sin(a)]))
            new_c = moved_cells(grid, m)
            if len(new_c) == 0 or not grid.in_bounds(new_c).all():
                continue
            if (grid.cells[new_c[:, 1], new_c[:, 0]] != FREE).any():
                continue
            if dist_occ[new_c[:, 1], new_c[:, 0]].min() < clearance_m:
                continue
            new_xy = grid.cell_to_world(new_c)
            if len(placed) and cKDTree(placed).query(new_xy)[0].min() < clearance_m:
                continue
            if pose_tree.query(new_xy)[0].min() < path_clearance_m:
                continue
            near = pose_tree.query_ball_point(new_xy.mean(axis=0), max_range_m)
            if len(near) < min_views:
                continue
            _, n = seen_through(new_xy, [scans[i] for i in sorted(near)], max_range_m)
            if n < min_views:
                continue
            moves.append(m)
            placed = np.vstack([placed, new_xy])
            break
    return moves


def tie_moves(edited: ObjectMap, grid: OccupancyGrid, moves: list[MapMove]) -> dict[int, dict]:
    """Object id in ``edited`` (the object map of the edited grid) -> {"move": the move's
    index, "true_pose": (3,) where its frame must go}: the object covering most of a move's
    new cells (at least half of them)."""
    owner = _owners(grid, edited)  # an edited map's objects stand where the map has them
    by_id = edited.by_id
    out: dict[int, dict] = {}
    for k, m in enumerate(moves):
        new = moved_cells(grid, m)
        on = new[grid.in_bounds(new)]
        ids, n = np.unique(owner[on[:, 1], on[:, 0]], return_counts=True)
        n[ids == 0] = 0
        if len(ids) and n.max() >= 0.5 * len(new):
            best = by_id[int(ids[np.argmax(n)])]
            out[best.id] = {"move": k, "true_pose": m.true_pose(best.base_pose_xytheta)}
    return out


def score_moves(final: ObjectMap, ties: dict[int, dict], n_moves: int) -> dict:
    """How GATMO's object map at a run's end stands against the moves.

    Per moved piece, its object is ``found`` (placed, its footprint on the recorded place:
    mean distance < 0.1 m and centre < 0.15 m, as in the simulated halls, so a symmetric
    piece is not penalised for an equivalent yaw), ``elsewhere`` (placed, moved, not there),
    ``absent`` (noticed gone, not found), ``unchanged`` (still where the edited map drew it);
    ``untied`` counts moves no object of the edited map covered. Of the other objects
    (not structure, in the map from the start): ``false_absent`` (marked absent),
    ``false_relocated`` (placed more than 0.15 m from where the map drew it); ``added``: objects
    that joined the map during the run, of which ``added_on_moved`` on a moved piece's
    recorded place (found, but as a new object)."""
    from gatmo.pipeline.evaluate import placement_error

    outcome = {"found": 0, "elsewhere": 0, "absent": 0, "unchanged": 0,
               "untied": n_moves - len(ties)}
    per_move: list[dict] = []
    true_places = []
    by_id = final.by_id
    for oid, t in sorted(ties.items()):
        o = by_id[oid]
        true_places.append(o.cells_world(t["true_pose"]))
        mean_d, centre_d = placement_error(o, t["true_pose"])
        base_d = float(np.hypot(*(o.pose_xytheta[:2] - o.base_pose_xytheta[:2])))
        if o.status in ("U", "M") and mean_d < 0.1 and centre_d < 0.15:
            kind = "found"
        elif o.status == "A":
            kind = "absent"
        elif o.status in ("U", "M") and (base_d > 0.15 or abs(wrap_angle(
                o.pose_xytheta[2] - o.base_pose_xytheta[2])) > np.radians(10)):
            kind = "elsewhere"
        else:
            kind = "unchanged"
        outcome[kind] += 1
        per_move.append({"object_id": oid, "move": t["move"], "outcome": kind,
                         "mean_m": mean_d, "centre_m": centre_d, "status": o.status})
    false_absent = false_relocated = added = added_on = 0
    tree = cKDTree(np.vstack(true_places)) if true_places else None
    for o in final.objects:
        if o.id in ties or o.structure:
            continue
        if o.base_pose_xytheta is None:
            if o.status in ("U", "M"):
                added += 1
                if tree is not None and np.median(tree.query(o.cells_world())[0]) < 0.1:
                    added_on += 1
            continue
        if o.status == "A":
            false_absent += 1
        elif np.hypot(*(o.pose_xytheta[:2] - o.base_pose_xytheta[:2])) > 0.15:
            false_relocated += 1
    return {**outcome, "moves": n_moves, "false_absent": false_absent,
            "false_relocated": false_relocated, "added": added, "added_on_moved": added_on,
            "per_move": per_move}
