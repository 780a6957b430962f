"""Open any supported log by its suffix or content, or by an explicit format."""

from __future__ import annotations

from contextlib import closing
from itertools import islice
from pathlib import Path

from gatmo.datasets._text import iter_lines
from gatmo.errors import FormatError

FORMATS = ("carmen", "rosbag", "wean")


def sniff_format(path: str | Path) -> str:
    """carmen | rosbag | wean, from the suffix and the first lines."""
    p = Path(path)
    if not p.exists():
        raise FormatError("no such file", file=p)
    if p.is_dir():
        if (p / "metadata.yaml").exists():
            return "rosbag"
        raise FormatError("a folder without metadata.yaml: not a ROS 2 bag", file=p)
    if p.suffix in (".bag", ".db3", ".mcap"):
        return "rosbag"
    # iter_lines turns a corrupt gzip stream into a FormatError naming the file; closing()
    # shuts the file when sniffing stops early
    with closing(iter_lines(p)) as lines:
        for _, line in islice(lines, 200):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            if parts[0] == "L" and len(parts) == 188:
                return "wean"
            if parts[0] == "O" and len(parts) == 5:
                return "wean"
            if parts[0].isupper() and parts[0].isalnum():
                return "carmen"
    raise FormatError(f"unknown log format; use --format {' | '.join(FORMATS)}", file=p)


def open_log(path: str | Path, fmt: str | None = None, *, odometry_optional: bool = False,
             **kw):
    """A ScanSource for ``path``: a CARMEN log, a ROS 1/2 bag, or a CMU Wean log.

    ``odometry_optional``: a ROS bag without odometry is read (scans carry
    ``odom_pose_xytheta = None``) instead of refused; the other formats always carry it."""
    fmt = fmt or sniff_format(path)
    if odometry_optional and fmt == "rosbag":
        kw["require_odometry"] = False
    if fmt == "carmen":
        from gatmo.datasets.carmen import CarmenLog

        return CarmenLog(path, **kw)
    if fmt == "rosbag":
        from gatmo.datasets.rosbag import RosBag

        return RosBag(path, **kw)
    if fmt == "wean":
        from gatmo.datasets.wean import WeanLog

        return WeanLog(path, **kw)
    raise FormatError(f"unknown format {fmt!r}: {' | '.join(FORMATS)}", field="--format")


def open_map(path: str | Path, **kw):
    """An OccupancyGrid from a map_server map (YAML + image) or a CMU Wean Hall map
    (``wean.dat``, ``.gz`` or not), told apart by content
    (:func:`gatmo.datasets.wean.is_wean_map`); ``kw`` go to :func:`gatmo.maps.io.load_map`."""
    from gatmo.datasets.wean import is_wean_map, load_wean_map

    if is_wean_map(path):

        return load_wean_map(path)
    from gatmo.maps.io import load_map

    return load_map(path, **kw)
