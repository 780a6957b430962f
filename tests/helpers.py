"""Small synthetic worlds for tests: grids built from boxes, and scans ray-marched in them.

The scan simulation here is a deliberately simple numpy ray march (fine steps), independent of
``gatmo.maps.raycast``, so tests can check the library against it.
"""

from __future__ import annotations

import numpy as np

from gatmo.datasets.types import Scan
from gatmo.maps.grid import FREE, OCCUPIED, OccupancyGrid


def room_grid(
    width_m: float = 10.0,
    height_m: float = 8.0,
    resolution_m: float = 0.05,
    boxes: list[tuple[float, float, float, float]] | tuple = (),
    origin_xy: tuple[float, float] = (0.0, 0.0),
    wall_m: float = 0.1,
) -> OccupancyGrid:
    """A rectangular room with walls of thickness ``wall_m`` and occupied axis-aligned ``boxes``.

    Boxes are (xmin, ymin, xmax, ymax) in world metres. Everything inside is free.
    """
    w = int(round(width_m / resolution_m))
    h = int(round(height_m / resolution_m))
    cells = np.full((h, w), FREE, dtype=np.int8)
    t = max(1, int(round(wall_m / resolution_m)))
    cells[:t, :] = OCCUPIED
    cells[-t:, :] = OCCUPIED
    cells[:, :t] = OCCUPIED
    cells[:, -t:] = OCCUPIED
    grid = OccupancyGrid(cells, resolution_m, (origin_xy[0], origin_xy[1], 0.0))
    for xmin, ymin, xmax, ymax in boxes:
        (ix0, iy0), (ix1, iy1) = grid.world_to_cell(np.array([[xmin, ymin], [xmax, ymax]]))
        grid.cells[max(iy0, 0) : iy1 + 1, max(ix0, 0) : ix1 + 1] = OCCUPIED
    return grid


def with_rotated_box(grid: OccupancyGrid, centre_xy: tuple[float, float], length_m: float,
                     width_m: float, yaw_rad: float) -> OccupancyGrid:
    """A copy of ``grid`` with the cells whose centres lie in a ``length_m`` x ``width_m`` box,
    centred at ``centre_xy`` and turned by ``yaw_rad``, occupied."""
    out = grid.copy()
    iy, ix = np.mgrid[0 : grid.cells.shape[0], 0 : grid.cells.shape[1]]
    d = grid.cell_to_world(np.stack([ix.ravel(), iy.ravel()], axis=1)) - np.asarray(centre_xy)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    inside = (np.abs(d[:, 0] * c + d[:, 1] * s) <= length_m / 2) & \
        (np.abs(-d[:, 0] * s + d[:, 1] * c) <= width_m / 2)
    out.cells.ravel()[inside] = OCCUPIED
    return out


def march_ranges(
    grid: OccupancyGrid,
    sensor_pose_xytheta: np.ndarray,
    angles_rad: np.ndarray,
    max_range_m: float,
    step_m: float | None = None,
) -> np.ndarray:
    """Ranges (B,) to the first occupied cell along each beam, by fine ray marching.

    Beams that hit nothing within ``max_range_m`` (or leave the grid) return ``max_range_m``.
    """
    step = step_m if step_m is not None else grid.resolution_m / 10.0
    ts = np.arange(0.0, max_range_m + step, step)
    x, y, th = sensor_pose_xytheta
    a = th + np.asarray(angles_rad)[:, None]
    px = x + ts[None, :] * np.cos(a)
    py = y + ts[None, :] * np.sin(a)
    c = grid.world_to_cell(np.stack([px.ravel(), py.ravel()], axis=1))
    inside = grid.in_bounds(c)
    hit = np.zeros(len(c), dtype=bool)
    hit[inside] = grid.cells[c[inside, 1], c[inside, 0]] == OCCUPIED
    hit = hit.reshape(px.shape)
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    return np.where(first >= 0, ts[np.maximum(first, 0)], max_range_m)


def make_scan(
    grid: OccupancyGrid,
    pose_xytheta,
    *,
    n_beams: int = 181,
    fov_rad: float = np.pi,
    max_range_m: float = 10.0,
    noise_m: float = 0.0,
    rng: np.random.Generator | None = None,
    odom_pose_xytheta=None,
    stamp_s: float = 0.0,
) -> Scan:
    """A scan from ``pose_xytheta`` (laser at the base origin) in ``grid``, with optional noise."""
    pose = np.asarray(pose_xytheta, dtype=float)
    angles = np.linspace(-fov_rad / 2, fov_rad / 2, n_beams)
    r = march_ranges(grid, pose, angles, max_range_m)
    if noise_m > 0:
        rng = rng or np.random.default_rng(0)
        hit = r < max_range_m
        r = np.where(hit, r + rng.normal(0.0, noise_m, r.shape), r)
    return Scan(
        stamp_s=stamp_s,
        ranges_m=r,
        angles_rad=angles,
        range_min_m=0.02,
        range_max_m=max_range_m,
        odom_pose_xytheta=pose if odom_pose_xytheta is None else np.asarray(odom_pose_xytheta),
        laser_pose_xytheta=np.zeros(3),
        gt_pose_xytheta=pose.copy(),
    )


def drive_scans(world: OccupancyGrid, true_xytheta: np.ndarray, *, odom_scale: float = 1.0,
                max_range_m: float = 4.0, seed: int = 3) -> list[Scan]:
    """Scans (181 beams, 1 cm noise) of ``world`` from the poses ``true_xytheta`` (N, 3), with
    odometry whose steps are ``odom_scale`` times the true ones (a wheel-scale error)."""
    from gatmo.geometry import compose, relative

    steps = relative(true_xytheta[:-1], true_xytheta[1:]) * [odom_scale, odom_scale, 1.0]
    odom = [true_xytheta[0]]
    for s in steps:
        odom.append(compose(odom[-1], s))
    rng = np.random.default_rng(seed)
    return [make_scan(world, p, n_beams=181, max_range_m=max_range_m, noise_m=0.01, rng=rng,
                      odom_pose_xytheta=o) for p, o in zip(true_xytheta, odom, strict=True)]
