"""``gatmo compare --rerun-save`` / ``--rerun-url``: the live view, recorded and read back.

The tests that need ``rerun-sdk`` skip without it (``pip install 'gatmo[rerun]'``); the error a
user gets without it is tested either way, with the import made to fail.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from gatmo.cli import main
from gatmo.datasets.sim import SimConfig, simulate_scenario
from gatmo.errors import ConfigError, MissingExtraError

HAVE_RERUN = importlib.util.find_spec("rerun") is not None
needs_rerun = pytest.mark.skipif(
    not HAVE_RERUN, reason="rerun-sdk is not installed: pip install 'gatmo[rerun]'"
)


@pytest.fixture(scope="module")
def scen(tmp_path_factory):
    cfg = SimConfig.for_preset("hall")
    cfg.robot.duration_s = 12.0
    return simulate_scenario(tmp_path_factory.mktemp("s"), runs=2, seed=5, config=cfg)


def _compare_args(scen, out: Path) -> list[str]:
    return ["compare", *map(str, scen.logs), "--map", str(scen.map_yaml), "--out", str(out),
            "--scenario", str(scen.scenario_json)]


def _read_rrd(path: Path):
    """(rows per entity over time, static entities, chunks) of the recording in an .rrd."""
    import rerun as rr

    reader = getattr(getattr(rr, "chunk", None), "RrdReader", None)
    if reader is None:
        pytest.skip(f"rerun-sdk {rr.__version__} has no rerun.chunk.RrdReader to read .rrd files")
    rows: Counter = Counter()
    static: set = set()
    chunks = list(reader(path).stream())
    for ch in chunks:
        if ch.is_static:
            static.add(ch.entity_path)
        else:
            rows[ch.entity_path] += ch.num_rows
    return rows, static, chunks


def _max_points(chunks, entity: str, column_suffix: str) -> int:
    most = 0
    for ch in chunks:
        if ch.entity_path != entity:
            continue
        batch = ch.to_record_batch()
        for name in batch.schema.names:
            if name.endswith(column_suffix):
                lengths = [len(v) for v in batch.column(name).to_pylist() if v is not None]
                most = max([most, *lengths])
    return most


def _rows_of(summary: dict, side: str) -> list:
    return [r for r in summary["logs"] if r["side"] == side]


@needs_rerun
def test_compare_records_both_sides_map_objects_and_ground_truth(scen, tmp_path, capsys):
    plain, live = tmp_path / "plain", tmp_path / "live"
    rrd = tmp_path / "view.rrd"
    assert main(_compare_args(scen, plain)) == 0
    assert main([*_compare_args(scen, live), "--rerun-save", str(rrd)]) == 0
    assert f"rerun recording: {rrd}" in capsys.readouterr().out
    assert rrd.exists() and rrd.stat().st_size > 50_000

    # the live view changes nothing in the comparison
    s_plain = json.loads((plain / "summary.json").read_text())
    s_live = json.loads((live / "summary.json").read_text())
    for a, b in zip(s_plain["logs"], s_live["logs"], strict=True):
        assert a["ate_rmse_m"] == b["ate_rmse_m"] and a["relocated"] == b["relocated"]

    rows, static, chunks = _read_rrd(rrd)
    n_scans = sum(r["scans"] for r in _rows_of(s_live, "static"))
    n_logs = len(scen.logs)
    assert n_scans == sum(r["scans"] for r in _rows_of(s_live, "gatmo")) > 100
    # one pose per scan on each side and for ground truth, and its error
    for side in ("static", "gatmo", "ground_truth"):
        assert rows[f"/world/{side}/pose"] == n_scans, side
    for side in ("static", "gatmo"):
        assert rows[f"/error/{side}"] == n_scans
        # scans, particles and trail at the filter update rate: fewer frames than scans
        frames = rows[f"/world/{side}/particles"]
        assert n_logs <= frames < n_scans
        assert rows[f"/world/{side}/scan"] == frames
        assert rows[f"/world/{side}/trail"] >= frames - n_logs
        assert 0 < _max_points(chunks, f"/world/{side}/particles", "positions") <= 500
    # the static map once, GATMO's map and objects at least at each log's start and end
    assert {"/world", "/world/map/static"} <= static
    assert rows["/world/map/gatmo"] >= 2 * n_logs
    assert rows["/world/objects/outlines"] >= 2 * n_logs
    assert rows["/events"] >= n_logs
    assert not any(p.startswith("/world/map/static") for p in rows)  # static only


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _viewer() -> str | None:
    exe = Path(sys.executable).parent / "rerun"
    return str(exe) if exe.exists() else shutil.which("rerun")


@needs_rerun
@pytest.mark.skipif(_viewer() is None, reason="no rerun executable")
@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # the server's file, cut short
def test_rerun_url_streams_to_a_viewer_server(scen, tmp_path):
    """A headless ``rerun --save`` server stands in for a viewer on another machine."""
    port = _free_port()
    got = tmp_path / "received.rrd"
    # its own process group: the pip-installed `rerun` is a wrapper that starts the binary
    server = subprocess.Popen([_viewer(), "--port", str(port), "--save", str(got)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.2)
        rc = main(["compare", str(scen.logs[0]), "--map", str(scen.map_yaml), "--out",
                   str(tmp_path / "c"), "--max-scans", "40",
                   "--rerun-url", f"rerun+http://127.0.0.1:{port}/proxy"])
        assert rc == 0
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=20)
    rows, static, _ = _read_rrd(got)
    assert rows["/world/static/pose"] == rows["/world/gatmo/pose"] == 40
    assert "/world/map/static" in static


@needs_rerun
def test_unreachable_viewer_is_one_error_line_before_the_run(scen, tmp_path, capsys):
    out = tmp_path / "c"
    rc = main(["compare", str(scen.logs[0]), "--map", str(scen.map_yaml), "--out", str(out),
               "--rerun-url", f"rerun+http://127.0.0.1:{_free_port()}/proxy"])
    assert rc == 1
    err = capsys.readouterr().err
    assert "viewer did not answer" in err and "Traceback" not in err
    assert not (out / "summary.json").exists()


def test_without_rerun_sdk_the_error_names_the_extra(scen, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun -> ImportError
    from gatmo.pipeline.live import RerunObserver

    with pytest.raises(MissingExtraError) as info:
        RerunObserver(save=tmp_path / "x.rrd")
    assert "pip install 'gatmo[rerun]'" in str(info.value)

    out = tmp_path / "c"
    rc = main([*_compare_args(scen, out), "--rerun-save", str(tmp_path / "x.rrd")])
    assert rc == 1
    err = capsys.readouterr().err
    assert "gatmo[rerun]" in err and "Traceback" not in err
    assert not (out / "summary.json").exists()  # refused before the comparison ran


@needs_rerun
def test_too_old_rerun_sdk_is_refused(tmp_path, monkeypatch):
    import rerun

    monkeypatch.setattr(rerun, "__version__", "0.18.2")
    from gatmo.pipeline.live import RerunObserver

    with pytest.raises(ConfigError, match="0.18.2 is too old"):
        RerunObserver(save=tmp_path / "x.rrd")


def test_cli_import_does_not_import_rerun():
    code = "import sys, gatmo.cli; sys.exit('rerun' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


def test_subsample_and_outline_helpers():
    from gatmo.objects.objectmap import MapObject
    from gatmo.pipeline.live import outline, subsample

    rows = np.arange(3000)[:, None] * np.ones((1, 3))
    sub = subsample(rows, 500)
    assert len(sub) == 500 and sub[0, 0] == 0 and sub[-1, 0] == 2999
    assert subsample(rows[:10], 500).shape == (10, 3)
    shape = np.array([[-0.5, -0.25], [0.5, 0.25]])
    o = MapObject(id=1, label=None, status="U", pose_xytheta=np.array([2.0, 3.0, np.pi / 2]),
                  shape_xy=shape, edge_xy=shape, resolution_m=0.1)
    box = outline(o)
    assert box.shape == (5, 2) and np.allclose(box[0], box[-1])
    # rotated a quarter turn: 1.1 m long along y, 0.6 m wide along x, centred on (2, 3)
    assert np.allclose(box.min(axis=0), [1.7, 2.45]) and np.allclose(box.max(axis=0), [2.3, 3.55])
