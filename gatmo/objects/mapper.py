"""GATMO driven scan by scan (paper, Fig. 3): absence by ray tracing (Alg. 1), S_free filtering,
mean shift, metaobjects, matching and relocation, new objects at the end of a run.

The caller gives the robot's precise pose in the map frame and whether it is confident;
absence and the tracking of unexplained returns run only while it is (a wrong pose sees through
everything). Map changes are exposed as region updates for the localizer.

Beyond the paper (each marked where it happens):

* beams are tested against the ranges the current map predicts: a beam that should end on an
  object but passes well beyond it is evidence the object is gone, one that ends on it is
  evidence it is there. Alg. 1's seen-through fraction *and* this beam evidence must agree
  before an object is absent;
* an object with some pass-through evidence but not enough to be absent is *in doubt*: its
  returns are no longer explained away by S_free (so a chair hypothesis forms where it now
  stands) and it is a matching candidate, which is how an object shifted by less than its own
  size is found;
* one metaobject may take several clusters of a scan (mean shift splits a sofa), and
  metaobjects whose evidence grids touch are merged.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy import ndimage

from gatmo.datasets.types import Scan
from gatmo.geometry import compose, inverse, transform_points
from gatmo.maps.grid import FREE, OCCUPIED, OccupancyGrid, add_counts
from gatmo.maps.raycast import cast_rays, traverse_rays
from gatmo.objects.config import GatmoConfig
from gatmo.objects.matching import (
    EdgeField,
    beam_consistency,
    extent_excess,
    lookalike,
    match_points,
)
from gatmo.objects.meanshift import mean_shift
from gatmo.objects.metaobject import Metaobject
from gatmo.objects.objectmap import MapObject, ObjectMap, shape_from_points


@dataclass
class Event:
    stamp_s: float
    run: int
    kind: str  # absent | relocated | restored | movable | added | gamma
    object_id: int
    label: str | None = None
    pose_old: list | None = None
    pose_new: list | None = None
    score: float | None = None
    support_scans: int | None = None  # scans of the chair hypothesis behind a match (Table II)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _rank_key(o: MapObject, mt, tier: int, earlier: bool) -> tuple:
    """How a match ``mt`` of ``o`` ranks among others: tier first, then at an earlier pose (its
    prior), the score to 0.05, then nearness to where ``o`` is (look-alikes: the nearest)."""
    return (tier, earlier, round(mt.score * 20) / 20, -_move_m(o, mt))


def _nearest_twin(best: tuple, rivals: list[tuple], cfg: GatmoConfig) -> tuple:
    """``match_twin_nearest``: of the (rank key, object, match) ``rivals`` for one chair, the
    one nearest to where it was among ``best`` and those that look alike to ``best``'s object,
    rank in its tier with the same prior (the key's first two fields) and score at most
    ``match_twin_score_margin`` below it. The key rounds the score to 0.05, so a twin 0.03
    below the best (two identical pieces' map cells fall differently on the grid) ranked a
    step lower, and the farther twin took the chair (hall 301, run 3: the absent footstool
    6.1 m away scored 0.87, its twin 10.0 m away 0.90)."""
    key, o, mt = best
    for k2, o2, mt2 in rivals:
        if (o2 is o or k2[:2] != key[:2]
                or mt2.score < mt.score - cfg.match_twin_score_margin
                or _move_m(o2, mt2) >= _move_m(best[1], best[2])
                or not lookalike(o2, o, cfg.lookalike_tolerance)):
            continue
        best = (k2, o2, mt2)
    return best


def _move_m(o: MapObject, mt) -> float:
    """How far the match ``mt`` moves ``o``'s frame [m]."""
    return float(np.hypot(*(mt.pose_xytheta[:2] - o.pose_xytheta[:2])))


def _diameter(points_xy: np.ndarray) -> float:
    """Largest distance between two points of a set (P, 2) [m]."""
    if len(points_xy) < 2:
        return 0.0
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = points_xy[ConvexHull(points_xy).vertices]
    except QhullError:  # collinear
        hull = points_xy
    d = hull[:, None, :] - hull[None, :, :]
    return float(np.sqrt((d**2).sum(-1).max()))


def _larger_than(diameter_m: float, o: MapObject) -> bool:
    """What was seen, ``diameter_m`` across, is larger than object ``o`` (3 cells of slack)."""
    return diameter_m > _diameter(o.shape_xy) + 3 * o.resolution_m


def _footprint_shift_m(o: MapObject, pose_a: np.ndarray, pose_b: np.ndarray) -> float:
    """How far the object's footprint moves from ``pose_a`` to ``pose_b`` [m]: the Hausdorff
    distance between its cells at the two poses. A symmetric outline turned half a turn about
    its centre does not move (a table found with its yaw flipped is where it was)."""
    from scipy.spatial import cKDTree

    a, b = o.cells_world(pose_a), o.cells_world(pose_b)
    if len(a) == 0:
        return 0.0
    return float(max(cKDTree(a).query(b)[0].max(), cKDTree(b).query(a)[0].max()))


STRUCTURE = -2  # owner code of walls, columns and specks too small to be objects


class GatmoMapper:
    """The object map kept true while the robot drives.

    Args:
        object_map: the objects (from :meth:`ObjectMap.from_grid` or a saved objects.json).
        base_grid: the static map the objects were cut from (FREE/UNKNOWN layout).
        cfg: parameters.
    """

    def __init__(self, object_map: ObjectMap, base_grid: OccupancyGrid, cfg: GatmoConfig):
        self.object_map = object_map
        self.base = base_grid.copy()
        self.cfg = cfg
        self.run = 0
        self._last_stamp = 0.0
        self._grid = object_map.render(self.base)
        self._pending: list[tuple[np.ndarray, int, int]] = []
        self._meta: list[Metaobject] = []
        self._next_meta = 1
        self._free = np.zeros(self._grid.cells.shape, dtype=np.int32)
        self._passed = np.zeros(self._grid.cells.shape, dtype=np.int32)
        # this run's beams passing well beyond a cell and returns in it, never cleared by
        # each other (add_max_flicker)
        self._passed_run = np.zeros(self._grid.cells.shape, dtype=np.int32)
        self._hit_run = np.zeros(self._grid.cells.shape, dtype=np.int32)
        self.flicker: dict[int, float] = {}  # per new object at the last end_run: _flicker()
        self._unexplained = np.zeros(self._grid.cells.shape, dtype=np.int32)
        # returns this run not explained by walls or other structure (on or near an object, or
        # near nothing): what the absence veto looks at
        self._near_returns = np.zeros(self._grid.cells.shape, dtype=np.int32)
        self._fields: dict[int, EdgeField] = {}
        self._inner: dict[int, np.ndarray] = {}  # per object id: _inner_cells, its frame
        self._cores: dict[int, set] = {}
        self.counts = {"absent": 0, "relocated": 0, "restored": 0, "added": 0, "movable": 0,
                       "gamma": 0, "persons": 0, "updates": 0, "skipped_poor_fit": 0,
                       "skipped_disagreement": 0, "unexplained_sparse": 0, "absence_vetoed": 0,
                       "gamma_unverified": 0, "gamma_gone": 0, "nudged": 0, "ambiguous": 0,
                       "seen_through_scans": 0, "gamma_flicker": 0, "shifted_not_gone": 0,
                       "taken_unseen": 0}
        self._ms: list[float] = []
        self._beams = None
        self._sparse_agrees = False  # the last pose test: too few beams, those agreeing
        self._expected: np.ndarray | None = None  # the map's ranges for the scan's beams
        self._view: tuple | None = None  # the scan being tracked (Metaobject.views)
        # what the localizer was last given: the reconfigured map plus, with
        # provisional_landmarks, the outlines of still chairs not matched yet
        self._loc_cells = self._grid.cells.copy()
        self._prov_near: np.ndarray | None = None  # cells within delta_W of such outlines
        self._run_open = False  # between begin_run and end_run
        self._prov_tick = 0  # scans GATMO took, for provisional_every_scans
        # ids of placed objects left out of the localizer's map (withhold_unseen_runs)
        self._withheld: set[int] = self._unseen_ids()
        self._reset_run_evidence()
        self._build_owner()
        if self._withheld:
            self._sync_localizer()

    @classmethod
    def from_config(cls, cfg: GatmoConfig, grid: OccupancyGrid,
                    object_map: ObjectMap | None = None) -> GatmoMapper:
        if object_map is None:
            object_map = ObjectMap.from_grid(grid, cfg)
        return cls(object_map, grid, cfg)

    def _reset_run_evidence(self) -> None:
        # objects the absence's match put on a Gamma object this run -> the pose they were
        # absent from (match_retake_from_gamma)
        self._on_gamma: dict[int, tuple[np.ndarray, MapObject]] = {}
        # objects a track's chair took from A this run, far from where they were absent ->
        # that pose and the track (match_retake_from_chair)
        self._on_chair: dict[int, tuple[np.ndarray, Metaobject]] = {}
        self._seen: dict[int, set] = {}  # Alg. 1's I'_i (local cell indices)
        # each object's history length at the run's start (longer: placed by evidence this run)
        self._hist0 = {o.id: len(o.history) for o in self.object_map.objects}
        self._rays: dict[int, int] = {}
        self._through: dict[int, int] = {}  # beams passing well beyond the object
        self._hits: dict[int, int] = {}  # beams ending on it
        self._far_hits: dict[int, int] = {}  # ... beyond absence_max_range_m
        # beyond Alg. 1: the object's cells the map expects beams to end on (its surface as
        # seen this run), and those of them beams passed well beyond (not later hit)
        self._front: dict[int, set] = {}
        self._front_through: dict[int, set] = {}
        self._doubt: set[int] = set()
        self._gamma_this_run: set[int] = set()  # Gamma objects seen this run
        # their returns per scan this run (their tracks' Metaobject.scan_points), for the
        # extent test
        self._gamma_points: dict[int, list] = {}
        # per Gamma object seen this run, its tracks' nearest view [m] (Metaobject.nearest_view_m)
        self._gamma_near: dict[int, float] = {}
        # per (object id, test): how often a chair was refused as this object this run
        self.refusals: dict[tuple[int, str], int] = {}
        # and where the refused chairs were: (object id, test) -> their centres (x, y) [m],
        # rounded to 0.1 m (the benchmark tells the chair at a piece's new place from others)
        self.refused_at: dict[tuple[int, str], set[tuple[float, float]]] = {}
        # the nudge (beyond the paper): per object id, the cells (ix, iy) returns that missed
        # it landed on -> in how many scans, the scans, their views, and the scans at the
        # last try
        self._nudge_cells: dict[int, dict[tuple[int, int], int]] = {}
        self._nudge_scans: dict[int, int] = {}
        self._nudge_views: dict[int, list] = {}
        self._nudge_tried: dict[int, int] = {}

    # ------------------------------------------------------------------ maps
    def grid(self) -> OccupancyGrid:
        """The reconfigured map (a copy)."""
        return self._grid.copy()

    def localizer_grid(self) -> OccupancyGrid:
        """The map the localizer is given (a copy): the reconfigured map without the objects
        withheld (``withhold_unseen_runs``) and, while a run lasts, with the provisional
        landmarks. A localizer made from it needs none of the queued region updates."""
        g = self._grid.copy()
        g.cells = self._loc_cells.copy()
        return g

    def _unseen_ids(self) -> set[int]:
        """Placed movable objects unseen for ``withhold_unseen_runs`` runs."""
        n = self.cfg.withhold_unseen_runs
        if n is None:
            return set()
        return {o.id for o in self.object_map.placed()
                if not o.structure and o.unseen_runs >= n}

    def withheld_ids(self) -> set[int]:
        """Ids of the placed objects the localizer's map leaves out (``withhold_unseen_runs``):
        after :meth:`end_run`, those the next run starts without; during a run, those no scan
        has seen standing yet."""
        return set(self._withheld)

    def _withheld_idx(self) -> list[int]:
        """Indices (into ``object_map.objects``) of the withheld objects not placed by
        evidence this run."""
        if not self._withheld:
            return []
        return [i for i, o in enumerate(self.object_map.objects)
                if o.id in self._withheld and o.status in ("U", "M")
                and not self._placed_this_run(o)]

    def _seen_this_run(self, o: MapObject) -> bool:
        """``o`` was seen standing at its place this run, or placed by evidence in it."""
        return self._confirmed(o) or self._placed_this_run(o)

    def _placed_this_run(self, o: MapObject) -> bool:
        """``o`` was placed by evidence this run (a match or an add: its history grew)."""
        return len(o.history) > self._hist0.get(o.id, 0)

    def _withheld_mask(self) -> np.ndarray | None:
        """Cells (bool, the grid's shape) of :meth:`_withheld_idx`'s objects, or None."""
        idx = self._withheld_idx()
        return np.isin(self._owner, idx) if idx else None

    def pop_map_changes(self) -> list[tuple[np.ndarray, int, int]]:
        """Region updates (cells_new (h, w), ix0, iy0) since the last call."""
        out, self._pending = self._pending, []
        return out

    def _core(self, o: MapObject) -> set:
        """Local indices of the cells Alg. 1 counts: those at least ``absence_margin_m`` inside
        the object's outline, so rays grazing its edge (raster aliasing, pose noise) do not
        make it absent. Thin objects and outline-only maps fall back to their deepest cells."""
        core = self._cores.get(o.id)
        if core is None:
            res = o.resolution_m
            idx = np.floor(o.shape_xy / res).astype(np.int64)
            lo = idx.min(axis=0) - 1
            mask = np.zeros(tuple(idx.max(axis=0) - lo + 2)[::-1], dtype=bool)
            mask[idx[:, 1] - lo[1], idx[:, 0] - lo[0]] = True
            depth = ndimage.distance_transform_edt(mask) * res
            d = depth[idx[:, 1] - lo[1], idx[:, 0] - lo[0]]
            keep = d >= self.cfg.absence_margin_m
            if keep.sum() < 5:
                keep = d >= d.max()
            core = self._cores[o.id] = set(np.nonzero(keep)[0].tolist())
        return core

    def _build_owner(self) -> None:
        """Per cell: which placed object covers it (index into ``object_map.objects``, -1 free,
        STRUCTURE), its local cell index, and for every cell the owner of the nearest occupied
        cell with the distance to it (S_free filtering)."""
        g = self._grid
        self._owner = np.full(g.cells.shape, -1, dtype=np.int32)
        self._local = np.full(g.cells.shape, -1, dtype=np.int32)
        occ = g.occupied
        self._owner[occ] = STRUCTURE
        for i, o in enumerate(self.object_map.objects):
            if o.status not in ("U", "M") or o.structure:
                continue
            c = g.world_to_cell(o.cells_world(dense=True))
            ok = g.in_bounds(c)
            c = c[ok]
            k = np.repeat(np.arange(len(o.shape_xy)), 4)[ok]
            keep = occ[c[:, 1], c[:, 0]]
            self._owner[c[keep, 1], c[keep, 0]] = i
            self._local[c[keep, 1], c[keep, 0]] = k[keep]
        self._normals = None  # the surface normals of this map, on first use
        if occ.any():
            dist, (iy, ix) = ndimage.distance_transform_edt(~occ, return_indices=True)
            self._near_dist = dist * g.resolution_m
            self._near_owner = self._owner[iy, ix]
        else:
            self._near_dist = np.full(g.cells.shape, np.inf)
            self._near_owner = np.full(g.cells.shape, -1, dtype=np.int32)

    def _rerender(self) -> None:
        self._grid = self.object_map.render(self.base)
        self._build_owner()
        self._sync_localizer()

    def _sync_localizer(self) -> None:
        """Queue region updates that bring the localizer's map to the reconfigured map plus
        the provisional landmarks (``provisional_landmarks``)."""
        target = self._grid.cells.copy()
        gone = self._withheld_mask()
        if gone is not None:
            target[gone] = FREE
        prov = self._provisional_mask()
        if prov is not None:
            target[prov & (target == FREE)] = OCCUPIED
        self._pending += _changed_regions(target, self._loc_cells)
        self._loc_cells = target

    def _provisional_mask(self) -> np.ndarray | None:
        """Cells of the provisional landmarks (bool, the grid's shape), or None (none, or the
        option is off); also sets ``_prov_near`` for :meth:`unexplained_at`."""
        self._prov_near = None
        c = self.cfg
        if not c.provisional_landmarks or not self._run_open:
            return None
        parts = [m.chair_points(verified=True) for m in self._meta
                 if m.matched_object is None and m.n_verified >= c.provisional_min_verified_scans
                 and m.dominant() == "chair"]
        parts = [p for p in parts if len(p) >= c.chair_min_cells]
        parts += [o.cells_world() for o in self.object_map.Gamma
                  if o.id in self._gamma_this_run]
        if not parts:
            return None
        g = self._grid
        groups = [cl[g.in_bounds(cl)] for cl in (g.world_to_cell(q) for q in parts)]
        cells = np.vstack(groups)
        mask = np.zeros(g.cells.shape, dtype=bool)
        mask[cells[:, 1], cells[:, 0]] = True
        r = int(np.ceil(c.provisional_near_m / g.resolution_m))
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        self._prov_near = _dilated(mask, xx**2 + yy**2 <= r * r, groups)
        return mask

    # ------------------------------------------------------------------ runs
    def begin_run(self, run_id: int) -> None:
        """Start run ``run_id`` (1-based; the number every event and history entry of the run
        carries)."""
        self.run = int(run_id)
        self.object_map.runs = max(self.object_map.runs, self.run)
        self._meta = []
        self._free[:] = 0
        self._passed[:] = 0
        self._passed_run[:] = 0
        self._hit_run[:] = 0
        self._unexplained[:] = 0
        self._near_returns[:] = 0
        self._reset_run_evidence()
        # "seen this run": a Gamma object's scans of a run before saw another layout
        self._gamma_points.clear()
        self._gamma_near.clear()
        self._run_open = True

    def end_run(self) -> list[Event]:
        """Dominant chairs seen this run and never matched become new objects (in M)."""
        events: list[Event] = []
        self.flicker = {}
        for m in self._meta:
            self._end_track(m, m.last_seen, events)
        self._meta = []
        self._run_open = False  # the provisional landmarks leave the localizer's map
        # only what a track of this run saw: the tests below count this run's rays, and a thing
        # seen in an earlier run only and turned down then (gone again, coming and going) would
        # pass them with no ray at all (the Intel log cut in two added three such things)
        seen = [g for g in self.object_map.Gamma if g.id in self._gamma_this_run]
        cells = {g.id: self._cells_if_stays(g) for g in seen}
        kept = [g for g in sorted(seen, key=lambda g: -len(g.shape_xy))
                if cells[g.id] is not None]
        taken = self._grid.occupied.copy()  # the map, and what is added below
        for o in kept:
            cy, cx = cells[o.id]
            if np.mean(taken[cy, cx]) > 0.3:
                continue
            # beyond the paper: returns in space the static map never knew (through a window,
            # an open door, past the mapped area) are the unmapped world, not new furniture
            if np.mean(self.base.cells[cy, cx] == FREE) < self.cfg.add_min_free_fraction:
                continue
            taken[cy, cx] = True
            if not self._take_unseen(o, events):
                self._add(o, self._last_stamp, events)
        for o in self.object_map.placed():
            o.unseen_runs = 0 if self._seen_this_run(o) else o.unseen_runs + 1
        self._withheld = self._unseen_ids()  # for the next run's localizer
        self._rerender()
        return events

    def _take_unseen(self, g: MapObject, events) -> bool:
        """With ``end_run_take_unseen_runs``: the Gamma object ``g``, about to be added at the
        run's end, is instead where the best-fitting movable object unseen at its place for
        that many runs (this one included) went: that object is relocated onto it (keeping its
        id) and ``g`` leaves Gamma. Beyond the paper (which matches chairs with M during the
        run): a piece moved while the robot looked elsewhere would otherwise stay in the map
        where it stood and come back as a new object."""
        n = self.cfg.end_run_take_unseen_runs
        if n is None:
            return False
        fits = [(fit[0], k, o, fit[1]) for k, o in enumerate(self.object_map.objects)
                if not o.structure and o.status == "M" and o.unseen_runs + 1 >= n
                and not self._seen_this_run(o)
                and (fit := self._fit_gamma_ranked(g, o)) is not None]
        if not fits:
            return False
        _, _, o, mt = max(fits, key=lambda f: (f[0], -f[1]))  # ties: the first, as before
        self.object_map.objects.remove(g)
        self._relocate(o, mt, self._last_stamp, events)
        self.counts["taken_unseen"] += 1
        return True

    def _add(self, o: MapObject, stamp_s, events) -> None:
        """A Gamma object ``o`` joins the map as a new object (in M)."""
        o.status = "M"
        o.record(self.run, stamp_s)
        events.append(Event(float(stamp_s), self.run, "added", o.id, o.label, None,
                            o.pose_xytheta.tolist()))
        self.counts["added"] += 1

    def _cells_if_stays(self, o: MapObject) -> tuple[np.ndarray, np.ndarray] | None:
        """The grid cells (rows, columns) of a Gamma object seen this run if it is still there
        at the run's end: large enough, on the map, not gone again, not coming and going (the
        end-of-run tests before it is added); else None."""
        if len(o.shape_xy) < self.cfg.add_min_cells:
            return None
        c = self._grid.world_to_cell(o.cells_world())
        c = c[self._grid.in_bounds(c)]
        if not len(c):  # off the map
            return None
        cy, cx = c[:, 1], c[:, 0]
        # beyond the paper: where rays went on well past its cells after the last return
        # landed there, it has gone again (a person who stood a while, a cart wheeled off)
        if np.mean(self._passed[cy, cx] >= self.cfg.match_free_rays
                   ) > self.cfg.add_max_passed_fraction:
            self.counts["gamma_gone"] += 1
            return None
        flicker = self.flicker[o.id] = self._flicker(cy, cx)
        if flicker > self.cfg.add_max_flicker:
            self.counts["gamma_flicker"] += 1
            return None
        return cy, cx

    def _flicker(self, cy: np.ndarray, cx: np.ndarray) -> float:
        """Of the beams that reached a new object's cells this run since a return first
        landed there, the fraction that passed well beyond them instead of ending there: the
        median over its cells that some return landed in (0 when none did). Beyond the
        paper: a thing gone most times it was looked at (a door swinging, people coming and
        going) is not furniture."""
        h = self._hit_run[cy, cx]
        p = self._passed_run[cy, cx]
        sel = h > 0
        if not sel.any():
            return 0.0
        return float(np.median(p[sel] / (p[sel] + h[sel])))

    # ---------------------------------------------------------------- update
    def update(self, pose_xytheta, scan: Scan, *, pose_confident: bool,
               stamp_s: float, pose_verified: bool = True, track: bool = True) -> list[Event]:
        """One scan from the base pose (map frame). Returns what changed. ``pose_verified``:
        the pose was confirmed by an independent check (scan-to-map alignment), not only by
        the filter's covariance; new objects need some scans from such poses. ``track``
        False: the scan is evidence of absence and presence only; its unexplained returns
        are counted (:meth:`unexplained_at`) but feed no metaobject."""
        t0 = time.perf_counter()
        self._last_stamp = float(stamp_s)
        events: list[Event] = []
        self.counts["updates"] += 1
        if not pose_confident:
            self._expire(stamp_s, events)
            return events
        lp = compose(np.asarray(pose_xytheta, dtype=float), scan.laser_pose_xytheta)
        pts = transform_points(lp, scan.points_laser_xy(only_valid=True))
        near_any, explained = self._explained(pts)
        fit = self._fits_map(lp, scan, pts, near_any)
        if isinstance(fit, str):
            self.counts[fit] += 1
            if fit == "skipped_disagreement" and self._sparse_agrees:
                # beyond the paper: no evidence of absence or presence from a pose the map
                # cannot test, but the localizer's mask learns where the unexplained returns are
                self.counts["unexplained_sparse"] += 1
                self._count_unexplained(pts[~explained])
            self._expire(stamp_s, events)
            return events
        self._count_near_returns(pts, lp)
        self._absence(lp, scan, pts, stamp_s, events, agreement=fit,
                      sees_through=bool(pose_verified) or not self.cfg.absence_from_verified_only)
        if events:  # the map changed: explain against the new one
            near_any, explained = self._explained(pts)
        un = pts[~explained]
        self._count_unexplained(un)
        # beyond the paper: a long-range laser's far returns are a beam every 0.2-0.3 m; a
        # person 15 m away makes a 'chair' that matches any small absent object. And only
        # returns well inside the laser's range are tracked: an object cut by the range limit
        # looks like a smaller one (a desk's near end, a footstool), and with a band of
        # untracked returns beyond, the rest of it shows in the ring test (_part_of_larger)
        reach = min(self.cfg.track_max_range_m,
                    scan.range_max_m - self.cfg.track_range_margin_m)
        # the beams of this scan, for the matches of the tracks it feeds (_beams_consistent):
        # an object cell within the laser's range stops a beam or is contradicted by it
        self._view = (lp, scan.angles_rad, scan.ranges_m,
                      min(scan.range_max_m, self.cfg.absence_max_range_m)
                      - self.cfg.match_through_m)
        if self.cfg.nudge and pose_verified:
            self._nudge(pts, lp, scan, stamp_s, events)
        if track:
            self._track(un[np.hypot(*(un - lp[:2]).T) <= reach], stamp_s, events,
                        verified=bool(pose_verified))
        self._expire(stamp_s, events)
        if self.cfg.provisional_landmarks:
            self._prov_tick += 1
            if self._prov_tick % self.cfg.provisional_every_scans == 0:
                self._sync_localizer()
        self._ms.append((time.perf_counter() - t0) * 1e3)
        return events

    def _count_unexplained(self, points_xy: np.ndarray) -> None:
        """Add map-frame returns (N, 2) the map does not explain to this run's counts."""
        cu = self._grid.world_to_cell(points_xy)
        ok = self._grid.in_bounds(cu)
        add_counts(self._unexplained, cu[ok, 1], cu[ok, 0])

    def _fits_map(self, lp, scan: Scan, pts: np.ndarray, near_any: np.ndarray) -> float | str:
        """The map's test of the pose a scan is laid from (laser at ``lp``, returns ``pts``
        (N, 2), ``near_any`` from :meth:`_explained`): the fraction of the beams the map
        expects that agree (:meth:`_agreement`; the beams are kept in ``_beams``), or the
        name of the count of why the scan is skipped."""
        if len(pts) and near_any.mean() < self.cfg.min_explained_fraction:
            # most returns off the map: the pose is wrong however confident the filter is
            return "skipped_poor_fit"
        self._beams = self._classify_beams(lp, scan)
        n, on = self._agreement(self._beams)
        # too little in view that the map expects to test the pose on, and what is there agrees
        k = self.cfg.unexplained_sparse_min_beams
        self._sparse_agrees = (k is not None and k <= n < self.cfg.agreement_min_beams
                               and on >= self.cfg.min_agreement * n)
        if n < self.cfg.agreement_min_beams or on < self.cfg.min_agreement * n:
            # beyond the paper: too little of what the map expects (walls, columns, furniture
            # that stayed) is where this pose says; a wrong pose sees through small objects
            # and makes phantom chairs, so the scan is skipped
            return "skipped_disagreement"
        return on / max(n, 1)

    def unexplained_at(self, points_xy: np.ndarray, min_count: int = 2) -> np.ndarray:
        """(N,) bool: map-frame points (N, 2) that land where this run's returns were not
        explained by the current map (at least ``min_count`` of them, in the point's cell or a
        neighbour) and that no map cell is within delta_W of: furniture the map does not have
        yet, and people. Beyond the paper: the stack withholds such returns from the localizer
        (they pull a likelihood field towards wherever they happen to fall near old
        furniture)."""
        g = self._grid
        c = g.world_to_cell(np.asarray(points_xy, dtype=float).reshape(-1, 2))
        ok = g.in_bounds(c)
        out = np.zeros(len(c), dtype=bool)
        cy, cx = c[ok, 1], c[ok, 0]
        out[ok] = (_max3x3_at(self._unexplained, cy, cx) >= min_count) & \
            (self._near_dist[cy, cx] > self.cfg.delta_W_m)
        if self._prov_near is not None:  # the localizer's map has them (provisional_landmarks)
            out[ok] &= ~self._prov_near[cy, cx]
        return out

    def withheld_at(self, points_xy: np.ndarray) -> np.ndarray:
        """(N,) bool: map-frame points (N, 2) within delta_W of an object left out of the
        localizer's map (``withhold_unseen_runs``): if it still stands, the localizer's map
        has nothing there to explain them. Beyond the paper."""
        idx = self._withheld_idx()
        if not idx:
            return np.zeros(len(points_xy), dtype=bool)
        return self._near_objects_at(points_xy, lambda owner: np.isin(owner, idx))

    def _near_objects_at(self, points_xy: np.ndarray, picked) -> np.ndarray:
        """(N,) bool: map-frame points (N, 2) within delta_W of a map cell whose object
        ``picked`` (object indices (M,), < 0 for none -> (M,) bool) picks."""
        out = np.zeros(len(points_xy), dtype=bool)
        g = self._grid
        c = g.world_to_cell(np.asarray(points_xy, dtype=float).reshape(-1, 2))
        ok = g.in_bounds(c)
        cy, cx = c[ok, 1], c[ok, 0]
        out[ok] = picked(self._near_owner[cy, cx]) & (self._near_dist[cy, cx] <= self.cfg.delta_W_m)
        return out

    def offset_at(self, points_xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the returns of one scan, placed in the map frame (N, 2) from a predicted
        pose, that belong to an object whose returns miss it by a consistent offset: at least
        ``offset_min_returns`` returns within ``absence_near_m`` whose nearest map cell is the
        object's, their median distance to it more than ``offset_min_m``, while the rest of
        the scan's returns near the map fit it (at least ``offset_min_fit_fraction`` of them
        within ``offset_fit_m``). Beyond the paper: a piece shifted by a decimetre or more that
        GATMO has not relocated yet returns next to its old place, and a likelihood field
        pulls the particles towards it; against everything else in view it is the one that
        disagrees. Walls and structure are never singled out. Empty when the scan as a whole
        does not fit (the prediction may be off)."""
        cfg = self.cfg
        min_returns = cfg.offset_min_returns
        g = self._grid
        pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
        out = np.zeros(len(pts), dtype=bool)
        c = g.world_to_cell(pts)
        ok = g.in_bounds(c)
        if ok.sum() < 2 * min_returns:
            return out
        idx = np.nonzero(ok)[0]
        dist = self._near_dist[c[ok, 1], c[ok, 0]]
        owner = self._near_owner[c[ok, 1], c[ok, 0]]
        near = dist <= cfg.absence_near_m  # returns far from the map: another matter
        odd = np.zeros(len(idx), dtype=bool)
        for i in np.unique(owner[near & (owner >= 0)]):
            mine = near & (owner == i)
            if mine.sum() >= min_returns and np.median(dist[mine]) > cfg.offset_min_m:
                odd |= mine
        rest = near & ~odd
        if not odd.any() or rest.sum() < 2 * min_returns:
            return out
        if np.mean(dist[rest] <= cfg.offset_fit_m) < cfg.offset_min_fit_fraction:
            return out
        out[idx[odd]] = True
        return out

    def _nudge(self, pts: np.ndarray, lp: np.ndarray, scan: Scan, stamp_s, events) -> None:
        """Beyond the paper: a piece shifted by less than its own size. Its old cells are still
        partly where it stands, so few rays pass through them (no absence), and its returns
        lie within delta_W of its outline (explained: no chair hypothesis forms). What shows
        it is that the beams the map expects to end on it end elsewhere while the rest of
        the scan fits the map (as :meth:`offset_at`). Per object, the returns within
        ``nudge_radius_m`` whose nearest map cell is its own are gathered over the scans in
        which at least ``nudge_min_off_fraction`` of its beams end more than
        ``offset_min_m`` before or beyond where the map has it (a return inside its old
        outline is near it, but a beam cannot end there if it stood there); after
        ``nudge_min_scans`` such scans the object is matched onto the cells hit in
        ``nudge_min_cell_scans`` of them (:func:`match_points`, as a chair would be) and
        relocated, keeping its id, if the match passes the chair tests (score, free space,
        enough of it seen, the beams of those scans) and beats its current pose."""
        c = self.cfg
        near = self._returns_near_map(pts, lp)
        if near is None:
            return
        _, cells, dist, owner = near
        odd = self._objects_off(dist, owner, self._beams[0], scan, self._expected)
        if not odd:
            return
        tries = []
        for o, mine in odd:
            hits = self._nudge_cells.setdefault(o.id, {})
            for key in set(map(tuple, cells[mine].tolist())):
                hits[key] = hits.get(key, 0) + 1
            n = self._nudge_scans[o.id] = self._nudge_scans.get(o.id, 0) + 1
            views = self._nudge_views.setdefault(o.id, [])
            if self._view is not None:
                views.append(self._view)
                del views[:-30]
            if n >= c.nudge_min_scans and n - self._nudge_tried.get(o.id, 0) >= c.nudge_min_scans:
                self._nudge_tried[o.id] = n
                tries.append(o)
        for o in tries:
            mt = self._nudge_fit(o)
            if mt is not None and o.status in ("U", "M"):
                # _relocate clears the object's evidence, the nudge's included
                self._relocate(o, mt, stamp_s, events, support_scans=self._nudge_scans[o.id])
                self.counts["nudged"] += 1

    def _returns_near_map(self, pts: np.ndarray, lp: np.ndarray):
        """Of the returns ``pts`` (N, 2) seen from the laser at ``lp``, those on the map and
        within ``absence_max_range_m``: (their indices (K,), cells (K, 2), distance to the
        nearest map cell (K,), its owner (K,)); None when fewer than 4 ``offset_min_returns``
        are."""
        g = self._grid
        cells = g.world_to_cell(pts)
        ok = g.in_bounds(cells) & (np.hypot(*(pts - lp[:2]).T) <= self.cfg.absence_max_range_m)
        if ok.sum() < 4 * self.cfg.offset_min_returns:
            return None
        cells = cells[ok]
        return (np.nonzero(ok)[0], cells, self._near_dist[cells[:, 1], cells[:, 0]],
                self._near_owner[cells[:, 1], cells[:, 0]])

    def _expected_ends(self, lp: np.ndarray, scan: Scan, use: np.ndarray):
        """Where the current map expects each beam of ``scan`` from the laser at ``lp`` to end:
        (range (B,) [m], beam directions (B, 2), the end point half a cell into the cell hit
        (B, 2), owner of that cell (B,): object index, STRUCTURE, or -1 for beams not in
        ``use`` (B,) bool, expected to reach max range, or ending off the map)."""
        g = self._grid
        expected = cast_rays(g, lp, scan.angles_rad, scan.range_max_m)
        u = np.stack([np.cos(lp[2] + scan.angles_rad), np.sin(lp[2] + scan.angles_rad)], axis=1)
        ends = lp[:2] + (expected[:, None] + g.resolution_m / 2) * u
        cells = g.world_to_cell(ends)
        ok = use & (expected < scan.range_max_m) & g.in_bounds(cells)
        own = np.full(len(expected), -1)
        own[ok] = self._owner[cells[ok, 1], cells[ok, 0]]
        return expected, u, ends, own

    def _objects_off(self, dist: np.ndarray, owner: np.ndarray, beam_owner: np.ndarray,
                     scan: Scan, expected: np.ndarray) -> list[tuple[MapObject, np.ndarray]]:
        """The objects whose beams miss them while the rest of the scan fits the map, each with
        its returns: [(object, (N,) bool)]. ``dist``, ``owner`` (N,): per return, the distance
        to the nearest map cell and its owner (``_near_dist``, ``_near_owner``);
        ``beam_owner`` (B,): per beam, the owner of the cell the map expects it to end on
        (:meth:`_classify_beams`), ``expected`` (B,) that range [m]. An object's returns are
        those within ``nudge_radius_m`` whose nearest map cell is its own; it is off when at
        least ``nudge_min_off_fraction`` of the beams the map expects to end on it (within
        ``absence_max_range_m``) end more than ``offset_min_m`` before or beyond it (a return
        inside its old outline is near it, but a beam cannot end there if it stood there).
        Empty unless the scan's other returns near the map fit it (at least
        ``offset_min_fit_fraction`` within ``offset_fit_m``): otherwise the pose is off."""
        c = self.cfg
        objs = self.object_map.objects
        cand = (dist <= c.nudge_radius_m) & (owner >= 0)
        rest = dist <= c.absence_near_m
        residual = np.where(scan.valid, scan.ranges_m, np.inf) - expected
        near_beams = expected <= c.absence_max_range_m
        odd = []
        for i in np.unique(owner[cand]):
            o = objs[int(i)]
            if o.structure or o.status not in ("U", "M") or not self._distinctive(o):
                continue
            mine = cand & (owner == i)
            expect = near_beams & (beam_owner == i)
            if mine.sum() < c.offset_min_returns or expect.sum() < c.offset_min_returns:
                continue
            if np.mean(np.abs(residual[expect]) > c.offset_min_m) >= c.nudge_min_off_fraction:
                odd.append((o, mine))
                rest &= ~mine
        if not odd or rest.sum() < 2 * c.offset_min_returns:
            return []
        if np.mean(dist[rest] <= c.offset_fit_m) < c.offset_min_fit_fraction:
            return []  # the scan as a whole misses the map: the pose, not an object, is off
        return odd

    def _nudge_fit(self, o: MapObject):
        """The match of ``o`` onto the returns gathered by :meth:`_nudge`, or None."""
        c = self.cfg
        hits = self._nudge_cells.get(o.id, {})
        keys = np.array([k for k, v in hits.items() if v >= c.nudge_min_cell_scans])
        if len(keys) < max(c.chair_min_cells, c.match_min_edge_fraction * len(o.edge_xy)):
            return None
        pts = self._grid.cell_to_world(keys)
        if _larger_than(_diameter(pts), o):
            return None
        views = self._nudge_views.get(o.id, [])
        mt = self._match(pts, o)
        now = self._field(o).score(transform_points(inverse(o.pose_xytheta), pts))
        if (mt.score < c.match_min_score or mt.score < now + c.nudge_min_gain
                or _footprint_shift_m(o, o.pose_xytheta, mt.pose_xytheta) <= c.nudge_min_shift_m
                or _move_m(o, mt) > c.nudge_max_shift_m
                or not self._free_consistent(o, mt)):
            return None
        sup, con = beam_consistency(o, mt.pose_xytheta, views, c.hit_tolerance_m,
                                    c.match_through_m)
        if con > c.match_max_through_fraction * (sup + con):
            return None
        return mt

    def _owned_by_doubted(self, owner: np.ndarray) -> np.ndarray:
        """(N,) bool: which entries of ``owner`` (object indices, < 0 for none) are in doubt."""
        objs = self.object_map.objects
        return np.array([i >= 0 and objs[i].id in self._doubt for i in owner], dtype=bool)

    def _count_near_returns(self, pts: np.ndarray, lp: np.ndarray) -> None:
        g = self._grid
        c = g.world_to_cell(pts)
        ok = g.in_bounds(c)
        ok &= np.hypot(*(pts - lp[:2]).T) <= self.cfg.absence_max_range_m
        c = c[ok]
        own = self._near_owner[c[:, 1], c[:, 0]]
        keep = (own >= 0) | (self._near_dist[c[:, 1], c[:, 0]] > self.cfg.delta_W_m)
        add_counts(self._near_returns, c[keep, 1], c[keep, 0])

    def _explained(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(near any occupied cell, explained) per point (N,). S_free filtering (paper,
        Sec. IV-B): returns within delta_W of the map are explained, except near an object in
        doubt (beyond the paper: so that the chair hypothesis sees where it stands now)."""
        g = self._grid
        c = g.world_to_cell(pts)
        ok = g.in_bounds(c)
        near = np.ones(len(pts), dtype=bool)
        owner = np.full(len(pts), STRUCTURE, dtype=np.int32)
        near[ok] = self._near_dist[c[ok, 1], c[ok, 0]] <= self.cfg.delta_W_m
        owner[ok] = self._near_owner[c[ok, 1], c[ok, 0]]
        explained = near.copy()
        if self._doubt:
            explained &= ~self._owned_by_doubted(owner)
        return near, explained

    # Algorithm 1, with hits clearing seen-through marks (beyond the paper)
    def _absence(self, lp, scan, pts, stamp_s, events, agreement: float,
                 sees_through: bool = True) -> None:
        """Alg. 1 and the beam evidence for one scan whose pose agrees with the map on
        ``agreement`` of the beams (:meth:`_agreement`). ``sees_through`` False (a pose only
        the filter vouches for): the scan's returns still show objects there, but its rays
        and beams passing through objects are no evidence they are gone."""
        g = self._grid
        c = self.cfg
        beams = self._beams
        if agreement < c.absence_min_agreement:
            # a pose 0.2 m off sees through small objects; that a new object has gone again
            # asks less of it (the Intel log: where chairs had been moved away the map's
            # agreement fell to 0.76-0.88)
            if sees_through and agreement >= c.add_gone_min_agreement:
                self._mark_passed(lp, scan, pts, from_m=0.0)
                self._count_run_hits(lp, pts)
            return
        if not sees_through:
            # beyond the paper: a filter locked onto the wrong place is as confident as a
            # right one, and its pose fits the map well enough to pass the agreement test (it
            # converged there because the scan fits); absences from such poses emptied the
            # map of pieces that stood where they were
            beams = (beams[0], beams[1], np.zeros_like(beams[2]), *beams[3:])
        # returns farther than absence_max_range_m count as free space up to that range
        ends = _ray_ends(lp, scan, pts, c.absence_max_range_m)
        if len(ends) == 0:
            return
        if sees_through:
            self.counts["seen_through_scans"] += 1
            self._mark_seen_through(lp, ends)
            self._mark_passed(lp, scan, pts, from_m=c.absence_max_range_m)
            self._count_run_hits(lp, pts)
        objs = self.object_map.objects
        hit_cells = g.world_to_cell(pts)
        okh = g.in_bounds(hit_cells)
        # a return is stronger evidence than rays passing: cells with returns are not free
        self._free[hit_cells[okh, 1], hit_cells[okh, 0]] = 0
        self._passed[hit_cells[okh, 1], hit_cells[okh, 0]] = 0
        hit_own = self._owner[hit_cells[okh, 1], hit_cells[okh, 0]]
        hit_loc = self._local[hit_cells[okh, 1], hit_cells[okh, 0]]
        for i in np.unique(hit_own[hit_own >= 0]):
            o = objs[int(i)]
            o.seen_count += 1
            if o.id in self._seen:  # returns on the object: those cells are there
                self._seen[o.id].difference_update(hit_loc[hit_own == i].tolist())
        touched = self._beam_evidence(beams)
        if c.absence_far_hits:
            self._count_far_hits(beams)
        back = {oid for oid in touched & self._withheld
                if self._confirmed(self.object_map.by_id[oid])}
        if back:  # seen standing there: back into the localizer's map
            self._withheld -= back
            self._sync_localizer()
        gone = []
        for oid in touched:
            o = self.object_map.by_id.get(oid)
            if o is None or o.status not in ("U", "M") or o.structure:
                continue
            through, hits = self._through.get(oid, 0), self._hits.get(oid, 0)
            if through >= c.doubt_min_beams and through >= c.doubt_fraction * (through + hits):
                self._doubt.add(oid)
            hits += self._far_hits.get(oid, 0)  # (absence_far_hits; else none counted)
            if (max(self._gone_fractions(o)) > c.beta_thresh
                    and self._rays.get(oid, 0) >= c.absence_min_rays
                    and through >= c.absence_min_beams
                    and through >= c.absence_through_fraction * (through + hits)):
                if not self._distinctive(o) and self._something_there(o):
                    self._doubt.add(oid)
                    self.counts["absence_vetoed"] += 1
                else:
                    gone.append(o)
        for o in gone:  # after the loop: marking re-renders and re-indexes the owner grid
            if o.status not in ("U", "M"):
                continue
            mt = self._shifted_fit(o) if c.absence_looks_near else None
            if mt is not None:
                self._relocate(o, mt, stamp_s, events)
                self.counts["shifted_not_gone"] += 1
            else:
                self._mark_absent(o, stamp_s, events)

    def _shifted_fit(self, o: MapObject):
        """(absence_looks_near) ``o`` matched onto this run's returns around its outline:
        cells within ``nudge_max_shift_m`` of it hit at least twice (``_near_returns``),
        nearer to it than to any other object or wall; the match if it passes the nudge's
        tests (score, ``absence_near_min_edge_fraction`` of its edge cells in returns, not
        larger, a shift, free space), else None."""
        c = self.cfg
        g = self._grid
        near = self._outline_distance(o, o.pose_xytheta, c.nudge_max_shift_m)
        if near is None:
            return None
        win, _, d = near
        keep = ((d <= c.nudge_max_shift_m) & (self._near_returns[win] >= 2)
                & self._own_or_unmapped(win, self.object_map.objects.index(o)))
        iy, ix = np.nonzero(keep)
        # which object is given (the returns are its own): no look-alikes to tell apart, so
        # less of it than a chair needs (match_min_edge_fraction), but not a speck that fits
        # any end of a larger piece beside it
        if len(iy) < max(c.chair_min_cells, c.absence_near_min_edge_fraction * len(o.edge_xy)):
            return None
        pts = g.cell_to_world(np.stack([ix + win[1].start, iy + win[0].start], axis=1))
        if _larger_than(_diameter(pts), o):
            return None
        mt = self._match(pts, o)
        if (mt.score < c.match_min_score
                or _footprint_shift_m(o, o.pose_xytheta, mt.pose_xytheta) <= c.nudge_min_shift_m
                or _move_m(o, mt) > c.nudge_max_shift_m
                or not self._free_consistent(o, mt)):
            return None
        return mt

    def _mark_seen_through(self, lp, ends) -> None:
        """Rays from the laser at ``lp`` to ``ends`` (R, 2): the cells they cross are seen
        free this run (a relocation may not put an object there) and, on an object, seen
        through (Alg. 1's I'_i)."""
        g = self._grid
        cells, ray = traverse_rays(g, lp[:2], ends, exclude_end_m=self.cfg.absence_exclude_end_m)
        if not len(cells):
            return
        add_counts(self._free, cells[:, 1], cells[:, 0])
        # rays that went on well beyond a cell: the evidence that a new object is gone again
        # (a chair grid smeared by pose jitter has cells just in front of the surface)
        beyond = np.hypot(*(g.cell_to_world(cells) - ends[ray]).T) > self.cfg.add_gone_beyond_m
        self._count_passes(cells[beyond])
        objs = self.object_map.objects
        own = self._owner[cells[:, 1], cells[:, 0]]
        for i in np.unique(own[own >= 0]):
            o = objs[int(i)]
            m = own == i
            seen = self._seen.setdefault(o.id, set())
            seen.update(self._local[cells[m, 1], cells[m, 0]].tolist())
            self._rays[o.id] = self._rays.get(o.id, 0) + len(np.unique(ray[m]))

    def _mark_passed(self, lp, scan: Scan, pts: np.ndarray, from_m: float) -> None:
        """Rays reaching past ``from_m`` [m], up to add_gone_max_range_m: the cells they pass
        beyond ``from_m`` - add_gone_beyond_m (:meth:`_mark_seen_through` counted the nearer
        ones) are evidence that a new object has gone again, and of nothing else."""
        c, g = self.cfg, self._grid
        if c.add_gone_max_range_m <= from_m:
            return
        ends = _ray_ends(lp, scan, pts, c.add_gone_max_range_m, longer_than_m=from_m)
        if not len(ends):
            return
        cells, ray = traverse_rays(g, lp[:2], ends, exclude_end_m=c.absence_exclude_end_m)
        if not len(cells):
            return
        xy = g.cell_to_world(cells)
        keep = ((np.hypot(*(xy - lp[:2]).T) > from_m - c.add_gone_beyond_m)
                & (np.hypot(*(xy - ends[ray]).T) > c.add_gone_beyond_m))
        self._count_passes(cells[keep])

    def _count_passes(self, cells: np.ndarray) -> None:
        """Rays passing well beyond ``cells`` (K, 2): in ``_passed`` (add_max_passed_fraction)
        and, where a return has landed this run, in ``_passed_run`` (add_max_flicker: a thing
        that came mid-run and stayed has not come and gone)."""
        add_counts(self._passed, cells[:, 1], cells[:, 0])
        cells = cells[self._hit_run[cells[:, 1], cells[:, 0]] > 0]
        add_counts(self._passed_run, cells[:, 1], cells[:, 0])

    def _count_run_hits(self, lp, pts: np.ndarray) -> None:
        """The returns ``pts`` (N, 2) within add_gone_max_range_m, as the rays counted in
        ``_passed_run`` (add_max_flicker)."""
        g = self._grid
        near = pts[np.hypot(*(pts - lp[:2]).T) <= self.cfg.add_gone_max_range_m]
        c = g.world_to_cell(near)
        c = c[g.in_bounds(c)]
        add_counts(self._hit_run, c[:, 1], c[:, 0])

    def _surface_normals(self) -> tuple[np.ndarray, np.ndarray]:
        """Per cell of the current map (H, W): the unit normal of the occupied surface (x and
        y components; its sign is arbitrary), zero where the surface has no one direction
        (a corner, a blob's inside, open space). The structure tensor of the occupied cells
        blurred by a cell, over about 3 cells: the gradients on both sides of a wall one cell
        thick point opposite ways, and their outer products agree on its normal."""
        if self._normals is None:
            occ = ndimage.gaussian_filter(self._grid.occupied.astype(np.float32), 1.0)
            gy, gx = np.gradient(occ)
            jxx = ndimage.gaussian_filter(gx * gx, 3.0)
            jyy = ndimage.gaussian_filter(gy * gy, 3.0)
            jxy = ndimage.gaussian_filter(gx * gy, 3.0)
            tr = jxx + jyy
            coherence = np.hypot(jxx - jyy, 2 * jxy) / np.maximum(tr, 1e-12)
            theta = 0.5 * np.arctan2(2 * jxy, jxx - jyy)
            ok = (tr > 1e-4) & (coherence > 0.5)
            self._normals = (np.where(ok, np.cos(theta), 0.0), np.where(ok, np.sin(theta), 0.0))
        return self._normals

    def _grazing(self, u: np.ndarray, cells: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """(B,) bool: of the beams ``ok`` with directions ``u`` (B, 2) the map expects to end in
        ``cells`` (B, 2), those meeting its surface more than ``absence_max_incidence_deg``
        from the normal (:meth:`_surface_normals`)."""
        out = np.zeros(len(u), dtype=bool)
        if self.cfg.absence_max_incidence_deg >= 90.0 or not ok.any():
            return out
        nx, ny = self._surface_normals()
        c = cells[ok]
        n = np.stack([nx[c[:, 1], c[:, 0]], ny[c[:, 1], c[:, 0]]], axis=1)
        cos_in = np.abs(np.sum(u[ok] * n, axis=1))
        has = np.hypot(n[:, 0], n[:, 1]) > 0.5
        out[ok] = has & (cos_in < np.cos(np.radians(self.cfg.absence_max_incidence_deg)))
        return out

    def _classify_beams(self, lp, scan):
        """Per beam: (owner of the cell the map expects it to end on: object index, STRUCTURE
        or -1 for none, passes well beyond it, ends on it) — the ranges the current map
        predicts against the measured ones; beams ending short of it (occluded) are neither."""
        c = self.cfg
        g = self._grid
        r = scan.ranges_m
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r >= scan.range_min_m)
        r = np.where(valid, np.minimum(r, scan.range_max_m), 0.0)
        expected, u, ends, own = self._expected_ends(lp, scan, valid)
        self._expected = expected
        cells = g.world_to_cell(ends)
        ok = valid & (expected < scan.range_max_m) & g.in_bounds(cells)
        # a beam passes through an object only if the map has the object a cell deeper along
        # it too: one that clips an edge cell (which holds the surface and some free space
        # beside it, as in any map built from scans) passes the object, not through it
        deeper = g.world_to_cell(ends + g.resolution_m * u)
        inside = g.in_bounds(deeper)
        own_deeper = np.full(len(r), -2)
        own_deeper[inside] = self._owner[deeper[inside, 1], deeper[inside, 0]]
        through = ok & (r > expected + c.absence_beyond_m) & (own_deeper == own)
        on = ok & (np.abs(r - expected) <= c.hit_tolerance_m)
        # a beam grazing the surface says nothing either way (absence_max_incidence_deg)
        grazing = self._grazing(u, cells, ok)
        through &= ~grazing
        on &= ~grazing
        # a beam with no return reads the range limit and ended on nothing: near the limit
        # it used to count as ending on any object the map expected there, and a gone
        # piece the robot drove towards collected such hits until it could not be absent
        on &= scan.valid
        # beyond absence_max_range_m a heading error of a degree moves a beam by more than a
        # small object's width: such beams are no evidence for or against an object
        own_near = np.where(expected <= c.absence_max_range_m, own, -1)
        loc = np.full(len(r), -1)
        loc[ok] = self._local[cells[ok, 1], cells[ok, 0]]
        return own, ok, through, on, own_near, loc

    def _agreement(self, beams) -> tuple[int, int]:
        """(beams the map expects to end on something, of them ending there) for the pose
        test, leaving out the beams of every object that this scan sees through as a whole
        (at least ``agreement_gone_min_beams`` of its beams, ``agreement_gone_fraction`` of
        them passing well beyond it). Beyond the paper: a piece that was moved away sends
        all its beams through, and counting them made the test fail exactly where the room
        changed (true poses, a rearranged hall: 41-52 % of scans skipped in a run, the
        evidence of every removal among them); a wrong pose instead disagrees a little on
        everything, walls and columns included. Only when at most one object, or
        ``agreement_gone_max_share`` of the objects in view, is gone are any left out. Hall
        seeds 101 and 103, true poses against poses 0.2 m off: this test at 0.85 skips
        0-25 % / 59-78 %, the plain fraction at 0.75 skipped 7-52 % / 48-64 %."""
        own, _, through, on = beams[:4]
        c = self.cfg
        in_view = gone = 0
        # the objects the localizer is not given are not what its pose is tested on
        out = (np.isin(own, self._withheld_idx()) if c.withhold_agreement
               else np.zeros(len(own), dtype=bool))
        keep = ~out
        own = np.where(out, -1, own)
        for i in np.unique(own[own >= 0]):
            m = own == i
            t, h = int(through[m].sum()), int(on[m].sum())
            in_view += int(t + h >= c.agreement_gone_min_beams)
            if t >= c.agreement_gone_min_beams and t >= c.agreement_gone_fraction * (t + h):
                keep &= ~m
                gone += 1
        if (gone > max(1, c.agreement_gone_max_share * in_view)
                and not self._structure_agrees(own, through, on)):
            # most of the furniture in view gone at once: the pose is wrong (a filter locked
            # onto a look-alike place 3.5 m off agreed on the columns and sent its beams
            # through every piece), not the room; the plain test decides
            keep = ~out
        return int((through & keep).sum() + (on & keep).sum()), int((on & keep).sum())

    def _structure_agrees(self, own: np.ndarray, through: np.ndarray, on: np.ndarray) -> bool:
        """``agreement_structure_min_beams``: enough of the beams the map expects to end on
        structure end there (per beam: ``own`` its expected owner, ``through``, ``on``). Walls
        of one direction fit a pose slid along them too: such a pose's scans then feed the
        tracks, but their rays are evidence of absence only if the scan-to-map alignment,
        which tests the whole map's edges, confirmed the pose (absence_from_verified_only)."""
        k = self.cfg.agreement_structure_min_beams
        if k is None:
            return False
        s = own == STRUCTURE
        t, h = int(through[s].sum()), int(on[s].sum())
        return h >= k and h >= self.cfg.min_agreement * (t + h)

    def _beam_evidence(self, beams) -> set[int]:
        """Beyond Alg. 1, robust to pose errors of a cell or two: the beams the current map says
        should end on an object either pass well beyond it (evidence it is gone) or end on it
        (evidence it is there); beams ending short of it (occluded) say nothing. Adds to the
        run's counts per object id; returns the ids touched by this scan."""
        _, _, through, on, own, loc = beams
        objs = self.object_map.objects
        touched = set()
        for i in np.unique(own[own >= 0]):
            m = own == i
            oid = objs[int(i)].id
            touched.add(oid)
            self._through[oid] = self._through.get(oid, 0) + int(np.sum(through[m]))
            self._hits[oid] = self._hits.get(oid, 0) + int(np.sum(on[m]))
            ft = self._front_through.setdefault(oid, set())
            ft.update(loc[m & through].tolist())
            ft.difference_update(loc[m & on].tolist())
            self._front.setdefault(oid, set()).update(loc[m & (through | on)].tolist())
        return touched

    def _count_far_hits(self, beams) -> None:
        """``absence_far_hits``: add to the run's counts the beams ending on each object
        beyond ``absence_max_range_m`` (:meth:`_classify_beams`)."""
        own, _, _, on, own_near = beams[:5]
        far = on & (own >= 0) & (own_near < 0)
        objs = self.object_map.objects
        for i, n in zip(*np.unique(own[far], return_counts=True), strict=True):
            oid = objs[int(i)].id
            self._far_hits[oid] = self._far_hits.get(oid, 0) + int(n)

    def _gone_fractions(self, o: MapObject) -> tuple[float, float]:
        """(Alg. 1's fraction of the core cells seen through this run, the fraction of the
        surface the beams should have ended on that they passed). Beyond Alg. 1, the second:
        a short-range laser reaches only the near side of an object (its rays end inside it
        at max range), so its core is never crossed; the surface seen through is the same
        evidence."""
        core = self._core(o)
        frac = len(self._seen.get(o.id, set()) & core) / max(len(core), 1)
        front = self._front.get(o.id, set())
        return frac, len(self._front_through.get(o.id, set())) / max(len(front), 1)

    def absence_evidence(self, object_id: int) -> dict:
        """This run's evidence that object ``object_id`` is gone (Alg. 1 and the beams):
        ``rays`` through its cells, ``beams_through`` (passing well beyond it) and
        ``beams_on`` (ending on it), ``core_seen`` and ``front_seen_through`` (the fractions
        beta_thresh is tested on), and ``doubted``."""
        o = self.object_map.by_id.get(object_id)
        placed = o is not None and o.status in ("U", "M") and not o.structure
        core_seen, front_seen_through = self._gone_fractions(o) if placed else (0.0, 0.0)
        return {
            "rays": self._rays.get(object_id, 0),
            "beams_through": self._through.get(object_id, 0),
            "beams_on": self._hits.get(object_id, 0),
            "core_seen": core_seen,
            "front_seen_through": front_seen_through,
            "doubted": object_id in self._doubt,
        }

    def _clear_evidence(self, oid: int) -> None:
        for d in (self._seen, self._rays, self._through, self._hits, self._far_hits, self._front,
                  self._front_through, self._nudge_cells, self._nudge_scans, self._nudge_views,
                  self._nudge_tried):
            d.pop(oid, None)
        self._doubt.discard(oid)

    def _mark_absent(self, o: MapObject, stamp_s, events) -> None:
        o.status = "A"
        o.record(self.run, stamp_s)
        self._clear_evidence(o.id)
        events.append(Event(float(stamp_s), self.run, "absent", o.id, o.label,
                            o.pose_xytheta.tolist(), None))
        self.counts["absent"] += 1
        self._rerender()
        # order does not matter: an absence may match a chair seen before it. Beyond the
        # paper, the chairs (tracks, and Gamma objects seen this run) are tried best fit to
        # this object first: the first to fit used to take it, often a look-alike's new place
        fits = []
        for m in self._meta:
            if m.matched_object is None and m.dominant() == "chair":
                view = self._chair_view(m)
                fit = None if view is None else self._fit(m, o, 0, view)
                if fit is not None:
                    fits.append((fit[0], len(fits), m, None, None))
        for g in self.object_map.Gamma if self.cfg.match_absence_to_gamma else []:
            if g.id in self._gamma_this_run:  # seen in an earlier run only: no evidence
                fit = self._fit_gamma_ranked(g, o)
                if fit is not None:
                    fits.append((fit[0], len(fits), None, g, fit[1]))
        for _, _, m, g, mt in sorted(fits, key=lambda f: f[:2], reverse=True):
            if o.status != "A":
                break
            if m is not None:
                self._try_match(m, stamp_s, events)  # its best object may be another one
            elif g in self.object_map.objects:
                self.object_map.objects.remove(g)
                absent_at = o.pose_xytheta.copy()
                self._relocate(o, mt, stamp_s, events)
                if self.cfg.match_retake_from_gamma:
                    self._on_gamma[o.id] = (absent_at, g)

    # ---------------------------------------------------------- metaobjects
    def _track(self, pts, stamp_s, events, verified: bool = True) -> None:
        c = self.cfg
        for m in self._meta:
            m.predict(stamp_s)
        if len(pts) < c.min_cluster_points:
            return
        centres, labels = mean_shift(pts, c.meanshift_bandwidth_m)
        assigned: dict[int, list[np.ndarray]] = {}
        fresh: list[np.ndarray] = []
        for k in range(len(centres)):
            z = pts[labels == k]
            if len(z) < c.min_cluster_points:
                continue
            best, best_lp = None, len(z) * np.log(c.beta_min_prob)  # m_new
            zc = z.mean(axis=0)
            for m in self._meta:
                if np.hypot(*(m.kf.x[:2] - zc)) > c.gate_m and not m.near(z, c.gate_m / 3):
                    continue
                lp = m.log_p(z)
                if lp > best_lp:
                    best, best_lp = m, lp
            if best is None:
                fresh.append(z)
            else:  # beyond the paper: several clusters may belong to one (large) object
                assigned.setdefault(best.id, []).append(z)
        by_id = {m.id: m for m in self._meta}
        touched = []
        for mid, zs in assigned.items():
            m = by_id[mid]
            z = np.vstack(zs)
            m.update(z, stamp_s, verified=verified)
            self._note_view(m, z)
            touched.append(m)
        for z in fresh:
            m = Metaobject(self._next_meta, z, stamp_s, c, self._grid.resolution_m,
                           verified=verified)
            self._note_view(m, z)
            self._next_meta += 1
            self._meta.append(m)
        self._merge_metaobjects()
        for m in touched:
            if m not in self._meta:
                continue
            if (m.matched_object is None and m.n_obs >= c.chair_min_scans
                    and m.n_obs % 3 == 0 and m.dominant() == "chair"):
                self._try_match(m, stamp_s, events)

    def _note_view(self, m: Metaobject, points_xy: np.ndarray) -> None:
        """Give track ``m`` the current scan's view (if any) and keep its nearest view: the
        median range [m] of ``points_xy`` (its returns in this scan, map frame) from the laser."""
        if self._view is None:
            return
        if (self.cfg.still_max_vacated is not None
                or self.cfg.person_min_vacated is not None):  # for Metaobject.vacated only
            m.note_passes(self._view, self.cfg.match_through_m)
        m.add_view(self._view)
        r = float(np.median(np.hypot(*(points_xy - self._view[0][:2]).T)))
        m.nearest_view_m = min(m.nearest_view_m, r)

    def _merge_metaobjects(self) -> None:
        """Chair-like metaobjects whose evidence grids touch are one object seen in parts."""
        metas = [m for m in self._meta if m.dominant() != "person"]
        gone: set[int] = set()
        for a_i, a in enumerate(metas):
            if a.id in gone:
                continue
            for b in metas[a_i + 1:]:
                if b.id in gone or a.matched_object is not None and b.matched_object is not None:
                    continue
                if a.touches(b):
                    a.absorb(b)
                    gone.add(b.id)
        if gone:
            self._meta = [m for m in self._meta if m.id not in gone]

    def _candidates(self, pts: np.ndarray) -> list[tuple[int, MapObject]]:
        """(tier, object) pairs a chair may be: absent ones (paper) and placed ones near it in
        doubt, tier 0; movable ones elsewhere not seen at their place this run (paper: A and
        M), tier -1; with
        ``prior_earlier_poses``, movable ones elsewhere not seen at their place this run that
        stood near the chair before, tier -2 (only a match at an earlier pose counts, then as
        tier 0); with ``match_retake_from_gamma``, one the absence's match put on a Gamma
        object this run, and with ``match_retake_from_chair``, one a far track's chair took
        from A this run: tier 0 if the chair is near where it was absent from."""
        c = pts.mean(axis=0)
        out = []
        for o in self.object_map.objects:
            if o.structure:
                continue
            if o.status == "A":
                if not self._absent_too_long(o):
                    out.append((0, o))
                continue
            if o.status not in ("U", "M"):
                continue
            if o.id in self._on_gamma:
                # placed on a Gamma object at its absence, before any live chair was seen:
                # a chair near where it was absent from may take it back
                if self._within_retake(o, self._on_gamma[o.id][0], c):
                    out.append((0, o))
                continue
            if o.id in self._on_chair and self._within_retake(o, self._on_chair[o.id][0], c):
                # a far chair took it from A: a chair near where it was absent from may take
                # it back (not the same track: its chair is not near there)
                out.append((0, o))
                continue
            confirmed = self._confirmed(o)
            near = np.hypot(*(o.pose_xytheta[:2] - c)) < self.cfg.doubt_search_m + o.extent_m()
            doubted = o.id in self._doubt
            if near and not confirmed and doubted:
                out.append((0, o))
            elif o.status == "M" and not confirmed and self.cfg.match_unseen_movable:
                out.append((-1, o))
            elif o.status == "M" and not confirmed and self.cfg.prior_earlier_poses:
                q = o.earlier_poses()
                if np.any(np.hypot(*(q[:, :2] - c).T) < self.cfg.doubt_search_m + o.extent_m()):
                    out.append((-2, o))
        return out

    def _within_retake(self, o: MapObject, absent_at: np.ndarray, xy: np.ndarray) -> bool:
        """``xy`` (2,) is near enough to ``absent_at`` (the pose ``o`` was absent from) for a
        chair there to take ``o`` back (``match_retake_from_gamma``, ``..._from_chair``):
        within ``doubt_search_m`` plus its extent."""
        return bool(np.hypot(*(absent_at[:2] - xy)) < self.cfg.doubt_search_m + o.extent_m())

    def _absent_too_long(self, o: MapObject) -> bool:
        """With ``absent_candidate_runs``: ``o`` has been absent for more runs than that (since
        the last entry of its history marking it absent), so no chair is tried as it."""
        k = self.cfg.absent_candidate_runs
        if k is None or o.status != "A":
            return False
        since = next((h["run"] for h in reversed(o.history) if h.get("status") == "A"), 0)
        return self.run - since > k

    def _at_earlier_pose(self, o: MapObject, pose_xytheta: np.ndarray) -> bool:
        """The object at ``pose_xytheta`` stands where it stood before (within
        ``earlier_pose_tolerance_m``; its current pose counts for an absent object)."""
        if not self.cfg.prior_earlier_poses:
            return False
        for q in o.earlier_poses():
            if o.status != "A" and np.allclose(q, o.pose_xytheta):
                continue  # where it is placed now is no earlier pose
            if np.hypot(*(q[:2] - pose_xytheta[:2])) > o.extent_m() + 0.5:
                continue
            if _footprint_shift_m(o, q, pose_xytheta) <= self.cfg.earlier_pose_tolerance_m:
                return True
        return False

    def _field(self, o: MapObject) -> EdgeField:
        f = self._fields.get(o.id)
        if f is None:
            f = self._fields[o.id] = EdgeField(o, self.cfg.match_edge_sigma_m)
        return f

    def _chair_view(self, m: Metaobject) -> tuple[np.ndarray, np.ndarray, float] | None:
        """(chair points, every return the track had, the chair's diameter [m]) of track
        ``m``, or None while it has fewer than ``chair_min_cells`` chair cells."""
        pts = m.chair_points()
        if len(pts) < self.cfg.chair_min_cells:
            return None
        return pts, m.chair_points(min_count=1, min_fraction=0.0), _diameter(pts)

    def _fit(self, m: Metaobject, o: MapObject, tier: int,
             view: tuple[np.ndarray, np.ndarray, float]) -> tuple[tuple, object] | None:
        """The chair of track ``m`` (its :meth:`_chair_view`) matched to ``o``, a candidate of
        ``tier`` (:meth:`_candidates`): (:func:`_rank_key`, match) if the match passes every
        test, else None (and the test that refused it counted in :attr:`refusals`)."""
        why = self._refusal(m, o, tier, view)
        if isinstance(why, str):
            self._refused(o, why, view[0])
            return None
        return why

    def _refused(self, o: MapObject, test: str, pts: np.ndarray) -> None:
        """Count a chair (cells ``pts`` (P, 2), map frame) refused as ``o`` by ``test``, and
        where it was (:attr:`refusals`, :attr:`refused_at`)."""
        key = (o.id, test)
        self.refusals[key] = self.refusals.get(key, 0) + 1
        c = np.round(pts.mean(axis=0), 1)
        self.refused_at.setdefault(key, set()).add((float(c[0]), float(c[1])))

    def _refusal(self, m: Metaobject, o: MapObject, tier: int,
                 view: tuple[np.ndarray, np.ndarray, float]) -> tuple[tuple, object] | str:
        pts, everything, diam_p = view
        if tier == -1 and m.n_obs < self.cfg.match_patience_scans:
            return "patience"  # a movable object seen nowhere yet: only once nothing absent fits
        if _larger_than(diam_p, o):
            return "larger"  # what is seen is larger than the object
        if len(pts) < self.cfg.match_min_edge_fraction * len(o.edge_xy):
            return "too_little"  # too little of the object seen yet to tell look-alikes apart
        mt = self._match(pts, o)
        if mt.score < self.cfg.match_min_score:
            return "score"
        if self._extends_beyond(o, mt, m.scan_points):
            return "extent"
        if not self._free_consistent(o, mt):
            return "free_space"
        # every return the track ever had must fit too, or this is a part of something
        # larger (a desk's corner looks like a footstool's)
        local = transform_points(inverse(mt.pose_xytheta), everything)
        if self._field(o).score(local) < self.cfg.match_min_score - 0.15:
            return "all_returns"
        if self._part_of_larger(o, mt):
            return "part_of_larger"
        if self.cfg.match_beam_check and not self._beams_consistent(o, mt, m.views):
            return "beams"
        # a speck: only a shift nearby
        if not self._distinctive(o) and self._far(o, mt):
            return "far"
        # across the room, only a chair seen from near enough to tell look-alikes apart
        if self._seen_only_from_afar(m.nearest_view_m) and self._far(o, mt):
            return "far_view"
        if self._beyond_max_move(o, mt):
            return "max_move"
        earlier = self._at_earlier_pose(o, mt.pose_xytheta)
        if tier == -2 and not earlier:
            return "not_earlier"
        if tier == -2:  # back where it stood: as good as doubted
            tier = 0
        return _rank_key(o, mt, tier, earlier), mt

    def _try_match(self, m: Metaobject, stamp_s, events, settle: bool = False) -> bool:
        """Match the chair of track ``m`` to the best candidate (:meth:`_candidates`) that
        passes every test, and relocate it. ``settle``: the track is leaving, so a match held
        back as ambiguous is made now (``match_ambiguity_settle``)."""
        view = self._chair_view(m)
        if view is None:
            return False
        best = None
        rivals: list = []
        for tier, o in self._candidates(view[0]):
            fit = self._fit(m, o, tier, view)
            if fit is None:
                continue
            key, mt = fit
            rivals.append((key, o, mt))
            if best is None or key > best[0]:
                best = (key, o, mt)
        if best is None:
            return False
        if self.cfg.match_twin_nearest:
            best = _nearest_twin(best, rivals, self.cfg)
        _, o, mt = best
        if (self.cfg.match_ambiguity_wait and not settle
                and m.n_obs < self.cfg.match_ambiguity_patience_scans
                and self._ambiguous(m.views, o, mt, view)):
            m.waited = True
            return False
        patient = m.n_obs < self.cfg.match_patience_scans
        if patient:
            # a different-looking candidate nearly as good: wait for more of the object
            for k2, o2, _ in rivals:
                if (o2 is not o and k2[:2] == best[0][:2] and k2[2] >= best[0][2] - 0.05
                        and not lookalike(o2, o, self.cfg.lookalike_tolerance)):
                    return False
        absent_at = o.pose_xytheta.copy() if o.status == "A" else None
        self._relocate(o, mt, stamp_s, events, support_scans=m.n_obs)
        left = self._on_chair.pop(o.id, None)
        if left is not None:
            self._release(left[1], stamp_s, events)
        if (self.cfg.match_retake_from_chair and absent_at is not None
                and not self._within_retake(o, absent_at, o.pose_xytheta[:2])):
            self._on_chair[o.id] = (absent_at, m)
        taken = self._on_gamma.pop(o.id, None)
        if taken is not None and taken[1] not in self.object_map.objects:
            # taken back: what the Gamma object was still stands there, and held the object
            # in the localizer's map until now; it joins the map as a new object at once
            self.object_map.objects.append(taken[1])
            self._add(taken[1], stamp_s, events)
            self._rerender()
        m.matched_object = o.id
        return True

    def _release(self, m: Metaobject, stamp_s, events) -> None:
        """Track ``m``'s chair lost the object it had been matched to
        (``match_retake_from_chair``): it is an unmatched chair again, as if no match had been
        made; a track that has ended joins Gamma now, as it would have then."""
        m.matched_object = None
        if not any(t is m for t in self._meta):
            self._end_track(m, stamp_s, events)

    def _settle(self, m: Metaobject, stamp_s, events) -> bool:
        """A leaving track whose match waited on ambiguity takes its best match now, with
        ``match_ambiguity_settle``; True if it relocated an object."""
        if not (self.cfg.match_ambiguity_settle and m.waited):
            return False
        return self._try_match(m, stamp_s, events, settle=True)

    def _confirmed(self, o: MapObject) -> bool:
        """``o`` was seen standing at its place this run (and is not in doubt)."""
        return self._hits.get(o.id, 0) >= self.cfg.confirm_min_beams and o.id not in self._doubt

    def _ambiguous(self, views: list, o: MapObject, mt,
                   view: tuple[np.ndarray, np.ndarray, float]) -> bool:
        """Beyond the paper: the chair seen by the scans ``views`` (a track's
        :attr:`Metaobject.views`), matched to ``o`` at ``mt``, fits an
        object that does not look like ``o`` and could be it (furniture not seen at its place
        this run, candidate or not) nearly as well: within ``match_ambiguity_margin``, not
        larger than it, free space and beams consistent there. What is seen of it does not
        yet tell the two apart (a corner of a lounge chair is a corner of a cabinet)."""
        pts, _, diam_p = view
        shapes: list[MapObject] = [o]
        for r in self.object_map.objects:
            # (an object is no rival of itself: lookalike() says nothing of specks too small
            # to call a shape, not even that one looks like itself)
            if (r is o or r.structure or r.status not in ("U", "M", "A") or not self._distinctive(r)
                    or self._confirmed(r) or self._absent_too_long(r)
                    or any(lookalike(r, q, self.cfg.lookalike_tolerance) for q in shapes)):
                continue
            shapes.append(r)
            if _larger_than(diam_p, r):
                continue
            mr = self._match(pts, r)
            if mr.score < mt.score - self.cfg.match_ambiguity_margin:
                continue
            if not self._free_consistent(r, mr):
                continue
            if self.cfg.match_beam_check and not self._beams_consistent(r, mr, views):
                continue
            self.counts["ambiguous"] += 1
            return True
        return False

    def _outline_distance(self, o: MapObject, pose_xytheta: np.ndarray, reach_m: float):
        """(window (rows, columns) of the grid reaching ``reach_m`` past ``o`` placed at
        ``pose_xytheta``, its cells in that window (bool), the distance [m] of every window
        cell to them), or None when the object is off the map."""
        g = self._grid
        cells = g.world_to_cell(o.cells_world(pose_xytheta, dense=True))
        ok = g.in_bounds(cells)
        if not ok.any():
            return None
        cells = np.unique(cells[ok], axis=0)
        win = _cells_window(cells, int(np.ceil(reach_m / g.resolution_m)) + 1, g.cells.shape)
        sy, sx = win
        mask = np.zeros((sy.stop - sy.start, sx.stop - sx.start), dtype=bool)
        mask[cells[:, 1] - sy.start, cells[:, 0] - sx.start] = True
        return win, mask, ndimage.distance_transform_edt(~mask) * g.resolution_m

    def _own_or_unmapped(self, win, own_index: int) -> np.ndarray:
        """Of the cells in the window ``win``: nearer to the object of index ``own_index``
        than to anything else, or beyond delta_W of the map (bool)."""
        return (self._near_owner[win] == own_index) | (self._near_dist[win] > self.cfg.delta_W_m)

    def _ring_counts(self, o: MapObject, pose_xytheta: np.ndarray, counts: np.ndarray,
                     r_in_m: float, r_out_m: float, min_hits: int = 2,
                     own_index: int | None = None) -> tuple[int, int]:
        """(cells of the object placed at ``pose_xytheta``, cells of the ring ``r_in_m`` <
        d <= ``r_out_m`` beyond its outline) holding at least ``min_hits`` of ``counts``
        (a per-cell grid of returns this run). With ``own_index`` (the object's index in the
        map), ring cells nearer to another object or wall are left out. -1, -1 when the
        object is off the map."""
        near = self._outline_distance(o, pose_xytheta, r_out_m)
        if near is None:
            return -1, -1
        win, mask, d = near
        ring = (d > r_in_m) & (d <= r_out_m)
        if own_index is not None:
            ring &= self._own_or_unmapped(win, own_index)
        hit = counts[win] >= min_hits
        return int(hit[mask].sum()), int(hit[ring].sum())

    def _part_of_larger(self, o: MapObject, mt) -> bool:
        """Beyond the paper: unexplained returns this run just outside the object placed at the
        match (a ring 0.1-0.4 m beyond its outline) mean what was seen is a part of something
        larger; a footstool fits any corner of a desk."""
        inside, outside = self._ring_counts(o, mt.pose_xytheta, self._unexplained, 0.1, 0.4)
        if inside < 0:
            return True
        return bool(outside > max(3, 0.25 * inside))

    def _extends_beyond(self, o: MapObject, mt, scan_points: list) -> bool:
        """With ``match_extent_check``: what single scans saw of the chair reaches more than
        ``match_extent_max_excess_m`` beyond ``o`` placed at ``mt`` along one of its sides
        (:func:`extent_excess` of its returns ``scan_points``)."""
        if not self.cfg.match_extent_check:
            return False
        ex = extent_excess(o, mt.pose_xytheta, scan_points, rect=self._field(o).rect)
        return ex is not None and ex > self.cfg.match_extent_max_excess_m

    def _beams_consistent(self, o: MapObject, mt, views: list) -> bool:
        """Beyond the paper: of the beams of the scans that saw the chair (``views``, as
        :attr:`Metaobject.views`) which the object at the match would have stopped, at most
        ``match_max_through_fraction`` went on well past it (:func:`beam_consistency`): a
        match that only fits the part of the chair one side showed is refused by the beams
        the other side let through."""
        sup, con = beam_consistency(o, mt.pose_xytheta, views, self.cfg.hit_tolerance_m,
                                    self.cfg.match_through_m)
        return con <= self.cfg.match_max_through_fraction * (sup + con)

    def _something_there(self, o: MapObject) -> bool:
        """Beyond the paper, for small objects: returns this run on or just around an object
        the rays see through (within ``absence_near_m`` of its outline, nearer to it than to
        anything else) mean it is there but not quite where the map has it: a pose error of a
        few cm, or a short shift. It is then in doubt, not absent, so the chair hypothesis that
        forms there relocates it (keeping its identity) instead of a false absence and a
        duplicate added at the end of the run."""
        idx = self.object_map.objects.index(o)
        inside, near = self._ring_counts(o, o.pose_xytheta, self._near_returns, 0.0,
                                         self.cfg.absence_near_m, own_index=idx)
        return inside + near >= self.cfg.absence_near_min_cells

    def _match(self, pts: np.ndarray, o: MapObject):
        """``o`` matched onto the chair points ``pts`` (P, 2) (map frame): its edge field,
        its yaw as the prior, and with ``match_free_first`` the free-space test choosing
        (:meth:`_free_consistent`)."""
        def free(pose: np.ndarray) -> bool:
            return self._free_consistent(o, SimpleNamespace(pose_xytheta=pose))

        return match_points(pts, o, self.cfg, self._field(o), prior_yaw=o.pose_xytheta[2],
                            accept=free if self.cfg.match_free_first else None)

    def _fit_gamma(self, g: MapObject, o: MapObject):
        """The match of ``o`` onto the Gamma object ``g`` (a chair seen, never added), or
        None if it fails the score, free-space or nearness (small objects) tests."""
        pts = g.cells_world()
        mt = self._match(pts, o)
        if not self._distinctive(o) and self._far(o, mt):
            self._refused(o, "gamma_far", pts)
            return None
        if (self._seen_only_from_afar(self._gamma_near.get(g.id, float("inf")))
                and self._far(o, mt)):
            self._refused(o, "gamma_far_view", pts)
            return None
        if mt.score < self.cfg.match_min_score:
            self._refused(o, "gamma_score", pts)
            return None
        if self._beyond_max_move(o, mt):
            self._refused(o, "gamma_max_move", pts)
            return None
        if self._extends_beyond(o, mt, self._gamma_points.get(g.id, [])):
            self._refused(o, "gamma_extent", pts)
            return None
        if not self._free_consistent(o, mt):
            self._refused(o, "gamma_free_space", pts)
            return None
        return mt

    def _fit_gamma_ranked(self, g: MapObject, o: MapObject) -> tuple[tuple, object] | None:
        """(:func:`_rank_key` as a tier-0 candidate, match) of ``o`` onto the Gamma object
        ``g`` (:meth:`_fit_gamma`), or None."""
        mt = self._fit_gamma(g, o)
        if mt is None:
            return None
        return _rank_key(o, mt, 0, self._at_earlier_pose(o, mt.pose_xytheta)), mt

    def _seen_only_from_afar(self, nearest_view_m: float) -> bool:
        """A chair whose nearest view was ``nearest_view_m`` (inf: not known, as for a track
        laid without a scan) was never seen within ``match_far_near_view_m``."""
        return bool(np.isfinite(nearest_view_m)
                    and nearest_view_m > self.cfg.match_far_near_view_m)

    def _far(self, o: MapObject, mt) -> bool:
        """The match ``mt`` puts ``o`` more than ``doubt_search_m`` from where it is."""
        return _move_m(o, mt) > self.cfg.doubt_search_m

    def _beyond_max_move(self, o: MapObject, mt) -> bool:
        """``match_max_move_m``: the match ``mt`` moves ``o`` farther than that. On the long
        real logs (ACES, MIT CSAIL) the relocations over 20 m were all of things that still
        stood, put onto generic shapes (a wall's corner, a blob of clutter) seen far away;
        the simulated halls' finds move pieces at most 17.7 m (docs/experiments.md,
        forty-sixth session)."""
        cap = self.cfg.match_max_move_m
        return cap is not None and _move_m(o, mt) > cap

    def _distinctive(self, o: MapObject) -> bool:
        """Beyond the paper (its small objects were confused): an object with less than
        ``small_object_area_m2`` of occupied cells (a table leg, a speck of clutter in a SLAM
        map) looks like any small thing, a person's legs standing still included, so it is
        only matched near where it was; and a pose error of a few cm is its own size, so rays
        pass through it while it stands there: it is absent only with no returns around it."""
        return len(o.shape_xy) * o.resolution_m**2 >= self.cfg.small_object_area_m2

    def _free_consistent(self, o: MapObject, mt) -> bool:
        """Beyond the paper: the object at the matched pose must not cover cells that rays
        crossed this run (seen free), or a partial view (one straight side) could put it
        anywhere along that side."""
        g = self._grid
        # only the object's inner cells: its edge cells hold its surface, so part of each is
        # free space that rays passing close beside it cross (as in any map built from scans)
        inner = self._inner.get(o.id)
        if inner is None:
            inner = self._inner[o.id] = _inner_cells(o)
        c = g.world_to_cell(transform_points(mt.pose_xytheta, inner))
        ok = g.in_bounds(c)
        if not ok.any():
            return False
        free = self._free[c[ok, 1], c[ok, 0]] >= self.cfg.match_free_rays
        return bool(np.mean(free) <= self.cfg.match_max_free_fraction)

    def _relocate(self, o: MapObject, mt, stamp_s, events,
                  support_scans: int | None = None) -> None:
        old = o.pose_xytheta.copy()
        o.pose_xytheta = mt.pose_xytheta.copy()
        moved = _footprint_shift_m(o, old, o.pose_xytheta) > 0.1
        o.status = "M" if (moved or o.moved_count) else "U"
        kind = "relocated" if moved else "restored"
        o.moved_count += int(moved)
        o.record(self.run, stamp_s)
        self._clear_evidence(o.id)
        self._hits[o.id] = self.cfg.confirm_min_beams  # just seen where it stands
        events.append(Event(float(stamp_s), self.run, kind, o.id, o.label, old.tolist(),
                            o.pose_xytheta.tolist(), float(mt.score), support_scans))
        self.counts[kind] += 1
        if moved:  # objects that look alike become movable too (paper, Fig. 1)
            for u in self.object_map.U:
                if not u.structure and u.id != o.id and lookalike(u, o,
                                                                   self.cfg.lookalike_tolerance):
                    u.status = "M"
                    u.record(self.run, stamp_s)
                    events.append(Event(float(stamp_s), self.run, "movable", u.id, u.label,
                                        u.pose_xytheta.tolist(), u.pose_xytheta.tolist()))
                    self.counts["movable"] += 1
        self._rerender()

    def _expire(self, stamp_s, events) -> None:
        keep = []
        for m in self._meta:
            if stamp_s - m.last_seen <= self.cfg.tau_memory_s:
                keep.append(m)
                continue
            if m.dominant() == "person" and not self._still_person(m):
                self.counts["persons"] += 1
            else:
                self._end_track(m, stamp_s, events)
        self._meta = keep

    def _still_person(self, m: Metaobject) -> bool:
        """With ``still_to_gamma``: ``m``, unmatched, is a still thing called a person for its
        motion (:meth:`Metaobject.still_though_moving`)."""
        return (self.cfg.still_to_gamma and m.matched_object is None
                and m.still_though_moving())

    def _end_track(self, m: Metaobject, stamp_s, events) -> None:
        """Track ``m`` ends (expired, or the run's end): an unmatched chair (unless it settles
        a held-back match now) or a still thing called a person joins Gamma."""
        if m.matched_object is not None:
            return
        if self._still_person(m) or (m.dominant() == "chair"
                                     and not self._settle(m, stamp_s, events)):
            self._to_gamma(m, stamp_s, events)

    def _to_gamma(self, m: Metaobject, stamp_s, events) -> None:
        pts = m.chair_points()
        if len(pts) < self.cfg.chair_min_cells:
            return
        if m.n_verified < self.cfg.gamma_min_verified_scans:
            # beyond the paper: seen only from poses the filter was sure of but nothing else
            # confirmed; a confidently wrong filter makes furniture out of walls
            self.counts["gamma_unverified"] += 1
            return
        self._gamma_part(pts, stamp_s, events, m.scan_points, m.nearest_view_m)

    def _gamma_part(self, pts: np.ndarray, stamp_s, events,
                    scan_points: list | None = None,
                    nearest_view_m: float = float("inf")) -> None:
        """Cells ``pts`` (P, 2) of a chair become a Gamma object, or join the one they overlap;
        ``scan_points``: the returns on it of the scans of its track that saw it
        (:attr:`Metaobject.scan_points`); ``nearest_view_m``: its track's nearest view."""
        # a part of an object the map already has where it stands (seen before it was placed
        # there) is no new object
        near, _ = self._explained(pts)
        if near.mean() > 0.5:
            return
        same = self._gamma_overlapping(pts)
        if same is not None:
            # the same unknown thing seen again by a new track (people walked in front of it,
            # the robot came back): one object, its cells the union of both views
            pts = np.vstack([same.cells_world(), pts])
            shape, edge, pose = shape_from_points(pts, self._grid.resolution_m)
            same.shape_xy, same.edge_xy, same.pose_xytheta = shape, edge, pose
            same.seen_count += 1
            self._gamma_this_run.add(same.id)
            self._gamma_points.setdefault(same.id, []).extend(scan_points or [])
            self._gamma_near[same.id] = min(self._gamma_near.get(same.id, float("inf")),
                                            nearest_view_m)
            self._fields.pop(same.id, None)
            self._inner.pop(same.id, None)
            self._cores.pop(same.id, None)
            return
        shape, edge, pose = shape_from_points(pts, self._grid.resolution_m)
        o = MapObject(self.object_map.next_id, None, "Gamma", pose, shape, edge,
                      resolution_m=self._grid.resolution_m)
        self.object_map.next_id += 1
        o.record(self.run, stamp_s)
        self.object_map.objects.append(o)
        self._gamma_this_run.add(o.id)
        self._gamma_points[o.id] = list(scan_points or [])
        self._gamma_near[o.id] = nearest_view_m
        events.append(Event(float(stamp_s), self.run, "gamma", o.id, None, None,
                            pose.tolist()))
        self.counts["gamma"] += 1

    def _gamma_overlapping(self, pts: np.ndarray) -> MapObject | None:
        """The object in Gamma that most of ``pts`` (P, 2) lie on (within delta_W), or None."""
        from scipy.spatial import cKDTree

        best, best_frac = None, 0.5
        for g in self.object_map.Gamma:
            d, _ = cKDTree(g.cells_world()).query(pts, distance_upper_bound=self.cfg.delta_W_m)
            frac = float(np.mean(np.isfinite(d)))
            if frac > best_frac:
                best, best_frac = g, frac
        return best

    def stats(self) -> dict:
        d = dict(self.counts)
        d["metaobjects"] = len(self._meta)
        d["ms_per_update"] = float(np.median(self._ms)) if self._ms else float("nan")
        return d


def _ray_ends(lp, scan: Scan, pts: np.ndarray, cap_m: float,
              longer_than_m: float = 0.0) -> np.ndarray:
    """(R, 2) where the rays of a scan from the laser at ``lp`` end, map frame [m]: first the
    returns ``pts`` (N, 2), then the beams that returned nothing (at the laser's max range),
    each cut at ``cap_m``; only rays reaching farther than ``longer_than_m``."""
    rng_ = np.hypot(*(pts - lp[:2]).T)
    long_ = rng_ > longer_than_m
    scale = np.minimum(1.0, cap_m / np.maximum(rng_[long_], 1e-9))
    ends = lp[:2] + (pts[long_] - lp[:2]) * scale[:, None]
    r = scan.ranges_m
    with np.errstate(invalid="ignore"):
        none = np.isfinite(r) & (r >= scan.range_max_m) & (r < 1e6)
    none_r = min(scan.range_max_m, cap_m)
    if none_r > longer_than_m and none.any():
        a = lp[2] + scan.angles_rad[none]
        ends = np.vstack([ends, lp[:2] + none_r * np.stack([np.cos(a), np.sin(a)], axis=1)])
    return ends


def _window(mask: np.ndarray, margin: int) -> tuple[slice, slice] | None:
    """(rows, columns) slices of the bounding box of ``mask``'s (H, W) True cells grown by
    ``margin`` cells (clipped to the grid), or None if none is True: a dilation reaching at
    most ``margin`` cells changes nothing outside it."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return None
    corners = np.array([[cols[0], rows[0]], [cols[-1], rows[-1]]])
    return _cells_window(corners, margin, mask.shape)


def _changed_regions(after: np.ndarray, before: np.ndarray) -> list[tuple[np.ndarray, int, int]]:
    """Region updates (cells (h, w) of ``after``, ix0, iy0) that cover every cell where the
    grids ``after`` and ``before`` (H, W) differ: the changed cells grown by 2 cells, one
    region per connected group. Worked out within a window 2 cells past the changes: the same
    regions as growing and labelling the whole grid, which on a large map cost a fifth of the
    stack's time."""
    diff = after != before
    win = _window(diff, 2)
    if win is None:
        return []
    lab, _ = ndimage.label(ndimage.binary_dilation(diff[win], iterations=2))
    y0, x0 = win[0].start, win[1].start
    out = []
    for sl in ndimage.find_objects(lab):
        if sl is None:
            continue
        sy = slice(sl[0].start + y0, sl[0].stop + y0)
        sx = slice(sl[1].start + x0, sl[1].stop + x0)
        out.append((after[sy, sx].copy(), sx.start, sy.start))
    return out


def _dilated(mask: np.ndarray, structure: np.ndarray,
             groups: list[np.ndarray] | None = None) -> np.ndarray:
    """``ndimage.binary_dilation(mask, structure)`` for a mask (H, W) and a square structure
    of odd side 2r + 1, dilated within the window r cells past the mask's cells only: nothing
    beyond reaches, and dilating the whole of a large map on every provisional landmark's
    change was a sixth of the stack's time on MIT CSAIL. ``groups``: the mask's cells
    (K, 2) (x, y) in groups that lie apart (landmarks across the map), each dilated within
    its own window; every cell of the mask must be in one."""
    out = np.zeros_like(mask, dtype=bool)
    r = structure.shape[0] // 2
    wins = [_window(mask, r)] if groups is None else [_cells_window(q, r, mask.shape)
                                                      for q in groups]
    for win in wins:
        if win is not None:
            out[win] |= ndimage.binary_dilation(mask[win], structure=structure)
    return out


def _cells_window(cells: np.ndarray, margin: int,
                  shape: tuple[int, int]) -> tuple[slice, slice] | None:
    """:func:`_window` of the cells (K, 2) (x, y) of a grid of ``shape`` (H, W)."""
    if len(cells) == 0:
        return None
    lo, hi = cells.min(axis=0), cells.max(axis=0)
    return (slice(max(lo[1] - margin, 0), min(hi[1] + margin + 1, shape[0])),
            slice(max(lo[0] - margin, 0), min(hi[0] + margin + 1, shape[1])))


def _max3x3_at(counts: np.ndarray, cy: np.ndarray, cx: np.ndarray) -> np.ndarray:
    """(K,) the largest of ``counts`` (H, W) over the 3 x 3 cells around each cell (cy, cx)
    (K,): ``ndimage.maximum_filter(counts, size=3)[cy, cx]`` (its border mode reflects, which
    for a 3 x 3 window repeats the edge cell, as clipping does), without filtering the whole
    grid on every scan (on MIT CSAIL's map that was a quarter of the stack's time)."""
    h, w = counts.shape
    out = counts[cy, cx].copy()
    xs = [np.clip(cx + dx, 0, w - 1) for dx in (-1, 0, 1)]
    for dy in (-1, 0, 1):
        yy = np.clip(cy + dy, 0, h - 1)
        for xx in xs:
            np.maximum(out, counts[yy, xx], out=out)
    return out


def _inner_cells(o: MapObject) -> np.ndarray:
    """(K, 2) the object's cells that are not edge cells, in its frame; all of them for an
    object that is mostly edge (small or thin: its few inner cells would let a match slide)."""
    if len(o.edge_xy) == 0:
        return o.shape_xy
    key = np.round(o.shape_xy / o.resolution_m).astype(np.int64)
    edge = np.round(o.edge_xy / o.resolution_m).astype(np.int64)
    inner = ~(key[:, None, :] == edge[None, :, :]).all(axis=2).any(axis=1)
    return o.shape_xy[inner] if inner.sum() >= 0.5 * len(key) else o.shape_xy
