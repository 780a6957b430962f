"""The batch's table: ``results.parquet`` (pyarrow) or ``results.csv``, and ``batch.json``."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from gatmo._io import atomic_write_bytes, atomic_write_text
from gatmo.batch.spec import Job

BASE_COLUMNS = ["job_id", "command", "map", "log", "site", "seed"]


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


def write_table(rows: list[dict], out_dir: Path) -> Path:
    """``results.parquet`` when pyarrow imports, else ``results.csv`` (columns: union of rows,
    first-seen order)."""
    cols: list[str] = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
        return atomic_write_text(out_dir / "results.csv", buf.getvalue())
    table = pa.Table.from_pylist([{k: r.get(k) for k in cols} for r in rows])
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return atomic_write_bytes(out_dir / "results.parquet", sink.getvalue().to_pybytes())


def write_batch_json(summary: dict, out_dir: Path) -> Path:
    return atomic_write_text(out_dir / "batch.json", json.dumps(summary, indent=1, default=str))


def read_table(path: str | Path) -> list[dict]:
    """Rows of a results file (CSV values come back as strings)."""
    path = Path(path)
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pylist()
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


__all__ = ["make_rows", "read_table", "write_batch_json", "write_table"]
