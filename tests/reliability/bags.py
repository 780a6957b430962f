"""Tiny ROS 1 / ROS 2 bags for the hostile-bag tests, with every part under the test's control.

``make_bag`` writes /tf_static (base_link -> laser), /scan and /odom like
:func:`gatmo.datasets.rosbag.write_ros2_bag`, but a test can drop a topic, give /scan another
message type, replace chosen messages by raw garbage or by hand-made bad messages, and set the
header stamps of the scans independently of the bag's record times.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo.datasets.rosbag import ODOM, SCAN, TF, TF_MSG_ROS1, _bag_messages
from gatmo.datasets.types import Scan

STRING = "std_msgs/msg/String"
LASER_POSE = np.array([0.2, -0.05, 0.1])


def scans(n: int = 8, beams: int = 30) -> list[Scan]:
    """``n`` scans 0.1 s apart, the robot driving 0.1 m per scan, laser at ``LASER_POSE``."""
    rng = np.random.default_rng(0)
    return [Scan(stamp_s=10.0 + 0.1 * i, ranges_m=rng.uniform(0.5, 5.0, beams),
                 angles_rad=np.linspace(-1.5, 1.5, beams), range_min_m=0.05, range_max_m=8.0,
                 odom_pose_xytheta=[0.1 * i, 0.0, 0.01 * i], laser_pose_xytheta=LASER_POSE)
            for i in range(n)]


def make_bag(path: str | Path, *, ros1: bool, n: int = 8, scan_type: str = SCAN,
             odom: bool = True, tf: bool = True, scan_topic: str = "/scan",
             garbage_scans: tuple[int, ...] = (), scan_stamps: list[float] | None = None,
             scan_edit=None, odom_edit=None) -> Path:
    """Write a bag; ``scan_edit(i, msg)`` / ``odom_edit(i, msg)`` may change message ``i``."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    path = Path(path)
    ss = scans(n)
    if ros1:
        from rosbags.rosbag1 import Writer

        ts = get_typestore(Stores.ROS1_NOETIC)
        ts.register(get_types_from_msg(TF_MSG_ROS1, TF))
        ser = ts.serialize_ros1
        w = Writer(path)
    else:
        from rosbags.rosbag2 import Writer

        ts = get_typestore(Stores.ROS2_HUMBLE)
        ser = ts.serialize_cdr
        w = Writer(path, version=8)
    odom_msg, scan_msg, tf_msg = _bag_messages(ts, ss, ros1=ros1, laser_frame="laser",
                                               base_frame="base_link")
    with w:
        ctf = w.add_connection("/tf_static", TF, typestore=ts) if tf else None
        cs = w.add_connection(scan_topic, scan_type, typestore=ts) if scan_type else None
        co = w.add_connection("/odom", ODOM, typestore=ts) if odom else None
        for i, s in enumerate(ss):
            ns = int(round(s.stamp_s * 1e9))  # record time always increases
            if i == 0 and ctf is not None:
                w.write(ctf, ns, ser(tf_msg(s), TF))
            if co is not None:
                m = odom_msg(s.stamp_s, s.odom_pose_xytheta, "odom", "base_link")
                if odom_edit is not None:
                    odom_edit(i, m)
                w.write(co, ns, ser(m, ODOM))
            if cs is None:
                continue
            if i in garbage_scans:
                w.write(cs, ns, bytes([0, 1, 0, 0]) + b"\xff" * 7)
            elif scan_type == SCAN:
                if scan_stamps is not None:
                    s.stamp_s = scan_stamps[i]
                m = scan_msg(s)
                if scan_edit is not None:
                    scan_edit(i, m)
                w.write(cs, ns, ser(m, SCAN))
            else:
                w.write(cs, ns, ser(ts.types[STRING](data="not a scan"), STRING))
    return path
