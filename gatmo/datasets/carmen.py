"""CARMEN logs (plain or ``.gz``): read FLASER / RLASER / ROBOTLASER1 / RAWLASER1-4 / ODOM /
TRUEPOS / PARAM, write ODOM + ROBOTLASER1 + TRUEPOS.

Message layouts (CARMEN ``logger`` / ``carmen_logfile``):

* ``FLASER n r1..rn x y theta odom_x odom_y odom_theta ts host logger_ts`` (old logs end after
  ``odom_theta ts`` or even ``odom_theta``); 180 beams over 180 degrees unless PARAM says
  otherwise. ``x y theta`` is the (possibly SLAM-corrected) pose, ``odom_*`` the odometry.
* ``ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode n r1..rn
  n_rem rem.. laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv fwd side turn ts host
  logger_ts``.
* ``RAWLASER1..4 type start_angle fov angular_res max_range accuracy remission_mode n r.. n_rem
  rem.. ts host logger_ts`` (no pose: odometry interpolated from ODOM).
* ``ODOM x y theta tv rv accel ts host logger_ts``; ``TRUEPOS x y theta odom_x odom_y odom_theta
  ts host logger_ts`` (simulator ground truth).

Odometry at scan stamps is interpolated from ODOM lines when a scan carries none.
"""

from __future__ import annotations

import gzip
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_bytes
from gatmo.datasets._text import iter_lines
from gatmo.datasets.types import ReadStats, Scan, sensor_info
from gatmo.errors import DataError, FormatError
from gatmo.geometry import interpolate_poses, relative

LASER_MESSAGES = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2", "RAWLASER1", "RAWLASER2",
                  "RAWLASER3", "RAWLASER4")


class CarmenLog:
    """A CARMEN log as a :class:`~gatmo.datasets.types.ScanSource`.

    Args:
        path: the log (plain or gzip).
        skip_bad: skip and count bad lines (``stats``) instead of raising.
        pose_is_reference: the log's own pose fields (FLASER x y theta, ROBOTLASER1 robot pose)
            are a reference (SLAM-corrected) pose: put them into ``gt_pose_xytheta``.
        laser: which laser messages to read (FLASER/ROBOTLASER1/RAWLASER1 are "front").
    """

    def __init__(self, path: str | Path, *, skip_bad: bool = False,
                 pose_is_reference: bool = False, laser: str = "front") -> None:
        self.path = str(path)
        self.skip_bad = skip_bad
        self.pose_is_reference = pose_is_reference
        self.laser = laser
        self.stats = ReadStats()
        self.unknown_messages: dict[str, int] = {}

    # ------------------------------------------------------------------ parsing
    def _bad(self, stats: ReadStats, msg: str, lineno: int, field: str | None = None):
        if self.skip_bad:
            stats.skip(f"line {lineno}: {msg}")
            return
        if field is not None and msg.startswith(f"{field}: "):
            msg = msg[len(field) + 2:]  # the error names the field itself: "file:line: field: "
        raise FormatError(msg, file=self.path, line=lineno, field=field)

    def _records(self, stats: ReadStats):
        """Yield ('laser', dict) / ('odom', ...) / ('true', ...) records in file order."""
        params: dict[str, str] = {}
        want = {"front": ("FLASER", "ROBOTLASER1", "RAWLASER1"),
                "rear": ("RLASER", "ROBOTLASER2", "RAWLASER2")}.get(self.laser, LASER_MESSAGES)
        for lineno, line in iter_lines(self.path):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            kind = parts[0]
            stats.records += 1
            try:
                if kind == "PARAM":
                    if len(parts) >= 3:
                        params[parts[1]] = parts[2]
                elif kind == "ODOM":
                    if len(parts) < 8:
                        self._bad(stats, f"ODOM needs 9 fields, found {len(parts)}", lineno)
                        continue
                    v = [float(x) for x in parts[1:8]]
                    yield "odom", {"stamp": v[6], "pose": v[0:3]}, lineno
                elif kind == "TRUEPOS":
                    if len(parts) < 8:
                        self._bad(stats, f"TRUEPOS needs 9 fields, found {len(parts)}",
                                  lineno)
                        continue
                    v = [float(x) for x in parts[1:8]]
                    yield "true", {"stamp": v[6], "pose": v[0:3]}, lineno
                elif kind in ("FLASER", "RLASER"):
                    if kind not in want:
                        continue
                    rec = self._parse_flaser(parts, params, stats, lineno)
                    if rec is not None:
                        yield "laser", rec, lineno
                elif kind.startswith("ROBOTLASER") or kind.startswith("RAWLASER"):
                    if kind not in want:
                        continue
                    rec = self._parse_robotlaser(parts, stats, lineno)
                    if rec is not None:
                        yield "laser", rec, lineno
                else:
                    self.unknown_messages[kind] = self.unknown_messages.get(kind, 0) + 1
            except (ValueError, IndexError, OverflowError):
                self._bad(stats, f"{kind}: missing or non-numeric field", lineno, field=kind)

    def _parse_flaser(self, parts, params, stats, lineno):
        kind = parts[0]
        n = int(parts[1])
        if n <= 0 or len(parts) < 2 + n + 6:
            self._bad(stats, f"{kind}: expected {n} readings and 6 pose values, found "
                      f"{len(parts) - 2} values", lineno, field=kind)
            return None
        ranges = np.array(parts[2 : 2 + n], dtype=float)
        v = [float(x) for x in parts[2 + n : 2 + n + 6]]
        rest = parts[2 + n + 6 :]
        if not rest:
            self._bad(stats, f"{kind}: missing timestamp", lineno, field=kind)
            return None
        stamp = float(rest[0])
        prefix = "robot_front_laser" if kind == "FLASER" else "robot_rear_laser"
        fov = float(params.get(f"laser_{'front' if kind == 'FLASER' else 'rear'}_laser_fov",
                               180.0))
        # CARMEN writes the FOV in degrees, but some logs (MIT CSAIL) carry radians (3.14159)
        fov = fov if fov <= 2 * np.pi + 1e-3 else np.radians(fov)
        start = -fov / 2.0
        angles = start + np.arange(n) * (fov / max(n - 1, 1))
        max_range = float(params.get(f"{prefix}_max", 81.0))
        return {"stamp": stamp, "ranges": ranges, "angles": angles, "max_range": max_range,
                "pose": v[0:3], "odom": v[3:6], "laser_pose": np.zeros(3)}

    def _parse_robotlaser(self, parts, stats, lineno):
        kind = parts[0]
        start, fov, res, max_range = (float(x) for x in parts[2:6])
        n = int(parts[8])
        if not all(np.isfinite([start, fov, res, max_range])) or max_range <= 0:
            self._bad(stats, f"{kind}: non-finite angles or range", lineno, field=kind)
            return None
        i = 9 + n
        if n <= 0 or len(parts) < i + 1:
            self._bad(stats, f"{kind}: expected {n} readings", lineno, field=kind)
            return None
        ranges = np.array(parts[9:i], dtype=float)
        n_rem = int(parts[i])
        i += 1 + n_rem
        angles = start + np.arange(n) * res
        if kind.startswith("RAWLASER"):
            if len(parts) < i + 1:
                self._bad(stats, f"{kind}: missing timestamp", lineno, field=kind)
                return None
            return {"stamp": float(parts[i]), "ranges": ranges, "angles": angles,
                    "max_range": max_range, "pose": None, "odom": None,
                    "laser_pose": np.zeros(3)}
        if len(parts) < i + 12:
            self._bad(stats, f"{kind}: expected laser pose, robot pose, velocities and timestamp",
                      lineno, field=kind)
            return None
        lp = np.array([float(x) for x in parts[i : i + 3]])
        rp = np.array([float(x) for x in parts[i + 3 : i + 6]])
        stamp = float(parts[i + 11])
        return {"stamp": stamp, "ranges": ranges, "angles": angles, "max_range": max_range,
                "pose": rp.tolist(), "odom": rp.tolist(), "laser_pose": relative(rp, lp)}

    # ---------------------------------------------------------------- iteration
    def __iter__(self) -> Iterator[Scan]:
        stats = ReadStats()
        lasers, odom_t, odom_p, true_t, true_p = [], [], [], [], []
        for kind, rec, lineno in self._records(stats):
            if kind == "laser":
                if lasers and rec["stamp"] <= lasers[-1][0]["stamp"]:
                    msg = (f"timestamp {rec['stamp']} does not increase (previous "
                           f"{lasers[-1][0]['stamp']})")
                    if self.skip_bad:
                        stats.skip(f"line {lineno}: {msg}")
                        continue
                    raise DataError(msg, file=self.path, line=lineno)
                if lasers and len(rec["ranges"]) != len(lasers[0][0]["ranges"]):
                    stats.skip(f"line {lineno}: beam count changed")
                lasers.append((rec, lineno))
            elif kind == "odom":
                odom_t.append(rec["stamp"])
                odom_p.append(rec["pose"])
            else:
                true_t.append(rec["stamp"])
                true_p.append(rec["pose"])
        odom_interp = _Interp(odom_t, odom_p)
        true_interp = _Interp(true_t, true_p)
        for rec, lineno in lasers:
            odom = rec["odom"]
            if odom is None:
                odom = odom_interp(rec["stamp"])
                if odom is None:
                    msg = "RAWLASER without ODOM lines to interpolate odometry"
                    if self.skip_bad:
                        stats.skip(f"line {lineno}: {msg}")
                        continue
                    raise DataError(msg, file=self.path, line=lineno)
            gt = true_interp(rec["stamp"])
            if gt is None and self.pose_is_reference and rec["pose"] is not None:
                gt = rec["pose"]
            stats.scans += 1
            yield Scan(
                stamp_s=rec["stamp"],
                ranges_m=rec["ranges"],
                angles_rad=rec["angles"],
                range_min_m=0.0,
                range_max_m=rec["max_range"],
                odom_pose_xytheta=np.asarray(odom, dtype=float),
                laser_pose_xytheta=np.asarray(rec["laser_pose"], dtype=float),
                gt_pose_xytheta=None if gt is None else np.asarray(gt, dtype=float),
            )
        self.stats = stats

    def sensor_info(self) -> dict:
        return sensor_info(self)


class _Interp:
    def __init__(self, t, p):
        self.t = np.asarray(t, dtype=float)
        self.p = np.asarray(p, dtype=float).reshape(-1, 3)
        if len(self.t) > 1:
            order = np.argsort(self.t, kind="stable")
            self.t, self.p = self.t[order], self.p[order]
            keep = np.concatenate([[True], np.diff(self.t) > 0])
            self.t, self.p = self.t[keep], self.p[keep]

    def __call__(self, t):
        if len(self.t) == 0 or t < self.t[0] - 0.5 or t > self.t[-1] + 0.5:
            return None
        if len(self.t) == 1:
            return self.p[0]
        return interpolate_poses(self.t, self.p, np.array([t]))[0]


def write_carmen(path: str | Path, scans: Iterable[Scan], *, robot: str = "gatmo") -> Path:
    """Write scans as a CARMEN log (PARAM header, ODOM, ROBOTLASER1, TRUEPOS); ``.gz`` by suffix.

    Ranges are written with 6 decimals, poses with 9, so reading back gives the scans to 1e-6.
    """
    from gatmo.geometry import compose

    out = ["# CARMEN log written by gatmo",
           "# message formats defined: PARAM ODOM ROBOTLASER1 TRUEPOS"]
    first = True
    for s in scans:
        if first:
            fov = float(s.angles_rad[-1] - s.angles_rad[0])
            res = fov / max(s.num_beams - 1, 1)
            out.append(f"PARAM robot_front_laser_max {s.range_max_m:.6f} {robot} 0")
            out.append(f"PARAM laser_front_laser_fov {np.degrees(fov):.6f} {robot} 0")
            out.append(f"PARAM laser_front_laser_resolution {np.degrees(res):.6f} {robot} 0")
            first = False
        t = f"{s.stamp_s:.9f}"
        o = s.odom_pose_xytheta
        out.append(f"ODOM {o[0]:.9f} {o[1]:.9f} {o[2]:.9f} 0 0 0 {t} {robot} {t}")
        res = (s.angles_rad[-1] - s.angles_rad[0]) / max(s.num_beams - 1, 1)
        ranges = " ".join(f"{r:.6f}" for r in np.nan_to_num(s.ranges_m, nan=0.0,
                                                                posinf=s.range_max_m))
        lp = compose(o, s.laser_pose_xytheta)
        out.append(
            f"ROBOTLASER1 0 {s.angles_rad[0]:.12f} "
            f"{s.angles_rad[-1] - s.angles_rad[0]:.12f} {res:.12f} {s.range_max_m:.6f} 0.01 0 "
            f"{s.num_beams} {ranges} 0 {lp[0]:.9f} {lp[1]:.9f} {lp[2]:.9f} "
            f"{o[0]:.9f} {o[1]:.9f} {o[2]:.9f} 0 0 0 0 0 {t} {robot} {t}"
        )
        if s.gt_pose_xytheta is not None:
            g = s.gt_pose_xytheta
            out.append(f"TRUEPOS {g[0]:.9f} {g[1]:.9f} {g[2]:.9f} {o[0]:.9f} {o[1]:.9f} "
                       f"{o[2]:.9f} {t} {robot} {t}")
    data = ("\n".join(out) + "\n").encode()
    if str(path).endswith(".gz"):
        data = gzip.compress(data, mtime=0)
    return atomic_write_bytes(path, data)
