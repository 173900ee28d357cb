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
from ._common import UsageError, cli_wording, did_you_mean

__all__ = ["build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    """argparse's parser with coloradar's one form of a usage error: one line naming the option
    as typed, ``coloradar: error: argument --stride: expected ... (see: coloradar odometry
    --help)``, exit 2; not the whole usage block (sub-commands inherit the class)."""

    def error(self, message: str):
        self.exit(2, f"coloradar: error: {message} (see: {self.prog} --help)\n")


def _new_parser() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction]:
    parser = _Parser(
        prog="coloradar",
        description="Read, process, simulate and evaluate ColoRadar radar data.")
    parser.add_argument("--version", action="version", version=f"coloradar {__version__}")
    return parser, parser.add_subparsers(dest="command", metavar="COMMAND")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with every sub-command of this package registered; with
    ``command``, only the module of that name when it registers that command (the others'
    imports, numba's and scipy.stats' among them, cost seconds a command does not need)."""
    parser, sub = _new_parser()
    from . import __path__ as pkg_path

    mods = sorted(m.name for m in pkgutil.iter_modules(pkg_path)
                  if not m.name.startswith("_") and m.name != "main")
    name = command.replace("-", "_") if command else None
    if name in mods:
        module = importlib.import_module(f"{__package__}.{name}")
        if hasattr(module, "register"):
            module.register(sub)
            if command in sub.choices:
                return parser
        parser, sub = _new_parser()  # the module registers another command: all of them
    for mod in mods:
        module = importlib.import_module(f"{__package__}.{mod}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def _commands(parser: argparse.ArgumentParser) -> list[str]:
    return [name for action in parser._subparsers._group_actions
            for name in getattr(action, "choices", None) or ()] if parser._subparsers else []


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 ok, 1 data error, 2 usage error)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv and not argv[0].startswith("-") else None
    parser = build_parser(command)
    choices = _commands(parser)
    if command is not None and command not in choices:
        hint = did_you_mean(command, choices)
        print(f"coloradar: error: unknown command {command!r}; {hint}(commands: "
              f"{', '.join(choices)}; see: coloradar --help)", file=sys.stderr)
        return 2
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
