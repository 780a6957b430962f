"""The one scan record every reader yields, and the protocol of a scan source."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

# Old SICK logs (CARMEN, the Kümmerle benchmark bags) write 80-82 m for "no return".
SICK_NO_RETURN_MIN_M = 80.0


@dataclass
class Scan:
    """One laser scan with the odometry at its stamp.

    Attributes:
        stamp_s: time of the scan [s].
        ranges_m: (B,) measured ranges [m]; invalid ones are kept as read and flagged by ``valid``.
        angles_rad: (B,) beam angles in the laser frame [rad], counter-clockwise, 0 = laser x axis.
        range_min_m, range_max_m: sensor limits [m].
        odom_pose_xytheta: (3,) pose of the robot base in the odometry frame at ``stamp_s``;
            None only from a reader asked for scans without odometry (a laser-only bag read
            for ``gatmo map build``), never from the default readers.
        laser_pose_xytheta: (3,) pose of the laser in the robot base frame.
        gt_pose_xytheta: (3,) ground-truth (or reference) base pose in the map frame, if known.
    """

    stamp_s: float
    ranges_m: np.ndarray
    angles_rad: np.ndarray
    range_min_m: float
    range_max_m: float
    odom_pose_xytheta: np.ndarray | None
    laser_pose_xytheta: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gt_pose_xytheta: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.ranges_m = np.asarray(self.ranges_m, dtype=np.float64)
        self.angles_rad = np.asarray(self.angles_rad, dtype=np.float64)
        if self.odom_pose_xytheta is not None:
            self.odom_pose_xytheta = np.asarray(self.odom_pose_xytheta, dtype=np.float64)
        self.laser_pose_xytheta = np.asarray(self.laser_pose_xytheta, dtype=np.float64)
        if self.gt_pose_xytheta is not None:
            self.gt_pose_xytheta = np.asarray(self.gt_pose_xytheta, dtype=np.float64)

    @property
    def num_beams(self) -> int:
        return int(self.ranges_m.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """(B,) bool: finite, inside (range_min, range_max), and not a SICK no-return value."""
        r = self.ranges_m
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(r) & (r > self.range_min_m) & (r < self.range_max_m)
            ok &= r < SICK_NO_RETURN_MIN_M
        return ok

    def points_laser_xy(self, only_valid: bool = True) -> np.ndarray:
        """Beam endpoints (N, 2) [m] in the laser frame."""
        r, a = self.ranges_m, self.angles_rad
        if only_valid:
            m = self.valid
            r, a = r[m], a[m]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)

    def points_base_xy(self, only_valid: bool = True) -> np.ndarray:
        """Beam endpoints (N, 2) [m] in the robot base frame."""
        from gatmo.geometry import transform_points

        return transform_points(self.laser_pose_xytheta, self.points_laser_xy(only_valid))


@dataclass
class ReadStats:
    """What a reader met: records read, scans yielded, bad records skipped (skip_bad=True)."""

    records: int = 0
    scans: int = 0
    skipped: int = 0
    skipped_reasons: list[str] = field(default_factory=list)

    def skip(self, reason: str) -> None:
        self.skipped += 1
        if len(self.skipped_reasons) < 20:
            self.skipped_reasons.append(reason)


@runtime_checkable
class ScanSource(Protocol):
    """A source of scans in time order (strictly increasing ``stamp_s``).

    Iterating may be repeated; each iteration re-reads from the start. ``stats`` describes the last
    complete iteration. ``path`` names the file for messages.
    """

    path: str
    stats: ReadStats

    def __iter__(self) -> Iterator[Scan]: ...


def sensor_info(source) -> dict:
    """Beams, field of view and maximum range of a source's first scan ({} when empty)."""
    for scan in source:
        return {"beams": scan.num_beams,
                "fov_deg": float(np.degrees(scan.angles_rad[-1] - scan.angles_rad[0])),
                "max_range_m": scan.range_max_m}
    return {}
