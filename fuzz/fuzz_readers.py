"""atheris fuzzing of gatmo's readers: every input must give a result or a GatmoError.

    python fuzz/fuzz_readers.py TARGET -max_total_time=60   # TARGET: carmen | tum | map | amcl
                                                            # | objects | wean
``make fuzz`` runs each target for a bounded time. Crashes are saved by libFuzzer as
crash-* files in the working folder.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import atheris

with atheris.instrument_imports(include=["gatmo"]):
    from gatmo.datasets.carmen import CarmenLog
    from gatmo.datasets.tum import read_tum
    from gatmo.datasets.wean import WeanLog
    from gatmo.errors import GatmoError
    from gatmo.localization.params import load_amcl_yaml
    from gatmo.maps.io import load_map
    from gatmo.maps.object_io import load_objects

TMP = Path(tempfile.mkdtemp(prefix="gatmo-fuzz-"))
(TMP / "m.pgm").write_bytes(b"P5\n4 4\n255\n" + bytes(16))


def _carmen(p):
    list(CarmenLog(p, skip_bad=True))
    list(CarmenLog(p))


TARGETS = {
    "carmen": ("x.log", _carmen),
    "wean": ("x.log", lambda p: list(WeanLog(p))),
    "tum": ("x.tum", read_tum),
    "map": ("m.yaml", lambda p: load_map(p, max_cells=10_000_000)),
    "amcl": ("a.yaml", load_amcl_yaml),
    "objects": ("o.json", load_objects),
}


def main() -> None:
    name = sys.argv.pop(1) if len(sys.argv) > 1 and sys.argv[1] in TARGETS else "carmen"
    fname, fn = TARGETS[name]
    path = TMP / fname

    def one(data: bytes) -> None:
        path.write_bytes(data)
        try:
            fn(path)
        except GatmoError:
            pass

    atheris.Setup(sys.argv, one)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
