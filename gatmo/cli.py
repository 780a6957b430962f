"""The ``gatmo`` command line. Each command maps its arguments onto one library call.

Imports of numpy, numba and the algorithm packages happen inside the commands, so
``gatmo --help`` stays instant. Library errors (:class:`gatmo.errors.GatmoError`) become one red
line and exit code 1; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from gatmo import __version__

app = typer.Typer(
    name="gatmo",
    help="Localization plus an object map that keeps up with moved furniture.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",
)
map_app = typer.Typer(help="Make occupancy maps.", no_args_is_help=True)
config_app = typer.Typer(help="Show or write configuration files.", no_args_is_help=True)
app.add_typer(map_app, name="map")
app.add_typer(config_app, name="config")

# options several commands share
FormatOpt = Annotated[str | None, typer.Option("--format", help="carmen | rosbag | wean")]
MapOpt = Annotated[Path, typer.Option("--map", help="map_server map YAML (the static map).")]
ParamsOpt = Annotated[Path | None, typer.Option("--params", help="AMCL parameter YAML.")]
ConfigOpt = Annotated[
    Path | None, typer.Option("--config", help="gatmo stack YAML (gatmo config dump stack).")
]
PresetOpt = Annotated[
    str | None, typer.Option("--preset", help="a named stack configuration instead of --config: "
                             "amcl (AMCL's defaults) | sim (gatmo's simulator) | real (the real "
                             "logs')")
]
PoseOpt = Annotated[str | None, typer.Option("--initial-pose", help="X,Y,YAW in the map frame.")]
GlobalOpt = Annotated[bool, typer.Option("--global", help="Global localization.")]
GroundTruthOpt = Annotated[Path | None, typer.Option(
    "--ground-truth", help="TUM ground truth in the map frame (else the log's own, if any).")]



def _console(stderr: bool = False):
    from rich.console import Console

    c = Console(stderr=stderr, highlight=False)
    if not c.is_terminal:  # logs and pipes: wide enough for the comparison table
        c = Console(stderr=stderr, highlight=False, width=max(c.width, 160))
    return c


def _version_callback(value: bool) -> None:
    if value:
        print(f"gatmo {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version_callback, is_eager=True, help="Print version."),
    ] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks on errors.")] = False,
) -> None:
    """gatmo: Monte Carlo localization and GATMO object maps."""


def _parse_pose(text: str | None, name: str = "--initial-pose"):
    if text is None:
        return None
    from gatmo.errors import ConfigError

    parts = text.replace(" ", "").split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"expected X,Y,YAW numbers, got {text!r}", field=name) from None
    if len(values) != 3:
        raise ConfigError(f"expected 3 values X,Y,YAW, got {len(values)}", field=name)
    return values


def _progress(description: str):
    """A rich progress bar usable as ``progress(i, n)``; returns (context manager, callback)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    bar = Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=_console(stderr=True),
        transient=False,
    )
    task = bar.add_task(description, total=None)

    def update(i: int, n: int | None) -> None:
        bar.update(task, completed=i, total=n)

    return bar, update


def _print_mapping(title: str, rows: dict) -> None:
    from rich.table import Table

    # as wide as its title: a long path as title is not broken mid-name
    table = Table(title=title, show_header=False, min_width=len(title))
    table.add_column("field", style="bold")
    table.add_column("value")
    for k, v in rows.items():
        if isinstance(v, float):
            v = f"{v:.4g}"
        elif isinstance(v, dict | list):
            import json

            v = json.dumps(v, default=str)
        table.add_row(str(k), str(v))
    _console().print(table)


# --------------------------------------------------------------------------- info
@app.command()
def info(
    file: Annotated[
        Path, typer.Argument(help="Log, bag, map YAML, wean.dat, TUM, relations, "
                             "objects.json, scenario.json, stack config or AMCL YAML.")
    ],
    fmt: FormatOpt = None,
) -> None:
    """Summarise a data file: sensor, beams, FOV, range, scans, duration, path, topics; an
    object map's objects by list and runs; a scenario's changes per run; a configuration's
    models and the preset it is."""
    from gatmo.datasets.info import summarize

    summary = summarize(file, fmt=fmt)
    topics = summary.pop("topics", None)
    _print_mapping(str(file), summary)
    if topics:
        from rich.table import Table

        table = Table(title="topics")
        for col in ("topic", "type", "messages"):
            table.add_column(col)
        for t in topics:
            table.add_row(str(t["topic"]), str(t["type"]), str(t["count"]))
        _console().print(table)


# ----------------------------------------------------------------------- simulate
@app.command()
def simulate(
    out: Annotated[Path, typer.Argument(help="Output folder.")],
    preset: Annotated[str, typer.Option(help="World preset: hall | office.")] = "hall",
    runs: Annotated[
        int, typer.Option(min=1, help="Runs (furniture rearranged between).")
    ] = 4,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 3,
    bag: Annotated[bool, typer.Option("--bag", help="Also write a ROS 2 bag per run.")] = False,
    bag_storage: Annotated[str, typer.Option(
        "--bag-storage", help="The ROS 2 bags' storage: sqlite3 | mcap (Jazzy's default).")
    ] = "sqlite3",
) -> None:
    """Simulate a rearranged-room scenario: map, logs, ground truth, scenario.json and
    stack.yaml (the stack configuration matched to the simulated robot)."""
    from gatmo.pipeline.runs import simulate as run_simulate

    result, stack_yaml = run_simulate(out, preset=preset, runs=runs, seed=seed, bag=bag,
                                      bag_storage=bag_storage)
    _print_mapping(f"scenario {preset} seed {seed} -> {out}", result.summary())
    logs = " ".join(str(p) for p in result.logs)
    gts = " ".join(f"--ground-truth {p}" for p in result.gt)
    _console().print(
        f"compare on it: gatmo compare {logs} --map {result.map_yaml} "
        f"--scenario {result.scenario_json} --config {stack_yaml} {gts} --out {out}-compare",
        soft_wrap=True)


# ----------------------------------------------------------------------- localize
@app.command()
def localize(
    map_yaml: MapOpt,
    log: Annotated[Path, typer.Option("--log", help="Log or bag with scans and odometry.")],
    out: Annotated[Path, typer.Option("--out", help="Output TUM trajectory.")],
    params: ParamsOpt = None,
    config: Annotated[
        Path | None, typer.Option("--config", help="gatmo stack YAML: its amcl section (e.g. a "
                                  "simulated scenario's stack.yaml); --params wins over it.")
    ] = None,
    preset: PresetOpt = None,
    initial_pose: PoseOpt = None,
    global_loc: GlobalOpt = False,
    fmt: FormatOpt = None,
    max_scans: Annotated[int | None, typer.Option(help="Stop after this many scans.")] = None,
    ground_truth: GroundTruthOpt = None,
) -> None:
    """Monte Carlo localization of a log in a static map; writes the pose at every scan (TUM)."""
    from gatmo.pipeline.localize import run_localize

    bar, update = _progress("localize")
    with bar:
        summary = run_localize(
            map_yaml,
            log,
            params_path=params,
            config_path=config,
            preset=preset,
            fmt=fmt,
            initial_pose=_parse_pose(initial_pose),
            global_localization=global_loc,
            out_path=out,
            max_scans=max_scans,
            progress=update,
            gt_path=ground_truth,
        )
    _print_mapping("localization", summary.as_dict())
    _print_warnings(summary.warnings)


# ---------------------------------------------------------------------------- run
@app.command()
def run(
    map_yaml: MapOpt,
    log: Annotated[Path, typer.Option("--log", help="Log or bag with scans and odometry.")],
    out: Annotated[Path, typer.Option("--out", help="Output folder.")],
    objects: Annotated[
        Path | None, typer.Option("--objects", help="objects.json from an earlier run.")
    ] = None,
    params: ParamsOpt = None,
    config: ConfigOpt = None,
    preset: PresetOpt = None,
    initial_pose: PoseOpt = None,
    global_loc: GlobalOpt = False,
    fmt: FormatOpt = None,
    max_scans: Annotated[int | None, typer.Option(help="Stop after this many scans.")] = None,
    ground_truth: GroundTruthOpt = None,
) -> None:
    """Full stack (localizer + scan matcher + GATMO) on one log: poses, objects, map, events."""
    from gatmo.pipeline.runs import run_gatmo

    bar, update = _progress("gatmo run")
    with bar:
        summary = run_gatmo(
            map_yaml, log, out, objects_path=objects, params_path=params, config_path=config,
            preset=preset, initial_pose=_parse_pose(initial_pose),
            global_localization=global_loc, fmt=fmt, max_scans=max_scans, progress=update,
            gt_path=ground_truth,
        )
    for row in summary.rows:
        _print_mapping(f"gatmo run -> {out}", row)
    _print_warnings(summary.warnings)


def _print_warnings(lines: list[str]) -> None:
    from rich.markup import escape

    for line in lines:
        _console().print(f"[yellow]warning:[/yellow] {escape(line)}", soft_wrap=True)


def _print_compare(result) -> None:
    from rich.table import Table

    cols = [
        ("run", "run", "{}"), ("log", "log", "{}"), ("side", "side", "{}"),
        ("ate_rmse_m", "ATE rmse m", "{:.3f}"), ("ate_median_m", "median m", "{:.3f}"),
        ("ate_max_m", "max m", "{:.2f}"), ("lost_fraction", "lost", "{:.1%}"),
        ("rel_trans_mean_m", "rel m", "{:.3f}"), ("rel_rot_mean_deg", "rel deg", "{:.2f}"),
        ("absent", "absent", "{}"), ("relocated", "relocated", "{}"), ("added", "added", "{}"),
        ("obj_moved", "moved", "{}"), ("obj_found", "found", "{}"),
        ("gatmo_trusted_fraction", "trusted", "{:.0%}"), ("ms_per_scan", "ms/scan", "{:.1f}"),
    ]
    present = [c for c in cols if any(c[0] in r for r in result.rows)]
    table = Table(title="static localizer vs gatmo (localizer + scan matcher + object map)")
    for _, head, _ in present:
        table.add_column(head, justify="right")
    for r in result.rows:
        table.add_row(*[fmt.format(r[k]) if r.get(k) is not None else "-" for k, _, fmt in present])
    for side, o in result.overall.items():
        row = []
        for k, _, fmt in present:
            if k == "side":
                row.append(f"[bold]{side}[/bold]")
            elif k == "log":
                row.append("[bold]all[/bold]")
            elif k in o:
                row.append(fmt.format(o[k]))
            else:
                row.append("")
        table.add_row(*row)
    console = _console()
    console.print(table)
    _print_warnings(result.warnings)
    console.print(f"summary: {result.out_dir / 'summary.json'}")
    for p in result.pictures:
        console.print(f"picture: {p}")


@app.command()
def compare(
    logs: Annotated[list[Path], typer.Argument(help="Logs in the order they were recorded.")],
    map_yaml: MapOpt,
    out: Annotated[Path, typer.Option("--out", help="Output folder.")],
    params: ParamsOpt = None,
    config: ConfigOpt = None,
    preset: PresetOpt = None,
    static_params: Annotated[
        Path | None, typer.Option("--static-params", help="AMCL parameter YAML for the static "
                                  "side only, e.g. the one your robot runs today (default: the "
                                  "full stack's).")
    ] = None,
    initial_pose: PoseOpt = None,
    global_loc: GlobalOpt = False,
    ground_truth: Annotated[
        list[Path] | None, typer.Option("--ground-truth", help="TUM ground truth, one per log.")
    ] = None,
    relations: Annotated[
        Path | None, typer.Option("--relations", help="Kuemmerle relations file.")
    ] = None,
    fmt: FormatOpt = None,
    max_scans: Annotated[int | None, typer.Option(help="At most this many scans per log.")] = None,
    scenario: Annotated[
        Path | None, typer.Option("--scenario", help="scenario.json of a simulated scenario.")
    ] = None,
    rerun: Annotated[
        bool, typer.Option("--rerun", help="Live view: spawn a Rerun viewer (or use the running "
                           "one) and stream map, scans, particles, objects, trajectories.")
    ] = False,
    rerun_url: Annotated[
        str | None, typer.Option("--rerun-url", help="Live view in a Rerun viewer elsewhere, "
                                 "e.g. rerun+http://HOST:9876/proxy (instead of spawning).")
    ] = None,
    rerun_save: Annotated[
        Path | None, typer.Option("--rerun-save", help="Record the live view to FILE.rrd "
                                  "(open with: rerun FILE.rrd); works with --rerun too.")
    ] = None,
) -> None:
    """Static localizer vs full stack on the same logs, object map carried from log to log."""
    from contextlib import nullcontext

    from gatmo.pipeline.runs import compare as run_compare

    live = nullcontext()
    if rerun or rerun_url or rerun_save:
        from gatmo.pipeline.live import RerunObserver

        live = RerunObserver(spawn=rerun, url=rerun_url, save=rerun_save)
    bar, update = _progress("compare")
    with live as observer, bar:
        result = run_compare(
            map_yaml, logs, out, params_path=params, config_path=config, preset=preset,
            initial_pose=_parse_pose(initial_pose), global_localization=global_loc,
            gt_paths=ground_truth, relations_path=relations, fmt=fmt, max_scans=max_scans,
            scenario_json=scenario, progress=update, observer=observer,
            static_params_path=static_params,
        )
    _print_compare(result)
    if rerun_save is not None:
        _console().print(f"rerun recording: {rerun_save}")


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("demo-out"),
    seed: Annotated[int, typer.Option(help="Scenario seed.")] = 3,
    runs: Annotated[int, typer.Option(min=1, help="Runs in the scenario.")] = 4,
) -> None:
    """Simulate the default hall scenario and compare static vs gatmo on it."""
    from gatmo.pipeline.runs import demo as run_demo

    bar, update = _progress("demo")
    with bar:
        result = run_demo(out, seed=seed, runs=runs, progress=update)
    _print_compare(result)


# --------------------------------------------------------------------------- batch
@app.command()
def batch(
    spec: Annotated[Path, typer.Argument(help="Batch SPEC.yaml: maps, logs, command, grid.")],
    out: Annotated[Path, typer.Option("--out", help="Output folder (also the checkpoint).")],
    backend: Annotated[str, typer.Option(help="local | ray")] = "local",
    address: Annotated[str | None, typer.Option(help="Ray cluster address (ray://...).")] = None,
    workers: Annotated[int | None, typer.Option(help="Parallel workers.")] = None,
) -> None:
    """Many jobs (localize | run | compare) over logs and a parameter grid, locally or on Ray."""
    from gatmo.batch import run_batch

    bar, update = _progress("batch")
    with bar:
        res = run_batch(spec, out, backend=backend, address=address, workers=workers,
                        progress=update)
    from rich.markup import escape

    d = res.as_dict()
    failed = d.pop("failed_jobs", [])
    _print_mapping(f"batch -> {out}", d)
    shown = 20
    for f in failed[:shown]:  # one line each, never wrapped: folder, then the error
        _console().print(f"[red]failed:[/red] {escape(f['folder'])}: {escape(str(f['error']))}",
                         soft_wrap=True)
    if len(failed) > shown:
        _console().print(f"... and {len(failed) - shown} more failed jobs", soft_wrap=True)
    if res.code_changed:
        _console().print("[yellow]warning:[/yellow] gatmo's source files changed while the batch "
                         "ran: jobs whose workers saw the change failed (CodeMismatch or "
                         "CodeChanged); running the batch again does them", soft_wrap=True)
    if failed:
        _console().print(f"failed jobs (folder, log, error): {escape(str(res.out_dir))}/batch.json",
                         soft_wrap=True)
        raise typer.Exit(1)


# ------------------------------------------------------------------------- config
@config_app.command("dump")
def config_dump(
    component: Annotated[str, typer.Argument(
        help="amcl | gatmo | sim | stack | mapping (map build)")] = "amcl",
    params: Annotated[
        Path | None, typer.Option("--params", help="Load this file first (e.g. ROS AMCL YAML).")
    ] = None,
    comments: Annotated[
        bool, typer.Option("--comments/--no-comments",
                           help="Write each parameter's description above it.")
    ] = True,
    preset: Annotated[
        str | None, typer.Option("--preset", help="stack only: amcl (AMCL's defaults) | sim "
                                 "(matched to gatmo's simulator) | real (the real logs' "
                                 "configuration)")
    ] = None,
) -> None:
    """Print a component's full configuration as YAML (defaults, as loaded from --params, or a
    named --preset), each parameter with its description as a comment."""
    from gatmo.config import dump_model
    from gatmo.errors import ConfigError

    if preset is not None:
        if component != "stack" or params is not None:
            raise ConfigError("a stack configuration's name: give it with `stack` and without "
                              "--params", field="--preset")
        from gatmo.pipeline.config import stack_preset

        sys.stdout.write(dump_model(stack_preset(preset), comments=comments))
        return

    if component == "amcl":
        from gatmo.localization.config import AmclConfig
        from gatmo.localization.params import load_amcl_yaml

        cfg = load_amcl_yaml(params) if params else AmclConfig()
    elif component == "gatmo":
        from gatmo.config import load_model
        from gatmo.objects.config import GatmoConfig

        cfg = load_model(GatmoConfig, params) if params else GatmoConfig()
    elif component == "sim":
        from gatmo.config import load_model
        from gatmo.datasets.sim import SimConfig

        cfg = load_model(SimConfig, params) if params else SimConfig()
    elif component == "stack":
        from gatmo.pipeline.config import load_stack_config

        cfg = load_stack_config(params)
    elif component == "mapping":
        from gatmo.pipeline.config import load_map_build_config

        cfg = load_map_build_config(params)
    else:
        raise ConfigError(
            f"unknown component {component!r}: amcl | gatmo | sim | stack | mapping",
            field="component"
        )
    sys.stdout.write(dump_model(cfg, comments=comments))


# --------------------------------------------------------------------- map render
@map_app.command("render")
def map_render(
    log: Annotated[Path, typer.Argument(help="Log with reference poses (e.g. *-corrected.log).")],
    out: Annotated[Path, typer.Option("--out", help="Output map YAML (image beside it).")],
    config: Annotated[
        Path | None, typer.Option("--config", help="Map-build configuration YAML: its render "
                                  "section (cell size, range, log-odds, thresholds).")
    ] = None,
    resolution: Annotated[float | None, typer.Option(
        help="Cell size [m]; replaces render.resolution_m (0.05).")] = None,
    max_range: Annotated[float | None, typer.Option(
        help="Use returns up to this range [m]; replaces render.max_range_m (20).")] = None,
    fmt: FormatOpt = None,
) -> None:
    """Render an occupancy map from a log whose poses are known (log-odds, map_server output)."""
    from gatmo.pipeline.config import load_map_build_config
    from gatmo.pipeline.mapping import render_reference_map

    cfg = load_map_build_config(config).render
    summary = render_reference_map(log, out, resolution_m=resolution, max_range_m=max_range,
                                   fmt=fmt, cfg=cfg)
    _print_mapping("map render", summary.as_dict())


# ---------------------------------------------------------------------- map build
@map_app.command("build")
def map_build(
    log: Annotated[Path, typer.Argument(help="Raw log or bag: scans, and odometry if it has "
                                        "any.")],
    out: Annotated[Path, typer.Option("--out", help="Output map YAML (image beside it; the "
                                      "configuration used beside it as MAP.build.yaml).")],
    poses_out: Annotated[
        Path | None, typer.Option("--poses-out", help="Optimized pose of every scan (TUM).")
    ] = None,
    odometry_out: Annotated[
        Path | None, typer.Option("--odometry-out", help="The scan-matching odometry's pose of "
                                  "every scan, before loop closure (TUM).")
    ] = None,
    config: Annotated[
        Path | None, typer.Option("--config", help="Map-build configuration YAML (sections "
                                  "icp, graph, render; `gatmo config dump mapping`, or the "
                                  "MAP.build.yaml of an earlier build).")
    ] = None,
    resolution: Annotated[float | None, typer.Option(
        help="Cell size [m]; replaces the configuration's render.resolution_m (0.05).")] = None,
    max_range: Annotated[float | None, typer.Option(
        help="Use returns up to this range [m]; replaces render.max_range_m (20).")] = None,
    max_scans: Annotated[int | None, typer.Option(help="Stop after this many scans.")] = None,
    no_odometry: Annotated[bool, typer.Option(
        "--no-odometry", help="Ignore the log's wheel odometry: scan matching from constant "
        "velocity alone, as KISS-ICP (sets icp.use_odometry false). A bag without odometry "
        "is matched so anyway.")] = False,
    fmt: FormatOpt = None,
) -> None:
    """Build a map from a raw log (scan matching, loop closures, gtsam pose graph).

    The occupancy grid is ray traced (log-odds) at the optimized poses; a map_server map.
    A ROS bag with scans alone (no odometry) is matched from constant velocity."""
    from gatmo.pipeline.config import load_map_build_config
    from gatmo.pipeline.mapping import build_map

    cfg = load_map_build_config(config)
    if no_odometry:
        cfg = cfg.model_copy(update={"icp": cfg.icp.model_copy(update={"use_odometry": False})})
    bar, update = _progress("map build")
    with bar:
        summary = build_map(log, out, cfg=cfg, poses_out=poses_out, odometry_out=odometry_out,
                            resolution_m=resolution, max_range_m=max_range, fmt=fmt,
                            max_scans=max_scans, progress=update)
    _print_mapping("map build", summary.as_dict())


# --------------------------------------------------------------------------- eval
@app.command("eval")
def eval_trajectory(
    poses: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM).")],
    ground_truth: Annotated[
        Path | None, typer.Option("--ground-truth", help="Ground-truth trajectory (TUM).")
    ] = None,
    relations: Annotated[
        Path | None, typer.Option("--relations", help="Relations file (t1 t2 x y z r p y).")
    ] = None,
    align: Annotated[bool, typer.Option(
        "--align", help="Fit the estimate rigidly onto the ground truth first (a trajectory "
        "in a frame of its own, e.g. from map build).")] = False,
    correct_scale: Annotated[bool, typer.Option(
        "--correct-scale", help="Fit a scale too (implies --align).")] = False,
    stamp_offset: Annotated[float, typer.Option(
        "--stamp-offset", help="Seconds added to the estimate's stamps.")] = 0.0,
    rpe_delta: Annotated[float | None, typer.Option(
        "--rpe-delta", min=1e-6, help="Also the relative pose error over this much travel [m] "
        "(as evo_rpe --delta_unit m).")] = None,
) -> None:
    """Score a trajectory: position error against ground truth (no alignment unless --align)
    and/or the relations error of the SLAM benchmark (Kümmerle et al. 2009)."""
    from gatmo.pipeline.trajectory import evaluate_trajectory

    res = evaluate_trajectory(poses, gt_path=ground_truth, relations_path=relations,
                              align=align, correct_scale=correct_scale,
                              stamp_offset_s=stamp_offset, rpe_delta_m=rpe_delta)
    _print_mapping(f"eval {poses.name}", res)


@app.command()
def calibrate(
    logs: Annotated[list[Path], typer.Argument(
        help="Logs or bags with scans and odometry, of one robot (pooled).")],
    reference: Annotated[list[Path] | None, typer.Option(
        "--reference", help="Reference poses of the robot (TUM, any fixed frame), one per log, "
        "e.g. from gatmo map build --poses-out; else the logs' own ground truth.")] = None,
    stamp_offset: Annotated[float, typer.Option(
        "--stamp-offset", help="Seconds added to the reference's stamps.")] = 0.0,
    params: ParamsOpt = None,
    config: ConfigOpt = None,
    preset: PresetOpt = None,
    out: Annotated[Path | None, typer.Option(
        "--out", help="Write the fitted alphas as AMCL YAML (Nav2's layout, or ROS 1's when "
        "--params is a ROS 1 file).")] = None,
    report: Annotated[Path | None, typer.Option(
        "--report", help="Write every figure of the fit as JSON.")] = None,
    min_alpha: Annotated[float, typer.Option(
        "--min-alpha", min=0.0, help="Least alpha written to --out (a filter given no noise "
        "of a kind cannot spread its particles that way).")] = 0.0,
    fmt: FormatOpt = None,
    max_scans: Annotated[int | None, typer.Option("--max-scans", help="At most this many "
                                                  "scans.")] = None,
) -> None:
    """Fit AMCL's odometry noise (alpha1-4, alpha5 for omni) to logs against reference poses.

    The fit is made at the update thresholds and odometry model of the AMCL parameters given
    (else AMCL's defaults). z std is the RMS of the errors over the standard deviation the
    alphas predict: 1 when they predict the errors, above 1 when they are too small."""
    import numpy as np

    from gatmo.pipeline.calibrate import calibrate_odometry

    res = calibrate_odometry(logs, reference_path=reference, stamp_offset_s=stamp_offset,
                             params_path=params, config_path=config, preset=preset, fmt=fmt,
                             max_scans=max_scans, out_path=out, min_alpha=min_alpha,
                             report_path=report)
    from rich.table import Table

    names = ", ".join(x.name for x in logs)
    title = f"calibrate {names}: {res['model']}, {res['steps']} steps of " \
            f"{res['update_min_d_m']:g} m / {res['update_min_a_rad']:g} rad"
    table = Table(title=title, min_width=len(title))
    for col in ("", "current", "fitted", "fitted, held out"):
        table.add_column(col, justify="left" if not col else "right")
    for i, (c, f) in enumerate(zip(res["current_alphas"], res["alphas"], strict=True)):
        table.add_row(f"alpha{i + 1}", f"{c:.4g}", f"{f:.4g}", "")
    for term, c, f, h in zip(res["terms"], res["z_std_current"], res["z_std_fitted"],
                             res["z_std_holdout"], strict=True):
        table.add_row(f"z std {term}", f"{c:.3f}", f"{f:.3f}", f"{h:.3f}")
    _console().print(table)
    _console().print(
        f"reference {res['reference']} at {res['reference_coverage']:.0%} of the scans; "
        f"{res['rejected']} outlier steps trimmed; travel scale {res['trans_scale']:.4f}, "
        f"turn scale {res['rot_scale']:.4f} (reference over odometry); the reference's own "
        f"noise taken out: {res['reference_noise_std'][0] * 100:.2f} / "
        f"{res['reference_noise_std'][1] * 100:.2f} cm along / across, "
        f"{np.degrees(res['reference_noise_std'][2]):.2f} deg"
        + (f"; written to {res['out']}" if "out" in res else ""), soft_wrap=True)
    _print_warnings(res["warnings"])


# ---------------------------------------------------------------------- entry point
def main(argv: list[str] | None = None) -> int:
    """Console entry point: run the app, turning GatmoError into one red line and exit code 1."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        app(args=argv, prog_name="gatmo")  # standalone: usage errors print and exit 2
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except Exception as exc:
        from gatmo.errors import GatmoError

        if debug or not isinstance(exc, GatmoError):
            raise
        from rich.markup import escape

        _console(stderr=True).print(
            f"[bold red]error:[/bold red] [red]{escape(str(exc))}[/red]", soft_wrap=True
        )
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
