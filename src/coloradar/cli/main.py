"""The ``coloradar`` command. Each sub-command lives in its own module of this package and
defines ``register(subparsers)``; the modules hold no processing logic of their own."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
import warnings

from .. import __version__
from ..errors import ColoradarError
from ..progress import interrupt_handling
from ._common import UsageError, cli_wording

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command of this package registered."""
    parser = argparse.ArgumentParser(
        prog="coloradar",
        description="Read, process, simulate and evaluate ColoRadar radar data.")
    parser.add_argument("--version", action="version", version=f"coloradar {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    from . import __path__ as pkg_path

    for mod in sorted(m.name for m in pkgutil.iter_modules(pkg_path)):
        if mod.startswith("_") or mod == "main":
            continue
        module = importlib.import_module(f"{__package__}.{mod}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 ok, 1 data error, 2 usage error)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    # Data-defect warnings are part of the output: print them once, briefly.
    warnings.simplefilter("once")
    warnings.formatwarning = lambda msg, cat, *a, **k: f"warning: {cli_wording(str(msg))}\n"
    try:
        # Ctrl-C stops every command within a unit of work, even where Python would swallow it.
        with interrupt_handling():
            code = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler below
        return code
    except BrokenPipeError:
        # The reader went away (`coloradar info | head -1`): not an error of ours. Point stdout
        # at /dev/null so that the interpreter's final flush does not fail again.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 141  # 128 + SIGPIPE, what a shell reports for a command ended by a closed pipe
    except UsageError as exc:
        # argparse's convention, whichever check found it: usage errors exit 2.
        print(f"coloradar: error: {exc} (see: coloradar {args.command} --help)", file=sys.stderr)
        return 2
    except ColoradarError as exc:
        print(f"coloradar: error: {cli_wording(str(exc))}", file=sys.stderr)
        return 1
    except OSError as exc:
        # Every file coloradar reads or writes goes through a helper that raises a named error;
        # this is the net for what no helper saw (a disk failing mid-run...).
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"coloradar: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("coloradar: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
