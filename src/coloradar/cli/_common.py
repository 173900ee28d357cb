"""Arguments and checks that several commands share."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import OutputExistsError


def add_file_output_args(p: argparse.ArgumentParser) -> None:
    """``--overwrite`` and ``--calib`` of the commands that read one run and write one file."""
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")


def new_output_file(out: str, overwrite: bool) -> Path:
    """``out`` as a path, refusing an existing file unless ``overwrite``."""
    path = Path(out)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists; pass --overwrite to replace it")
    return path
