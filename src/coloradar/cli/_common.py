"""Arguments and checks that several commands share."""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

from ..errors import ColoradarError
from ..formats.atomic import new_output_path


class UsageError(ColoradarError):
    """The command line itself is wrong (options that exclude each other, a value an option
    does not accept, a missing argument): exit status 2, as argparse's own usage errors."""


# The library's messages name both spellings, ``pass overwrite=True (--overwrite)``, for API
# callers and command-line users alike; on the command line only the option means anything.
_BOTH_SPELLINGS = re.compile(r"\b[A-Za-z_]\w*=(?:True|'[^']*'|\S+?) \((--[A-Za-z][\w-]*"
                             r"(?: [^)]+)?)\)")
_ORIENTATION_STYLE = re.compile(r"\b[A-Za-z_]\w* '([^']*)' \((--[\w-]+ \1)\)")


def cli_wording(message: str) -> str:
    """``message`` as the command line says it: ``pass overwrite=True (--overwrite)`` becomes
    ``pass --overwrite``, ``use orientation 'groundtruth' (--orientation groundtruth)``
    becomes ``use --orientation groundtruth``."""
    return _ORIENTATION_STYLE.sub(r"\2", _BOTH_SPELLINGS.sub(r"\1", message))


def add_file_output_args(p: argparse.ArgumentParser) -> None:
    """``--overwrite`` and ``--calib`` of the commands that read one run and write one file."""
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")


def _number(text: str, kind, test, what: str):
    try:
        v = kind(text)
    except ValueError:
        v = None
    if v is None or v != v or not test(v):  # v != v: nan
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """An option's value that must be a finite number > 0 (a size, a rate, a duration)."""
    return _number(text, float, lambda v: 0 < v < float("inf"), "a number > 0")


def non_negative_float(text: str) -> float:
    """An option's value that must be a finite number ≥ 0 (a range gate, a start time)."""
    return _number(text, float, lambda v: 0 <= v < float("inf"), "a number ≥ 0")


def positive_int(text: str) -> int:
    """An option's value that must be a whole number ≥ 1 (a stride, a resolution)."""
    return _number(text, int, lambda v: v >= 1, "a whole number ≥ 1")


def add_executor_args(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The "where the work runs" options of the batch commands: ``--jobs`` (local pool) or
    ``--scheduler`` / ``--scheduler-file`` (Dask). Returns the group, for more options."""
    g = p.add_argument_group("where the work runs")
    g.add_argument("--jobs", "-j", type=positive_int, metavar="N",
                   help=f"local worker processes (default: all cores, {os.cpu_count()} here; "
                        "1: in this process)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on the Dask cluster of this scheduler (tcp://host:8786)")
    g.add_argument("--scheduler-file", metavar="FILE",
                   help="run on the Dask cluster whose scheduler wrote FILE "
                        "(dask scheduler --scheduler-file FILE)")
    return g


def executor_from_args(args: argparse.Namespace):
    """The Dask executor the options of :func:`add_executor_args` name, or None (the local
    pool of ``--jobs``); both at once is a usage error."""
    if not (args.scheduler or args.scheduler_file):
        return None
    if args.jobs is not None:
        raise UsageError("--jobs sets the local pool; on a Dask cluster the workers "
                         "(dask worker --nworkers/--nthreads) set the parallelism")
    from ..batch.executors import make_executor
    return make_executor(scheduler=args.scheduler, scheduler_file=args.scheduler_file)


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
