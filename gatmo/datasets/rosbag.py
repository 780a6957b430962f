"""ROS 1 and ROS 2 bags through ``rosbags``: LaserScan + Odometry (or /tf odom->base) + the laser
pose from /tf_static, optional ground truth (nav_msgs/Odometry), and writers for both.

A broken bag (truncated, corrupt bytes, a topic of the wrong type, a message that does not
deserialize, non-finite fields, no laser transform) is refused with a one-line
:class:`~gatmo.errors.GatmoError` naming the file and, where known, the topic and message index
(``/scan[12]``). With ``skip_bad=True`` bad messages are skipped and counted in ``stats`` instead;
a bag whose storage breaks mid-topic keeps the messages read before the break.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from gatmo.datasets.types import ReadStats, Scan, sensor_info
from gatmo.errors import ConfigError, DataError, FormatError, GatmoError
from gatmo.geometry import compose, interpolate_poses

SCAN = "sensor_msgs/msg/LaserScan"
ODOM = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
TF_MSG_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"
# frames that are never the robot base: a transform chain from the laser stops below them
WORLD_FRAMES = ("odom", "map", "world")


def _yaw(q) -> float:
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}"[:300] if text else type(exc).__name__


def _finite(what: str, *values: float) -> None:
    if not np.all(np.isfinite(np.asarray(values, dtype=float))):
        raise DataError(f"non-finite {what}")


class RosBag:
    """A ROS 1 ``.bag`` or ROS 2 bag folder as a :class:`~gatmo.datasets.types.ScanSource`.

    Topics default to the first LaserScan topic (``/scan``, ``/base_scan`` preferred), the
    Odometry topic ``/odom`` (else /tf odom->base), and ``/base_pose_ground_truth`` when present.
    The laser pose in the base frame comes from /tf_static or /tf (the chain from the scan's
    ``frame_id`` up to the base frame); ``laser_pose_xytheta`` overrides it. A bag without that
    transform is refused unless ``skip_bad`` (then the laser is put at the base origin and the
    fact counted in ``stats``).

    A bag without odometry is refused unless ``require_odometry`` is False: then its scans
    carry ``odom_pose_xytheta = None`` (``has_odometry`` says so after an iteration), and the
    base frame is the top of the laser's transform chain, or the laser's own frame where the
    bag has no transforms (what scan matching alone, as KISS-ICP, needs).
    """

    def __init__(self, path: str | Path, *, scan_topic: str | None = None,
                 odom_topic: str | None = None, gt_topic: str | None = None,
                 skip_bad: bool = False, laser_pose_xytheta=None,
                 require_odometry: bool = True) -> None:
        self.path = str(path)
        self.scan_topic, self.odom_topic, self.gt_topic = scan_topic, odom_topic, gt_topic
        self.skip_bad = skip_bad
        self.require_odometry = require_odometry
        self.has_odometry: bool | None = None  # known after an iteration
        self.laser_pose_xytheta = (None if laser_pose_xytheta is None
                                   else np.asarray(laser_pose_xytheta, dtype=float))
        self.stats = ReadStats()

    @contextmanager
    def _reader(self):
        from rosbags.highlevel import AnyReader

        try:
            r = AnyReader([Path(self.path)])
            r.open()
        except Exception as exc:  # rosbags raises its own family, sqlite3, struct, ... on junk
            hint = ""
            if Path(self.path).suffix == ".bag" and "index" in str(exc).lower():
                hint = " (a ROS 1 bag cut short has no index: `rosbag reindex` may recover it)"
            raise FormatError(f"cannot open bag: {_one_line(exc)}{hint}",
                              file=self.path) from None
        try:
            yield r
        finally:
            try:
                r.close()
            except Exception:  # noqa: S110 - closing a broken bag must not hide the real error
                pass

    def topics(self) -> list[dict]:
        with self._reader() as r:
            return [{"topic": c.topic, "type": c.msgtype, "count": c.msgcount}
                    for c in r.connections]

    def _listing(self, conns) -> str:
        return ", ".join(sorted(f"{c.topic} ({c.msgtype})" for c in conns)) or "none"

    def _pick(self, conns, wanted, msgtype, prefer, required):
        by_topic = {c.topic: c for c in conns}
        if wanted is not None:
            if wanted not in by_topic:
                raise FormatError(f"topic {wanted} not in the bag (topics: "
                                  f"{self._listing(conns)})", file=self.path, field=wanted)
            if by_topic[wanted].msgtype != msgtype:
                raise FormatError(f"topic {wanted} carries {by_topic[wanted].msgtype}, expected "
                                  f"{msgtype}", file=self.path, field=wanted)
            return by_topic[wanted]
        typed = [c for c in conns if c.msgtype == msgtype]
        for p in prefer:
            for c in typed:
                if c.topic == p:
                    return c
        if typed and prefer != ("/base_pose_ground_truth",):
            return typed[0]
        if required:
            raise FormatError(f"no {msgtype} topic in the bag (topics: {self._listing(conns)})",
                              file=self.path)
        return None

    def _bad(self, stats: ReadStats, where: str, msg: str, cls=FormatError) -> None:
        if self.skip_bad:
            stats.skip(f"{where}: {msg}")
            return
        raise cls(msg, file=self.path, field=where)

    def _read(self, r, conns, stats: ReadStats, parse: Callable) -> list:
        """(index in its topic, ``parse(msg)``) for every message of ``conns`` in time order; a
        message that does not deserialize or parse is refused or skipped; a storage error ends
        the read (refused, or with ``skip_bad`` what was read before it is kept)."""
        out = []
        it = r.messages(connections=conns)
        counts: dict[str, int] = {}
        while True:
            try:
                item = next(it)
            except StopIteration:
                break
            except Exception as exc:  # truncated or corrupt storage: nothing after it is readable
                topics = "+".join(c.topic for c in conns)
                self._bad(stats, f"{topics}[{sum(counts.values())}]",
                          f"cannot read the bag past here: {_one_line(exc)}")
                break
            c, _, raw = item
            stats.records += 1
            i = counts.get(c.topic, 0)
            counts[c.topic] = i + 1
            try:
                out.append((i, parse(r.deserialize(raw, c.msgtype))))
            except GatmoError as exc:
                self._bad(stats, f"{c.topic}[{i}]", exc.message, type(exc))
            except Exception as exc:  # garbage that deserialized into the wrong shape, or did not
                self._bad(stats, f"{c.topic}[{i}]",
                          f"bad {c.msgtype} message: {_one_line(exc)}")
        return out

    @staticmethod
    def _parse_scan(m):
        t = _stamp(m.header)
        with np.errstate(invalid="ignore", over="ignore"):  # garbage values stay as read
            ranges = np.asarray(m.ranges, dtype=np.float64)
        a0, da = float(m.angle_min), float(m.angle_increment)
        rmin, rmax = float(m.range_min), float(m.range_max)
        _finite("stamp, angles or range limits", t, a0, da, rmin, rmax)
        if ranges.ndim != 1 or len(ranges) == 0:
            raise DataError("LaserScan with no ranges")
        return t, ranges, a0, da, rmin, rmax, str(m.header.frame_id)

    @staticmethod
    def _parse_odom(m):
        t = _stamp(m.header)
        p = m.pose.pose
        pose = (float(p.position.x), float(p.position.y), _yaw(p.orientation))
        _finite("stamp or pose", t, *pose)
        return t, pose, str(m.child_frame_id)

    @staticmethod
    def _parse_tf(m):
        out = []
        for tr in m.transforms:
            q, t = tr.transform.rotation, tr.transform.translation
            pose = (float(t.x), float(t.y), _yaw(q))
            stamp = _stamp(tr.header)
            _finite("transform", stamp, *pose)
            out.append((tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"), stamp,
                        pose))
        return out

    @staticmethod
    def _laser_pose(scan_frame: str, base_frame: str | None, edges: dict):
        """Pose (3,) of ``scan_frame`` in the base frame by the chain of transforms up to
        ``base_frame`` (or the top of the chain below odom/map); None when there is none."""
        if base_frame is not None and scan_frame == base_frame:
            return np.zeros(3)
        pose, frame, seen = np.zeros(3), scan_frame, set()
        while frame != base_frame and frame in edges and frame not in seen:
            seen.add(frame)
            parent, p = edges[frame]
            if parent in WORLD_FRAMES:
                break
            pose = compose(np.asarray(p, dtype=float), pose)
            frame = parent
        return None if frame == scan_frame else pose

    def __iter__(self) -> Iterator[Scan]:
        stats = ReadStats()
        with self._reader() as r:
            conns = list(r.connections)
            scan_c = self._pick(conns, self.scan_topic, SCAN, ("/scan", "/base_scan"), True)
            odom_c = self._pick(conns, self.odom_topic, ODOM, ("/odom",), False)
            gt_c = self._pick(conns, self.gt_topic, ODOM, ("/base_pose_ground_truth",), False)
            if gt_c is not None and odom_c is not None and gt_c.topic == odom_c.topic:
                gt_c = None
            tf_c = [c for c in conns if c.msgtype == TF]
            odom = [o for _, o in self._read(r, [odom_c], stats, self._parse_odom)] \
                if odom_c else []
            gt = [g for _, g in self._read(r, [gt_c], stats, self._parse_odom)] if gt_c else []
            scans_raw = self._read(r, [scan_c], stats, self._parse_scan)
            tfs = [tr for _, msg in self._read(r, tf_c, stats, self._parse_tf) for tr in msg] \
                if tf_c else []
        edges: dict[str, tuple[str, tuple]] = {}  # child -> (parent, first pose seen)
        tf_odom = []
        for parent, child, t, pose in tfs:
            if parent in WORLD_FRAMES[:1] and odom_c is None:
                tf_odom.append((t, pose, child))
            edges.setdefault(child, (parent, pose))
        if odom_c is None:
            odom = tf_odom
        if not odom and (self.require_odometry or odom_c is not None):
            raise FormatError("no odometry: neither a nav_msgs/Odometry topic nor /tf odom->base"
                              " (gatmo map build runs on scans alone)"
                              if odom_c is None and not tf_odom else
                              f"no readable odometry on {odom_c.topic}", file=self.path)
        if not scans_raw:
            raise FormatError(f"no readable scan on {scan_c.topic}", file=self.path,
                              field=scan_c.topic)
        base_frame = next((f.lstrip("/") for _, _, f in odom if f), None)
        scan_frame = scans_raw[0][1][6].lstrip("/")
        laser_pose = self.laser_pose_xytheta
        if laser_pose is None:
            laser_pose = self._laser_pose(scan_frame, base_frame, edges)
        if laser_pose is None and not odom and scan_frame not in edges:
            laser_pose = np.zeros(3)  # no odometry, no transforms: the laser is the base
        if laser_pose is None:
            msg = (f"no transform from the laser frame '{scan_frame}' to the base frame "
                   f"'{base_frame or '?'}' in /tf or /tf_static; give laser_pose_xytheta")
            if not self.skip_bad:
                raise FormatError(msg, file=self.path, field="tf")
            stats.skip(f"tf: {msg}; laser put at the base origin")
            laser_pose = np.zeros(3)
        self.has_odometry = bool(odom)
        odom_t = np.array([o[0] for o in odom])
        odom_p = np.array([o[1] for o in odom]).reshape(-1, 3)
        order = np.argsort(odom_t, kind="stable")
        odom_t, odom_p = odom_t[order], odom_p[order]
        keep = np.concatenate([[True], np.diff(odom_t) > 0])[:len(odom_t)]
        odom_t, odom_p = odom_t[keep], odom_p[keep]
        gt_t = np.array([g[0] for g in gt])
        gt_p = np.array([g[1] for g in gt]).reshape(-1, 3)
        if len(gt_t) > 1:
            order = np.argsort(gt_t, kind="stable")
            gt_t, gt_p = gt_t[order], gt_p[order]
        stamps = np.array([s[0] for _, s in scans_raw])
        if not odom:
            odom_at = [None] * len(stamps)
        elif len(odom_t) > 1:
            odom_at = interpolate_poses(odom_t, odom_p, stamps)
        else:
            odom_at = np.repeat(odom_p[:1], len(stamps), axis=0)
        gt_at = interpolate_poses(gt_t, gt_p, stamps) if len(gt_t) > 1 else None
        last = -np.inf
        for k, (i, (t, ranges, a0, da, rmin, rmax, _)) in enumerate(scans_raw):
            if t <= last:
                self._bad(stats, f"{scan_c.topic}[{i}]",
                          f"scan stamp {t} does not increase (previous {last})", DataError)
                continue
            last = t
            g = None
            if gt_at is not None and gt_t[0] - 0.1 <= t <= gt_t[-1] + 0.1:
                g = gt_at[k]
            stats.scans += 1
            yield Scan(
                stamp_s=t, ranges_m=ranges, angles_rad=a0 + np.arange(len(ranges)) * da,
                range_min_m=rmin, range_max_m=rmax, odom_pose_xytheta=odom_at[k],
                laser_pose_xytheta=laser_pose.copy(), gt_pose_xytheta=g,
            )
        self.stats = stats

    def sensor_info(self) -> dict:
        return sensor_info(self)


def _bag_messages(ts, scans: list[Scan], *, ros1: bool, laser_frame: str, base_frame: str):
    """Message builders on typestore ``ts`` (ROS 1 headers carry ``seq``)."""
    g = ts.types
    Header, Time = g["std_msgs/msg/Header"], g["builtin_interfaces/msg/Time"]
    extra = {"seq": 0} if ros1 else {}

    def stamp(t):
        sec = int(np.floor(t))
        return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)) % 1_000_000_000)

    def header(t, frame):
        return Header(**extra, stamp=stamp(t), frame_id=frame)

    def quat(yaw):
        return g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(yaw / 2)),
                                                  w=float(np.cos(yaw / 2)))

    def odom(t, pose, frame, child):
        p = g["geometry_msgs/msg/Pose"](
            position=g["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0),
            orientation=quat(pose[2]))
        pc = g["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36))
        zero = g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        tw = g["geometry_msgs/msg/TwistWithCovariance"](
            twist=g["geometry_msgs/msg/Twist"](linear=zero, angular=zero),
            covariance=np.zeros(36))
        return g[ODOM](header=header(t, frame), child_frame_id=child, pose=pc, twist=tw)

    def scan(s: Scan):
        da = float(s.angles_rad[1] - s.angles_rad[0]) if s.num_beams > 1 else 0.0
        return g[SCAN](
            header=header(s.stamp_s, laser_frame),
            angle_min=float(s.angles_rad[0]), angle_max=float(s.angles_rad[-1]),
            angle_increment=da, time_increment=0.0, scan_time=0.0,
            range_min=float(s.range_min_m), range_max=float(s.range_max_m),
            ranges=s.ranges_m.astype(np.float32), intensities=np.zeros(0, np.float32))

    def laser_tf(s: Scan):
        lp = s.laser_pose_xytheta
        tr = g["geometry_msgs/msg/Transform"](
            translation=g["geometry_msgs/msg/Vector3"](x=float(lp[0]), y=float(lp[1]), z=0.0),
            rotation=quat(lp[2]))
        ts_ = g["geometry_msgs/msg/TransformStamped"](
            header=header(s.stamp_s, base_frame), child_frame_id=laser_frame, transform=tr)
        return g[TF](transforms=[ts_])

    return odom, scan, laser_tf


def _write_bag(writer, ts, scans: list[Scan], *, ros1: bool, scan_topic, odom_topic, gt_topic,
               laser_tf: bool) -> None:
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    odom_msg, scan_msg, tf_msg = _bag_messages(ts, scans, ros1=ros1, laser_frame="laser",
                                               base_frame="base_link")
    kw = {"latching": 1} if ros1 else {}
    ctf = writer.add_connection("/tf_static", TF, typestore=ts, **kw) if laser_tf else None
    cs = writer.add_connection(scan_topic, SCAN, typestore=ts)
    co = writer.add_connection(odom_topic, ODOM, typestore=ts) if odom_topic else None
    cg = writer.add_connection(gt_topic, ODOM, typestore=ts) if gt_topic else None
    for k, s in enumerate(scans):
        ns = int(round(s.stamp_s * 1e9))
        if k == 0 and ctf is not None:
            writer.write(ctf, ns, serialize(tf_msg(s), TF))
        if co is not None and s.odom_pose_xytheta is not None:
            writer.write(co, ns, serialize(odom_msg(s.stamp_s, s.odom_pose_xytheta, "odom",
                                                    "base_link"), ODOM))
        writer.write(cs, ns, serialize(scan_msg(s), SCAN))
        if cg is not None and s.gt_pose_xytheta is not None:
            writer.write(cg, ns, serialize(odom_msg(s.stamp_s, s.gt_pose_xytheta, "map",
                                                    "base_link"), ODOM))


#: ROS 2 bag storage formats :func:`write_ros2_bag` writes (mcap: ROS 2 Jazzy's default)
ROS2_STORAGES = ("sqlite3", "mcap")


def check_ros2_storage(storage: str, field: str = "storage") -> None:
    """A ConfigError naming ``field`` unless ``storage`` is one of :data:`ROS2_STORAGES`."""
    if storage not in ROS2_STORAGES:
        raise ConfigError(f"unknown ROS 2 bag storage {storage!r}: {' | '.join(ROS2_STORAGES)}",
                          field=field)


def write_ros2_bag(path: str | Path, scans: Iterable[Scan], *, scan_topic: str = "/scan",
                   odom_topic: str | None = "/odom", gt_topic: str | None = None,
                   laser_tf: bool = True, storage: str = "sqlite3") -> Path:
    """Write scans as a ROS 2 bag folder (``storage``: sqlite3 or mcap): LaserScan, Odometry
    (odom -> base_link; none when ``odom_topic`` is None: a laser-only bag), optional
    ground-truth Odometry, and base_link -> laser on /tf_static (the first scan's
    ``laser_pose_xytheta``) unless ``laser_tf`` is False."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    check_ros2_storage(storage)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    ts = get_typestore(Stores.ROS2_HUMBLE)
    path = Path(path)
    with Writer(path, version=8, storage_plugin=plugin) as w:
        _write_bag(w, ts, list(scans), ros1=False, scan_topic=scan_topic,
                   odom_topic=odom_topic, gt_topic=gt_topic, laser_tf=laser_tf)
    return path


def write_ros1_bag(path: str | Path, scans: Iterable[Scan], *, scan_topic: str = "/scan",
                   odom_topic: str | None = "/odom", gt_topic: str | None = None,
                   laser_tf: bool = True) -> Path:
    """Write scans as a ROS 1 ``.bag`` with the same topics as :func:`write_ros2_bag`."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg(TF_MSG_ROS1, TF))
    path = Path(path)
    with Writer(path) as w:
        _write_bag(w, ts, list(scans), ros1=True, scan_topic=scan_topic,
                   odom_topic=odom_topic, gt_topic=gt_topic, laser_tf=laser_tf)
    return path
