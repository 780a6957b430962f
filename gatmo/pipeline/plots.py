"""Pictures for ``gatmo compare`` (matplotlib, headless): maps with trajectories and moved
objects, error over time, and the identification curve (paper, Fig. 5)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gatmo.maps.grid import OccupancyGrid


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _show_grid(ax, grid: OccupancyGrid, title: str) -> None:
    img = np.full(grid.cells.shape, 0.8)
    img[grid.cells == 0] = 1.0
    img[grid.cells == 100] = 0.0
    xmin, xmax, ymin, ymax = grid.extent_xy
    ax.imshow(img, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(xmin, xmax, ymin, ymax),
              interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)


def _zoom(ax, *trajs) -> None:
    pts = np.concatenate([t[:, :2] for t in trajs if t is not None and len(t)])
    if len(pts) == 0:
        return
    lo, hi = pts.min(axis=0) - 4.0, pts.max(axis=0) + 4.0
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])


def shown_moves(events: list[dict]) -> list[dict]:
    """The relocation and addition events (as dicts, in order) the map picture draws: those
    with a new pose."""
    return [ev for ev in events
            if ev.get("kind") in ("relocated", "added") and ev.get("pose_new") is not None]


def plot_log(out_dir: Path, base: OccupancyGrid, grid_before: OccupancyGrid, mapper,
             t_static, t_gatmo, gt, *, scenario_json=None, run: int = 1) -> list[Path]:
    """Write the three pictures of one log; returns their paths."""
    plt = _plt()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    gt_p = None if gt is None else gt.poses_xytheta

    # 1. static map vs reconfigured map, both trajectories, moved objects with arrows
    fig, axes = plt.subplots(1, 2, figsize=(12, 6), constrained_layout=True)
    _show_grid(axes[0], base, "static map: static localizer")
    _show_grid(axes[1], mapper.grid(), f"reconfigured map after run {run}: gatmo")
    for ax, tr, colour in ((axes[0], t_static, "tab:red"), (axes[1], t_gatmo, "tab:blue")):
        if gt_p is not None:
            ax.plot(gt_p[:, 0], gt_p[:, 1], "-", color="tab:green", lw=1.0, label="ground truth")
        ax.plot(tr.poses_xytheta[:, 0], tr.poses_xytheta[:, 1], "-", color=colour, lw=0.9,
                label=tr.side)
        _zoom(ax, tr.poses_xytheta, gt_p)
        ax.legend(fontsize=7, loc="upper right")
    for ev in shown_moves(t_gatmo.events):
        p1 = np.asarray(ev["pose_new"], dtype=float)
        label = ev.get("label") or f"#{ev.get('object_id')}"
        if ev.get("pose_old") is not None and ev["kind"] == "relocated":
            p0 = np.asarray(ev["pose_old"], dtype=float)
            axes[1].annotate("", xy=p1[:2], xytext=p0[:2],
                             arrowprops={"arrowstyle": "->", "color": "tab:orange", "lw": 1.5})
        axes[1].text(p1[0], p1[1], f" {label}", fontsize=7, color="tab:orange")
    p = out_dir / "map.png"
    fig.savefig(p, dpi=110, bbox_inches="tight")  # a wide map leaves bands above and below
    plt.close(fig)
    paths.append(p)

    # 2. error over time
    if gt is not None:
        from gatmo.pipeline.runs import error_series

        fig, ax = plt.subplots(figsize=(9, 3.2), constrained_layout=True)
        for tr, colour in ((t_static, "tab:red"), (t_gatmo, "tab:blue")):
            e = error_series(tr, gt)
            ax.plot(tr.stamps_s - tr.stamps_s[0], np.maximum(e, 0.01), color=colour, lw=0.9,
                    label=tr.side)
        ax.axhline(0.5, color="gray", ls=":", lw=0.8, label="lost (0.5 m)")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("position error [m]")
        ax.set_yscale("log")
        ax.set_ylim(0.01, None)
        ax.legend(fontsize=8)
        ax.set_title(f"run {run}: localization error against ground truth", fontsize=9)
        p = out_dir / "error.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)

    # 3. identification curve: fraction of moved objects identified vs scans
    n_moved = None
    if scenario_json is not None and Path(scenario_json).exists():
        n_moved = _moved_in_run(Path(scenario_json), run)
    reloc = sorted(e["scan_index"] for e in t_gatmo.events if e.get("kind") == "relocated")
    if n_moved is None:
        n_moved = max(1, sum(1 for e in t_gatmo.events if e.get("kind") == "absent"))
    fig, ax = plt.subplots(figsize=(5, 3.2), constrained_layout=True)
    n = len(t_gatmo.stamps_s)
    xs = np.arange(n + 1)
    ys = np.searchsorted(np.asarray(reloc), xs, side="right") / max(n_moved, 1)
    ax.step(xs, np.minimum(ys, 1.0), where="post", color="tab:blue")
    ax.set_xlabel("scans into the run")
    ax.set_ylabel("moved objects identified")
    ax.set_ylim(0, 1.05)
    ax.set_title(f"run {run}: identification ({n_moved} moved)", fontsize=9)
    p = out_dir / "identification.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths


def _moved_in_run(scenario_json: Path, run: int) -> int | None:
    try:
        data = json.loads(scenario_json.read_text())
        runs = data.get("runs", [])
        for r in runs:
            if int(r.get("run", -1)) == run:
                moved = r.get("moved") or r.get("changes") or []
                return sum(1 for m in moved if m.get("kind") in ("moved", "shifted"))
    except (OSError, ValueError, TypeError, AttributeError):
        return None
    return None
