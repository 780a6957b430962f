"""Echo worlds for the batch tests: a tiny map and log files whose lines are the "scans"."""

from __future__ import annotations

from pathlib import Path

MAP_YAML = "image: m.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n" \
           "occupied_thresh: 0.65\nfree_thresh: 0.196\n"


def echo_world(tmp: Path, logs=("a.log", "b.log"), lines=(3, 5)) -> Path:
    """A 2x2 map and log files of ``lines`` lines each (an echo job's "scans")."""
    (tmp / "maps").mkdir()
    (tmp / "maps" / "m.yaml").write_text(MAP_YAML)
    (tmp / "maps" / "m.pgm").write_bytes(b"P5\n2 2\n255\n" + bytes(4))
    (tmp / "logs").mkdir()
    for name, n in zip(logs, lines, strict=True):
        (tmp / "logs" / name).write_text("x\n" * n)
    return tmp


def write_spec(tmp: Path, text: str, name: str = "spec.yaml") -> Path:
    p = tmp / name
    p.write_text(text)
    return p
