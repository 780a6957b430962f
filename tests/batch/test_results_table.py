"""The batch's results table: parquet (pyarrow) and CSV hold and give back the same rows."""

from __future__ import annotations

import sys

import pytest

from gatmo.batch import run_batch
from gatmo.batch.results import have_pyarrow, read_table, write_table
from tests.batch.world import echo_world, write_spec

ROWS = [
    {"job_id": "123456789012", "command": "echo", "log": "/x/a.log", "site": None, "seed": 0,
     "echo.k": 1, "echo.mode": 0.5, "status": "ok", "error": None, "scans": 3,
     "ate_rmse_m": 0.25, "lost": False},
    {"job_id": "00000000e123", "command": "echo", "log": "/x/b.log", "site": "s", "seed": 1,
     "echo.k": 2, "echo.mode": "auto", "status": "failed",
     "error": "RuntimeError: echo job asked to fail", "scans": None, "ate_rmse_m": None,
     "lost": True, "only_here": 7},
]
# what both formats read back: a grid mixing numbers and text becomes text
EXPECTED = [dict(ROWS[0], **{"echo.mode": "0.5"}, only_here=None), dict(ROWS[1])]

needs_pyarrow = pytest.mark.skipif(
    not have_pyarrow(), reason="pyarrow not installed (part of the ray extra): the parquet "
                               "path is untested here, results.csv is written instead")


def test_csv_round_trip_is_typed(tmp_path):
    path = write_table(ROWS, tmp_path, fmt="csv")
    assert path.name == "results.csv"
    assert read_table(path) == EXPECTED


@needs_pyarrow
def test_parquet_round_trip_matches_csv(tmp_path):
    path = write_table(ROWS, tmp_path, fmt="parquet")
    assert path.name == "results.parquet"
    assert read_table(path) == EXPECTED
    assert read_table(path) == read_table(write_table(ROWS, tmp_path / "c", fmt="csv"))
    import pyarrow.parquet as pq

    schema = pq.read_schema(path)
    assert str(schema.field("scans").type) == "int64"
    assert str(schema.field("ate_rmse_m").type) == "double"
    assert str(schema.field("echo.mode").type) == "string"


def _echo_spec(tmp_path):
    echo_world(tmp_path)
    return write_spec(tmp_path, """
maps: {m: maps/m.yaml}
logs: [{map: m, glob: "logs/*.log"}]
command: echo
grid: {echo.fail: [false, true], echo.k: [1, 2.5]}
""")


@needs_pyarrow
def test_batch_writes_parquet_with_pyarrow(tmp_path):
    spec = _echo_spec(tmp_path)
    out = tmp_path / "out"
    (out).mkdir()
    (out / "results.csv").write_text("left over by a run without pyarrow\n")
    res = run_batch(spec, out, workers=2)
    assert res.results_path == out / "results.parquet"
    assert not (out / "results.csv").exists()  # one current table
    rows = read_table(res.results_path)
    assert len(rows) == res.jobs == 8
    assert sorted(r["scans"] for r in rows if r["status"] == "ok") == [3, 3, 5, 5]
    assert {r["echo.k"] for r in rows} == {1.0, 2.5}
    assert sum(r["status"] == "failed" for r in rows) == 4


def test_batch_writes_csv_without_pyarrow(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow -> ImportError
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    assert not have_pyarrow()
    spec = _echo_spec(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.parquet").write_bytes(b"stale")
    res = run_batch(spec, out, workers=1)
    assert res.results_path == out / "results.csv"
    assert not (out / "results.parquet").exists()
    rows = read_table(res.results_path)
    assert sorted(r["scans"] for r in rows if r["status"] == "ok") == [3, 3, 5, 5]
    assert {r["echo.k"] for r in rows} == {1.0, 2.5}


def test_unknown_format_is_refused(tmp_path):
    with pytest.raises(ValueError, match="parquet | csv"):
        write_table(ROWS, tmp_path, fmt="xlsx")
