"""Arguments and checks that several commands share."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..formats.atomic import new_output_path


def add_file_output_args(p: argparse.ArgumentParser) -> None:
    """``--overwrite`` and ``--calib`` of the commands that read one run and write one file."""
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")


def add_quiet_arg(p: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress line and no summary; warnings and errors are still printed
    (on stderr), so that nothing a user must know is hidden."""
    p.add_argument("--quiet", action="store_true",
                   help="no progress or summary lines (warnings and errors still show)")


def new_output_file(out: str, overwrite: bool) -> Path:
    """``out`` as a path, refusing an existing file unless ``overwrite`` (checked before any
    input is read, so that a long command fails at once)."""
    return new_output_path(out, overwrite)


def processing_setting(text: str) -> tuple[str, object]:
    """``--set NAME=VALUE``, parsed by :meth:`coloradar.dsp.ProcessingSettings.parse_setting`."""
    from ..dsp import ProcessingSettings  # dsp is heavy: only for the commands that parse it

    try:
        return ProcessingSettings.parse_setting(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
