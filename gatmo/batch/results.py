"""The batch's table: ``results.parquet`` (pyarrow) or ``results.csv``, and ``batch.json``.

Both formats hold the same rows. pyarrow infers each column's type; a column whose values do
not share one type (e.g. a grid ``[0.5, auto]``) is written as strings. :func:`read_table`
gives back typed values for both formats (CSV cells are parsed column by column), so code
reading the table does not depend on which format was written.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from gatmo._io import atomic_write_bytes, atomic_write_text
from gatmo.batch.spec import Job

BASE_COLUMNS = ["job_id", "command", "map", "log", "site", "seed"]
# never parsed as numbers when read back from CSV (a job id can be all digits)
TEXT_COLUMNS = {"job_id", "command", "map", "log", "site", "status", "error", "folder"}
FORMATS = ("parquet", "csv")


def make_rows(jobs: list[Job], results: dict[str, dict], param_keys: list[str]) -> list[dict]:
    """One row per job: identity, each parameter, status/error, flattened summary numbers."""
    rows = []
    for j in jobs:
        r = results[j.id]
        row = {"job_id": j.id, "command": j.command, "map": j.map_name,
               "log": ";".join(j.logs), "site": j.site, "seed": j.seed}
        point = dict(j.point)
        for k in param_keys:
            row[k] = point.get(k)
        row.update(status=r["status"], error=r["error"], folder=j.folder,
                   seconds=r.get("seconds"))
        for k, v in r["summary"].items():
            row.setdefault(k, v)
        rows.append(row)
    return rows


def have_pyarrow() -> bool:
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def write_table(rows: list[dict], out_dir: Path, fmt: str | None = None) -> Path:
    """Write ``results.parquet`` (``fmt`` "parquet"; default when pyarrow imports) or
    ``results.csv`` (columns: union of rows, first-seen order). The other format's file, left
    by an earlier run, is removed so that the folder holds one current table."""
    if fmt is None:
        fmt = "parquet" if have_pyarrow() else "csv"
    if fmt not in FORMATS:
        raise ValueError(f"unknown table format {fmt!r}: parquet | csv")
    cols: list[str] = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    if fmt == "csv":
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
        path = atomic_write_text(out_dir / "results.csv", buf.getvalue())
    else:
        path = atomic_write_bytes(out_dir / "results.parquet", _parquet_bytes(rows, cols))
    stale = out_dir / ("results.csv" if fmt == "parquet" else "results.parquet")
    stale.unlink(missing_ok=True)
    return Path(path)


def _parquet_bytes(rows: list[dict], cols: list[str]) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = []
    for k in cols:
        values = [r.get(k) for r in rows]
        try:
            arrays.append(pa.array(values))
        except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
            # mixed types in one column (or an int beyond 64 bits): keep them as text
            arrays.append(pa.array([None if v is None else str(v) for v in values],
                                   type=pa.string()))
    table = pa.Table.from_arrays(arrays, names=cols) if cols else pa.table({})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


def write_batch_json(summary: dict, out_dir: Path) -> Path:
    return atomic_write_text(out_dir / "batch.json", json.dumps(summary, indent=1, default=str))


def read_table(path: str | Path) -> list[dict]:
    """Rows of a results file. CSV cells are typed back per column: empty -> None; a column of
    integers -> int, of numbers -> float, of True/False -> bool; anything else stays text."""
    path = Path(path)
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pylist()
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return rows
    for k in rows[0]:
        values = [r[k] for r in rows]
        if k in TEXT_COLUMNS:
            conv = None
        else:
            conv = _column_type([v for v in values if v != ""])
        for r in rows:
            v = r[k]
            r[k] = None if v == "" else (conv(v) if conv is not None else v)
    return rows


def _column_type(values: list[str]):
    if not values:
        return None
    for conv in (int, float):
        try:
            for v in values:
                conv(v)
        except ValueError:
            continue
        return conv
    if all(v in ("True", "False") for v in values):
        return lambda v: v == "True"
    return None


__all__ = ["have_pyarrow", "make_rows", "read_table", "write_batch_json", "write_table"]
