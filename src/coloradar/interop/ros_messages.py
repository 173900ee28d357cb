"""ROS messages, topics and times shared by bag export (:mod:`.bag_export`) and import
(:mod:`.bag_import`); needs ``rosbags`` (optional extra ``ros``) only when a bag is touched.

Topics and messages (export writes them; import reads them back, and more):

=========================  =========================  ===============================================
stream                     default topic              message
=========================  =========================  ===============================================
lidar/pointclouds          ``/lidar/points``          ``sensor_msgs/PointCloud2`` x y z intensity
cascade/pointclouds        ``/cascade/points``        ``sensor_msgs/PointCloud2`` x y z intensity doppler
single_chip/pointclouds    ``/single_chip/points``    same
imu                        ``/imu/data``              ``sensor_msgs/Imu`` (no orientation: covariance[0] = -1)
groundtruth                ``/groundtruth/odom``      ``nav_msgs/Odometry`` world -> base (or PoseStamped)
vicon                      ``/vicon/pose``            ``geometry_msgs/PoseStamped`` in ``world``
extrinsics                 ``/tf_static``             ``tf2_msgs/TFMessage``: base -> every sensor
=========================  =========================  ===============================================

Frame ids are the sensor names (``cascade``, ``single_chip``, ``lidar``, ``imu``, ``vicon``),
``base`` (the rig) and ``world`` (the ground truth's frame). The ``doppler`` field is the
dataset's range rate [m/s] (> 0 receding).

Times: a file time ``t`` [s, float64] becomes ``sec = floor(t)``, ``nanosec = round((t - sec)
· 1e9)``; reading back, ``sec + nanosec / 1e9`` is the float64 nearest to the original, because a
float64 near 1.6e9 s is spaced 2.4e-7 s apart, far coarser than 1 ns. So export followed by import
gives the very same float64 timestamps.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..calib import Extrinsic
from ..errors import FormatError, MissingDependencyError
from .pointcloud2 import CloudLayout, encode_cloud

__all__ = [
    "BASE_FRAME",
    "DEFAULT_TOPICS",
    "EXPORT_STREAMS",
    "FIELD_ALIASES",
    "LIDAR_FIELDS",
    "RADAR_FIELDS",
    "ROS_FORMATS",
    "WORLD_FRAME",
    "ns_to_times",
    "times_to_ns",
]

ROS_FORMATS = ("ros1", "ros2")

DEFAULT_TOPICS: dict[str, str] = {
    "lidar/pointclouds": "/lidar/points",
    "cascade/pointclouds": "/cascade/points",
    "single_chip/pointclouds": "/single_chip/points",
    "imu": "/imu/data",
    "groundtruth": "/groundtruth/odom",
    "vicon": "/vicon/pose",
    "tf_static": "/tf_static",
}
"""Stream -> topic used by export, and (reversed) by import when no topic map is given."""

EXPORT_STREAMS = tuple(k for k in DEFAULT_TOPICS if k != "tf_static")
"""Streams export and import know (besides ``tf_static``)."""

RADAR_POINT_SOURCES = ("auto", "shipped", "adc", "heatmaps")
GROUNDTRUTH_MSGS = ("odometry", "pose")

RADAR_FIELDS = ("x", "y", "z", "intensity", "doppler")
LIDAR_FIELDS = ("x", "y", "z", "intensity")
# Names other recorders use for the same quantities (import only).
FIELD_ALIASES: dict[str, tuple[str, ...]] = {
    "doppler": ("range_rate", "velocity", "v_doppler", "radial_velocity"),
    "intensity": ("power", "snr", "rcs", "i"),
}

WORLD_FRAME = "world"
BASE_FRAME = "base"

_TYPES = {
    "cloud": "sensor_msgs/msg/PointCloud2",
    "imu": "sensor_msgs/msg/Imu",
    "odometry": "nav_msgs/msg/Odometry",
    "pose": "geometry_msgs/msg/PoseStamped",
    "pose_cov": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "transform": "geometry_msgs/msg/TransformStamped",
    "tf": "tf2_msgs/msg/TFMessage",
}


def _rosbags():
    try:
        import rosbags  # noqa: F401
    except ImportError:  # pragma: no cover - depends on the environment
        raise MissingDependencyError("ROS bags need the optional 'rosbags' package: "
                             "pip install 'coloradar[ros]'") from None


# -- time ---------------------------------------------------------------------------------------
def times_to_ns(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 Unix times [s] -> ``(sec, nanosec)`` int64 arrays (ROS ``Time``), exactly invertible.

    Parameters
    ----------
    t
        float64 ``(N,)`` [s], non-negative.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        int64 ``(N,)`` seconds and nanoseconds in ``[0, 1e9)``.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if np.any(~np.isfinite(t)) or np.any(t < 0):
        raise FormatError("ROS times must be finite, non-negative Unix seconds")
    sec = np.floor(t)
    # t - floor(t) is exact (Sterbenz), so only the scaling rounds, far below 1 ns.
    nsec = np.rint((t - sec) * 1e9).astype(np.int64)
    sec = sec.astype(np.int64)
    carry = nsec >= 1_000_000_000
    sec[carry] += 1
    nsec[carry] -= 1_000_000_000
    return sec, nsec


def ns_to_times(sec: np.ndarray, nsec: np.ndarray) -> np.ndarray:
    """``(sec, nanosec)`` -> float64 Unix times [s] (the inverse of :func:`times_to_ns`)."""
    return np.asarray(sec, dtype=np.float64) + np.asarray(nsec, dtype=np.float64) / 1e9


# -- building messages (export) ----------------------------------------------------------
class _Builder:
    """Message construction for one typestore (ROS 1 Noetic or ROS 2 Humble definitions)."""

    def __init__(self, fmt: str):
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = fmt == "ros1"
        self.store = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.store.types:
            # rosbags' Noetic store lacks tf2_msgs; its definition is one line (tf2_msgs/TFMessage).
            from rosbags.typesys import get_types_from_msg

            self.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                   "tf2_msgs/msg/TFMessage"))
        T = self.store.types
        self.Time = T["builtin_interfaces/msg/Time"]
        self.Header = T["std_msgs/msg/Header"]
        self.PointField = T["sensor_msgs/msg/PointField"]
        self.PointCloud2 = T["sensor_msgs/msg/PointCloud2"]
        self.Imu = T["sensor_msgs/msg/Imu"]
        self.Vector3 = T["geometry_msgs/msg/Vector3"]
        self.Quaternion = T["geometry_msgs/msg/Quaternion"]
        self.Point = T["geometry_msgs/msg/Point"]
        self.Pose = T["geometry_msgs/msg/Pose"]
        self.PoseStamped = T["geometry_msgs/msg/PoseStamped"]
        self.PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
        self.Twist = T["geometry_msgs/msg/Twist"]
        self.TwistWithCovariance = T["geometry_msgs/msg/TwistWithCovariance"]
        self.Odometry = T["nav_msgs/msg/Odometry"]
        self.Transform = T["geometry_msgs/msg/Transform"]
        self.TransformStamped = T["geometry_msgs/msg/TransformStamped"]
        self.TFMessage = T["tf2_msgs/msg/TFMessage"]
        self.serialize = self.store.serialize_ros1 if self.ros1 else self.store.serialize_cdr

    def header(self, sec: int, nsec: int, frame: str, seq: int = 0):
        stamp = self.Time(sec=int(sec), nanosec=int(nsec))
        if self.ros1:
            return self.Header(seq=seq, stamp=stamp, frame_id=frame)
        return self.Header(stamp=stamp, frame_id=frame)

    def cloud(self, header, points: np.ndarray, names: tuple[str, ...]):
        layout, data = encode_cloud(points, names)
        fields = [self.PointField(name=n, offset=o, datatype=d, count=c)
                  for n, o, d, c in zip(layout.names, layout.offsets, layout.datatypes,
                                        layout.counts, strict=True)]
        return self.PointCloud2(header=header, height=layout.height, width=layout.width,
                                fields=fields, is_bigendian=False, point_step=layout.point_step,
                                row_step=layout.row_step, data=data,
                                is_dense=bool(np.all(np.isfinite(points))))

    def quat(self, q: np.ndarray):
        return self.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def vec(self, v: np.ndarray):
        return self.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def pose(self, row: np.ndarray):
        return self.Pose(position=self.Point(x=float(row[0]), y=float(row[1]), z=float(row[2])),
                         orientation=self.quat(row[3:7]))

    def imu(self, header, row: np.ndarray):
        no_orientation = np.zeros(9)
        no_orientation[0] = -1.0  # sensor_msgs/Imu: "-1 in element 0: no orientation estimate"
        return self.Imu(header=header, orientation=self.quat(np.array([0.0, 0.0, 0.0, 1.0])),
                        orientation_covariance=no_orientation,
                        angular_velocity=self.vec(row[3:6]), angular_velocity_covariance=np.zeros(9),
                        linear_acceleration=self.vec(row[0:3]),
                        linear_acceleration_covariance=np.zeros(9))

    def odometry(self, header, row: np.ndarray, child: str):
        zero = self.Twist(linear=self.vec(np.zeros(3)), angular=self.vec(np.zeros(3)))
        return self.Odometry(header=header, child_frame_id=child,
                             pose=self.PoseWithCovariance(pose=self.pose(row), covariance=np.zeros(36)),
                             twist=self.TwistWithCovariance(twist=zero, covariance=np.zeros(36)))

    def pose_stamped(self, header, row: np.ndarray):
        return self.PoseStamped(header=header, pose=self.pose(row))

    def tf_static(self, sec: int, nsec: int, transforms: Mapping[str, Extrinsic]):
        items = [self.TransformStamped(header=self.header(sec, nsec, BASE_FRAME),
                                       child_frame_id=name,
                                       transform=self.Transform(translation=self.vec(e.translation),
                                                                rotation=self.quat(e.quaternion)))
                 for name, e in sorted(transforms.items())]
        return self.TFMessage(transforms=items)

@functools.lru_cache(maxsize=2)
def _builder(fmt: str) -> _Builder:
    # Building a typestore compiles its message classes: ~0.1-0.3 s, paid once per format.
    return _Builder(fmt)


# -- reading messages (import) ------------------------------------------------------------
def _stamp(msg: Any) -> tuple[int, int]:
    st = msg.header.stamp
    return int(st.sec), int(st.nanosec)


def _pose_row(msg: Any) -> np.ndarray:
    if hasattr(msg, "transform"):  # TransformStamped
        t, q = msg.transform.translation, msg.transform.rotation
        return np.array([t.x, t.y, t.z, q.x, q.y, q.z, q.w], dtype=np.float64)
    pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w], dtype=np.float64)


def _layout(msg: Any) -> CloudLayout:
    return CloudLayout(tuple(f.name for f in msg.fields), tuple(int(f.offset) for f in msg.fields),
                       tuple(int(f.datatype) for f in msg.fields), tuple(int(f.count) for f in msg.fields),
                       int(msg.point_step), int(msg.row_step), int(msg.height), int(msg.width),
                       bool(msg.is_bigendian))
