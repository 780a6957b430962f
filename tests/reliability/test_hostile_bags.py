"""Hostile ROS bags: truncated, corrupt, wrongly typed, topics or the laser transform missing.

Outcome for every bag: scans, or a one-line GatmoError naming the file (and the topic and
message index where one message is at fault); with ``skip_bad`` bad messages are skipped and
counted instead.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatmo.datasets.open import open_log
from gatmo.datasets.rosbag import RosBag, write_ros1_bag, write_ros2_bag
from gatmo.errors import DataError, FormatError, GatmoError
from tests.reliability.bags import LASER_POSE, STRING, make_bag, scans

pytest.importorskip("rosbags")

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
KINDS = pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])


def _path(tmp_path, ros1, name="b"):
    return tmp_path / (f"{name}.bag" if ros1 else name)


def _refused(path, cls=GatmoError, **kw) -> GatmoError:
    with pytest.raises(cls) as e:
        list(RosBag(path, **kw))
    assert e.value.file == str(path) and "\n" not in str(e.value)
    return e.value


def _outcome(path, **kw):
    """The scans, or the GatmoError (checked: one line, names the file); anything else fails."""
    try:
        bag = RosBag(path, **kw)
        out = list(bag)
    except GatmoError as exc:
        assert "\n" not in str(exc) and exc.file == str(path)
        return exc
    t = np.array([s.stamp_s for s in out])
    assert np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
    for s in out:
        assert s.num_beams >= 1 and s.angles_rad.shape == s.ranges_m.shape
        assert np.all(np.isfinite(s.odom_pose_xytheta))
        assert np.all(np.isfinite(s.laser_pose_xytheta))
    return out


# ------------------------------------------------------------------ writers and the good case
@KINDS
def test_writers_round_trip_with_the_laser_transform(tmp_path, ros1):
    ss = scans()
    p = _path(tmp_path, ros1)
    (write_ros1_bag if ros1 else write_ros2_bag)(p, ss)
    back = list(open_log(p))
    assert len(back) == len(ss)
    for a, b in zip(ss, back, strict=True):
        np.testing.assert_allclose(b.laser_pose_xytheta, LASER_POSE, atol=1e-9)
        np.testing.assert_allclose(b.odom_pose_xytheta, a.odom_pose_xytheta, atol=1e-9)
        np.testing.assert_allclose(b.ranges_m, a.ranges_m, atol=1e-5)
        assert abs(a.stamp_s - b.stamp_s) < 1e-9


# ------------------------------------------------------------------ truncated and corrupt
@pytest.mark.parametrize("frac", [0.0, 0.001, 0.25, 0.5, 0.75, 0.99])
def test_truncated_ros1_bag_is_refused_naming_the_file(tmp_path, frac):
    good = write_ros1_bag(tmp_path / "good.bag", scans()).read_bytes()
    p = tmp_path / "cut.bag"
    p.write_bytes(good[: int(frac * len(good))])
    for skip_bad in (False, True):  # without its index at the end a ROS 1 bag cannot be read
        e = _refused(p, FormatError, skip_bad=skip_bad)
        assert "cannot open bag" in str(e)
    if frac >= 0.25:
        assert "rosbag reindex" in str(e)


@pytest.mark.parametrize("frac", [0.0, 0.01, 0.25, 0.5, 0.75])
def test_truncated_ros2_bag_is_refused_naming_the_folder(tmp_path, frac):
    good = write_ros2_bag(tmp_path / "good", scans())
    p = tmp_path / "cut"
    shutil.copytree(good, p)
    db = p / "good.db3"
    db.write_bytes(db.read_bytes()[: int(frac * db.stat().st_size)])
    for skip_bad in (False, True):
        assert "cannot open bag" in str(_refused(p, FormatError, skip_bad=skip_bad))


def test_ros2_metadata_truncated_or_missing(tmp_path):
    good = write_ros2_bag(tmp_path / "good", scans())
    meta = (good / "metadata.yaml").read_text()
    (good / "metadata.yaml").write_text(meta[: len(meta) // 2])
    _refused(good, FormatError)
    (good / "metadata.yaml").unlink()
    _refused(good, FormatError)


@KINDS
def test_garbage_messages_are_refused_by_topic_and_index_or_skipped(tmp_path, ros1):
    p = make_bag(_path(tmp_path, ros1), ros1=ros1, garbage_scans=(3, 5))
    e = _refused(p, FormatError)
    assert e.field == "/scan[3]" and "LaserScan" in str(e)
    bag = RosBag(p, skip_bad=True)
    out = list(bag)
    assert len(out) == 6 and bag.stats.skipped == 2
    assert [r.split(":")[0] for r in bag.stats.skipped_reasons] == ["/scan[3]", "/scan[5]"]


def test_ros1_storage_broken_mid_topic_keeps_what_came_before(tmp_path):
    """A ROS 1 record whose data length is garbage (beyond the end of the chunk): reading stops
    there. Refused naming the message; with skip_bad the scans before it are kept."""
    from rosbags.typesys import Stores, get_typestore

    from gatmo.datasets.rosbag import SCAN, _bag_messages

    ss = scans()
    raw = bytearray(write_ros1_bag(tmp_path / "a.bag", ss).read_bytes())
    ts = get_typestore(Stores.ROS1_NOETIC)
    _, scan_msg, _ = _bag_messages(ts, ss, ros1=True, laser_frame="laser",
                                   base_frame="base_link")
    at = bytes(raw).find(bytes(ts.serialize_ros1(scan_msg(ss[3]), SCAN)))
    assert at > 0
    raw[at - 4 : at] = b"\xff\xff\xff\x7f"  # the record's data length
    p = tmp_path / "broken.bag"
    p.write_bytes(bytes(raw))
    e = _refused(p, FormatError)
    assert e.field == "/scan[3]" and "cannot read the bag past here" in str(e)
    bag = RosBag(p, skip_bad=True)
    out = list(bag)
    assert [s.stamp_s for s in out] == pytest.approx([10.0, 10.1, 10.2])
    assert bag.stats.skipped == 1 and bag.stats.skipped_reasons[0].startswith("/scan[3]")


@KINDS
def test_every_scan_garbage_is_refused_even_with_skip_bad(tmp_path, ros1):
    p = make_bag(_path(tmp_path, ros1), ros1=ros1, garbage_scans=tuple(range(8)))
    assert "no readable scan" in str(_refused(p, FormatError, skip_bad=True))


@KINDS
def test_non_finite_and_empty_messages(tmp_path, ros1):
    def nan_odom(i, m):
        if i == 2:
            m.pose.pose.position.x = float("nan")

    def empty_scan(i, m):
        if i == 4:
            m.ranges = np.zeros(0, np.float32)

    p = make_bag(_path(tmp_path, ros1, "o"), ros1=ros1, odom_edit=nan_odom)
    e = _refused(p, DataError)
    assert e.field == "/odom[2]" and "non-finite" in str(e)
    bag = RosBag(p, skip_bad=True)
    assert len(list(bag)) == 8 and bag.stats.skipped == 1  # odometry interpolated over the gap
    p = make_bag(_path(tmp_path, ros1, "s"), ros1=ros1, scan_edit=empty_scan)
    assert _refused(p, DataError).field == "/scan[4]"
    bag = RosBag(p, skip_bad=True)
    assert len(list(bag)) == 7 and bag.stats.skipped == 1


@KINDS
@pytest.mark.parametrize("case, stamps", [
    ("duplicate", [10.0, 10.1, 10.2, 10.3, 10.4, 10.4, 10.6, 10.7]),
    ("backwards", [10.0, 10.1, 10.2, 10.3, 10.4, 10.35, 10.6, 10.7]),
])
def test_duplicate_and_backwards_header_stamps(tmp_path, ros1, case, stamps):
    p = make_bag(_path(tmp_path, ros1), ros1=ros1, scan_stamps=stamps)
    e = _refused(p, DataError)
    assert e.field == "/scan[5]" and "does not increase" in str(e)
    bag = RosBag(p, skip_bad=True)
    out = list(bag)
    assert len(out) == 7 and bag.stats.skipped == 1
    assert [s.stamp_s for s in out] == pytest.approx(stamps[:5] + stamps[6:])


# ------------------------------------------------------------------ topics and types
@KINDS
def test_scan_topic_of_the_wrong_type(tmp_path, ros1):
    p = make_bag(_path(tmp_path, ros1), ros1=ros1, scan_type=STRING)
    e = _refused(p, FormatError)
    assert "no sensor_msgs/msg/LaserScan topic" in str(e) and f"/scan ({STRING})" in str(e)
    e = _refused(p, FormatError, scan_topic="/scan")
    assert e.field == "/scan" and f"carries {STRING}" in str(e)
    p = make_bag(_path(tmp_path, ros1, "g"), ros1=ros1)
    e = _refused(p, FormatError, odom_topic="/scan")  # odometry asked from the wrong topic
    assert e.field == "/scan" and "expected nav_msgs/msg/Odometry" in str(e)


@KINDS
def test_missing_scan_or_odom_topic(tmp_path, ros1):
    p = make_bag(_path(tmp_path, ros1, "s"), ros1=ros1, scan_type=None)
    assert "no sensor_msgs/msg/LaserScan topic" in str(_refused(p, FormatError, skip_bad=True))
    p = make_bag(_path(tmp_path, ros1, "o"), ros1=ros1, odom=False)
    assert "no odometry" in str(_refused(p, FormatError, skip_bad=True))
    p = make_bag(_path(tmp_path, ros1, "n"), ros1=ros1, scan_topic="/laser/scan")
    assert len(list(RosBag(p))) == 8  # any LaserScan topic will do when /scan is absent


@KINDS
def test_missing_laser_transform(tmp_path, ros1):
    p = make_bag(_path(tmp_path, ros1), ros1=ros1, tf=False)
    e = _refused(p, FormatError)
    assert e.field == "tf" and "'laser'" in str(e) and "'base_link'" in str(e)
    bag = RosBag(p, skip_bad=True)  # read with the laser at the base origin, and counted
    out = list(bag)
    assert len(out) == 8 and bag.stats.skipped == 1 and "tf:" in bag.stats.skipped_reasons[0]
    np.testing.assert_array_equal(out[0].laser_pose_xytheta, np.zeros(3))
    out = list(RosBag(p, laser_pose_xytheta=[0.3, 0.0, 0.0]))  # or given by the caller
    np.testing.assert_array_equal(out[0].laser_pose_xytheta, [0.3, 0.0, 0.0])


def test_laser_transform_through_a_chain_of_frames():
    from gatmo.geometry import compose

    a, b = np.array([0.1, 0.0, 0.5]), np.array([0.2, 0.1, -0.2])
    edges = {"laser": ("mount", tuple(b)), "mount": ("base_link", tuple(a)),
             "base_link": ("odom", (5.0, 5.0, 1.0))}
    np.testing.assert_allclose(RosBag._laser_pose("laser", "base_link", edges), compose(a, b))
    np.testing.assert_allclose(RosBag._laser_pose("laser", None, edges), compose(a, b))
    np.testing.assert_array_equal(RosBag._laser_pose("base_link", "base_link", edges),
                                  np.zeros(3))
    assert RosBag._laser_pose("sonar", "base_link", edges) is None
    edges["mount"] = ("laser", tuple(a))  # a cycle ends the walk: no way to the base
    assert RosBag._laser_pose("laser", "base_link", edges) is None


# ------------------------------------------------------------------ properties
@pytest.fixture(scope="module")
def good_bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("good")
    r1 = write_ros1_bag(d / "a.bag", scans()).read_bytes()
    r2 = write_ros2_bag(d / "b", scans())
    return r1, (r2 / "metadata.yaml").read_text(), (r2 / "b.db3").read_bytes()


def _mutate(data: bytes, cut: int | None, flips: list[tuple[int, int]]) -> bytes:
    b = bytearray(data if cut is None else data[: cut % (len(data) + 1)])
    for off, val in flips:
        if b:
            b[off % len(b)] = val
    return bytes(b)


CUT = st.none() | st.integers(0, 10**6)
FLIPS = st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), max_size=4)


@SETTINGS
@given(cut=CUT, flips=FLIPS, skip_bad=st.booleans())
def test_ros1_bytes_cut_or_flipped(tmp_path, good_bags, cut, flips, skip_bad):
    p = tmp_path / "x.bag"
    p.write_bytes(_mutate(good_bags[0], cut, flips))
    _outcome(p, skip_bad=skip_bad)


@SETTINGS
@given(cut=CUT, flips=FLIPS, meta_cut=st.none() | st.integers(0, 2000), skip_bad=st.booleans())
def test_ros2_bytes_cut_or_flipped(tmp_path, good_bags, cut, flips, meta_cut, skip_bad):
    _, meta, db = good_bags
    p = tmp_path / "x"
    shutil.rmtree(p, ignore_errors=True)
    p.mkdir()
    (p / "metadata.yaml").write_text(meta if meta_cut is None else meta[:meta_cut])
    (p / "b.db3").write_bytes(_mutate(db, cut, flips))
    _outcome(p, skip_bad=skip_bad)


@SETTINGS
@given(ros1=st.booleans(), scan_type=st.sampled_from([None, STRING, "nav_msgs/msg/Odometry",
                                                       "sensor_msgs/msg/LaserScan"]),
       odom=st.booleans(), tf=st.booleans(), garbage=st.sets(st.integers(0, 5), max_size=6),
       stamps=st.none() | st.lists(st.sampled_from([0.0, 10.0, 10.1, 10.2]),
                                   min_size=6, max_size=6),
       skip_bad=st.booleans())
def test_bag_structure(tmp_path, ros1, scan_type, odom, tf, garbage, stamps, skip_bad):
    p = _path(tmp_path, ros1)
    if p.is_dir():
        shutil.rmtree(p)
    p.unlink(missing_ok=True)
    make_bag(p, ros1=ros1, n=6, scan_type=scan_type, odom=odom, tf=tf,
             garbage_scans=tuple(garbage), scan_stamps=stamps)
    out = _outcome(p, skip_bad=skip_bad)
    expect_ok = (scan_type == "sensor_msgs/msg/LaserScan" and odom and (tf or skip_bad)
                 and len(garbage) < 6)  # no readable scan at all is refused even with skip_bad
    if not skip_bad:
        expect_ok = expect_ok and not garbage and (
            stamps is None or (np.all(np.isfinite(stamps)) and np.all(np.diff(stamps) > 0)))
    if expect_ok:
        assert isinstance(out, list) and len(out) >= 1
    else:
        assert isinstance(out, GatmoError) or len(out) < 6


def test_open_log_on_missing_paths_and_bare_folders(tmp_path):
    (tmp_path / "empty").mkdir()
    for p, text in [(tmp_path / "none.bag", "no such file"), (tmp_path / "none", "no such file"),
                    (tmp_path / "empty", "without metadata.yaml")]:
        with pytest.raises(FormatError, match=text) as e:
            list(open_log(p))
        assert e.value.file == str(p)
