"""Dataset / Sequence / per-sensor lazy streams over folders or zips."""

from .dataset import Dataset, detect_dataset_layout, find_runs, open_dataset
from .sequence import (
    STREAMS,
    CameraSensor,
    LidarSensor,
    RadarSensor,
    Sequence,
    detect_layout,
    open_sequence,
    resolve_calibration,
)
from .streams import FrameStream, ImuData, PoseData

__all__ = [
    "STREAMS",
    "CameraSensor",
    "Dataset",
    "FrameStream",
    "ImuData",
    "LidarSensor",
    "PoseData",
    "RadarSensor",
    "Sequence",
    "detect_dataset_layout",
    "detect_layout",
    "find_runs",
    "open_dataset",
    "open_sequence",
    "resolve_calibration",
]
