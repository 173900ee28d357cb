"""Arguments and checks that several commands share."""

from __future__ import annotations

import argparse
import difflib
import os
import re
import sys
from collections.abc import Iterable
from pathlib import Path

from ..errors import ColoradarError, WriteError
from ..formats.atomic import check_writable, new_output_path
from ..formats.layout import LAYOUTS, PROCESS_PRODUCTS
from ..formats.source import check_input_path


class UsageError(ColoradarError):
    """The command line itself is wrong (options that exclude each other, a value an option
    does not accept, a missing argument): exit status 2, as argparse's own usage errors."""


# The library's messages name both spellings, ``pass overwrite=True (--overwrite)``, for API
# callers and command-line users alike; on the command line only the option means anything.
_BOTH_SPELLINGS = re.compile(r"\b[A-Za-z_]\w*=(?:True|'[^']*'|\S+?) \((--[A-Za-z][\w-]*"
                             r"(?: [^)]+)?)\)")
# The same said the other way round, ``pass --overwrite (overwrite=True)`` (the capture importer).
_OPTION_FIRST = re.compile(r"(--[A-Za-z][\w-]*) \([A-Za-z_]\w*=(?:True|'[^']*'|[^)\s]+)\)")
_ORIENTATION_STYLE = re.compile(r"\b[A-Za-z_]\w* '([^']*)' \((--[\w-]+ \1)\)")


def cli_wording(message: str) -> str:
    """``message`` as the command line says it: ``pass overwrite=True (--overwrite)`` becomes
    ``pass --overwrite`` (as does ``pass --overwrite (overwrite=True)``), ``use orientation
    'groundtruth' (--orientation groundtruth)``
    becomes ``use --orientation groundtruth``."""
    message = _OPTION_FIRST.sub(r"\1", _BOTH_SPELLINGS.sub(r"\1", message))
    return _ORIENTATION_STYLE.sub(r"\2", message)


def add_run_out_radar_args(c: argparse.ArgumentParser, file: str) -> None:
    """RUN, ``--out FILE`` (a ``file`` to write) and ``--radar`` of a ``calibrate`` command."""
    c.add_argument("run", metavar="RUN", help="run folder or .zip")
    c.add_argument("--out", required=True, metavar="FILE",
                   help=f"the {file} to write (outside the dataset)")
    c.add_argument("--radar", choices=("single_chip", "cascade"), default="single_chip",
                   help="which radar (default: single_chip)")


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


def finite_float(text: str) -> float:
    """An option's value that may be any finite number (an offset of either sign)."""
    return _number(text, float, lambda v: abs(v) < float("inf"), "a finite number")


def non_negative_int(text: str) -> int:
    """An option's value that must be a whole number ≥ 0 (a random seed)."""
    return _number(text, int, lambda v: v >= 0, "a whole number ≥ 0")


def float_in(low: float, high: float, *, low_open: bool = False, high_open: bool = False):
    """The ``type=`` of an option whose value must lie in ``[low, high]`` (``(`` / ``)`` with
    ``low_open`` / ``high_open``): the bounds the library would refuse after the work, said
    by the parser, naming the option, before any."""
    lo, hi = "(" if low_open else "[", ")" if high_open else "]"

    def test(v: float) -> bool:
        return (low < v if low_open else low <= v) and (v < high if high_open else v <= high)

    def parse(text: str) -> float:
        return _number(text, float, test, f"a number in {lo}{low:g}, {high:g}{hi}")

    parse.__name__ = f"float_in_{low:g}_{high:g}"
    return parse


def int_in(low: int, high: int | None = None):
    """The ``type=`` of an option whose value must be a whole number ``≥ low`` (and
    ``≤ high`` when given)."""
    def parse(text: str) -> int:
        if high is None:
            return _number(text, int, lambda v: v >= low, f"a whole number ≥ {low}")
        return _number(text, int, lambda v: low <= v <= high,
                       f"a whole number in [{low}, {high}]")

    parse.__name__ = f"int_in_{low}_{high}"
    return parse


# An image's memory grows as the square of its dots per inch: 1200 (print quality) is about
# 100 MB per picture; 1e9 failed only after the work, out of memory.
dpi = int_in(1, 1200)


# A local pool of more processes than this is no pool a machine runs (each one a Python with
# numpy); 1e9 would fail only when the pool starts them.
jobs_count = int_in(1, 1024)


def add_executor_args(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The "where the work runs" options of the batch commands: ``--jobs`` (local pool) or
    ``--scheduler`` / ``--scheduler-file`` (Dask). Returns the group, for more options."""
    g = p.add_argument_group("where the work runs")
    g.add_argument("--jobs", "-j", type=jobs_count, metavar="N",
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


# Folders only a recorded run has (``coloradar process`` writes <radar>/heatmaps and
# <radar>/pointclouds into its own output folders, so those do not make a folder a run).
_RUN_MARKERS = tuple(dict.fromkeys(
    m for lay in LAYOUTS.values() for m in lay.run_markers
    if m.split("/")[-1] not in PROCESS_PRODUCTS))
_CALIB_NAMES = ("calib", "calib.zip")


def _has_run_marker(folder: Path) -> bool:
    """A recorded run: a radar's ADC folder, or two of a run's sensor folders (a user's own
    folder with one ``camera/`` or ``imu/`` in it is no run)."""
    found = [m for m in _RUN_MARKERS if (folder / m).is_dir()]
    return any("/" in m for m in found) or len(found) >= 2


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _protected(inputs: Iterable[str | os.PathLike[str] | None]) -> list[tuple[Path, str]]:
    """``(resolved path, what it is)`` of every input a command may not write into: each
    input itself (run, dataset root, zip, calib) and the calib folder beside a run."""
    out: list[tuple[Path, str]] = []
    for given in inputs:
        if given is None:
            continue
        p = Path(given).resolve()
        if (p.is_dir() and _has_run_marker(p)) or (p.is_file() and p.suffix.lower() == ".zip"):
            out.append((p, "the run"))
            out += [(p.parent / c, "the calibration") for c in _CALIB_NAMES
                    if (p.parent / c).exists()]
            if any((p.parent / c).exists() for c in _CALIB_NAMES):
                # The dataset root itself (not a folder inside it, such as root/processed):
                # product folders written there would make the root look like a run.
                out.append((p.parent, "the dataset root"))
        elif p.is_dir():
            out.append((p, "the input folder"))
        elif p.exists():
            out.append((p, "the input file"))
    return out


def check_output_outside_dataset(out: str | os.PathLike[str],
                                 inputs: Iterable[str | os.PathLike[str] | None] = (), *,
                                 writable: bool = True) -> Path:
    """The one rule of every command that writes: never into the dataset.

    ``out`` (a file or folder about to be written) may not be, or lie inside, one of
    ``inputs`` (runs, dataset roots, run zips, calib folders; None entries are skipped), the
    calib folder beside an input run, or any run folder at all (a folder holding a run's
    sensor folders: ``lidar/``, ``imu/``, ``groundtruth/``, ``<radar>/adc_samples/``...); nor
    be the dataset root that holds an input run (a folder inside that root, such as
    ``root/processed``, is allowed). Then (``writable``) that something can be created where
    ``out`` goes (:func:`~coloradar.formats.atomic.check_writable`), so that a read-only
    output is refused before the work, not after it. Call it after checking the inputs and
    before anything is read or written.

    Parameters
    ----------
    out
        The output path, as given.
    inputs
        The input paths of the command, as given.
    writable
        Also check that ``out`` can be written (False: for a folder only read, or a check
        that the caller makes later itself).

    Returns
    -------
    pathlib.Path
        ``out`` as a path.

    Raises
    ------
    WriteError
        ``out`` is an input (arguments swapped) or lies inside one or inside a run (never a
        suggestion to ``--overwrite`` it); or nothing can be written there.
    """
    path = Path(out)
    target = path.resolve()
    for p, what in _protected(inputs):
        if target == p:
            raise WriteError(f"{path}: this is {what} the command reads, not an output; "
                             "coloradar never writes into a dataset (are the arguments "
                             "swapped? see --help)")
        if _inside(target, p) and what != "the dataset root":
            raise WriteError(f"{path}: lies inside {what} {p}; coloradar never writes into a "
                             "dataset: choose an output outside it")
    for folder in (target, *target.parents):
        if folder.is_dir() and _has_run_marker(folder):
            if folder == target:
                raise WriteError(f"{path}: this is a ColoRadar run, not an output; coloradar "
                                 "never writes into a dataset (are the arguments swapped? "
                                 "see --help)")
            raise WriteError(f"{path}: lies inside the ColoRadar run {folder}; coloradar never "
                             "writes into a dataset: choose an output outside it")
    if writable:
        check_writable(path)
    return path


def check_input(path: str | os.PathLike[str], expected: str = "a run folder or a run .zip"
                ) -> None:
    """Check an input path before any output (so that swapped arguments are said as a
    missing or wrong input, never as an output that exists)."""
    check_input_path(path, expected)


def new_output_file(out: str, overwrite: bool,
                    inputs: Iterable[str | os.PathLike[str] | None] = ()) -> Path:
    """``out`` as a path, refusing a path inside the dataset (:func:`check_output_outside_dataset`
    with ``inputs``) and an existing file unless ``overwrite`` (checked before any input is
    read, so that a long command fails at once)."""
    check_output_outside_dataset(out, inputs)
    return new_output_path(out, overwrite)


def did_you_mean(name: str, names: Iterable[str]) -> str:
    """``"did you mean pfa? "`` for the known ``names`` closest to a misspelt ``name``
    (difflib), or ``""`` when none is close."""
    names = list(names)
    # "lidar" for "lidar/pointclouds": a known name it begins is as close as a misspelling.
    starts = [n for n in names if name and n.startswith(name) and n != name]
    close = list(dict.fromkeys(starts + difflib.get_close_matches(name, names, n=2,
                                                                  cutoff=0.6)))[:2]
    return f"did you mean {' or '.join(close)}? " if close else ""


def is_run_folder_path(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a run folder of the dataset (it holds a recorded run's sensor
    folders), without opening it."""
    p = Path(path)
    return p.is_dir() and _has_run_marker(p)


def processing_setting(text: str) -> tuple[str, object]:
    """``--set NAME=VALUE``, parsed by :meth:`coloradar.dsp.ProcessingSettings.parse_setting`;
    an unknown name is answered with the closest known ones only (not all ~40 of them)."""
    from dataclasses import fields

    from ..dsp import ProcessingSettings  # dsp is heavy: only for the commands that parse it

    name, sep, _ = text.partition("=")
    names = [f.name for f in fields(ProcessingSettings) if f.name != "workers"]
    if not sep or name.strip() not in names:
        hint = did_you_mean(name.strip(), names) if sep else ""
        what = f"unknown setting {name.strip()!r}" if sep else f"expected NAME=VALUE, got {text!r}"
        raise argparse.ArgumentTypeError(f"{what}{'; ' + hint if hint else ' '}(the names: "
                                         "coloradar.dsp.ProcessingSettings, docs/dsp.md)")
    try:
        return ProcessingSettings.parse_setting(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def pick_radar(seq, given: str | None, default: str, quiet: bool = False) -> str:
    """The radar a command runs on: ``given`` (``--radar``); else the run's only radar when it
    has one alone (said on stderr: the default would fail on it), else ``default``."""
    if given is not None:
        return given
    has = [r for r in ("single_chip", "cascade")
           if any(s.startswith(r + "/") for s in seq.available())]
    if len(has) == 1 and has[0] != default:
        if not quiet:
            print(f"{seq.name}: the run has the {has[0]} radar only: using it (--radar "
                  f"{has[0]})", file=sys.stderr)
        return has[0]
    return default


def other_radar_hint(seq, radar: str) -> str:
    """``"; the run has the cascade: pass --radar cascade"`` when the other radar has data,
    else ``""``: the end of a message saying ``radar`` lacks what a command needs."""
    other = "cascade" if radar == "single_chip" else "single_chip"
    if any(s.startswith(other + "/") for s in seq.available()):
        return f"; the run has the {other} radar: pass --radar {other}"
    return ""


def calibration_run(args: argparse.Namespace):
    """A ``calibrate`` command's inputs, checked before any work: the output file (refused
    inside the dataset or when it exists without ``--overwrite``), the run, its radar's
    calibration and its ADC stream (a :class:`MissingDataError` when it has no frames)."""
    from ..dataset import open_sequence
    from ..errors import MissingDataError
    from ..formats.source import check_input_path

    check_input_path(args.run, "a run folder or a run .zip")
    out = new_output_file(args.out, args.overwrite, inputs=(args.run, args.calib))
    seq = open_sequence(args.run, calib=args.calib)
    stream = seq.radar(args.radar).adc
    if len(stream) == 0:
        raise MissingDataError(f"{args.run}: no {args.radar} ADC frames")
    return out, seq, seq.calib.radar(args.radar), stream
