"""``gatmo map render``: an occupancy map from a log whose poses are known (a SLAM-corrected
CARMEN log such as the radish ``*-corrected`` logs, or a log with ground truth)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gatmo.errors import DataError


@dataclass
class RenderSummary:
    scans: int
    skipped: int
    size_cells: str
    resolution_m: float
    occupied_cells: int
    out: str

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def render_reference_map(log: str | Path, out_yaml: str | Path, *, resolution_m: float = 0.05,
                         max_range_m: float = 20.0, fmt: str | None = None,
                         image_format: str = "pgm") -> RenderSummary:
    """Render ``log`` at its reference poses (CARMEN pose fields, or ground truth) into a
    map_server map. Records that are bad or out of order are skipped and counted."""
    from gatmo.datasets.open import open_log, sniff_format
    from gatmo.maps.io import save_map
    from gatmo.maps.mapping import render_map

    fmt = fmt or sniff_format(log)
    kw = {"pose_is_reference": True} if fmt == "carmen" else {}
    src = open_log(log, fmt=fmt, skip_bad=True, **kw)
    scans = [s for s in src if s.gt_pose_xytheta is not None]
    if not scans:
        raise DataError("no scan carries a reference pose to map with", file=log)
    poses = np.array([s.gt_pose_xytheta for s in scans])
    grid = render_map(scans, poses, resolution_m=resolution_m, max_range_m=max_range_m)
    save_map(grid, out_yaml, image_format=image_format)
    return RenderSummary(len(scans), src.stats.skipped, f"{grid.width} x {grid.height}",
                         resolution_m, int(grid.occupied.sum()), str(out_yaml))
