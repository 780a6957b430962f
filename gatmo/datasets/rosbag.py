"""ROS 1 and ROS 2 bags through ``rosbags``: LaserScan + Odometry (or /tf odom->base) + the laser
pose from /tf_static, optional ground truth (nav_msgs/Odometry), and a ROS 2 writer."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from gatmo.datasets.types import ReadStats, Scan, sensor_info
from gatmo.errors import DataError, FormatError
from gatmo.geometry import interpolate_poses

SCAN = "sensor_msgs/msg/LaserScan"
ODOM = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"


def _yaw(q) -> float:
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


class RosBag:
    """A ROS 1 ``.bag`` or ROS 2 bag folder as a :class:`~gatmo.datasets.types.ScanSource`.

    Topics default to the first LaserScan topic (``/scan``, ``/base_scan`` preferred), the
    Odometry topic ``/odom`` (else /tf odom->base), and ``/base_pose_ground_truth`` when present.
    """

    def __init__(self, path: str | Path, *, scan_topic: str | None = None,
                 odom_topic: str | None = None, gt_topic: str | None = None,
                 skip_bad: bool = False) -> None:
        self.path = str(path)
        self.scan_topic, self.odom_topic, self.gt_topic = scan_topic, odom_topic, gt_topic
        self.skip_bad = skip_bad
        self.stats = ReadStats()

    def _reader(self):
        from rosbags.highlevel import AnyReader

        try:
            return AnyReader([Path(self.path)])
        except Exception as exc:  # rosbags raises its own family on broken bags
            raise FormatError(f"cannot open bag: {exc}", file=self.path) from None

    def topics(self) -> list[dict]:
        with self._reader() as r:
            return [{"topic": c.topic, "type": c.msgtype, "count": c.msgcount}
                    for c in r.connections]

    def _pick(self, conns, wanted, msgtype, prefer, required):
        by_topic = {c.topic: c for c in conns}
        if wanted is not None:
            if wanted not in by_topic:
                raise FormatError(f"topic {wanted} not in the bag (topics: "
                                  f"{', '.join(sorted(by_topic))})", file=self.path, field=wanted)
            return by_topic[wanted]
        typed = [c for c in conns if c.msgtype == msgtype]
        for p in prefer:
            for c in typed:
                if c.topic == p:
                    return c
        if typed and prefer != ("/base_pose_ground_truth",):
            return typed[0]
        if required:
            raise FormatError(f"no {msgtype} topic in the bag (topics: "
                              f"{', '.join(sorted(by_topic))})", file=self.path)
        return None

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
            odom_t, odom_p, gt_t, gt_p = [], [], [], []
            laser_pose = None
            base_frame = None
            if odom_c is not None:
                for c, _, raw in r.messages(connections=[odom_c]):
                    m = r.deserialize(raw, c.msgtype)
                    odom_t.append(_stamp(m.header))
                    p = m.pose.pose
                    odom_p.append((p.position.x, p.position.y, _yaw(p.orientation)))
                    base_frame = m.child_frame_id or base_frame
            if gt_c is not None:
                for c, _, raw in r.messages(connections=[gt_c]):
                    m = r.deserialize(raw, c.msgtype)
                    gt_t.append(_stamp(m.header))
                    p = m.pose.pose
                    gt_p.append((p.position.x, p.position.y, _yaw(p.orientation)))
            scan_frame = None
            scans_raw = []
            for c, _, raw in r.messages(connections=[scan_c]):
                m = r.deserialize(raw, c.msgtype)
                scan_frame = scan_frame or m.header.frame_id
                scans_raw.append((_stamp(m.header), np.asarray(m.ranges, dtype=np.float64),
                                  float(m.angle_min), float(m.angle_increment),
                                  float(m.range_min), float(m.range_max)))
                stats.records += 1
            if tf_c:
                tf_odom_t, tf_odom_p = [], []
                for c, _, raw in r.messages(connections=tf_c):
                    m = r.deserialize(raw, c.msgtype)
                    for tr in m.transforms:
                        child = tr.child_frame_id.lstrip("/")
                        parent = tr.header.frame_id.lstrip("/")
                        q, t = tr.transform.rotation, tr.transform.translation
                        if laser_pose is None and child == (scan_frame or "").lstrip("/"):
                            laser_pose = np.array([t.x, t.y, _yaw(q)])
                        elif odom_c is None and parent == "odom":
                            tf_odom_t.append(_stamp(tr.header))
                            tf_odom_p.append((t.x, t.y, _yaw(q)))
                if odom_c is None:
                    odom_t, odom_p = tf_odom_t, tf_odom_p
        if not odom_t:
            raise FormatError("no odometry: neither a nav_msgs/Odometry topic nor /tf odom->base",
                              file=self.path)
        if laser_pose is None:
            stats.skip("no base->laser transform in /tf or /tf_static: laser at the base origin")
            laser_pose = np.zeros(3)
        odom_t = np.asarray(odom_t)
        odom_p = np.asarray(odom_p)
        order = np.argsort(odom_t, kind="stable")
        odom_t, odom_p = odom_t[order], odom_p[order]
        keep = np.concatenate([[True], np.diff(odom_t) > 0])
        odom_t, odom_p = odom_t[keep], odom_p[keep]
        gt_t = np.asarray(gt_t)
        gt_p = np.asarray(gt_p).reshape(-1, 3)
        stamps = np.array([s[0] for s in scans_raw])
        odom_at = interpolate_poses(odom_t, odom_p, stamps) if len(odom_t) > 1 else \
            np.repeat(odom_p[:1], len(stamps), axis=0)
        gt_at = interpolate_poses(gt_t, gt_p, stamps) if len(gt_t) > 1 else None
        last = -np.inf
        for i, (t, ranges, a0, da, rmin, rmax) in enumerate(scans_raw):
            if t <= last:
                msg = f"scan stamp {t} does not increase (previous {last})"
                if self.skip_bad:
                    stats.skip(f"{scan_c.topic}[{i}]: {msg}")
                    continue
                raise DataError(msg, file=self.path, field=f"{scan_c.topic}[{i}]")
            last = t
            gt = None
            if gt_at is not None and gt_t[0] - 0.1 <= t <= gt_t[-1] + 0.1:
                gt = gt_at[i]
            stats.scans += 1
            yield Scan(
                stamp_s=t, ranges_m=ranges, angles_rad=a0 + np.arange(len(ranges)) * da,
                range_min_m=rmin, range_max_m=rmax, odom_pose_xytheta=odom_at[i],
                laser_pose_xytheta=laser_pose.copy(), gt_pose_xytheta=gt,
            )
        self.stats = stats

    def sensor_info(self) -> dict:
        return sensor_info(self)


def write_ros2_bag(path: str | Path, scans: Iterable[Scan], *, scan_topic: str = "/scan",
                   odom_topic: str = "/odom", gt_topic: str | None = None) -> Path:
    """Write scans as a ROS 2 bag (LaserScan, Odometry, optional ground-truth Odometry)."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    LaserScan = ts.types[SCAN]
    Odometry = ts.types[ODOM]
    g = ts.types
    path = Path(path)

    def stamp(t):
        sec = int(np.floor(t))
        return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)) % 1_000_000_000)

    def odom_msg(t, pose, frame, child):
        q = g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(pose[2] / 2)),
                                               w=float(np.cos(pose[2] / 2)))
        p = g["geometry_msgs/msg/Pose"](
            position=g["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0),
            orientation=q)
        pc = g["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36))
        zero = g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        tw = g["geometry_msgs/msg/TwistWithCovariance"](
            twist=g["geometry_msgs/msg/Twist"](linear=zero, angular=zero),
            covariance=np.zeros(36))
        return Odometry(header=Header(stamp=stamp(t), frame_id=frame), child_frame_id=child,
                        pose=pc, twist=tw)

    with Writer(path, version=8) as w:
        cs = w.add_connection(scan_topic, SCAN, typestore=ts)
        co = w.add_connection(odom_topic, ODOM, typestore=ts)
        cg = w.add_connection(gt_topic, ODOM, typestore=ts) if gt_topic else None
        for s in scans:
            ns = int(round(s.stamp_s * 1e9))
            da = float(s.angles_rad[1] - s.angles_rad[0]) if s.num_beams > 1 else 0.0
            msg = LaserScan(
                header=Header(stamp=stamp(s.stamp_s), frame_id="laser"),
                angle_min=float(s.angles_rad[0]), angle_max=float(s.angles_rad[-1]),
                angle_increment=da, time_increment=0.0, scan_time=0.0,
                range_min=float(s.range_min_m), range_max=float(s.range_max_m),
                ranges=s.ranges_m.astype(np.float32), intensities=np.zeros(0, np.float32),
            )
            w.write(co, ns, ts.serialize_cdr(odom_msg(s.stamp_s, s.odom_pose_xytheta, "odom",
                                                       "base_link"), ODOM))
            w.write(cs, ns, ts.serialize_cdr(msg, SCAN))
            if cg is not None and s.gt_pose_xytheta is not None:
                w.write(cg, ns, ts.serialize_cdr(
                    odom_msg(s.stamp_s, s.gt_pose_xytheta, "map", "base_link"), ODOM))
    return path
