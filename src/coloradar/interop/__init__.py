"""Bridges to where radar-robotics users already work: ROS 1 / ROS 2 bags (``rosbags``,
optional) and HDF5 learning files (``h5py``, optional).

* :mod:`.ros_messages` — topics, message types, times and message helpers both directions share;
* :mod:`.bag_export` — :func:`export_bag`: a run to a bag;
* :mod:`.bag_import` — :func:`import_bag`: a bag to a run;
* :mod:`.pointcloud2` — ``sensor_msgs/PointCloud2`` bytes both ways;
* :mod:`.hdf5` — one ``.h5`` file of learning samples.

Above ``dataset``, ``geometry`` and ``dsp`` (computed radar points); below the CLI.
"""

from .bag_export import ExportResult, export_bag
from .bag_import import BagImport, ImportResult, import_bag, iter_topics, parse_topic_map
from .pointcloud2 import CloudLayout, decode_cloud, encode_cloud
from .ros_messages import DEFAULT_TOPICS, EXPORT_STREAMS, ROS_FORMATS, ns_to_times, times_to_ns

__all__ = [
    "DEFAULT_TOPICS",
    "EXPORT_STREAMS",
    "ROS_FORMATS",
    "BagImport",
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
