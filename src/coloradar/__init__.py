"""coloradar: read, process, simulate and evaluate ColoRadar 4D mmWave radar data.

Quick start::

    import coloradar as cr
    seq = cr.open_sequence("12_21_2020_ec_hallways_run0.zip", calib="calib")
    adc = seq.cascade.adc[0]                       # complex64 (tx, rx, chirp, sample)
"""

from ._version import __version__
from .calib import Calibration, RadarCalib, load_calibration
from .dataset import Dataset, Sequence, open_dataset, open_sequence
from .errors import (
    CalibrationError,
    CalibrationWarning,
    ColoradarError,
    DataWarning,
    ExtrapolationError,
    FormatError,
    MissingDataError,
    OutputExistsError,
)

__all__ = [
    "Calibration",
    "CalibrationError",
    "CalibrationWarning",
    "ColoradarError",
    "DataWarning",
    "Dataset",
    "ExtrapolationError",
    "FormatError",
    "MissingDataError",
    "OutputExistsError",
    "RadarCalib",
    "Sequence",
    "__version__",
    "load_calibration",
    "open_dataset",
    "open_sequence",
]
