"""Kümmerle et al. 2009 relations files: ``t1 t2 x y z roll pitch yaw`` per line."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Relations:
    """``rel_xytheta[k]`` is the pose of the robot at ``t2_s[k]`` in its frame at ``t1_s[k]``."""

    t1_s: np.ndarray
    t2_s: np.ndarray
    rel_xytheta: np.ndarray

    def __len__(self) -> int:
        return len(self.t1_s)


def read_relations(path: str | Path) -> Relations:
    from gatmo.datasets._text import numeric_rows

    a, _ = numeric_rows(path, "t1 t2 x y z roll pitch yaw")
    return Relations(a[:, 0], a[:, 1], a[:, [2, 3, 7]])
