"""Hostile input for every reader: success or a GatmoError, never another exception."""

from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatmo.errors import GatmoError

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])

TOKENS = st.sampled_from(["FLASER", "ROBOTLASER1", "RAWLASER1", "ODOM", "PARAM", "TRUEPOS",
                          "NEFF", "3", "180", "-1", "0.5", "nan", "inf", "1e309", "x", "",
                          "#", "999999999", "-0", "L", "O"])
LINES = st.lists(st.lists(TOKENS, max_size=12).map(" ".join), max_size=12).map("\n".join)


def _only_gatmo_errors(fn):
    try:
        fn()
    except GatmoError as exc:
        assert "\n" not in str(exc)  # one line


@SETTINGS
@given(text=LINES)
def test_carmen_reader(tmp_path, text):
    from gatmo.datasets.carmen import CarmenLog

    p = tmp_path / "x.log"
    p.write_text(text)
    _only_gatmo_errors(lambda: list(CarmenLog(p)))
    _only_gatmo_errors(lambda: list(CarmenLog(p, skip_bad=True)))


@SETTINGS
@given(data=st.binary(max_size=300))
def test_any_log_bytes(tmp_path, data):
    from gatmo.datasets.open import open_log

    p = tmp_path / "x.log"
    p.write_bytes(data)
    _only_gatmo_errors(lambda: list(open_log(p)))


#: a gzip member's 10-byte header (deflate, no flags): what follows it is a stream to decode
GZIP_HEADER = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03"


@SETTINGS
@given(data=st.binary(max_size=200), whole=st.booleans(), text=LINES)
def test_gzip_streams_as_log_map_or_info(tmp_path, data, whole, text):
    # random bytes seldom make a gzip header, so a corrupt stream behind a valid header (what
    # a download cut short leaves) is drawn on purpose: as a log, a map and for `gatmo info`
    import gzip

    from gatmo.datasets.info import summarize
    from gatmo.datasets.open import open_log, open_map

    body = gzip.compress(text.encode()) if whole else GZIP_HEADER + data
    p = tmp_path / "x.log.gz"
    p.write_bytes(body[: len(body) // 2] if whole and data[:1] == b"\x00" else body)
    _only_gatmo_errors(lambda: list(open_log(p)))
    _only_gatmo_errors(lambda: open_map(p))
    _only_gatmo_errors(lambda: summarize(p))


WEAN_MAP_TOKENS = st.sampled_from(["robot_specifications->resolution", "robot_specifications->x",
                                   "global_map[0]:", "2", "3", "0", "-1", "0.5", "1.000", "x",
                                   "nan", "inf", "-5", "1e309", ":", ""])
WEAN_MAP = st.lists(st.lists(WEAN_MAP_TOKENS, max_size=5).map(" ".join), max_size=8).map(
    lambda lines: "robot_specifications->global_mapsize_x 30\n" + "\n".join(lines))


@SETTINGS
@given(text=WEAN_MAP, gz=st.booleans())
def test_wean_map(tmp_path, text, gz):
    # a CMU Wean Hall map (`--map wean.dat.gz`): its header, sizes and values drawn broken
    import gzip

    from gatmo.datasets.open import open_map

    p = tmp_path / "wean.dat"
    p.write_bytes(gzip.compress(text.encode()) if gz else text.encode())
    _only_gatmo_errors(lambda: open_map(p))


@SETTINGS
@given(text=LINES)
def test_wean_tum_relations(tmp_path, text):
    from gatmo.datasets.relations import read_relations
    from gatmo.datasets.tum import read_tum
    from gatmo.datasets.wean import WeanLog

    p = tmp_path / "x.txt"
    p.write_text(text)
    _only_gatmo_errors(lambda: list(WeanLog(p)))
    _only_gatmo_errors(lambda: read_tum(p))
    _only_gatmo_errors(lambda: read_relations(p))


YAML_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10, 10**12),
                        st.floats(allow_nan=True), st.text(max_size=8),
                        st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=4))


@SETTINGS
@given(fields=st.dictionaries(st.sampled_from(["image", "resolution", "origin", "negate",
                                               "occupied_thresh", "free_thresh", "mode",
                                               "extra"]), YAML_VALUES, max_size=8),
       pixels=st.binary(max_size=64))
def test_map_yaml(tmp_path, fields, pixels):
    import yaml

    from gatmo.maps.io import load_map

    (tmp_path / "m.pgm").write_bytes(b"P5\n4 4\n255\n" + pixels[:16].ljust(16, b"\0"))
    if isinstance(fields.get("image"), str):
        fields["image"] = "m.pgm" if fields["image"] == "" else fields["image"]
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(fields))
    _only_gatmo_errors(lambda: load_map(tmp_path / "m.yaml"))


@SETTINGS
@given(fields=st.dictionaries(st.sampled_from(["min_particles", "max_particles", "laser_z_hit",
                                               "odom_alpha1", "odom_model_type", "kld_err",
                                               "laser_max_beams", "bogus"]), YAML_VALUES,
                              max_size=6))
def test_amcl_params(tmp_path, fields):
    import yaml

    from gatmo.localization.params import load_amcl_yaml

    (tmp_path / "a.yaml").write_text(yaml.safe_dump(fields))
    _only_gatmo_errors(lambda: load_amcl_yaml(tmp_path / "a.yaml"))


JSONISH = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(), st.floats(),
                                 st.text(max_size=5)),
                       lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=5),
                                                                           c, max_size=4),
                       max_leaves=20)


@SETTINGS
@given(obj=st.fixed_dictionaries({"id": JSONISH, "status": JSONISH, "pose": JSONISH,
                                  "shape_cells_xy": JSONISH, "history": JSONISH}),
       version=st.sampled_from([1, 2, "1", None]))
def test_objects_json(tmp_path, obj, version):
    from gatmo.maps.object_io import load_objects

    doc = {"format": "gatmo-objects", "version": version, "resolution_m": 0.05,
           "next_id": 3, "objects": [obj]}
    (tmp_path / "o.json").write_text(json.dumps(doc))
    _only_gatmo_errors(lambda: load_objects(tmp_path / "o.json"))


@SETTINGS
@given(fields=st.dictionaries(st.sampled_from(["amcl", "gatmo", "fusion", "icp", "seed",
                                               "image", "laser_z_hit", "odom_alpha1", "graph",
                                               "render", "bogus"]),
                              YAML_VALUES | st.dictionaries(
                                  st.sampled_from(["ros__parameters", "alpha1", "z_hit",
                                                   "laser_model", "passes", "match",
                                                   "free_thresh", "group_size", "bogus"]),
                                  YAML_VALUES | JSONISH, max_size=3), max_size=5),
       runs=JSONISH)
def test_info_on_any_yaml_and_scenario_json(tmp_path, fields, runs):
    # gatmo info tells a map, a stack config, a map-build config, an AMCL file, a scenario
    # and an objects.json apart by their keys: whichever it takes a file for, the outcome is
    # a summary or one line
    import yaml

    from gatmo.datasets.info import summarize

    (tmp_path / "c.yaml").write_text(yaml.safe_dump(fields))
    _only_gatmo_errors(lambda: summarize(tmp_path / "c.yaml"))
    doc = {"format": "gatmo-scenario", "runs": runs, "map_objects": runs}
    (tmp_path / "s.json").write_text(json.dumps(doc))
    _only_gatmo_errors(lambda: summarize(tmp_path / "s.json"))


BATCH_WORDS = st.sampled_from(["run", "compare", "echo", "localize", "hall", "*.clf",
                               "amcl.alpha1", "gatmo.x", "sim", ""])
BATCH_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-3, 5) | st.floats(allow_nan=True) | BATCH_WORDS,
    lambda c: st.lists(c, max_size=3) | st.dictionaries(
        st.sampled_from(["map", "glob", "site", "hall", "amcl.alpha1", "seed", "x"]), c,
        max_size=3),
    max_leaves=12)


@SETTINGS
@given(fields=st.dictionaries(st.sampled_from(["maps", "logs", "command", "params", "preset",
                                               "grid", "seeds", "max_scans", "extra"]),
                              BATCH_VALUES, max_size=8))
def test_batch_spec(tmp_path, fields):
    # `gatmo batch SPEC.yaml`: any spec is expanded into jobs or refused with a GatmoError.
    # Drawn as a valid spec with some fields replaced, so the grid, seeds and preset are reached
    import yaml

    from gatmo.batch.spec import expand_jobs
    from gatmo.maps.io import save_map
    from tests.helpers import room_grid

    (tmp_path / "run_1.clf").write_text("ODOM 0 0 0 0 0 0 1.0 h 1.0\n")
    save_map(room_grid(2.0, 2.0), tmp_path / "m.yaml")
    spec = {"maps": {"hall": "m.yaml"}, "logs": [{"map": "hall", "glob": "*.clf"}],
            "command": "echo", "grid": {"amcl.alpha1": [0.1, 0.2]}}
    spec.update(fields)
    p = tmp_path / "spec.yaml"
    p.write_text(yaml.safe_dump(spec))
    _only_gatmo_errors(lambda: expand_jobs(p))
