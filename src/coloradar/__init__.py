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
    FrameIndexError,
    MissingDataError,
    MissingDependencyError,
    OutputExistsError,
    ReadError,
    SettingsError,
    WriteError,
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
    "FrameIndexError",
    "MissingDataError",
    "MissingDependencyError",
    "OutputExistsError",
    "RadarCalib",
    "ReadError",
    "Sequence",
    "SettingsError",
    "WriteError",
    "__version__",
    "load_calibration",
    "open_dataset",
    "open_sequence",
]

# Subpackages reachable as attributes (``cr.dsp``, ``cr.viz``...) but imported only when first
# used, so that ``import coloradar`` stays light (no matplotlib, no simulator).
_SUBPACKAGES = frozenset({"batch", "calib", "cli", "dataset", "demo", "dsp", "errors", "formats",
                          "geometry", "odometry", "progress", "sim", "viz"})


def __getattr__(name: str) -> object:
    if name in _SUBPACKAGES:
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _SUBPACKAGES)
