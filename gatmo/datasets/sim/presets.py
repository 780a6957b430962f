"""World presets and furniture placement: ``hall`` (large room, furniture dominates) and
``office`` (rooms and a corridor, walls dominate)."""

from __future__ import annotations

import numpy as np

from gatmo.datasets.sim.world import Piece, World, box_polygon
from gatmo.errors import ConfigError


def _rect(x0, y0, x1, y1) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def _walls_of(x0, y0, x1, y1, t=0.15) -> list[np.ndarray]:
    return [_rect(x0 - t, y0 - t, x1 + t, y0), _rect(x0 - t, y1, x1 + t, y1 + t),
            _rect(x0 - t, y0, x0, y1), _rect(x1, y0, x1 + t, y1)]


def route_distance(points_xy: np.ndarray, route: np.ndarray) -> np.ndarray:
    """Distance (N,) from points to a closed polyline route (K, 2)."""
    a, b = route, np.roll(route, -1, axis=0)
    ab = b - a
    ap = points_xy[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(-1) / np.maximum((ab**2).sum(-1), 1e-12)[None], 0, 1)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points_xy[:, None, :] - closest, axis=-1).min(axis=1)


def placement_ok(piece: Piece, others: list[Piece], world: World, route: np.ndarray,
                 clearance_m: float = 0.6, gap_m: float = 0.15) -> bool:
    """Inside a room away from walls, clear of the route and of other pieces.

    Pieces are compared by bounding circles plus ``gap_m``, a conservative test: two accepted
    pieces never overlap whatever their yaw. The route polyline keeps ``clearance_m`` [m] free
    beyond a piece's bounding circle (so the robot, which cuts corners a little, never touches
    furniture).
    """
    c = piece.pose_xytheta[:2]
    r = piece.radius_m
    inside = False
    for poly in world.interior:
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        if np.all(c - r - 0.1 >= lo) and np.all(c + r + 0.1 <= hi):
            inside = True
            break
    if not inside:
        return False
    for poly in world.static_polys:
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        nearest = np.clip(c, lo, hi)
        if np.hypot(*(c - nearest)) < r + 0.1:
            return False
    d_route = route_distance(c[None], route)[0]
    if d_route < r + clearance_m:
        return False
    for o in others:
        if o.id != piece.id and np.hypot(*(c - o.pose_xytheta[:2])) < r + o.radius_m + gap_m:
            return False
    return True


def random_pose(world: World, rng: np.random.Generator, route: np.ndarray | None = None,
                near_m: tuple[float, float] = (0.9, 2.8)) -> np.ndarray:
    """A random pose in a room; with ``route``, 85 % of the time within ``near_m`` of the route
    (sideways of a random route point), where a short-range laser sees it."""
    if route is not None and rng.random() < 0.85:
        k = int(rng.integers(len(route)))
        a, b = route[k], route[(k + 1) % len(route)]
        u = rng.random()
        p = a + u * (b - a)
        d = (b - a) / max(np.hypot(*(b - a)), 1e-9)
        side = np.array([-d[1], d[0]]) * rng.choice([-1.0, 1.0])
        q = p + side * rng.uniform(*near_m)
        return np.array([q[0], q[1], rng.uniform(-np.pi, np.pi)])
    poly = world.interior[rng.integers(len(world.interior))]
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    return np.array([rng.uniform(lo[0], hi[0]), rng.uniform(lo[1], hi[1]),
                     rng.uniform(-np.pi, np.pi)])


def place(world: World, piece: Piece, route: np.ndarray, rng: np.random.Generator,
          tries: int = 400) -> bool:
    """Put ``piece`` at a random free pose with a random yaw; False (pose unchanged) if none of
    ``tries`` candidates fits."""
    old = piece.pose_xytheta.copy()
    for _ in range(tries):
        piece.pose_xytheta = random_pose(world, rng, route)
        if placement_ok(piece, world.pieces, world, route):
            return True
    piece.pose_xytheta = old
    return False


HALL_LABELS = ["lounge_chair", "lounge_chair", "lounge_chair", "desk", "desk", "cabinet",
               "cabinet", "box", "box", "trash_can", "footstool", "footstool", "sofa",
               "partition", "round_table", "lounge_chair"]
OFFICE_LABELS = ["desk", "desk", "cabinet", "lounge_chair", "box", "sofa", "trash_can",
                 "footstool"]


def make_world(preset: str, rng: np.random.Generator) -> tuple[World, np.ndarray]:
    """A world and the robot's route (closed polyline (K, 2)) for a preset."""
    if preset == "hall":
        W, H = 20.0, 14.0
        world = World((-0.5, -0.5, W + 0.5, H + 0.5), [_rect(0, 0, W, H)], _walls_of(0, 0, W, H))
        for cx, cy in ((6.5, 5.25), (13.5, 5.25), (6.5, 8.75), (13.5, 8.75)):
            world.static_polys.append(_rect(cx - 0.2, cy - 0.2, cx + 0.2, cy + 0.2))
        route = np.array([[3.5, 3.5], [16.5, 3.5], [16.5, 7.0], [3.5, 7.0], [3.5, 10.5],
                          [16.5, 10.5], [16.5, 7.0], [3.5, 7.0]])
        labels = HALL_LABELS
    elif preset == "office":
        W, H = 18.0, 11.0
        rooms = [_rect(0, 0, 6, 4.5), _rect(6.15, 0, 12, 4.5), _rect(12.15, 0, 18, 4.5),
                 _rect(0, 6.5, 9, 11), _rect(9.15, 6.5, 18, 11), _rect(0, 4.65, 18, 6.35)]
        world = World((-0.5, -0.5, W + 0.5, H + 0.5), rooms, [])
        t = 0.15
        walls = _walls_of(0, 0, W, H, t)
        # corridor walls with 1 m doors, and room separators
        for y0, doors in ((4.5, (2.0, 8.5, 14.5)), (6.35, (3.5, 12.5))):
            xs = [0.0]
            for d in doors:
                xs += [d, d + 1.0]
            xs.append(W)
            for a, b in zip(xs[::2], xs[1::2], strict=True):
                walls.append(_rect(a, y0, b, y0 + t))
            world.doors += [_rect(d, y0, d + 1.0, y0 + t) for d in doors]
        walls += [_rect(6.0, 0, 6.15, 4.5), _rect(12.0, 0, 12.15, 4.5), _rect(9.0, 6.5, 9.15, H)]
        world.static_polys = walls
        route = np.array([[1.5, 5.5], [16.5, 5.5], [15.0, 5.5], [15.0, 2.2], [15.0, 5.5],
                          [9.0, 5.5], [9.0, 2.2], [9.0, 5.5], [4.0, 5.5], [4.0, 8.8],
                          [4.0, 5.5], [13.0, 5.5], [13.0, 8.8], [13.0, 5.5]])
        labels = OFFICE_LABELS
    else:
        raise ConfigError(f"unknown preset {preset!r}: hall | office", field="preset")
    for i, label in enumerate(labels):
        piece = Piece(i + 1, label, np.zeros(3))
        if place(world, piece, route, rng):
            world.pieces.append(piece)
    return world, route


__all__ = ["box_polygon", "make_world", "place", "placement_ok", "route_distance"]
