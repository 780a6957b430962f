"""Readers and writers: round trips, hand-made files, bad input, and every real file."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from gatmo.datasets.carmen import CarmenLog, write_carmen
from gatmo.datasets.info import summarize
from gatmo.datasets.metrics import ate, relations_error
from gatmo.datasets.open import open_log, sniff_format
from gatmo.datasets.relations import Relations, read_relations
from gatmo.datasets.tum import read_tum, write_tum
from gatmo.datasets.types import Scan
from gatmo.errors import DataError, FormatError
from gatmo.geometry import compose

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def need(rel: str) -> Path:
    p = DATA / rel
    if not p.exists():
        pytest.skip(f"{p} not found: real data absent")
    return p


def _scans(n=5, gt=True):
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        out.append(Scan(
            stamp_s=100.0 + 0.1 * i,
            ranges_m=rng.uniform(0.1, 9.0, 91),
            angles_rad=np.linspace(-np.pi / 2, np.pi / 2, 91),
            range_min_m=0.0,
            range_max_m=10.0,
            odom_pose_xytheta=np.array([0.1 * i, -0.05 * i, 0.02 * i]),
            laser_pose_xytheta=np.array([0.2, 0.0, 0.0]),
            gt_pose_xytheta=np.array([1 + 0.1 * i, 2.0, 0.5]) if gt else None,
        ))
    return out


@pytest.mark.parametrize("name", ["run.clf", "run.clf.gz"])
def test_carmen_round_trip(tmp_path, name):
    scans = _scans()
    write_carmen(tmp_path / name, scans)
    back = list(CarmenLog(tmp_path / name))
    assert len(back) == len(scans)
    for a, b in zip(scans, back, strict=True):
        assert abs(a.stamp_s - b.stamp_s) < 1e-9
        np.testing.assert_allclose(a.ranges_m, b.ranges_m, atol=1e-6)
        np.testing.assert_allclose(a.angles_rad, b.angles_rad, atol=1e-9)
        np.testing.assert_allclose(a.odom_pose_xytheta, b.odom_pose_xytheta, atol=1e-9)
        np.testing.assert_allclose(a.laser_pose_xytheta, b.laser_pose_xytheta, atol=1e-9)
        np.testing.assert_allclose(a.gt_pose_xytheta, b.gt_pose_xytheta, atol=1e-9)
        assert b.range_max_m == 10.0
    assert sniff_format(tmp_path / name) == "carmen"


FLASER_OLD = "FLASER 3 1.0 2.0 81.9 0.5 0.6 0.1 0.4 0.5 0.1 {t}\n"
FLASER_NEW = "FLASER 3 1.0 2.0 81.9 0.5 0.6 0.1 0.4 0.5 0.1 {t} host {t}\n"


def test_flaser_old_and_new_formats_and_unknown_messages(tmp_path):
    p = tmp_path / "a.log"
    p.write_text("# c\nPARAM laser_front_laser_fov 90 h 0\n" + FLASER_OLD.format(t=1.0)
                 + "NEFF 3.2\n" + FLASER_NEW.format(t=2.0))
    log = CarmenLog(p, pose_is_reference=True)
    scans = list(log)
    assert len(scans) == 2 and log.unknown_messages == {"NEFF": 1}
    np.testing.assert_allclose(scans[0].angles_rad, np.radians([-45, 0, 45]))
    np.testing.assert_allclose(scans[1].odom_pose_xytheta, [0.4, 0.5, 0.1])
    np.testing.assert_allclose(scans[1].gt_pose_xytheta, [0.5, 0.6, 0.1])
    assert scans[0].valid.tolist() == [True, True, False]  # 81.9 m: SICK "no return"


@pytest.mark.parametrize(
    "text, line, cls",
    [
        ("FLASER 3 1.0 2.0 0.5 0.6 0.1 0.4 0.5 0.1\n", 1, FormatError),  # truncated
        ("ODOM 1 2\n", 1, FormatError),
        ("FLASER 3 1.0 x 3 0.5 0.6 0.1 0.4 0.5 0.1 1.0\n", 1, FormatError),
        (FLASER_OLD.format(t=2.0) + FLASER_OLD.format(t=1.0), 2, DataError),  # backwards
    ],
)
def test_carmen_bad_lines_name_file_and_line(tmp_path, text, line, cls):
    p = tmp_path / "bad.log"
    p.write_text(text)
    with pytest.raises(cls) as e:
        list(CarmenLog(p))
    assert e.value.line == line and e.value.file == str(p)
    if e.value.field is not None:  # the message names the field once: "file:line: FLASER: ..."
        assert str(e.value).count(f"{e.value.field}:") == 1, str(e.value)
    log = CarmenLog(p, skip_bad=True)
    list(log)
    assert log.stats.skipped == 1


def test_tum_round_trip_and_errors(tmp_path):
    t = np.array([1.0, 2.5, 3.0])
    p = np.array([[0, 0, 0.1], [1, 2, -3.0], [3, 4, 3.1]])
    write_tum(tmp_path / "a.tum", t, p)
    t2, p2 = read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(t2, t)
    np.testing.assert_allclose(p2, p, atol=1e-9)
    (tmp_path / "b.tum").write_text("1 2 3\n")
    with pytest.raises(FormatError) as e:
        read_tum(tmp_path / "b.tum")
    assert e.value.line == 1


def test_metrics_known_answers():
    t = np.arange(5.0)
    gt = np.zeros((5, 3))
    est = gt.copy()
    est[:, 0] = [0, 0, 0, 0, 1.0]
    a = ate(t, est, t, gt)
    assert np.isclose(a["rmse_m"], np.sqrt(1 / 5)) and a["max_m"] == 1 and a["lost_fraction"] == 0.2
    poses = np.array([[0, 0, 0], [1, 0, np.pi / 2], [1, 1, np.pi / 2]])
    rel = Relations(np.array([0.0, 1.0]), np.array([1.0, 2.0]),
                    np.array([[1.0, 0, np.pi / 2], [1.1, 0, 0]]))
    r = relations_error(np.arange(3.0), poses, rel)
    assert r["n_used"] == 2 and np.isclose(r["trans_mean_m"], 0.05)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_rosbag_round_trip(tmp_path, storage):
    # mcap: what ROS 2 Jazzy records by default; read as the folder or its .mcap file
    from gatmo.datasets.rosbag import RosBag, write_ros2_bag

    scans = _scans(gt=True)
    for s in scans:
        s.laser_pose_xytheta = np.zeros(3)
    write_ros2_bag(tmp_path / "b", scans, gt_topic="/base_pose_ground_truth", storage=storage)
    files = {p.suffix for p in (tmp_path / "b").iterdir()}
    assert files == {".yaml", ".db3" if storage == "sqlite3" else ".mcap"}
    if storage == "mcap":
        assert len(list(open_log(tmp_path / "b" / "b.mcap"))) == len(scans)
    back = list(open_log(tmp_path / "b"))
    assert len(back) == len(scans)
    for a, b in zip(scans, back, strict=True):
        np.testing.assert_allclose(a.ranges_m, b.ranges_m, atol=1e-5)
        np.testing.assert_allclose(a.odom_pose_xytheta, b.odom_pose_xytheta, atol=1e-9)
        np.testing.assert_allclose(a.gt_pose_xytheta, b.gt_pose_xytheta, atol=1e-9)
    with pytest.raises(FormatError) as e:
        list(RosBag(tmp_path / "b", scan_topic="/nope"))
    assert "/nope" in str(e.value) and "/scan" in str(e.value)


@pytest.mark.parametrize("ros1", [False, True])
def test_a_laser_only_bag_is_refused_unless_scans_alone_are_asked_for(tmp_path, ros1):
    from gatmo.datasets.rosbag import RosBag, write_ros1_bag, write_ros2_bag

    scans = _scans()
    for s in scans:
        s.laser_pose_xytheta = np.array([0.2, 0.0, 0.1])
    write = write_ros1_bag if ros1 else write_ros2_bag
    with_tf = write(tmp_path / ("a.bag" if ros1 else "a"), scans, odom_topic=None)
    bare = write(tmp_path / ("b.bag" if ros1 else "b"), scans, odom_topic=None, laser_tf=False)
    with pytest.raises(FormatError) as e:  # every command but map build needs the wheels
        list(RosBag(with_tf))
    assert "no odometry" in str(e.value) and "map build" in str(e.value)
    src = RosBag(with_tf, require_odometry=False)
    back = list(src)
    assert src.has_odometry is False and len(back) == len(scans)
    assert all(b.odom_pose_xytheta is None for b in back)
    # base_link -> laser from /tf_static: the base frame is the top of the laser's chain
    np.testing.assert_allclose(back[0].laser_pose_xytheta, [0.2, 0.0, 0.1], atol=1e-9)
    np.testing.assert_allclose(back[3].ranges_m, scans[3].ranges_m, atol=1e-5)
    # `gatmo info` describes it rather than refusing it
    about = summarize(with_tf)
    assert about["scans"] == len(scans) and about["has_odometry"] is False
    # no transforms at all: the laser's frame is the base frame (as KISS-ICP takes it)
    bare_back = list(RosBag(bare, require_odometry=False))
    np.testing.assert_allclose(bare_back[0].laser_pose_xytheta, 0.0)
    # a bag with odometry reads the same either way
    write(tmp_path / ("c.bag" if ros1 else "c"), scans)
    c = RosBag(tmp_path / ("c.bag" if ros1 else "c"), require_odometry=False)
    np.testing.assert_allclose([s.odom_pose_xytheta for s in c],
                               [s.odom_pose_xytheta for s in scans], atol=1e-9)
    assert c.has_odometry is True


@pytest.mark.slow
@pytest.mark.parametrize(
    "rel, scans, beams",
    [
        ("slam-benchmark/intel.sort.bag", 13631, 180),
        ("slam-benchmark/aces.sort.bag", 7374, 180),
        ("slam-benchmark/mit-csail.sort.bag", 1988, 361),
        ("slam-benchmark/mit-csail.clf", 1988, 361),
        ("uob-meeting/simpath2.bag", 634, 500),
        ("freiburg-course/csail.log", 686, 361),
        ("radish-corrected/aces-corrected.log.gz", 440, 180),
    ],
)
def test_real_logs_load(rel, scans, beams):
    s = summarize(need(rel))
    assert s["scans"] == scans and s["beams"] == beams


def test_real_wean():
    from gatmo.datasets.wean import WeanLog, load_wean_map

    g = load_wean_map(need("cmu-wean/wean.dat.gz"))
    assert g.cells.shape == (800, 800) and g.resolution_m == 0.1
    assert g.free.sum() > 2 * g.occupied.sum()  # a building: mostly free (P(free) in the file)
    log = list(WeanLog(need("cmu-wean/robotdata1.log.gz")))
    assert len(log) > 500 and log[0].num_beams == 180
    assert 0.2 < np.hypot(*log[0].laser_pose_xytheta[:2]) < 0.3  # laser ~25 cm ahead


def test_intel_corrected_joins_relations():
    rel = read_relations(need("slam-benchmark/intel.relations"))
    log = CarmenLog(need("radish-corrected/intel-corrected.log.gz"), pose_is_reference=True,
                    skip_bad=True)
    scans = list(log)
    t = np.array([s.stamp_s for s in scans]) + 976052857.33753
    p = np.array([s.gt_pose_xytheta for s in scans])
    r = relations_error(t, p, rel)  # relation stamps match scan stamps within 2 ms
    assert r["n_used"] == 40
    assert abs(r["trans_mean_m"] - 0.043) < 0.001 and abs(r["rot_mean_deg"] - 0.70) < 0.01


def test_relations_file_parses():
    r = read_relations(need("slam-benchmark/mit-csail.relations"))
    assert len(r) > 100 and r.rel_xytheta.shape == (len(r), 3)


def test_gz_garbage_is_a_format_error(tmp_path):
    p = tmp_path / "x.log.gz"
    p.write_bytes(gzip.compress(b"\x00\x01\x02 nonsense"))
    with pytest.raises(FormatError):
        list(open_log(p))
    _ = compose


def test_truncated_gzip_is_a_format_error(tmp_path):
    # found by the atheris harness: gzip magic followed by garbage raised a bare exception
    p = tmp_path / "t.log"
    p.write_bytes(b"\x1f\x8b*\n")
    with pytest.raises(FormatError, match="corrupt"):
        list(CarmenLog(p))
    from gatmo.datasets.wean import WeanLog

    with pytest.raises(FormatError, match="corrupt"):
        list(WeanLog(p))


def test_info_tells_a_scenario_a_stack_config_and_ros_amcl_files_from_maps(tmp_path):
    # every file `gatmo simulate` writes, and the configurations `gatmo run` takes, are
    # summarised by what they are, not refused as a map or an objects.json
    from gatmo.config import dump_model
    from gatmo.datasets.sim import SimConfig
    from gatmo.pipeline.config import StackConfig, real_stack_config
    from gatmo.pipeline.runs import simulate

    cfg = SimConfig.for_preset("hall")
    cfg.robot.duration_s = 5.0
    scen, stack_yaml = simulate(tmp_path / "s", runs=2, seed=5, sim_config=cfg)
    s = summarize(scen.scenario_json)
    assert (s["kind"], s["preset"], s["seed"], s["runs"]) == ("scenario", "hall", 5, 2)
    assert s["scans_per_run"] == [50, 50] and s["map_objects"] > 10
    assert sum(sum(v) for k, v in s.items() if k.endswith("_per_run") and k != "people_per_run"
               and k != "scans_per_run") > 0  # changes by kind, per run
    s = summarize(stack_yaml)
    assert (s["kind"], s["preset"], s["laser_model"]) == ("stack config", "sim",
                                                        "likelihood_field_prob")
    assert s["gatmo_needs_cloud_within"] == "0.1 m / 3 deg"
    assert s["parameters_not_amcl_defaults"] > 0
    one = StackConfig()
    one.amcl.alpha1 = 0.3
    for name, c, preset, n in (("amcl", StackConfig(), "amcl", 0), ("one", one, "none", 1),
                               ("real", real_stack_config(), "real", None)):
        (tmp_path / f"{name}.yaml").write_text(dump_model(c, comments=True))
        s = summarize(tmp_path / f"{name}.yaml")
        assert s["preset"] == preset and (n is None or s["parameters_not_amcl_defaults"] == n)
    (tmp_path / "nav2.yaml").write_text("amcl:\n  ros__parameters:\n    z_hit: 0.95\n"
                                        "    alpha1: 0.05\n")
    (tmp_path / "ros1.yaml").write_text("laser_z_hit: 0.9\nodom_alpha1: 0.1\n"
                                        "initial_pose_x: 1.5\ninitial_pose_a: 0.3\n")
    nav2, ros1 = summarize(tmp_path / "nav2.yaml"), summarize(tmp_path / "ros1.yaml")
    assert nav2["kind"] == ros1["kind"] == "AMCL parameters"
    # the start the commands take from the file, or that there is none
    assert ros1["initial_pose_xytheta"] == [1.5, 0.0, 0.3]
    assert nav2["initial_pose_xytheta"].startswith("none")
    assert nav2["alphas"][0] == 0.05 and nav2["z_hit / z_rand"][0] == 0.95
    assert ros1["alphas"][0] == 0.1 and ros1["z_hit / z_rand"][0] == 0.9
    assert summarize(scen.map_yaml)["kind"] == "map"
    (tmp_path / "junk.yaml").write_text("foo: 1\n")
    with pytest.raises(FormatError, match="image"):  # nothing it knows: the map's error
        summarize(tmp_path / "junk.yaml")


def test_open_map_reads_a_wean_format_map_by_content_and_commands_take_it(tmp_path):
    # `--map` takes a CMU Wean Hall map (the 16-833 course's format) as it takes a map_server
    # YAML; told apart by its header, whatever the file is called
    from gatmo.datasets.open import open_map
    from gatmo.datasets.wean import is_wean_map
    from gatmo.maps.io import save_map
    from tests.helpers import make_scan, room_grid

    room = room_grid(4.0, 3.0, resolution_m=0.1)  # cells[iy, ix]
    p_free = np.where(room.occupied, 0.0, 1.0)  # the file holds P(free), rows are x
    rows = "\n".join(" ".join(f"{v:.3f}" for v in col) for col in p_free.T)
    text = ("robot_specifications->global_mapsize_x 400\nrobot_specifications->"
            "global_mapsize_y 300\nrobot_specifications->resolution 10\n\n"
            f"global_map[0]: {room.width} {room.height}\n{rows}\n")
    wean = tmp_path / "lab.dat.gz"
    wean.write_bytes(gzip.compress(text.encode()))
    assert is_wean_map(wean) and not is_wean_map(tmp_path / "missing.dat")
    g = open_map(wean)
    np.testing.assert_array_equal(g.occupied, room.occupied)
    assert g.resolution_m == pytest.approx(0.1)
    info = summarize(wean)  # `gatmo info`
    assert info["kind"] == "map" and info["size_cells"] == f"{room.width} x {room.height}"
    save_map(room, tmp_path / "m.yaml")
    assert not is_wean_map(tmp_path / "m.yaml")
    np.testing.assert_array_equal(open_map(tmp_path / "m.yaml").occupied, room.occupied)
    # and `gatmo localize --map lab.dat.gz` runs on it
    from gatmo.pipeline.localize import run_localize

    scans = [make_scan(room, [1.0 + 0.05 * i, 1.5, 0.0], max_range_m=4.0, stamp_s=0.1 * i)
             for i in range(10)]
    from gatmo.datasets.carmen import write_carmen

    write_carmen(tmp_path / "lab.clf", scans)
    s = run_localize(wean, tmp_path / "lab.clf", out_path=tmp_path / "p.tum",
                     initial_pose=[1.0, 1.5, 0.0])
    assert s.scans == 10 and s.errors["ate_median_m"] < 0.1


def test_info_counts_the_wheels_stalls_and_jumps(tmp_path):
    """``gatmo info`` on a log: ``odom_catch_ups`` counts the steps that follow odometry
    standing exactly still and are over 3x the median step (each simulated stall's catch-up,
    the robot moving), ``odom_jumps`` the steps the localizer will take for jumps (over 1 m or
    1 rad); a run without stalls has neither."""
    from gatmo.datasets.sim import SimConfig, make_world, simulate_run
    from gatmo.datasets.sim.robot import stall_odometry
    from gatmo.geometry import relative

    cfg = SimConfig.for_preset("hall")
    cfg.robot.duration_s = 30.0
    cfg.people.count_per_run = 0
    world, route = make_world("hall", np.random.default_rng(2))
    scans = simulate_run(world, route, cfg, np.random.default_rng(3))
    plain = tmp_path / "plain.clf"
    write_carmen(plain, scans)
    s = summarize(plain)
    assert s["odom_catch_ups"] == 0 and s["odom_jumps"] == 0
    odom = np.array([sc.odom_pose_xytheta for sc in scans])
    stall = cfg.odom.model_copy(update={"stall_rate_per_min": 6.0, "stall_s": 1.0})
    stalled, starts = stall_odometry(odom, stall, 0.1, np.random.default_rng(4))
    # one odometry jump, 2 m ahead, at a scan clear of the stalls
    j = next(i for i in range(50, len(scans))
             if all(abs(i - a) > 15 and abs(i - a - 10) > 15 for a in starts))
    moved = [compose(compose(stalled[j - 1], [2.0, 0.0, 0.0]), relative(stalled[j - 1], o))
             for o in stalled[j:]]
    stalled[j:] = moved
    for sc, o in zip(scans, stalled, strict=True):
        sc.odom_pose_xytheta = o
    path = tmp_path / "stalled.clf"
    write_carmen(path, scans)
    s = summarize(path)
    caught = [a for a in starts if a + 10 < len(scans)]
    assert len(caught) >= 2
    assert s["odom_catch_ups"] == len(caught) and s["odom_jumps"] == 1
