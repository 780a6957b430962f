"""TUM trajectories: ``t x y z qx qy qz qw`` per line (planar: z = 0, yaw from the quaternion)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_text
from gatmo.errors import DataError


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps_s (N,), poses_xytheta (N, 3))``; bad rows raise FormatError with the line."""
    from gatmo.datasets._text import numeric_rows

    rows, lines = numeric_rows(path, "t x y z qx qy qz qw")
    t = rows[:, 0]
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        i = bad[0] + 1
        raise DataError(f"timestamp {t[i]} does not increase", file=path, line=int(lines[i]))
    qx, qy, qz, qw = rows[:, 4], rows[:, 5], rows[:, 6], rows[:, 7]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return t, np.column_stack([rows[:, 1], rows[:, 2], yaw])


def write_tum(path: str | Path, stamps_s: np.ndarray, poses_xytheta: np.ndarray) -> Path:
    """Write a planar trajectory (atomic), 9 decimals."""
    stamps_s = np.asarray(stamps_s, dtype=float)
    p = np.asarray(poses_xytheta, dtype=float).reshape(-1, 3)
    half = p[:, 2] / 2.0
    rows = np.column_stack([stamps_s, p[:, 0], p[:, 1], np.zeros(len(p)), np.zeros(len(p)),
                            np.zeros(len(p)), np.sin(half), np.cos(half)])
    lines = ["# t x y z qx qy qz qw"] + [" ".join(f"{v:.9f}" for v in r) for r in rows]
    return atomic_write_text(path, "\n".join(lines) + "\n")
