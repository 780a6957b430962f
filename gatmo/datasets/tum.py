"""TUM trajectories: ``t x y z qx qy qz qw`` per line (planar: z = 0, yaw from the quaternion)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_text
from gatmo.errors import DataError, FormatError


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps_s (N,), poses_xytheta (N, 3))``; bad rows raise FormatError with the line."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"cannot read: {exc}", file=path) from None
    stamps, poses = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 8:
            raise FormatError(f"expected 8 values 't x y z qx qy qz qw', found {len(parts)}",
                              file=path, line=lineno)
        try:
            t, x, y, _z, qx, qy, qz, qw = (float(p) for p in parts)
        except ValueError:
            raise FormatError("non-numeric value", file=path, line=lineno) from None
        if not all(np.isfinite([t, x, y, qx, qy, qz, qw])):
            raise FormatError("non-finite value", file=path, line=lineno)
        if stamps and t <= stamps[-1]:
            raise DataError(f"timestamp {t} does not increase", file=path, line=lineno)
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        stamps.append(t)
        poses.append((x, y, yaw))
    return np.array(stamps, dtype=float), np.array(poses, dtype=float).reshape(-1, 3)


def write_tum(path: str | Path, stamps_s: np.ndarray, poses_xytheta: np.ndarray) -> Path:
    """Write a planar trajectory (atomic), 9 decimals."""
    stamps_s = np.asarray(stamps_s, dtype=float)
    p = np.asarray(poses_xytheta, dtype=float).reshape(-1, 3)
    half = p[:, 2] / 2.0
    rows = np.column_stack([stamps_s, p[:, 0], p[:, 1], np.zeros(len(p)), np.zeros(len(p)),
                            np.zeros(len(p)), np.sin(half), np.cos(half)])
    lines = ["# t x y z qx qy qz qw"] + [" ".join(f"{v:.9f}" for v in r) for r in rows]
    return atomic_write_text(path, "\n".join(lines) + "\n")
