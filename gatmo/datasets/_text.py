"""Whitespace-separated numeric text files (TUM, relations): rows with located errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo.errors import FormatError


def numeric_rows(path: str | Path, layout: str) -> tuple[np.ndarray, np.ndarray]:
    """Rows (N, k) of a file whose lines hold the k fields named in ``layout`` (e.g.
    "t x y z qx qy qz qw"), and their 1-based line numbers (N,). Blank and '#' lines are
    skipped; a wrong field count or a non-numeric or non-finite value is a FormatError with the
    line."""
    path = Path(path)
    k = len(layout.split())
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"cannot read: {exc}", file=path) from None
    rows, lines = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != k:
            raise FormatError(f"expected {k} values '{layout}', found {len(parts)}",
                              file=path, line=lineno)
        try:
            row = [float(p) for p in parts]
        except ValueError:
            raise FormatError("non-numeric value", file=path, line=lineno) from None
        if not np.all(np.isfinite(row)):
            raise FormatError("non-finite value", file=path, line=lineno)
        rows.append(row)
        lines.append(lineno)
    return np.array(rows, dtype=float).reshape(-1, k), np.array(lines, dtype=np.int64)


def iter_lines(path: str | Path):
    """(line number, text) of a plain or gzip text file; a corrupt or truncated gzip stream is a
    FormatError naming the file, not an EOFError or zlib error from deep inside."""
    import gzip
    import zlib

    path = Path(path)
    try:
        with open(path, "rb") as f:
            gz = f.read(2) == b"\x1f\x8b"
        fh = gzip.open(path, "rt", errors="replace") if gz else open(path, errors="replace")
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror or exc}", file=path) from None
    lineno = 0
    try:
        with fh:
            for lineno, line in enumerate(fh, start=1):  # noqa: B007 - reported below
                yield lineno, line
    except (EOFError, zlib.error, gzip.BadGzipFile, OSError) as exc:
        raise FormatError(f"corrupt or truncated compressed data: {exc}", file=path,
                          line=lineno + 1) from None
