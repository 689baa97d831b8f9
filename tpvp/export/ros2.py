"""A plan as a ROS 2 bag (MCAP storage), written with the pure-Python ``rosbags`` (no ROS needed).

Three topics, one message each, all stamped alike: ``/tpvp/views`` (``geometry_msgs/msg/PoseArray``:
the camera's pose at every view, in execution order), ``/tpvp/route`` (``nav_msgs/msg/Path``: the
same poses as ``PoseStamped``, the route the camera takes) and ``/tf_static`` (``tf2_msgs/msg/TFMessage``
with one transform from the robot's frame to the plan's own frame, :data:`SCAN_FRAME`). The poses
are the plan moved into the robot's frame by the base-from-scan transform
(:func:`tpvp.export.poses.moved_plan`); their orientations turn OpenCV camera axes (x right,
y down, z forward) into that frame, as in ``plan.csv``.

The bag is rosbag2 format version 8, the newest Humble's rosbag2 reads (Iron and Jazzy read it too;
version 9, Jazzy's, writes its QoS profiles in a form Humble cannot parse). Every topic is offered *transient local* (latched): ``ros2 bag play``
then keeps each one-shot message for subscribers that join later (RViz, a planner node).
"""

from __future__ import annotations

import os
from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation
from pathlib import Path

import numpy as np
import pandas as pd
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from tpvp.errors import ConfigError
from tpvp.export.poses import moved_plan
from tpvp.sensor.camera import rotation_to_quaternion

#: The child frame of the static transform: the plan's own frame (the scans' / the session's world).
SCAN_FRAME = "tpvp_scan"
#: Topic -> message type, in the order they are written.
TOPICS = {"/tpvp/views": "geometry_msgs/msg/PoseArray", "/tpvp/route": "nav_msgs/msg/Path",
          "/tf_static": "tf2_msgs/msg/TFMessage"}
BAG_VERSION = 8
#: ``builtin_interfaces/Time.sec`` is an int32.
LATEST_STAMP = 2**31 - 1
#: The log time of messages stamped 0 (1 s after the epoch): rosbags' MCAP reader takes a chunk that
#: starts at log time 0 for an empty one and skips it.
ZERO_STAMP_LOG_NS = 10**9
_NEVER = QosTime(0, 0)  # rosbag2's "infinite" (unset) duration
LATCHED = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, _NEVER, _NEVER,
              QosLiveliness.AUTOMATIC, _NEVER, False)


def stamp_nanoseconds(seconds: str) -> int:
    """A stamp given in seconds since the epoch (text, read exactly: a float64 holds a 2023 stamp
    to about 0.2 microseconds only) in whole nanoseconds; one clear error for one a ROS time cannot hold."""
    try:
        value = Decimal(str(seconds).strip())
    except InvalidOperation:
        value = Decimal("NaN")
    if not value.is_finite() or not 0 <= value < LATEST_STAMP:
        raise ConfigError(f"--stamp {seconds}: a ROS time is 0 to {LATEST_STAMP} seconds since 1970")
    return int((value * 10**9).to_integral_value(ROUND_HALF_EVEN))


def check_frame(frame: str) -> str:
    """``frame`` if tf2 can hold it as the static transform's parent; one clear error otherwise."""
    if not frame or frame != frame.strip() or frame.startswith("/") or frame == SCAN_FRAME:
        raise ConfigError(f"--frame {frame!r}: the robot's frame is a tf2 frame name (not empty, no leading '/' or "
                          f"spaces, not {SCAN_FRAME!r}: the static transform goes from it to {SCAN_FRAME}, the "
                          f"plan's own frame)")
    return frame


def plan_messages(table: pd.DataFrame, frame: str, matrix: np.ndarray, stamp_ns: int, typestore) -> dict:
    """Topic -> the one message of :data:`TOPICS` for ``table`` moved by ``matrix`` into ``frame``."""
    types = typestore.types
    sec, nanosec = divmod(stamp_ns, 10**9)
    header = types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](sec, nanosec), frame)
    point, quaternion = types["geometry_msgs/msg/Point"], types["geometry_msgs/msg/Quaternion"]
    poses = [types["geometry_msgs/msg/Pose"](point(row.x, row.y, row.z), quaternion(row.qx, row.qy, row.qz, row.qw))
             for row in moved_plan(table, matrix).itertuples()]
    x, y, z, w = rotation_to_quaternion(matrix[:3, :3])
    transform = types["geometry_msgs/msg/Transform"](types["geometry_msgs/msg/Vector3"](*matrix[:3, 3]),
                                                     quaternion(x, y, z, w))
    return {
        "/tpvp/views": types["geometry_msgs/msg/PoseArray"](header, poses),
        "/tpvp/route": types["nav_msgs/msg/Path"](header, [types["geometry_msgs/msg/PoseStamped"](header, pose)
                                                           for pose in poses]),
        "/tf_static": types["tf2_msgs/msg/TFMessage"](
            [types["geometry_msgs/msg/TransformStamped"](header, SCAN_FRAME, transform)]),
    }


def write_plan_bag(folder, name: str, table: pd.DataFrame, frame: str, matrix: np.ndarray, stamp_ns: int) -> Path:
    """Write the plan as the bag ``name`` into the existing, empty ``folder`` (the bag's staging
    folder): ``metadata.yaml`` and ``<name>.mcap``, every message logged at the stamp (a zero stamp
    at :data:`ZERO_STAMP_LOG_NS`)."""
    folder = Path(folder)
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    messages = plan_messages(table, frame, matrix, stamp_ns, typestore)
    # rosbags creates the bag's folder itself and names the .mcap after it: write it inside, move its files up.
    inner = folder / name
    with Writer(inner, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype in TOPICS.items():
            connection = writer.add_connection(topic, msgtype, typestore=typestore, offered_qos_profiles=[LATCHED])
            writer.write(connection, stamp_ns or ZERO_STAMP_LOG_NS, typestore.serialize_cdr(messages[topic], msgtype))
    for item in inner.iterdir():
        os.replace(item, folder / item.name)
    inner.rmdir()
    return folder
