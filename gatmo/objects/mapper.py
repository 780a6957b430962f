"""GATMO driven scan by scan (paper, Fig. 3): absence by ray tracing (Alg. 1), S_free filtering,
mean shift, metaobjects, matching and relocation, new objects at the end of a run.

The caller gives the robot's precise pose in the map frame and whether it is confident;
absence and the tracking of unexplained returns run only while it is (a wrong pose sees through
everything). Map changes are exposed as region updates for the localizer.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from gatmo.datasets.types import Scan
from gatmo.geometry import compose, transform_points, wrap_angle
from gatmo.maps.grid import OccupancyGrid
from gatmo.maps.likelihood import LikelihoodField
from gatmo.maps.raycast import cast_rays, traverse_rays
from gatmo.objects.config import GatmoConfig
from gatmo.objects.matching import EdgeField, lookalike, match_points
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

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _extents(points_xy: np.ndarray) -> np.ndarray:
    """Sorted extents (2,) of a point set along its principal axes [m]."""
    if len(points_xy) < 2:
        return np.zeros(2)
    d = points_xy - points_xy.mean(axis=0)
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    proj = d @ vt.T
    return np.sort(proj.max(axis=0) - proj.min(axis=0))


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
        self._explain = LikelihoodField(self._grid.copy(), cfg.delta_W_m + 0.1)
        self._pending: list[tuple[np.ndarray, int, int]] = []
        self._meta: list[Metaobject] = []
        self._next_meta = 1
        self._seen: dict[int, set] = {}
        self._rays: dict[int, int] = {}
        self._free = np.zeros(self._grid.cells.shape, dtype=np.int32)
        self._beam_votes: dict[int, list[int]] = {}  # id -> [scans voting gone, present]
        self._present_this_run: set[int] = set()  # ids with returns on them this run
        self._fields: dict[int, EdgeField] = {}
        self._cores: dict[int, set] = {}
        self.counts = {"absent": 0, "relocated": 0, "restored": 0, "added": 0, "movable": 0,
                       "gamma": 0, "persons": 0, "updates": 0}
        self._ms: list[float] = []
        self._build_owner()

    @classmethod
    def from_config(cls, cfg: GatmoConfig, grid: OccupancyGrid,
                    object_map: ObjectMap | None = None) -> GatmoMapper:
        if object_map is None:
            object_map = ObjectMap.from_grid(grid, cfg)
        return cls(object_map, grid, cfg)

    # ------------------------------------------------------------------ maps
    def grid(self) -> OccupancyGrid:
        """The reconfigured map (a copy)."""
        return self._grid.copy()

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
        g = self._grid
        self._owner = np.full(g.cells.shape, -1, dtype=np.int32)
        self._local = np.full(g.cells.shape, -1, dtype=np.int32)
        for i, o in enumerate(self.object_map.objects):
            if o.status not in ("U", "M") or o.structure:
                continue
            c = g.world_to_cell(o.cells_world())
            ok = g.in_bounds(c)
            k = np.nonzero(ok)[0]
            self._owner[c[ok, 1], c[ok, 0]] = i
            self._local[c[ok, 1], c[ok, 0]] = k

    def _rerender(self) -> None:
        new = self.object_map.render(self.base)
        diff = new.cells != self._grid.cells
        if diff.any():
            lab, _ = ndimage.label(ndimage.binary_dilation(diff, iterations=2))
            for sl in ndimage.find_objects(lab):
                if sl is None:
                    continue
                cells = new.cells[sl].copy()
                self._pending.append((cells, sl[1].start, sl[0].start))
                self._explain.update_region(cells, sl[1].start, sl[0].start)
        self._grid = new
        self._build_owner()

    # ------------------------------------------------------------------ runs
    def begin_run(self, run_id: int) -> None:
        self.run = int(run_id)
        self._meta = []
        self._seen = {}
        self._rays = {}
        self._free[:] = 0
        self._beam_votes = {}
        self._present_this_run = set()

    def end_run(self) -> list[Event]:
        """Dominant chairs seen this run and never matched become new objects (in M)."""
        events: list[Event] = []
        for m in self._meta:
            if m.dominant() == "chair" and m.matched_object is None:
                self._to_gamma(m, m.last_seen, events)
        self._meta = []
        for o in list(self.object_map.Gamma):
            if len(o.shape_xy) < self.cfg.add_min_cells:
                continue
            c = self._grid.world_to_cell(o.cells_world())
            ok = self._grid.in_bounds(c)
            overlap = np.mean(self._grid.occupied[c[ok, 1], c[ok, 0]]) if ok.any() else 1.0
            if overlap > 0.3:
                continue
            o.status = "M"
            o.record(self.run, self._last_stamp)
            events.append(Event(self._last_stamp, self.run, "added", o.id, o.label, None,
                                o.pose_xytheta.tolist()))
            self.counts["added"] += 1
        self._rerender()
        return events


    # ---------------------------------------------------------------- update
    def update(self, pose_xytheta, scan: Scan, *, pose_confident: bool,
               stamp_s: float) -> list[Event]:
        """One scan from the base pose (map frame). Returns what changed."""
        t0 = time.perf_counter()
        self._last_stamp = float(stamp_s)
        events: list[Event] = []
        self.counts["updates"] += 1
        if not pose_confident:
            self._expire(stamp_s, events)
            return events
        lp = compose(np.asarray(pose_xytheta, dtype=float), scan.laser_pose_xytheta)
        pts = transform_points(lp, scan.points_laser_xy(only_valid=True))
        far = self._explain.distance_at(pts) > self.cfg.delta_W_m
        if len(pts) and 1.0 - far.mean() < self.cfg.min_explained_fraction:
            # most returns off the map: the pose is wrong however confident the filter is
            self.counts["skipped_poor_fit"] = self.counts.get("skipped_poor_fit", 0) + 1
            self._expire(stamp_s, events)
            return events
        self._absence(lp, scan, pts, stamp_s, events)
        unexplained = pts[far]
        self._track(unexplained, stamp_s, events)
        self._expire(stamp_s, events)
        self._ms.append((time.perf_counter() - t0) * 1e3)
        return events

    # Algorithm 1, with hits clearing seen-through marks (beyond the paper)
    def _absence(self, lp, scan, pts, stamp_s, events) -> None:
        g = self._grid
        c = self.cfg
        r = scan.ranges_m
        with np.errstate(invalid="ignore"):
            far = np.isfinite(r) & (r >= scan.range_max_m) & (r < 1e6)
        far_r = np.minimum(scan.range_max_m, c.absence_max_range_m)
        a = lp[2] + scan.angles_rad[far]
        far_pts = lp[:2] + far_r * np.stack([np.cos(a), np.sin(a)], axis=1)
        # returns farther than absence_max_range_m count as free space up to that range
        rng_ = np.hypot(*(pts - lp[:2]).T)
        scale = np.minimum(1.0, c.absence_max_range_m / np.maximum(rng_, 1e-9))
        ends = lp[:2] + (pts - lp[:2]) * scale[:, None]
        if len(far_pts):
            ends = np.vstack([ends, far_pts])
        if len(ends) == 0:
            return
        cells, ray = traverse_rays(g, lp[:2], ends, exclude_end_m=c.absence_exclude_end_m)
        if len(cells) == 0:
            return
        # free space seen this run: a relocation may not put an object there
        np.add.at(self._free, (cells[:, 1], cells[:, 0]), 1)
        own = self._owner[cells[:, 1], cells[:, 0]]
        hit_cells = g.world_to_cell(pts)
        okh = g.in_bounds(hit_cells)
        # a return is stronger evidence than rays passing: cells with returns are not free
        self._free[hit_cells[okh, 1], hit_cells[okh, 0]] = 0
        hit_own = self._owner[hit_cells[okh, 1], hit_cells[okh, 0]]
        hit_loc = self._local[hit_cells[okh, 1], hit_cells[okh, 0]]
        sel = own >= 0
        objs = self.object_map.objects
        for i in np.unique(own[sel]):
            o = objs[int(i)]
            m = own == i
            seen = self._seen.setdefault(o.id, set())
            seen.update(self._local[cells[m, 1], cells[m, 0]].tolist())
            self._rays[o.id] = self._rays.get(o.id, 0) + len(np.unique(ray[m]))
        for i in np.unique(hit_own[hit_own >= 0]):
            o = objs[int(i)]
            o.seen_count += 1
            self._present_this_run.add(o.id)
            if o.id in self._seen:  # returns on the object: those cells are there
                self._seen[o.id].difference_update(hit_loc[hit_own == i].tolist())
        votes = self._vote_beams(lp, scan)
        gone = []
        for i in np.unique(own[sel]):
            o = objs[int(i)]
            core = self._core(o)
            frac = len(self._seen.get(o.id, set()) & core) / max(len(core), 1)
            if frac > c.beta_thresh and self._rays.get(o.id, 0) >= c.absence_min_rays:
                v = votes.get(o.id, [0, 0])
                if v[0] >= c.absence_min_votes and v[0] > 2 * v[1]:
                    gone.append(o)
        for o in gone:  # after the loop: marking re-renders and may re-index the objects
            if o.status in ("U", "M"):
                self._mark_absent(o, stamp_s, events)

    def _vote_beams(self, lp, scan) -> dict[int, list[int]]:
        """Beyond Alg. 1, robust to pose errors of a cell or two: per scan, the beams the map
        says should end on an object either pass well beyond it (a vote for gone) or end near
        it (a vote for present). Returns the run's votes per object id."""
        c = self.cfg
        g = self._grid
        expected = cast_rays(g, lp, scan.angles_rad, scan.range_max_m)
        r = np.where(np.isfinite(scan.ranges_m), scan.ranges_m, scan.range_max_m)
        hit = expected < scan.range_max_m
        ends = lp[:2] + (expected[:, None] + g.resolution_m / 2) * np.stack(
            [np.cos(lp[2] + scan.angles_rad), np.sin(lp[2] + scan.angles_rad)], axis=1)
        cells = g.world_to_cell(ends)
        ok = hit & g.in_bounds(cells)
        own = np.full(len(r), -1)
        own[ok] = self._owner[cells[ok, 1], cells[ok, 0]]
        objs = self.object_map.objects
        for i in np.unique(own[own >= 0]):
            m = own == i
            if m.sum() < c.absence_min_beams:
                continue
            through = np.mean(r[m] > expected[m] + c.absence_beyond_m)
            v = self._beam_votes.setdefault(objs[int(i)].id, [0, 0])
            if through >= 0.7:
                v[0] += 1
            elif through <= 0.3:
                v[1] += 1
        return self._beam_votes

    def _mark_absent(self, o: MapObject, stamp_s, events) -> None:
        o.status = "A"
        o.record(self.run, stamp_s)
        self._beam_votes.pop(o.id, None)
        self._seen.pop(o.id, None)
        self._rays.pop(o.id, None)
        events.append(Event(float(stamp_s), self.run, "absent", o.id, o.label,
                            o.pose_xytheta.tolist(), None))
        self.counts["absent"] += 1
        self._rerender()
        # order does not matter: an absence may match a chair seen before it
        for m in self._meta:
            if m.matched_object is None and m.dominant() == "chair":
                self._try_match(m, stamp_s, events, only=[o])
        for g in list(self.object_map.Gamma):
            self._try_match_gamma(g, o, stamp_s, events)

    # ---------------------------------------------------------- metaobjects
    def _track(self, pts, stamp_s, events) -> None:
        c = self.cfg
        if len(pts) < c.min_cluster_points:
            return
        centres, labels = mean_shift(pts, c.meanshift_bandwidth_m)
        for m in self._meta:
            m.predict(stamp_s)
        used: set[int] = set()
        for k in range(len(centres)):
            z = pts[labels == k]
            if len(z) < c.min_cluster_points:
                continue
            best, best_lp = None, len(z) * np.log(c.beta_min_prob)  # m_new
            for m in self._meta:
                if m.id in used or np.hypot(*(m.kf.x[:2] - z.mean(axis=0))) > c.gate_m:
                    continue
                lp = m.log_p(z)
                if lp > best_lp:
                    best, best_lp = m, lp
            if best is None:
                best = Metaobject(self._next_meta, z, stamp_s, c, self._grid.resolution_m)
                self._next_meta += 1
                self._meta.append(best)
            else:
                best.update(z, stamp_s)
            used.add(best.id)
            if (best.matched_object is None and best.n_obs >= c.chair_min_scans
                    and best.n_obs % 3 == 0 and best.dominant() == "chair"):
                self._try_match(best, stamp_s, events)

    def _candidates(self) -> list[MapObject]:
        return [o for o in self.object_map.A if not o.structure]

    def _field(self, o: MapObject) -> EdgeField:
        f = self._fields.get(o.id)
        if f is None:
            f = self._fields[o.id] = EdgeField(o, self.cfg.match_edge_sigma_m)
        return f

    def _try_match(self, m: Metaobject, stamp_s, events, only=None) -> bool:
        pts = m.chair_points()
        if len(pts) < self.cfg.chair_min_cells:
            return False
        best = None
        rivals: list = []
        ext_p = _extents(pts)
        for o in only if only is not None else self._candidates():
            ext_o = _extents(o.shape_xy)
            if np.any(ext_p > ext_o + 3 * o.resolution_m):
                continue  # what is seen is larger than the object
            if len(pts) < self.cfg.match_min_edge_fraction * len(o.edge_xy):
                continue  # too little of the object seen yet to tell look-alikes apart
            mt = match_points(pts, o, self.cfg, self._field(o), prior_yaw=o.pose_xytheta[2])
            if mt.score < self.cfg.match_min_score or not self._free_consistent(o, mt):
                continue
            dist = np.hypot(*(mt.pose_xytheta[:2] - o.pose_xytheta[:2]))
            key = (round(mt.score * 20) / 20, -dist)  # look-alikes: prefer the nearest one
            rivals.append((key, o, mt))
            if best is None or key > best[0]:
                best = (key, o, mt)
        if best is None:
            return False
        _, o, mt = best
        patient = m.n_obs < self.cfg.match_patience_scans
        if patient and only is None:
            # a different-looking candidate nearly as good: wait for more of the object
            for k2, o2, _ in rivals:
                if o2 is not o and k2[0] >= best[0][0] - 0.05 and not lookalike(
                        o2, o, self.cfg.lookalike_tolerance):
                    return False
            # a placed look-alike right here is more likely the one that moved a little
            c = pts.mean(axis=0)
            if np.hypot(*(mt.pose_xytheta[:2] - o.pose_xytheta[:2])) > 1.0:
                for u in self.object_map.placed():
                    if (not u.structure and u is not o
                            and np.hypot(*(u.pose_xytheta[:2] - c)) < 1.0 + u.extent_m() / 2
                            and lookalike(u, o, self.cfg.lookalike_tolerance)):
                        return False
        self._relocate(o, mt, stamp_s, events)
        m.matched_object = o.id
        return True

    def _try_match_gamma(self, g: MapObject, o: MapObject, stamp_s, events) -> None:
        pts = g.cells_world()
        mt = match_points(pts, o, self.cfg, self._field(o), prior_yaw=o.pose_xytheta[2])
        if mt.score >= self.cfg.match_min_score and self._free_consistent(o, mt):
            self.object_map.objects.remove(g)
            self._relocate(o, mt, stamp_s, events)

    def _free_consistent(self, o: MapObject, mt) -> bool:
        """Beyond the paper: the object at the matched pose must not cover cells that rays
        crossed this run (seen free), or a partial view (one straight side) could put it
        anywhere along that side."""
        g = self._grid
        c = g.world_to_cell(o.cells_world(mt.pose_xytheta))
        ok = g.in_bounds(c)
        if not ok.any():
            return False
        free = self._free[c[ok, 1], c[ok, 0]] >= self.cfg.match_free_rays
        return bool(np.mean(free) <= self.cfg.match_max_free_fraction)

    def _relocate(self, o: MapObject, mt, stamp_s, events) -> None:
        old = o.pose_xytheta.copy()
        o.pose_xytheta = mt.pose_xytheta.copy()
        moved = np.hypot(*(old[:2] - o.pose_xytheta[:2])) > 0.1 or \
            abs(wrap_angle(old[2] - o.pose_xytheta[2])) > np.radians(5)
        o.status = "M" if (moved or o.moved_count) else "U"
        kind = "relocated" if moved else "restored"
        o.moved_count += int(moved)
        o.record(self.run, stamp_s)
        events.append(Event(float(stamp_s), self.run, kind, o.id, o.label, old.tolist(),
                            o.pose_xytheta.tolist(), float(mt.score)))
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
            dom = m.dominant()
            if dom == "person":
                self.counts["persons"] += 1
            elif dom == "chair" and m.matched_object is None:
                self._to_gamma(m, stamp_s, events)
        self._meta = keep

    def _to_gamma(self, m: Metaobject, stamp_s, events) -> None:
        pts = m.chair_points()
        if len(pts) < self.cfg.chair_min_cells:
            return
        shape, edge, pose = shape_from_points(pts, self._grid.resolution_m)
        o = MapObject(self.object_map.next_id, None, "Gamma", pose, shape, edge,
                      resolution_m=self._grid.resolution_m)
        self.object_map.next_id += 1
        o.record(self.run, stamp_s)
        self.object_map.objects.append(o)
        events.append(Event(float(stamp_s), self.run, "gamma", o.id, None, None,
                            pose.tolist()))
        self.counts["gamma"] += 1

    def stats(self) -> dict:
        d = dict(self.counts)
        d["metaobjects"] = len(self._meta)
        d["ms_per_update"] = float(np.median(self._ms)) if self._ms else float("nan")
        return d
