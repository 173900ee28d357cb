"""Exceptions and warnings raised by coloradar.

Every error a user can provoke with bad input derives from :class:`ColoradarError`, so that
``except coloradar.ColoradarError`` catches all of them; each message names the file and what was
expected. Each class also derives from the built-in exception a caller would have caught before
(``ValueError``, ``KeyError``, ``IndexError``, ``OSError``, ``ImportError``), so that code written
against those keeps working.
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


class SettingsError(ColoradarError, ValueError):
    """A setting or argument has a value outside what it accepts (an unknown mode, a
    non-positive size, a probability outside (0, 1), a frame index past the end...)."""


class FrameIndexError(ColoradarError, IndexError):
    """A frame (or bin) index lies outside the stream (or axis) it indexes."""


class ReadError(ColoradarError, OSError):
    """An input exists but cannot be read: not a regular file (a FIFO, a device, a folder
    where a file was expected) or no permission."""


class WriteError(ColoradarError, OSError):
    """An output cannot be written: its folder is a file, no permission, the disk is full..."""


class MissingDependencyError(ColoradarError, ImportError):
    """An optional extra (``pip install 'coloradar[viz]'``, ``[dask]``, ``[rerun]``...) that
    the call needs is not installed."""


class CalibrationWarning(UserWarning):
    """A calibration file had a known defect that coloradar corrected (the message says how)."""


class DataWarning(UserWarning):
    """A data stream is inconsistent (e.g. more frames than timestamps); coloradar worked around it."""
