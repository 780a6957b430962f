"""atheris fuzzing of gatmo's readers: every input must give a result or a GatmoError.

    python fuzz/fuzz_readers.py TARGET -max_total_time=60   # TARGET: carmen | tum | map | amcl
                                                            # | objects | wean | rosbag | sniff
``make fuzz`` runs each target for a bounded time. Crashes are saved by libFuzzer as
crash-* files in the working folder.

``rosbag`` starts from a seed corpus of tiny valid bags written at start-up (a ROS 1 ``.bag``, a
ROS 2 bag's sqlite file, its ``metadata.yaml``); the input's first byte picks which of the three
the rest replaces. rosbags is instrumented too for that target, and each input is bounded
(``-timeout=20 -rss_limit_mb=2048`` unless given).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import atheris

BAG = len(sys.argv) > 1 and sys.argv[1] == "rosbag"

with atheris.instrument_imports(include=["gatmo", "rosbags"] if BAG else ["gatmo"]):
    if BAG:
        import rosbags.highlevel  # noqa: F401 - instrumented for coverage
        import rosbags.rosbag1  # noqa: F401
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401

        from gatmo.datasets.rosbag import RosBag, write_ros1_bag, write_ros2_bag
    from gatmo.datasets.carmen import CarmenLog
    from gatmo.datasets.info import summarize
    from gatmo.datasets.open import open_log, open_map
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


def _sniffed(p):
    """What `gatmo info`, `--log` and `--map` do with a file of unknown kind (format told by
    content: CARMEN, Wean, a Wean map, gzip'd or not)."""
    for fn in (lambda: list(open_log(p)), lambda: open_map(p, max_cells=10_000_000),
               lambda: summarize(p)):
        try:
            fn()
        except GatmoError:
            pass


def _bag_seeds() -> Path:
    """A corpus folder with one valid input per mode (0: ROS 1, 1: ROS 2 sqlite, 2: metadata)."""
    import numpy as np

    from gatmo.datasets.types import Scan

    rng = np.random.default_rng(0)
    scans = [Scan(stamp_s=10.0 + 0.1 * i, ranges_m=rng.uniform(0.5, 5.0, 20),
                  angles_rad=np.linspace(-1.5, 1.5, 20), range_min_m=0.05, range_max_m=8.0,
                  odom_pose_xytheta=[0.1 * i, 0.0, 0.01 * i], laser_pose_xytheta=[0.2, 0.0, 0.0])
             for i in range(4)]
    good = TMP / "good"
    r2 = write_ros2_bag(good / "b2", scans)
    (TMP / "b2").mkdir()
    (TMP / "b2" / "metadata.yaml").write_bytes((r2 / "metadata.yaml").read_bytes())
    (TMP / "b2" / "b2.db3").write_bytes((r2 / "b2.db3").read_bytes())
    corpus = TMP / "corpus_rosbag"
    corpus.mkdir()
    (corpus / "ros1").write_bytes(b"\x00" + write_ros1_bag(good / "a.bag", scans).read_bytes())
    (corpus / "ros2").write_bytes(b"\x01" + (r2 / "b2.db3").read_bytes())
    (corpus / "meta").write_bytes(b"\x02" + (r2 / "metadata.yaml").read_bytes())
    return corpus


def _rosbag(data: bytes) -> None:
    mode, rest = (data[0] % 3, data[1:]) if data else (0, b"")
    if mode == 0:
        path = TMP / "x.bag"
        path.write_bytes(rest)
    else:
        path = TMP / "b2"
        name = "b2.db3" if mode == 1 else "metadata.yaml"
        keep = (TMP / "good" / "b2" / name).read_bytes()
        (path / name).write_bytes(rest)
    try:
        for skip_bad in (False, True):
            try:
                list(RosBag(path, skip_bad=skip_bad))
            except GatmoError:
                pass
    finally:
        if mode:
            (path / name).write_bytes(keep)


TARGETS = {
    "carmen": ("x.log", _carmen),
    "wean": ("x.log", lambda p: list(WeanLog(p))),
    "tum": ("x.tum", read_tum),
    "sniff": ("x.gz", _sniffed),
    "map": ("m.yaml", lambda p: load_map(p, max_cells=10_000_000)),
    "amcl": ("a.yaml", load_amcl_yaml),
    "objects": ("o.json", load_objects),
    "rosbag": (None, None),  # bytes, not a file: see _rosbag
}


def main() -> None:
    name = sys.argv.pop(1) if len(sys.argv) > 1 and sys.argv[1] in TARGETS else "carmen"
    fname, fn = TARGETS[name]
    path = TMP / (fname or "unused")
    if name == "rosbag":
        corpus = _bag_seeds()
        if not any(not a.startswith("-") for a in sys.argv[1:]):
            sys.argv.append(str(corpus))
        for flag in ("-timeout=20", "-rss_limit_mb=2048"):
            if not any(a.startswith(flag.split("=")[0] + "=") for a in sys.argv[1:]):
                sys.argv.append(flag)

    def one(data: bytes) -> None:
        if name == "rosbag":
            _rosbag(data)
            return
        path.write_bytes(data)
        try:
            fn(path)
        except GatmoError:
            pass

    atheris.Setup(sys.argv, one)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
