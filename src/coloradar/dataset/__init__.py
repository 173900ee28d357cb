"""Dataset / Sequence / per-sensor lazy streams over folders or zips."""

from .dataset import Dataset, find_runs, open_dataset
from .sequence import STREAMS, LidarSensor, RadarSensor, Sequence, open_sequence, resolve_calibration
from .streams import FrameStream, ImuData, PoseData

__all__ = [
    "STREAMS",
    "Dataset",
    "FrameStream",
    "ImuData",
    "LidarSensor",
    "PoseData",
    "RadarSensor",
    "Sequence",
    "find_runs",
    "open_dataset",
    "open_sequence",
    "resolve_calibration",
]
