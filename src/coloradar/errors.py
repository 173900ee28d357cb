"""Exceptions and warnings raised by coloradar.

Every error a user can provoke with bad input derives from :class:`ColoradarError`, so that
``except coloradar.ColoradarError`` catches all of them; each message names the file and what was
expected.
"""

from __future__ import annotations


class ColoradarError(Exception):
    """Base class of every error coloradar raises on bad input."""


class FormatError(ColoradarError, ValueError):
    """A data file does not have the layout or size its kind and configuration require."""


class CalibrationError(ColoradarError, ValueError):
    """A calibration file is missing, malformed, or inconsistent with another."""


class MissingDataError(ColoradarError, KeyError):
    """A sensor, stream or file that was asked for is not in the dataset or run."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class ExtrapolationError(ColoradarError, ValueError):
    """A time asked of a trajectory or stream lies outside the span it covers."""


class OutputExistsError(ColoradarError, FileExistsError):
    """An output would overwrite existing files and overwriting was not requested."""


class CalibrationWarning(UserWarning):
    """A calibration file had a known defect that coloradar corrected (the message says how)."""


class DataWarning(UserWarning):
    """A data stream is inconsistent (e.g. more frames than timestamps); coloradar worked around it."""
