"""CMU Wean Hall data: ``robotdata*.log(.gz)`` (``O``/``L`` lines, centimetres) and ``wean.dat``.

``O x y theta ts``: odometry (cm, rad). ``L x y theta xl yl thetal r1..r180 ts``: the robot's
and the laser's odometry poses and 180 ranges (cm) from -90 to +90 degrees. The map file has a
header (``robot_specifications->...``, ``global_map[0]: W H``) then rows of P(occupied) with
-1 for unknown.
"""

from __future__ import annotations

import gzip
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from gatmo.datasets._text import iter_lines
from gatmo.datasets.types import ReadStats, Scan
from gatmo.errors import DataError, FormatError
from gatmo.geometry import relative
from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid


def _open(path: Path):
    with open(path, "rb") as f:
        gz = f.read(2) == b"\x1f\x8b"
    return gzip.open(path, "rt", errors="replace") if gz else open(path, errors="replace")


def is_wean_map(path: str | Path) -> bool:
    """Whether ``path`` is a CMU Wean Hall / Beeson-format map (``robot_specifications->...``
    header, plain or gzip'd), not a map_server YAML."""
    import zlib

    try:
        with _open(Path(path)) as fh:
            # 64 characters: a header, or a binary file that is not one (never read whole)
            return fh.read(64).lstrip().startswith("robot_specifications")
    except (OSError, EOFError, zlib.error):
        return False  # unreadable: load_map reports what is wrong with it


class WeanLog:
    """A CMU ``robotdata`` log as a ScanSource (metres, laser pose relative to the base)."""

    def __init__(self, path: str | Path, *, skip_bad: bool = False) -> None:
        self.path = str(path)
        self.skip_bad = skip_bad
        self.stats = ReadStats()

    def __iter__(self) -> Iterator[Scan]:
        stats = ReadStats()
        angles = np.radians(np.arange(180) - 90.0 + 0.5)
        last = -np.inf
        for lineno, line in iter_lines(self.path):
            parts = line.split()
            if not parts:
                continue
            stats.records += 1
            if parts[0] != "L":
                continue
            if len(parts) != 1 + 6 + 180 + 1:
                msg = f"L line needs 187 fields, found {len(parts) - 1}"
                if self.skip_bad:
                    stats.skip(f"line {lineno}: {msg}")
                    continue
                raise FormatError(msg, file=self.path, line=lineno, field="L")
            try:
                v = np.array(parts[1:], dtype=float)
            except ValueError:
                if self.skip_bad:
                    stats.skip(f"line {lineno}: non-numeric")
                    continue
                raise FormatError("non-numeric field", file=self.path, line=lineno) from None
            t = float(v[-1])
            if t <= last:
                if self.skip_bad:
                    stats.skip(f"line {lineno}: stamp does not increase")
                    continue
                raise DataError(f"timestamp {t} does not increase", file=self.path,
                                line=lineno)
            last = t
            robot = np.array([v[0] / 100.0, v[1] / 100.0, v[2]])
            laser = np.array([v[3] / 100.0, v[4] / 100.0, v[5]])
            stats.scans += 1
            yield Scan(stamp_s=t, ranges_m=v[6:186] / 100.0, angles_rad=angles,
                       range_min_m=0.0, range_max_m=81.83, odom_pose_xytheta=robot,
                       laser_pose_xytheta=relative(robot, laser))
        self.stats = stats


def load_wean_map(path: str | Path) -> OccupancyGrid:
    """The Wean Hall map as an OccupancyGrid (10 cm).

    instruct.txt calls the values P(occupied), but the file holds P(free): 68 % of its known
    cells are above 0.65 in a map that is mostly corridor, and CMU's own reader (16-833
    ``map_reader.py``) flips them. So p_occ = 1 - value; p_occ > 0.65 occupied, < 0.196 free
    (map_server's defaults), -1 unknown. Rows of the file are x, columns y.
    """
    path = Path(path)
    res_cm = 10.0
    size = None
    rows = []
    # iter_lines: a cut or corrupt gzip stream is a FormatError with the file, not a zlib error
    for lineno, line in iter_lines(path):
        s = line.strip()
        if not s:
            continue
        if s.startswith("robot_specifications->resolution"):
            try:
                res_cm = float(s.split()[-1])
            except ValueError:
                res_cm = float("nan")
            if not (np.isfinite(res_cm) and res_cm > 0):
                raise FormatError("the resolution must be a positive number of cm",
                                  file=path, line=lineno, field="resolution")
            continue
        if s.startswith("robot_specifications"):
            continue
        if s.startswith("global_map[0]"):
            try:
                w, h = (int(x) for x in s.split(":")[1].split())
            except (ValueError, IndexError):
                raise FormatError("expected 'global_map[0]: WIDTH HEIGHT'", file=path,
                                  line=lineno) from None
            size = (w, h)
            continue
        if size is None:
            raise FormatError("map values before the 'global_map[0]: WIDTH HEIGHT' header",
                              file=path, line=lineno)
        try:
            row = np.array(s.split(), dtype=float)
        except ValueError:
            raise FormatError("non-numeric map value", file=path, line=lineno) from None
        if len(row) != size[1]:
            raise FormatError(f"expected {size[1]} values in a row, found {len(row)}",
                              file=path, line=lineno)
        rows.append(row)
    if size is None or len(rows) != size[0] or size[1] < 1:
        raise FormatError(f"expected a global_map header and {size} rows, found {len(rows)}",
                          file=path)
    p = np.vstack(rows)  # p[x, y]
    cells = np.full(p.shape, UNKNOWN, dtype=np.int8)
    known = p >= 0
    p_occ = 1.0 - p
    cells[known & (p_occ > 0.65)] = OCCUPIED
    cells[known & (p_occ < 0.196)] = FREE
    return OccupancyGrid(cells.T.copy(), res_cm / 100.0, (0.0, 0.0, 0.0))
