"""Runs over logs with files in and out: ``gatmo run`` and ``gatmo compare``.

``compare`` runs the same logs twice in one go with the same seeds and parameters:

* ``static``: the Monte Carlo localizer alone on the static map, as an AMCL user has it today;
* ``gatmo``: localizer + scan matcher + GATMO, the object map carried from log to log and fed
  back into the localizer's likelihood field.

Per log, results are written as soon as the log is done (atomically), so an error in a later
log (unreadable file, ground truth that does not match) keeps what was already compared.
"""

from __future__ import annotations

import copy
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gatmo._io import atomic_write_text
from gatmo.errors import DataError, GatmoError
from gatmo.maps.grid import UNKNOWN, OccupancyGrid
from gatmo.pipeline.stack import LocalizationStack

Progress = Callable[[int, int | None], None]

SIDES = ("static", "gatmo")


# ----------------------------------------------------------------------------- traces
@dataclass
class RunTrace:
    """Everything one side produced on one log (in memory)."""

    log: str
    side: str
    stamps_s: np.ndarray
    poses_xytheta: np.ndarray
    localizer_poses_xytheta: np.ndarray
    confident: np.ndarray
    ms: np.ndarray
    events: list = field(default_factory=list)
    resets: int = 0
    relocalizations: int = 0  # the filter started again by the stack (fusion.relocalize)
    map_updates: int = 0
    # (N, 3) base poses (map frame) the stack handed GATMO as trusted; NaN rows: scans it was
    # not handed (no trusted pose; every scan on the static side); None: not recorded
    gatmo_poses_xytheta: np.ndarray | None = None
    # (N,) bool: of those, the poses the scan-to-map alignment confirmed (GATMO's
    # pose_verified); (N,) str: what the alignment concluded per scan
    # (gatmo.pipeline.stack.ALIGN_OUTCOMES, "" where it did not run); None: not recorded
    gatmo_verified: np.ndarray | None = None
    align_outcomes: np.ndarray | None = None
    # (object id, test) -> how often GATMO refused a chair as that object this run, by the
    # matching test that refused it (GatmoMapper.refusals); empty on the static side
    refusals: dict = field(default_factory=dict)
    # (object id, test) -> the refused chairs' centres (x, y) [m] (GatmoMapper.refused_at)
    refused_at: dict = field(default_factory=dict)

    def mean_ms(self) -> float:
        return float(np.mean(self.ms)) if len(self.ms) else float("nan")


@dataclass
class GroundTruth:
    stamps_s: np.ndarray
    poses_xytheta: np.ndarray
    source: str
    in_log: bool = False  # carried in the log's scans, not a file the user gave


def load_scans(log: str | Path, fmt: str | None = None, max_scans: int | None = None) -> list:
    """Read a whole log into memory (both sides of a comparison use the same scans)."""
    from gatmo.datasets.open import open_log

    src = open_log(log, fmt=fmt)
    scans = []
    for scan in src:
        scans.append(scan)
        if max_scans is not None and len(scans) >= max_scans:
            break
    if not scans:
        raise DataError("no scans in the log", file=log)
    return scans


def ground_truth_of(scans: list, log: str | Path, gt_path: str | Path | None, *,
                    stamp_offset_s: float = 0.0) -> GroundTruth | None:
    """Ground truth from a TUM file (``stamp_offset_s`` added to its stamps), else from the
    scans' own gt poses, else None.

    A TUM file whose stamps do not cover the log is refused: scoring against it would be
    meaningless.
    """
    stamps = np.array([s.stamp_s for s in scans])
    if gt_path is not None:
        from gatmo.datasets.tum import read_tum

        gt_s, gt_p = read_tum(gt_path)
        if len(gt_s) == 0:
            raise DataError("ground truth is empty", file=gt_path)
        gt_s = np.asarray(gt_s, dtype=float) + stamp_offset_s
        covered = np.mean((stamps >= gt_s[0] - 0.05) & (stamps <= gt_s[-1] + 0.05))
        if covered < 0.5:
            raise DataError(
                f"ground-truth stamps [{gt_s[0]:.3f}, {gt_s[-1]:.3f}] s cover {covered:.0%} of "
                f"the log's scans [{stamps[0]:.3f}, {stamps[-1]:.3f}] s ({Path(log).name})",
                file=gt_path,
            )
        return GroundTruth(np.asarray(gt_s), np.asarray(gt_p), str(gt_path))
    have = [s.gt_pose_xytheta is not None for s in scans]
    if sum(have) >= max(2, len(scans) // 2):
        idx = [i for i, h in enumerate(have) if h]
        return GroundTruth(
            stamps[idx], np.array([scans[i].gt_pose_xytheta for i in idx]), f"{log} (in-log)",
            in_log=True)
    return None


def known_fraction(grid: OccupancyGrid, scan, pose_xytheta: np.ndarray) -> float:
    """Share of ``scan``'s returns, laid at the robot pose ``pose_xytheta`` (map frame), that
    fall on known cells of ``grid`` (free or occupied, inside it); 1.0 for a scan without
    returns."""
    from gatmo.geometry import compose, transform_points

    pts = transform_points(compose(pose_xytheta, scan.laser_pose_xytheta), scan.points_laser_xy())
    if len(pts) == 0:
        return 1.0
    return float(np.mean(grid.value_at(pts) != UNKNOWN))


#: below this share of returns on known map cells a pose is not in the map's frame (or the log
#: was recorded elsewhere): a run from it, or a score against it, would be meaningless
MIN_KNOWN_FRACTION = 0.1


def check_overlap(grid: OccupancyGrid, scan, pose_xytheta: np.ndarray, log: str | Path,
                  origin: str = "the initial pose") -> float:
    """Fraction of the first scan's endpoints that land on the map's known area.

    A log recorded elsewhere, or a start given in another frame, puts the returns in unknown
    space or outside the grid; refuse it instead of reporting a meaningless error figure.
    ``origin`` says where the pose came from, for the message.
    """
    known = known_fraction(grid, scan, pose_xytheta)
    if known < MIN_KNOWN_FRACTION:
        x, y, th = (float(v) for v in pose_xytheta)
        hint = ("the log's ground truth may be in another frame than the map's; "
                if origin == GT_ORIGIN else "")
        raise DataError(
            f"the log does not overlap the map: {known:.0%} of the first scan's returns at "
            f"{origin} ({x:.2f} m, {y:.2f} m, {np.degrees(th):.1f} deg) fall on known map "
            f"cells; {hint}give the start in the map frame (--initial-pose X,Y,YAW) or "
            "localize globally (--global)",
            file=log,
        )
    return known


#: :func:`initial_pose_origin` of a start taken from the log's ground truth
GT_ORIGIN = "the log's first ground-truth pose"


def initial_pose_origin(initial_pose, configured=None) -> str:
    """Where :func:`initial_pose_for` took a (non-None) start from, for messages."""
    if initial_pose is not None:
        return "the given initial pose"
    if configured is not None:
        return "the configuration's initial pose (amcl.initial_pose_xytheta)"
    return GT_ORIGIN


def vet_ground_truth(grid: OccupancyGrid, scans: list, gt: GroundTruth | None, log: str | Path,
                     samples: int = 10) -> tuple[GroundTruth | None, list[str]]:
    """``gt`` checked to be in the map's frame: at up to ``samples`` of its poses spread over
    the log, the median share of the nearest scan's returns on known map cells must reach
    :data:`MIN_KNOWN_FRACTION` (most of them, where the poses are right). A ground-truth file
    that fails is refused (:class:`DataError` naming it); ground truth carried in the log (a
    simulator's, e.g. Stage's ``base_pose_ground_truth``, often in the simulator's own frame) is
    dropped with a warning line, so nothing is scored against it. Returns (gt or None,
    warnings)."""
    if gt is None or len(gt.stamps_s) == 0:
        return gt, []
    stamps = np.array([s.stamp_s for s in scans])
    pick = np.unique(np.linspace(0, len(gt.stamps_s) - 1, min(samples, len(gt.stamps_s)))
                     .round().astype(int))
    fracs = []
    for i in pick:
        j = int(np.argmin(np.abs(stamps - gt.stamps_s[i])))
        if abs(stamps[j] - gt.stamps_s[i]) <= 0.05:
            fracs.append(known_fraction(grid, scans[j], gt.poses_xytheta[i]))
    if not fracs or float(np.median(fracs)) >= MIN_KNOWN_FRACTION:
        return gt, []
    what = (f"{float(np.median(fracs)):.0%} of the log's returns at its poses fall on known map "
            f"cells (median of {len(fracs)} scans): it is not in the map's frame")
    if not gt.in_log:
        raise DataError(f"ground truth: {what}", file=gt.source)
    return None, [f"{log}: the ground truth in the log is not scored against: {what} (e.g. a "
                  "simulator's own world frame); give one in the map frame with --ground-truth"]


# ---------------------------------------------------------------------------- builders
def initial_pose_for(scans: list, initial_pose, global_localization: bool, configured=None):
    """The initial pose (x, y, theta; map frame) a run starts from, None for global
    localization: the given one (``--initial-pose``), else none with ``global_localization``,
    else the configuration's (``configured``: ``amcl.initial_pose_xytheta``, a ROS AMCL file's
    ``initial_pose_x / _y / _a``, as AMCL starts from it), else the log's first ground-truth
    pose, else None."""
    if initial_pose is not None:
        return np.asarray(initial_pose, dtype=float)
    if global_localization:
        return None
    if configured is not None:
        return np.asarray(configured, dtype=float)
    first = scans[0].gt_pose_xytheta
    return None if first is None else np.asarray(first, dtype=float)


def make_localizer(cfg, grid: OccupancyGrid, seed: int, initial_pose, global_localization: bool):
    from gatmo.localization.mcl import MonteCarloLocalizer

    loc = MonteCarloLocalizer.from_config(cfg.amcl, grid, rng=np.random.default_rng(seed))
    if initial_pose is not None:
        loc.set_initial_pose(np.asarray(initial_pose, dtype=float))
    else:
        loc.global_localization()
    return loc


def make_matcher(cfg):
    from gatmo.scanmatch.odometry import ScanMatchOdometry

    return ScanMatchOdometry.from_config(cfg.icp)


#: the anchor filter's random seed is the localizer's plus this (fusion.anchor_filter)
ANCHOR_SEED_OFFSET = 7919


def make_full_stack(cfg, mapper, seed: int, initial_pose,
                    loc_grid: OccupancyGrid | None = None) -> LocalizationStack:
    """The full stack: the localizer on GATMO's current map, or on ``loc_grid`` fixed if given
    (global localization when ``initial_pose`` is None), the scan matcher if
    ``cfg.fusion.use_scan_matcher``, GATMO."""
    grid = loc_grid if loc_grid is not None else mapper.localizer_grid()
    anchor = None
    if cfg.fusion.anchor_filter:
        f = cfg.fusion
        amcl = cfg.amcl.model_copy(update={"laser_model": f.anchor_laser_model,
                                           "sigma_hit_m": f.anchor_sigma_hit_m})
        # its own draw: the two filters' particles are independent
        anchor = make_localizer(cfg.model_copy(update={"amcl": amcl}), grid,
                                seed + ANCHOR_SEED_OFFSET, initial_pose, initial_pose is None)
    return LocalizationStack(
        make_localizer(cfg, grid, seed, initial_pose, initial_pose is None),
        make_matcher(cfg) if cfg.fusion.use_scan_matcher else None,
        mapper,
        cfg.fusion,
        loc_grid=loc_grid,
        anchor=anchor,
        initial_pose_xytheta=initial_pose,
        initial_std_m=float(np.sqrt(max(cfg.amcl.initial_cov_xx_m2, cfg.amcl.initial_cov_yy_m2))),
    )


def run_full(cfg, mapper, scans: list, seed: int, initial_pose, **side_kwargs) -> RunTrace:
    """The full stack over one log, ``cfg.fusion.passes`` times (offline).

    Every pass after the first localizes on the map the pass before ended with, fixed, and
    its GATMO starts again from the object map the run began with. ``fusion.passes_objects``
    names the pass that updates ``mapper`` (the others run on copies): its events, refusals
    and poses handed to GATMO are the trace's; the published and localizer poses are the last
    pass's, and the time per scan the sum over the passes. ``side_kwargs`` go to
    :func:`run_side` for the pass whose object map is kept."""
    passes = cfg.fusion.passes
    keep = 0 if cfg.fusion.passes_objects == "first" else passes - 1
    start = copy.deepcopy(mapper) if passes > 1 else None  # the object map the run began with
    quiet = {"log": side_kwargs.get("log", ""), "run_id": side_kwargs["run_id"]}
    loc_grid, ms = None, np.zeros(len(scans))
    for k in range(passes):
        m = mapper if k == keep else copy.deepcopy(start)
        t = run_side(make_full_stack(cfg, m, seed, initial_pose, loc_grid=loc_grid), scans,
                     side="gatmo", **(side_kwargs if k == keep else quiet))
        ms += t.ms
        loc_grid = m.grid()
        if k == keep:
            kept = t
    return replace(kept, poses_xytheta=t.poses_xytheta, ms=ms,
                   localizer_poses_xytheta=t.localizer_poses_xytheta, confident=t.confident,
                   resets=t.resets, relocalizations=t.relocalizations)


def run_side(
    stack: LocalizationStack,
    scans: list,
    *,
    log: str,
    side: str,
    run_id: int,
    progress: Progress | None = None,
    offset: int = 0,
    total: int | None = None,
    observer=None,
) -> RunTrace:
    """Step a stack through one log's scans. ``observer`` (e.g. a
    :class:`gatmo.pipeline.live.RerunObserver`) sees every step; its time is not in ``ms``."""
    stack.begin_run(run_id)
    n = len(scans)
    stamps = np.empty(n)
    poses = np.empty((n, 3))
    loc_poses = np.empty((n, 3))
    confident = np.zeros(n, dtype=bool)
    gatmo_poses = np.full((n, 3), np.nan)
    gatmo_verified = np.zeros(n, dtype=bool)
    align_outcomes = np.full(n, "", dtype=object)
    ms = np.empty(n)
    events: list = []
    resets = relocalizations = 0
    for i, scan in enumerate(scans):
        step = stack.step(scan)
        stamps[i] = step.stamp_s
        poses[i] = step.pose_xytheta
        loc_poses[i] = step.localizer_pose_xytheta
        confident[i] = step.confident
        if step.gatmo_pose_xytheta is not None:
            gatmo_poses[i] = step.gatmo_pose_xytheta
        gatmo_verified[i] = step.gatmo_pose_verified
        align_outcomes[i] = step.align_outcome or ""
        ms[i] = step.ms
        resets += int(step.reset)
        relocalizations += int(step.relocalized)
        for ev in step.events:
            events.append(_event_dict(ev, scan_index=i))
        if observer is not None:
            observer.on_step(side, i, scan, step, stack)
        if progress is not None and (i % 20 == 0 or i == n - 1):
            progress(offset + i + 1, total)
    t0 = time.perf_counter()
    end_events = list(stack.end_run())
    for ev in end_events:
        events.append(_event_dict(ev, scan_index=n))
    if n:
        ms[-1] += (time.perf_counter() - t0) * 1e3
    mapper = getattr(stack, "mapper", None)
    refusals, refused_at = ({}, {}) if mapper is None else (
        dict(mapper.refusals), {k: set(v) for k, v in mapper.refused_at.items()})
    if observer is not None:
        observer.on_run_end(side, stack, end_events)
    return RunTrace(
        log=log,
        side=side,
        stamps_s=stamps,
        poses_xytheta=poses,
        localizer_poses_xytheta=loc_poses,
        confident=confident,
        ms=ms,
        events=events,
        resets=resets,
        relocalizations=relocalizations,
        map_updates=stack.n_map_updates,
        gatmo_poses_xytheta=gatmo_poses,
        gatmo_verified=gatmo_verified,
        align_outcomes=align_outcomes,
        refusals=refusals,
        refused_at=refused_at,
    )


def _event_dict(ev, scan_index: int) -> dict:
    d = ev.as_dict() if hasattr(ev, "as_dict") else dict(ev)
    d["scan_index"] = int(scan_index)
    return json.loads(json.dumps(d, default=_json_default))


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    return str(o)


# ----------------------------------------------------------------------------- metrics
def score(trace: RunTrace, gt: GroundTruth | None, relations=None) -> dict:
    """ATE (no alignment: the map frame is fixed), lost fraction, relations error, timing."""
    row: dict = {
        "log": Path(trace.log).name,
        "side": trace.side,
        "scans": int(len(trace.stamps_s)),
        "ms_per_scan": float(np.mean(trace.ms)) if len(trace.ms) else float("nan"),
        "ms_per_scan_median": float(np.median(trace.ms)) if len(trace.ms) else float("nan"),
    }
    if gt is not None:
        from gatmo.datasets.metrics import ate

        a = ate(trace.stamps_s, trace.poses_xytheta, gt.stamps_s, gt.poses_xytheta)
        row.update(
            ate_rmse_m=a["rmse_m"],
            ate_median_m=a["median_m"],
            ate_max_m=a["max_m"],
            lost_fraction=a["lost_fraction"],
        )
    if relations is not None:
        from gatmo.datasets.metrics import relations_error

        r = relations_error(trace.stamps_s, trace.poses_xytheta, relations)
        row.update(
            rel_trans_mean_m=r["trans_mean_m"],
            rel_rot_mean_deg=r["rot_mean_deg"],
            rel_used=r["n_used"],
        )
    if trace.side == "gatmo" and trace.gatmo_poses_xytheta is not None and len(trace.stamps_s):
        # the share of scans whose pose the stack trusted enough to hand GATMO: none, and the
        # object map cannot change (untrusted_logs says so to the user)
        row["gatmo_trusted_fraction"] = float(np.mean(np.isfinite(trace.gatmo_poses_xytheta[:, 0])))
    kinds = [e.get("kind") for e in trace.events]
    row.update(
        absent=kinds.count("absent"),
        relocated=kinds.count("relocated"),
        added=kinds.count("added"),
        movable=kinds.count("movable"),
        resets=trace.resets,
        relocalizations=trace.relocalizations,
    )
    return row


#: below this share of a log's scans handed to GATMO as trusted, the user is told why the
#: object map (nearly) did not change
UNTRUSTED_WARN_FRACTION = 0.01


def untrusted_logs(rows: list, cfg) -> list[str]:
    """One line per full-stack row of ``rows`` (as :func:`score` makes them) whose GATMO was
    handed fewer than :data:`UNTRUSTED_WARN_FRACTION` of the scans as trusted (mostly: the
    localizer's cloud seldom or never passed GATMO's strict test, ``fusion.absence_max_std_*``),
    so the object map could hardly change, whatever moved. ``cfg``: the stack config run."""
    f = cfg.fusion
    out = []
    for r in rows:
        frac = r.get("gatmo_trusted_fraction")
        if frac is None or frac >= UNTRUSTED_WARN_FRACTION:
            continue
        n = round(frac * r["scans"])
        out.append(
            f"{r['log']}: GATMO was handed {n} of {r['scans']} scans as trusted, so the object "
            "map could hardly change. It takes a scan only from a pose whose particle cloud "
            f"is within {f.absence_max_std_xy_m:g} m / {f.absence_max_std_theta_deg:g} deg "
            "(fusion.absence_max_std_xy_m / _theta_deg). A sensor model and odometry noise "
            "matched to the robot tighten the cloud: --preset real for a real laser, a "
            "simulated scenario's stack.yaml (--config)")
    return out


def error_series(trace: RunTrace, gt: GroundTruth) -> np.ndarray:
    """Position error (N,) [m] of a trace against ground truth interpolated at its stamps."""
    from gatmo.geometry import interpolate_poses

    g = interpolate_poses(gt.stamps_s, gt.poses_xytheta, trace.stamps_s)
    e = np.hypot(*(trace.poses_xytheta[:, :2] - g[:, :2]).T)
    outside = (trace.stamps_s < gt.stamps_s[0] - 0.05) | (trace.stamps_s > gt.stamps_s[-1] + 0.05)
    e[outside] = np.nan
    return e


# ------------------------------------------------------------------------------ writers
def write_trace(trace: RunTrace, out_dir: Path) -> None:
    from gatmo.datasets.tum import write_tum

    out_dir.mkdir(parents=True, exist_ok=True)
    write_tum(out_dir / "poses.tum", trace.stamps_s, trace.poses_xytheta)
    if trace.side == "gatmo":
        text = "".join(json.dumps(e, default=_json_default) + "\n" for e in trace.events)
        atomic_write_text(out_dir / "events.jsonl", text)


def write_object_map(mapper, base_grid: OccupancyGrid, out_dir: Path, base_meta: dict) -> None:
    """objects.json and the reconfigured map, each written atomically."""
    from gatmo.maps.io import save_map
    from gatmo.maps.object_io import save_objects

    out_dir.mkdir(parents=True, exist_ok=True)
    save_map(mapper.grid(), out_dir / "map.yaml")
    save_objects(out_dir / "objects.json", mapper.object_map, base_grid_meta=base_meta)


def _base_meta(map_yaml: Path, grid: OccupancyGrid) -> dict:
    return {
        "map_yaml": str(map_yaml),
        "resolution_m": grid.resolution_m,
        "origin_xytheta": list(grid.origin_xytheta),
        "shape": [grid.height, grid.width],
    }


def _make_mapper(cfg, grid: OccupancyGrid, objects_path: Path | None):
    from gatmo.objects.mapper import GatmoMapper

    object_map = None
    if objects_path is not None:
        from gatmo.maps.object_io import load_objects

        object_map = load_objects(objects_path, grid)
    return GatmoMapper.from_config(cfg.gatmo, grid, object_map=object_map)


# ----------------------------------------------------------------------------- gatmo run
@dataclass
class RunSummary:
    rows: list
    out_dir: Path
    warnings: list = field(default_factory=list)  # untrusted_logs

    def as_dict(self) -> dict:
        return {"out_dir": str(self.out_dir), "logs": self.rows, "warnings": self.warnings}


def run_gatmo(
    map_yaml: str | Path,
    log: str | Path,
    out_dir: str | Path,
    *,
    objects_path: str | Path | None = None,
    params_path: str | Path | None = None,
    config_path: str | Path | None = None,
    preset: str | None = None,
    initial_pose=None,
    global_localization: bool = False,
    fmt: str | None = None,
    run_id: int | None = None,
    max_scans: int | None = None,
    progress: Progress | None = None,
    gt_path: str | Path | None = None,
) -> RunSummary:
    """``gatmo run``: the full stack on one log; writes poses.tum, objects.json, map, events.
    Scored against ``gt_path`` (TUM, map frame) if given, else the log's own ground truth.
    ``run_id``: the run's number in the object map's history and events; None: the one after
    the last run laid on ``objects_path`` (1 on a fresh map). ``preset``: a named stack
    configuration (:data:`gatmo.pipeline.config.STACK_PRESETS`) instead of ``config_path``."""
    from gatmo.datasets.open import open_map
    from gatmo.pipeline.config import dump_stack_config, load_stack_config

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = load_stack_config(config_path, params_path, preset)
    atomic_write_text(out / "config.yaml", dump_stack_config(cfg))
    base = open_map(map_yaml)
    mapper = _make_mapper(cfg, base, Path(objects_path) if objects_path else None)
    scans = load_scans(log, fmt, max_scans)
    pose0 = initial_pose_for(scans, initial_pose, global_localization,
                             cfg.amcl.initial_pose_xytheta)
    if pose0 is not None:
        check_overlap(base, scans[0], pose0, log,
                      initial_pose_origin(initial_pose, cfg.amcl.initial_pose_xytheta))
    gt, gt_warnings = vet_ground_truth(base, scans, ground_truth_of(scans, log, gt_path), log)
    if run_id is None:
        run_id = mapper.object_map.runs + 1
    trace = run_full(cfg, mapper, scans, cfg.seed, pose0, log=str(log), run_id=run_id,
                     progress=progress, total=len(scans))
    write_trace(trace, out)
    write_object_map(mapper, base, out, _base_meta(Path(map_yaml), base))
    rows = [score(trace, gt)]
    return RunSummary(rows, out, gt_warnings + untrusted_logs(rows, cfg))


# ------------------------------------------------------------------------------ compare
@dataclass
class CompareResult:
    out_dir: Path
    rows: list  # one dict per (log, side)
    overall: dict  # side -> dict
    pictures: list
    traces: dict = field(default_factory=dict)  # (log index, side) -> RunTrace
    # the static side ran its own amcl section (out_dir/static_amcl.yaml), not the stack's
    static_amcl: bool = False
    warnings: list = field(default_factory=list)  # untrusted_logs

    def as_dict(self) -> dict:
        return {"out_dir": str(self.out_dir), "logs": self.rows, "overall": self.overall,
                "pictures": [str(p) for p in self.pictures],
                "static_config": "static_amcl.yaml" if self.static_amcl else "config.yaml",
                "warnings": self.warnings}


def _overall(rows: list) -> dict:
    out = {}
    for side in SIDES:
        rs = [r for r in rows if r["side"] == side]
        if not rs:
            continue
        scans = np.array([r["scans"] for r in rs], dtype=float)
        o = {"logs": len(rs), "scans": int(scans.sum())}
        for key in ("ate_rmse_m", "lost_fraction", "ms_per_scan", "gatmo_trusted_fraction"):
            vals = [r.get(key) for r in rs]
            if all(v is not None for v in vals):
                v = np.array(vals, dtype=float)
                if key == "ate_rmse_m":  # pooled RMSE over all scans
                    o[key] = float(np.sqrt(np.sum(scans * v**2) / scans.sum()))
                else:
                    o[key] = float(np.sum(scans * v) / scans.sum())
        for key in ("ate_max_m",):
            vals = [r.get(key) for r in rs if r.get(key) is not None]
            if vals:
                o[key] = float(max(vals))
        for key in ("absent", "relocated", "added"):
            o[key] = int(sum(r.get(key, 0) for r in rs))
        # with a scenario: the pieces moved and those found (right object, true pose)
        for key in ("obj_moved", "obj_found", "obj_false_relocations"):
            if all(key in r for r in rs):
                o[key] = int(sum(r[key] for r in rs))
        out[side] = o
    return out


def compare(
    map_yaml: str | Path,
    logs: Sequence[str | Path],
    out_dir: str | Path,
    *,
    params_path: str | Path | None = None,
    config_path: str | Path | None = None,
    initial_pose=None,
    global_localization: bool = False,
    gt_paths: Sequence[str | Path] | None = None,
    relations_path: str | Path | None = None,
    fmt: str | None = None,
    max_scans: int | None = None,
    pictures: bool = True,
    scenario_json: str | Path | None = None,
    progress: Progress | None = None,
    keep_traces: bool = False,
    config=None,
    sides: Sequence[str] = SIDES,
    observer=None,
    static_params_path: str | Path | None = None,
    static_amcl=None,
    preset: str | None = None,
) -> CompareResult:
    """``gatmo compare``: static localizer vs full stack on the same logs, same seeds.

    The static side runs the full stack's ``amcl`` section unless ``static_params_path`` (a
    ROS 1 / Nav2 AMCL YAML, as ``params_path``) or ``static_amcl`` (an
    :class:`gatmo.localization.config.AmclConfig`) gives it its own: the AMCL a robot runs
    today against gatmo's configuration. That section is then written to
    ``out_dir/static_amcl.yaml`` and named in ``summary.json``.
    ``observer``: a live view (:class:`gatmo.pipeline.live.RerunObserver`) or None.
    ``preset``: a named stack configuration instead of ``config_path``."""
    from gatmo.datasets.open import open_map
    from gatmo.pipeline.config import dump_stack_config, load_stack_config

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if gt_paths and len(gt_paths) != len(logs):
        raise GatmoError(
            f"{len(gt_paths)} ground-truth files for {len(logs)} logs", field="--ground-truth"
        )
    cfg = config if config is not None else load_stack_config(config_path, params_path, preset)
    atomic_write_text(out / "config.yaml", dump_stack_config(cfg))
    if static_params_path is not None:
        from gatmo.localization.params import load_amcl_yaml

        static_amcl = load_amcl_yaml(static_params_path)
    static_cfg = cfg
    if static_amcl is not None:
        from gatmo.config import dump_model

        static_cfg = cfg.model_copy(update={"amcl": static_amcl})
        atomic_write_text(out / "static_amcl.yaml", dump_model(static_amcl))
    base = open_map(map_yaml)
    meta = _base_meta(Path(map_yaml), base)
    relations = None
    if relations_path is not None:
        from gatmo.datasets.relations import read_relations

        relations = read_relations(relations_path)

    mapper = _make_mapper(cfg, base, None)
    if observer is not None:
        observer.on_map("static", base)
    scenario, ties = None, {}
    if scenario_json is not None:
        from gatmo.datasets.sim import load_scenario
        from gatmo.pipeline.evaluate import tie_objects

        scenario = load_scenario(scenario_json)
        ties = tie_objects(mapper.object_map, scenario)
    rows: list = []
    pics: list = []
    traces: dict = {}
    gt_warnings: list[str] = []
    done = 0
    for k, log in enumerate(logs):
        scans = load_scans(log, fmt, max_scans)
        pose0 = initial_pose_for(scans, initial_pose, global_localization,
                                 cfg.amcl.initial_pose_xytheta)
        if pose0 is not None:
            check_overlap(base, scans[0], pose0, log,
                          initial_pose_origin(initial_pose, cfg.amcl.initial_pose_xytheta))
        gt, warned = vet_ground_truth(
            base, scans, ground_truth_of(scans, log, gt_paths[k] if gt_paths else None), log)
        gt_warnings += warned
        seed = cfg.seed + k
        name = f"{k + 1:02d}_{Path(log).stem.split('.')[0]}"
        total = 2 * len(scans)
        grid_before = mapper.grid()
        if observer is not None:
            observer.on_log(k, name, np.array([s.stamp_s for s in scans]), gt)
            observer.on_map("gatmo", grid_before)
            observer.on_objects(mapper.object_map.objects)

        static = LocalizationStack(make_localizer(static_cfg, base, seed, pose0, pose0 is None))
        t_static = run_side(static, scans, log=str(log), side="static", run_id=k + 1,
                            progress=_offset(progress, done), total=None, observer=observer)
        # its localizer on grid_before (and, with fusion.passes, the map a pass before ended with)
        t_gatmo = run_full(cfg, mapper, scans, seed, pose0, log=str(log), run_id=k + 1,
                           progress=_offset(progress, done + len(scans)), total=None,
                           observer=observer)
        done += total
        write_trace(t_static, out / "static" / name)
        write_trace(t_gatmo, out / "gatmo" / name)
        write_object_map(mapper, base, out / "gatmo" / name, meta)
        for t in (t_static, t_gatmo):
            row = score(t, gt, relations)
            row["run"] = k + 1
            if scenario is not None and t.side == "gatmo":
                from gatmo.pipeline.evaluate import score_run

                run_no = _run_number(log, k + 1)
                if run_no <= len(scenario["runs"]):
                    o = score_run(mapper.object_map, ties, scenario, run_no, t.events)
                    row.update({f"obj_{key}": v for key, v in o.items() if key != "run"})
            rows.append(row)
        if pictures:
            from gatmo.pipeline.plots import plot_log

            pics.extend(
                plot_log(out / "pictures" / name, base, grid_before, mapper, t_static, t_gatmo,
                         gt, scenario_json=scenario_json, run=k + 1)
            )
        if keep_traces:
            traces[(k, "static")] = t_static
            traces[(k, "gatmo")] = t_gatmo
        result = CompareResult(out, rows, _overall(rows), pics, traces,
                               static_amcl=static_amcl is not None,
                               warnings=gt_warnings + untrusted_logs(rows, cfg))
        atomic_write_text(
            out / "summary.json", json.dumps(result.as_dict(), indent=2, default=_json_default)
        )
    if not logs:
        result = CompareResult(out, rows, _overall(rows), pics, traces,
                               static_amcl=static_amcl is not None)
    return result


def _run_number(log, default: int) -> int:
    import re

    m = re.search(r"run_(\d+)", Path(log).name)
    return int(m.group(1)) if m else default


def _offset(progress: Progress | None, offset: int) -> Progress | None:
    if progress is None:
        return None
    return lambda i, n: progress(offset + i, None)


__all__ = [
    "CompareResult",
    "GroundTruth",
    "RunSummary",
    "RunTrace",
    "compare",
    "error_series",
    "ground_truth_of",
    "load_scans",
    "run_gatmo",
    "score",
]


# --------------------------------------------------------------------------------- demo
#: the stack configuration ``simulate`` writes beside a scenario (sim_stack_config)
SCENARIO_STACK_YAML = "stack.yaml"


def simulate(out_dir: str | Path, *, preset: str = "hall", runs: int = 4, seed: int = 3,
             bag: bool = False, sim_config=None, bag_storage: str = "sqlite3"):
    """``gatmo simulate``: a scenario (:func:`gatmo.datasets.sim.simulate_scenario`) and beside
    it ``stack.yaml``, the stack configuration matched to the simulated robot
    (:func:`gatmo.pipeline.config.sim_stack_config` with the odometry alphas of the
    simulator's config: a sensor model sharp enough for GATMO's pose test, the true start
    pose's small cloud), for ``--config``.
    ``sim_config``: the simulator's :class:`gatmo.datasets.sim.SimConfig` (default: the
    preset's). Returns ``(ScenarioResult, path of stack.yaml)``."""
    from gatmo.config import dump_model
    from gatmo.datasets.sim import SimConfig, simulate_scenario
    from gatmo.pipeline.config import sim_stack_config

    scen = simulate_scenario(out_dir, preset=preset, runs=runs, seed=seed, bag=bag,
                             bag_storage=bag_storage,
                             config=sim_config)
    stack = sim_stack_config((SimConfig.for_preset(preset) if sim_config is None
                              else sim_config).odom)
    stack_yaml = scen.out_dir / SCENARIO_STACK_YAML
    atomic_write_text(stack_yaml, dump_model(stack, comments=True))
    return scen, stack_yaml


def demo(out_dir: str | Path, *, preset: str = "hall", runs: int = 4, seed: int = 3,
         progress: Progress | None = None) -> CompareResult:
    """``gatmo demo``: simulate the default scenario, then compare static vs gatmo on it with
    the scenario's ``stack.yaml``, as a user would (``gatmo simulate`` then ``gatmo compare
    --config``)."""
    out = Path(out_dir)
    scen, stack_yaml = simulate(out / "scenario", preset=preset, runs=runs, seed=seed)
    return compare(
        scen.map_yaml,
        scen.logs,
        out / "compare",
        scenario_json=scen.scenario_json,
        progress=progress,
        config_path=stack_yaml,
    )
