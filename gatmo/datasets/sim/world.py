"""Worlds of walls, columns and labelled furniture; analytic ray casting; rasterization.

Ray casting here intersects beams with line segments and circles in closed form (numpy), on
purpose independent of :mod:`gatmo.maps.raycast`, so tests can check one against the other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gatmo.geometry import transform_points
from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

# label -> ("box", (length_m, width_m)) or ("circle", radius_m); same label, same shape
SHAPES: dict[str, tuple[str, tuple[float, ...]]] = {
    "lounge_chair": ("box", (0.7, 0.7)),
    "desk": ("box", (1.4, 0.7)),
    "cabinet": ("box", (0.9, 0.45)),
    "box": ("box", (0.5, 0.5)),
    "trash_can": ("circle", (0.18,)),
    "footstool": ("box", (0.45, 0.45)),
    "sofa": ("box", (1.8, 0.8)),
    "partition": ("box", (1.6, 0.08)),
    "round_table": ("circle", (0.45,)),
}


def box_polygon(length_m: float, width_m: float) -> np.ndarray:
    a, b = length_m / 2.0, width_m / 2.0
    return np.array([[-a, -b], [a, -b], [a, b], [-a, b]])


@dataclass
class Piece:
    """A piece of furniture: ``pose_xytheta`` places its own frame (centred) in the world."""

    id: int
    label: str
    pose_xytheta: np.ndarray

    @property
    def kind(self) -> str:
        return SHAPES[self.label][0]

    @property
    def radius_m(self) -> float:
        """Bounding radius [m]."""
        kind, dims = SHAPES[self.label]
        return dims[0] if kind == "circle" else float(np.hypot(dims[0], dims[1]) / 2.0)

    def polygon_world(self) -> np.ndarray | None:
        kind, dims = SHAPES[self.label]
        if kind != "box":
            return None
        return transform_points(self.pose_xytheta, box_polygon(*dims))

    def as_dict(self) -> dict:
        kind, dims = SHAPES[self.label]
        return {"id": self.id, "label": self.label,
                "pose": [float(v) for v in self.pose_xytheta],
                "shape": {"kind": kind, "dims_m": list(dims)}}


@dataclass
class World:
    """Static walls and columns (polygons, never move), furniture pieces, room bounds."""

    bounds_xy: tuple[float, float, float, float]  # xmin, ymin, xmax, ymax of the grid
    interior: list[np.ndarray]  # polygons of free floor (rooms, corridors)
    static_polys: list[np.ndarray]  # walls and columns
    pieces: list[Piece] = field(default_factory=list)
    doors: list[np.ndarray] = field(default_factory=list)  # free floor joining rooms

    def copy(self) -> World:
        return World(self.bounds_xy, self.interior, self.static_polys,
                     [Piece(p.id, p.label, p.pose_xytheta.copy()) for p in self.pieces],
                     self.doors)

    def piece(self, piece_id: int) -> Piece | None:
        for p in self.pieces:
            if p.id == piece_id:
                return p
        return None

    def segments_and_circles(self, extra_circles: np.ndarray | None = None):
        """All blocking geometry: segments (S, 4) and circles (C, 3) as (x, y, r)."""
        segs, circles = [], []
        polys = list(self.static_polys)
        for p in self.pieces:
            poly = p.polygon_world()
            if poly is None:
                circles.append((*p.pose_xytheta[:2], SHAPES[p.label][1][0]))
            else:
                polys.append(poly)
        for poly in polys:
            segs.append(np.hstack([poly, np.roll(poly, -1, axis=0)]))
        s = np.vstack(segs) if segs else np.zeros((0, 4))
        c = np.array(circles, dtype=float).reshape(-1, 3)
        if extra_circles is not None and len(extra_circles):
            c = np.vstack([c, extra_circles])
        return s, c


def cast(origin_xy: np.ndarray, angles_world: np.ndarray, segs: np.ndarray, circles: np.ndarray,
         max_range_m: float) -> np.ndarray:
    """Ranges (B,) from ``origin_xy`` along world angles to the nearest segment or circle."""
    d = np.stack([np.cos(angles_world), np.sin(angles_world)], axis=1)  # (B, 2)
    best = np.full(len(d), np.inf)
    if len(segs):
        p, q = segs[:, :2], segs[:, 2:]
        e = q - p  # (S, 2)
        w = p - origin_xy  # (S, 2)
        den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # (B, S)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / den
            u = (w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]) / den
        ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
        best = np.minimum(best, np.where(ok, t, np.inf).min(axis=1))
    if len(circles):
        m = origin_xy - circles[:, :2]  # (C, 2)
        b = d @ m.T  # (B, C)
        c = (m**2).sum(axis=1) - circles[:, 2] ** 2
        disc = b**2 - c[None, :]
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        ok = (disc >= 0) & (t > 1e-9)
        best = np.minimum(best, np.where(ok, t, np.inf).min(axis=1))
    return np.minimum(best, max_range_m)


def points_in_polygon(points_xy: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd test (N,) for a simple polygon (K, 2)."""
    x, y = points_xy[:, 0][:, None], points_xy[:, 1][:, None]
    x1, y1 = poly[:, 0][None, :], poly[:, 1][None, :]
    x2, y2 = np.roll(poly[:, 0], -1)[None, :], np.roll(poly[:, 1], -1)[None, :]
    cond = (y1 > y) != (y2 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
    return (cond & (x < xi)).sum(axis=1) % 2 == 1


def rasterize(world: World, resolution_m: float = 0.05) -> OccupancyGrid:
    """Occupancy grid of a world as a laser-built map has it: interiors free, every cell that
    walls, columns or furniture overlap occupied (filled), the rest unknown.

    A map built from scans marks the cell a return lands in, so a surface lies inside its edge
    cells and their centres are on it on average. Marking only cells whose centre is inside an
    obstacle put every surface half a cell beyond the edge cells' centres, and anything that
    matches scans against cell centres (likelihood field, scan-to-map ICP) half a cell off: from
    the true pose, scan-to-map ICP moved 3.2 cm (median, hall seed 103), 0.6 cm against edges
    on the surfaces. The grid's cells are offset half a cell from the world's whole-metre
    walls, so a wall's surface runs through the middle of its edge cells rather than along
    their faces (a real map's grid is not aligned to its walls either).
    """
    xmin, ymin, xmax, ymax = world.bounds_xy
    xmin, ymin = xmin - resolution_m / 2, ymin - resolution_m / 2
    w = int(np.ceil((xmax - xmin) / resolution_m))
    h = int(np.ceil((ymax - ymin) / resolution_m))
    cells = np.full((h, w), UNKNOWN, dtype=np.int8)
    grid = OccupancyGrid(cells, resolution_m, (xmin, ymin, 0.0))
    # overlap is tested on 4 x 4 points inside each cell (anything thinner than a quarter
    # cell can slip between them; no wall or piece is)
    sub = (np.arange(4) - 1.5) * resolution_m / 4
    sub_xy = np.stack(np.meshgrid(sub, sub), axis=-1).reshape(-1, 2)

    def fill(poly, value, overlap=False):
        lo = grid.world_to_cell(poly.min(axis=0)[None])[0]
        hi = grid.world_to_cell(poly.max(axis=0)[None])[0]
        x0, y0 = max(lo[0], 0), max(lo[1], 0)
        x1, y1 = min(hi[0] + 1, w), min(hi[1] + 1, h)
        if x1 <= x0 or y1 <= y0:
            return
        iy, ix = np.mgrid[y0:y1, x0:x1]
        centres = grid.cell_to_world(np.stack([ix.ravel(), iy.ravel()], axis=1))
        if overlap:
            probe = (centres[:, None, :] + sub_xy[None]).reshape(-1, 2)
            inside = points_in_polygon(probe, poly).reshape(len(centres), -1).any(axis=1)
        else:
            inside = points_in_polygon(centres, poly)
        sub_cells = cells[y0:y1, x0:x1]
        sub_cells[inside.reshape(iy.shape)] = value

    for poly in [*world.interior, *world.doors]:
        fill(poly, FREE)
    for poly in world.static_polys:
        fill(poly, OCCUPIED, overlap=True)
    for p in world.pieces:
        poly = p.polygon_world()
        if poly is None:
            r = SHAPES[p.label][1][0]
            ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
            poly = p.pose_xytheta[:2] + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        fill(poly, OCCUPIED, overlap=True)
    return grid
