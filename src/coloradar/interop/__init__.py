"""Bridges to where radar-robotics users already work: ROS 1 / ROS 2 bags (``rosbags``, optional).

Above ``dataset``, ``geometry`` and ``dsp`` (computed radar points); below the CLI.
"""

from .pointcloud2 import CloudLayout, decode_cloud, encode_cloud
from .ros import (
    DEFAULT_TOPICS,
    EXPORT_STREAMS,
    ROS_FORMATS,
    ExportResult,
    ImportResult,
    export_bag,
    import_bag,
    iter_topics,
    ns_to_times,
    parse_topic_map,
    times_to_ns,
)

__all__ = [
    "DEFAULT_TOPICS",
    "EXPORT_STREAMS",
    "ROS_FORMATS",
    "CloudLayout",
    "ExportResult",
    "ImportResult",
    "decode_cloud",
    "encode_cloud",
    "export_bag",
    "import_bag",
    "iter_topics",
    "ns_to_times",
    "parse_topic_map",
    "times_to_ns",
]
