"""The object map (paper, Sec. III): the static map split into objects o_i = (I_i, E_i, N_i, p_i)
by region growing, each kept in its own frame so that a move changes p_i only; and the lists
U (unclassified), A (absent), M (movable, placed), Gamma (seen, never added)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from gatmo.geometry import transform_points
from gatmo.maps.grid import FREE, OCCUPIED, OccupancyGrid

STATUSES = ("U", "A", "M", "Gamma")


@dataclass
class MapObject:
    """One object.

    Attributes:
        id: stable identity (kept when the object moves).
        label: semantic label given by a user or a scenario (None if unknown).
        status: "U", "A", "M" or "Gamma".
        pose_xytheta: (3,) pose of the object frame in the map frame (p_i).
        shape_xy: (K, 2) cell centres I_i in the object frame [m].
        edge_xy: (E, 2) edge cell centres E_i in the object frame [m].
        structure: walls and other large connected structure; never absent, never moved.
        history: list of {run, stamp_s, pose, status} in order.
        unseen_runs: runs ended, while the object was placed, since it was last seen standing
            (enough beams from confirmed poses ending on it) or placed by evidence
            (withhold_unseen_runs).
    """

    id: int
    label: str | None
    status: str
    pose_xytheta: np.ndarray
    shape_xy: np.ndarray
    edge_xy: np.ndarray
    structure: bool = False
    base_pose_xytheta: np.ndarray | None = None  # where the base (static) map draws it
    resolution_m: float = 0.05
    seen_count: int = 0
    moved_count: int = 0
    history: list = field(default_factory=list)
    unseen_runs: int = 0

    def cells_world(self, pose_xytheta: np.ndarray | None = None, dense: bool = False):
        """Shape points (K, 2) in the map frame (at ``pose_xytheta``, default the current
        pose). ``dense`` adds 4 sub-cell points per cell so a rotated shape leaves no holes."""
        pts = self.shape_xy
        if dense and len(pts):
            r = self.resolution_m / 4.0
            off = np.array([[-r, -r], [r, -r], [-r, r], [r, r]])
            pts = (pts[:, None, :] + off[None]).reshape(-1, 2)
        pose = self.pose_xytheta if pose_xytheta is None else pose_xytheta
        return transform_points(pose, pts)



    def record(self, run: int, stamp_s: float) -> None:
        self.history.append({"run": int(run), "stamp_s": float(stamp_s),
                             "pose": [float(v) for v in self.pose_xytheta],
                             "status": self.status})

    def earlier_poses(self) -> np.ndarray:
        """(K, 3) poses where the object stood before: where the static map drew it and every
        pose it was placed at since (U or M in its history), in order, without repeats."""
        poses = [] if self.base_pose_xytheta is None else [np.asarray(self.base_pose_xytheta)]
        for h in self.history:
            if h.get("status") in ("U", "M"):
                q = np.asarray(h["pose"], dtype=float)
                if not any(np.allclose(q, p) for p in poses):
                    poses.append(q)
        return np.array(poses, dtype=float).reshape(-1, 3)

    def extent_m(self) -> float:
        if len(self.shape_xy) == 0:
            return 0.0
        return float(np.max(self.shape_xy.max(axis=0) - self.shape_xy.min(axis=0)))


def edges_of(mask: np.ndarray) -> np.ndarray:
    """Cells of ``mask`` with a 4-neighbour outside it."""
    inner = ndimage.binary_erosion(mask, structure=np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]]),
                                   border_value=0)
    return mask & ~inner


def shape_from_points(points_xy: np.ndarray, resolution_m: float):
    """Object-frame shape (K, 2), edges (E, 2) and the centroid pose for world points."""
    c = points_xy.mean(axis=0)
    local = points_xy - c
    idx = np.floor(local / resolution_m).astype(np.int64)
    idx = np.unique(idx, axis=0)
    lo = idx.min(axis=0)
    mask = np.zeros(tuple(idx.max(axis=0) - lo + 1)[::-1], dtype=bool)
    mask[idx[:, 1] - lo[1], idx[:, 0] - lo[0]] = True
    shape = (idx + 0.5) * resolution_m
    ey, ex = np.nonzero(edges_of(mask))
    edge = (np.stack([ex + lo[0], ey + lo[1]], axis=1) + 0.5) * resolution_m
    return shape, edge, np.array([c[0], c[1], 0.0])


@dataclass
class ObjectMap:
    """The objects, the resolution of their cells [m], the next free id, and ``runs``: the
    number of the last run laid on this map (0: none yet), so a run started from a saved map
    takes the next number."""

    objects: list[MapObject]
    resolution_m: float
    next_id: int = 1
    runs: int = 0

    @classmethod
    def from_grid(cls, grid: OccupancyGrid, cfg) -> ObjectMap:
        """Region growing with 8-connectivity over occupied cells (paper, Sec. III)."""
        occ = grid.occupied
        lab, n = ndimage.label(occ, structure=np.ones((3, 3), dtype=bool))
        edges = edges_of(occ)
        objects = []
        slices = ndimage.find_objects(lab)
        for k, sl in enumerate(slices, start=1):
            if sl is None:
                continue
            sub = lab[sl] == k
            iy, ix = np.nonzero(sub)
            if len(iy) < cfg.min_object_cells:
                continue
            iy = iy + sl[0].start
            ix = ix + sl[1].start
            world = grid.cell_to_world(np.stack([ix, iy], axis=1))
            centre = world.mean(axis=0)
            e = edges[iy, ix]
            pose = np.array([centre[0], centre[1], 0.0])
            obj = MapObject(id=len(objects) + 1, label=None, status="U", pose_xytheta=pose,
                            shape_xy=world - centre, edge_xy=world[e] - centre,
                            base_pose_xytheta=pose.copy(), resolution_m=grid.resolution_m)
            obj.structure = obj.extent_m() > cfg.wall_min_extent_m
            objects.append(obj)
        return cls(objects, grid.resolution_m, len(objects) + 1)

    @property
    def by_id(self) -> dict[int, MapObject]:
        return {o.id: o for o in self.objects}

    def in_list(self, status: str) -> list[MapObject]:
        return [o for o in self.objects if o.status == status]

    U = property(lambda self: self.in_list("U"))
    A = property(lambda self: self.in_list("A"))
    M = property(lambda self: self.in_list("M"))
    Gamma = property(lambda self: self.in_list("Gamma"))

    def placed(self) -> list[MapObject]:
        """Objects drawn in the map: U and M."""
        return [o for o in self.objects if o.status in ("U", "M")]

    def render(self, base: OccupancyGrid) -> OccupancyGrid:
        """The reconfigured map: ``base`` with every object's footprint in the base map cleared,
        then the placed objects (U, M) drawn at their current poses."""
        g = base.copy()
        for o in self.objects:
            if o.structure or o.base_pose_xytheta is None:
                continue
            c = g.world_to_cell(o.cells_world(o.base_pose_xytheta))
            c = c[g.in_bounds(c)]
            g.cells[c[:, 1], c[:, 0]] = FREE
        for o in self.placed():
            moved = o.base_pose_xytheta is None or not np.allclose(o.pose_xytheta,
                                                                     o.base_pose_xytheta)
            c = g.world_to_cell(o.cells_world(dense=moved))
            c = c[g.in_bounds(c)]
            g.cells[c[:, 1], c[:, 0]] = OCCUPIED
        return g

    def copy(self) -> ObjectMap:
        import copy

        return copy.deepcopy(self)
