"""Rearranging furniture between runs: moved elsewhere, shifted and turned, removed, added.

Each piece independently, with the config's probabilities, is removed, moved to a new free place
(random yaw), shifted by ``shift_min_m..shift_max_m`` and turned by up to 60 deg, or put back
at one of its poses in earlier layouts (``return_prob``; a change of kind "moved" with
``"returned": true``); then
``add_count`` new pieces (new ids, random labels) appear. Every new pose passes
:func:`gatmo.datasets.sim.presets.placement_ok` (no overlaps, route kept clear); a piece whose move
finds no room stays where it was.
"""

from __future__ import annotations

import numpy as np

from gatmo.datasets.sim.config import RearrangeConfig
from gatmo.datasets.sim.presets import place, placement_ok
from gatmo.datasets.sim.world import SHAPES, Piece, World
from gatmo.geometry import wrap_angle

KINDS = ("moved", "shifted", "added", "removed")


def _pose(p: np.ndarray | None) -> list[float] | None:
    return None if p is None else [round(float(v), 9) for v in p]


def rearrange(world: World, route: np.ndarray, cfg: RearrangeConfig, rng: np.random.Generator,
              next_id: int, earlier: dict[int, list[np.ndarray]] | None = None,
              ) -> tuple[World, list[dict], int]:
    """A new layout (``world`` is left unchanged), the list of changes
    ``{id, label, kind, old_pose, new_pose}`` (poses (x, y, theta) or None), and the next free id.
    Ids of pieces that stay are stable; added pieces get ids from ``next_id`` on. ``earlier``:
    per piece id, its poses (3,) in earlier layouts (for ``return_prob``)."""
    new = world.copy()
    changes: list[dict] = []
    earlier = earlier or {}
    p_other = cfg.remove_prob + cfg.move_prob + cfg.shift_prob
    for piece in list(new.pieces):
        old = piece.pose_xytheta.copy()
        u = rng.random()
        returned = False
        if u < cfg.remove_prob:
            new.pieces.remove(piece)
            changes.append({"id": piece.id, "label": piece.label, "kind": "removed",
                            "old_pose": _pose(old), "new_pose": None})
            continue
        if u < cfg.remove_prob + cfg.move_prob:
            kind, ok = "moved", place(new, piece, route, rng)
        elif u < cfg.remove_prob + cfg.move_prob + cfg.shift_prob:
            kind, ok = "shifted", False
            for _ in range(100):
                d = rng.uniform(cfg.shift_min_m, cfg.shift_max_m)
                a = rng.uniform(-np.pi, np.pi)
                turn = rng.uniform(-np.pi / 3, np.pi / 3)
                piece.pose_xytheta = np.array([old[0] + d * np.cos(a), old[1] + d * np.sin(a),
                                               float(wrap_angle(old[2] + turn))])
                if placement_ok(piece, new.pieces, new, route):
                    ok = True
                    break
        elif u < p_other + cfg.return_prob:
            back = [p for p in earlier.get(piece.id, []) if np.hypot(*(p[:2] - old[:2])) > 0.2]
            if not back:
                continue
            kind, returned = "moved", True
            piece.pose_xytheta = np.asarray(back[int(rng.integers(len(back)))], dtype=float)
            ok = placement_ok(piece, new.pieces, new, route)
        else:
            continue
        if not ok:
            piece.pose_xytheta = old
            continue
        changes.append({"id": piece.id, "label": piece.label, "kind": kind,
                        "old_pose": _pose(old), "new_pose": _pose(piece.pose_xytheta)})
        if returned:
            changes[-1]["returned"] = True
    labels = sorted(SHAPES)
    for _ in range(cfg.add_count):
        piece = Piece(next_id, labels[int(rng.integers(len(labels)))], np.zeros(3))
        if place(new, piece, route, rng):
            new.pieces.append(piece)
            changes.append({"id": piece.id, "label": piece.label, "kind": "added",
                            "old_pose": None, "new_pose": _pose(piece.pose_xytheta)})
            next_id += 1
    return new, changes, next_id


__all__ = ["KINDS", "rearrange"]
