"""Kümmerle et al. 2009 relations files: ``t1 t2 x y z roll pitch yaw`` per line."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gatmo.errors import FormatError


@dataclass
class Relations:
    """``rel_xytheta[k]`` is the pose of the robot at ``t2_s[k]`` in its frame at ``t1_s[k]``."""

    t1_s: np.ndarray
    t2_s: np.ndarray
    rel_xytheta: np.ndarray

    def __len__(self) -> int:
        return len(self.t1_s)


def read_relations(path: str | Path) -> Relations:
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"cannot read: {exc}", file=path) from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 8:
            raise FormatError(f"expected 8 values 't1 t2 x y z roll pitch yaw', found {len(parts)}",
                              file=path, line=lineno)
        try:
            rows.append([float(v) for v in parts])
        except ValueError:
            raise FormatError("non-numeric value", file=path, line=lineno) from None
    a = np.array(rows, dtype=float).reshape(-1, 8)
    return Relations(a[:, 0], a[:, 1], a[:, [2, 3, 7]])
