"""Run every benchmark module ``benchmarks/bench_*.py`` in turn (``make bench``).

Each module exposes ``main(argv=None) -> int`` and writes its JSON into ``bench-out/``.
``python -m benchmarks NAME ...`` runs only the named ones (e.g. ``localization``).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    here = Path(__file__).parent
    names = sorted(m.name for m in pkgutil.iter_modules([str(here)]) if m.name.startswith("bench_"))
    if argv:
        wanted = {a if a.startswith("bench_") else f"bench_{a}" for a in argv}
        names = [n for n in names if n in wanted]
    failed = []
    for name in names:
        print(f"\n=== {name} ===", flush=True)
        t0 = time.perf_counter()
        try:
            rc = importlib.import_module(f"benchmarks.{name}").main([])
        except Exception as exc:  # keep going: one broken benchmark must not hide the others
            print(f"{name} failed: {exc!r}")
            rc = 1
        print(f"=== {name}: rc={rc} in {time.perf_counter() - t0:.1f} s ===", flush=True)
        if rc:
            failed.append(name)
    if failed:
        print("failed:", ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
