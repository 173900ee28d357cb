"""Follow a run's output folder through ``process_run`` and count the modules it visits.

How it counts (the same rule before and after a refactor, so the figures compare):

1. A tiny synthetic run (tests/_synth.py: 2 cascade + 3 single-chip ADC frames) is processed
   with ``process_run(run, out, jobs=1)``, serially in this process, under ``sys.setprofile``.
2. A call is *about the folder* when one of its arguments carries the output folder: a path at
   or under ``out``, or an object, list or dict holding one (two levels deep: a list of
   ``RunTarget``, a job holding a ``ProcessedRun``).
3. A reader reads each function once: a call of a function already met (a loop's second turn,
   the next frame, a helper used again) is skipped with everything under it.
4. The *room* at any moment is the module of the innermost call about the folder; it is noted
   at every such call and return. Consecutive notes of the same module are one *stay*.

Printed: the walk of stays, stays per module, and the returns (stays beyond a module's first).

A second walk follows the folder *on disk*: the module whose code touches the file system for
the folder (a ``pathlib`` method on a path under ``out``, or a call of ``os``/``io``
``scandir, stat, open, unlink, replace, rename, mkdir, rmdir, chmod`` from a function about the
folder) is noted at each touch, with the same reading rule (each function once) and the same
collapsing into stays: it says how many modules hold knowledge of the folder's files and how
often the walk goes back and forth between them.

Run:  PYTHONPATH=src python benchmarks/count_folder_visits.py
"""

from __future__ import annotations

import collections
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def _carries(v, out: str, depth: int = 2) -> bool:
    if isinstance(v, str | os.PathLike):
        try:
            p = os.path.abspath(os.fspath(v))
        except TypeError:
            return False
        return p == out or p.startswith(out + os.sep)
    if depth == 0 or isinstance(v, int | float | bytes | type(None)):
        return False
    if isinstance(v, list | tuple | set | frozenset):
        return any(_carries(x, out, depth - 1) for x in list(v)[:8])
    if isinstance(v, dict):
        return any(_carries(x, out, depth - 1) for x in list(v.values())[:8])
    attrs = getattr(v, "__dict__", None)
    if attrs is None and hasattr(v, "__dataclass_fields__"):
        attrs = {k: getattr(v, k, None) for k in v.__dataclass_fields__}
    if isinstance(attrs, dict):
        return any(_carries(x, out, depth - 1) for x in attrs.values())
    return False


def main() -> None:
    from _synth import write_run
    from coloradar.batch.run_processing import process_run

    tmp = Path(tempfile.mkdtemp(prefix="visits_"))
    write_run(tmp)
    run = tmp / "12_21_2020_ec_hallways_run0"
    out = os.path.abspath(tmp / "out")
    pkg = str(Path(sys.modules["coloradar"].__file__).parent) + os.sep

    seen_edges: set = set()
    # Stack entries: (code, about-the-folder module or None, skipped)
    stack: list[tuple] = []
    rooms: list[str] = []
    disk: list[str] = []
    fs_methods = {"exists", "is_dir", "is_file", "stat", "unlink", "mkdir", "open", "read_text",
                  "write_text", "read_bytes", "write_bytes", "rename", "replace", "iterdir",
                  "rmdir", "touch", "lstat", "is_symlink"}
    fs_calls = {"scandir", "stat", "open", "unlink", "remove", "replace", "rename", "mkdir",
                "makedirs", "rmdir", "chmod", "listdir", "lstat"}

    def touch() -> None:
        for _code, _mod, skipped, pmod in reversed(stack):
            if pmod is None:
                continue
            if not skipped and (not disk or disk[-1] != pmod):
                disk.append(pmod)
                if os.environ.get("VISITS_DEBUG"):
                    print("touch", pmod, _code.co_name, file=sys.stderr)
            return

    def room() -> str | None:
        for _code, mod, skipped, _pmod in reversed(stack):
            if skipped:
                return None
            if mod:
                return mod
        return None

    def note() -> None:
        r = room()
        if r and (not rooms or rooms[-1] != r):
            rooms.append(r)

    def prof(frame, event, arg):
        if event == "call":
            code = frame.f_code
            parent_skipped = bool(stack) and stack[-1][2]
            if not code.co_filename.startswith(pkg):
                if (code.co_filename.endswith("pathlib.py") and code.co_name in fs_methods
                        and _carries(frame.f_locals.get("self"), out)):
                    touch()
                stack.append((code, None, parent_skipped, None))
                return
            skipped = parent_skipped or code in seen_edges
            seen_edges.add(code)
            n = code.co_argcount + code.co_kwonlyargcount
            n += bool(code.co_flags & 4) + bool(code.co_flags & 8)
            args = [frame.f_locals.get(a) for a in code.co_varnames[:n]]
            about = any(_carries(a, out) for a in args)
            mod = (code.co_filename[len(pkg):].removesuffix(".py").replace(os.sep, ".")
                   if about else None)
            stack.append((code, mod, skipped,
                          code.co_filename[len(pkg):].removesuffix(".py").replace(os.sep, ".")))
            if not skipped:
                note()
        elif event == "c_call":
            if (getattr(arg, "__name__", "") in fs_calls
                    and getattr(arg, "__module__", "") in ("posix", "os", "io", "_io", "builtins")
                    and next((e[1] for e in reversed(stack) if e[3] is not None), None)):
                touch()
        elif event == "return":
            if stack:
                stack.pop()
                note()

    sys.setprofile(prof)
    try:
        process_run(run, out, jobs=1, progress=False)
    finally:
        sys.setprofile(None)
    counts = collections.Counter(rooms)
    print("walk:", " -> ".join(rooms))
    print(f"{len(rooms)} stays in {len(counts)} modules, "
          f"{len(rooms) - len(counts)} returns to a module left before")
    for mod, n in counts.most_common():
        print(f"  {mod:32s} {n}")
    dcounts = collections.Counter(disk)
    print("on disk:", " -> ".join(disk))
    print(f"{len(disk)} stays in {len(dcounts)} modules touching the folder, "
          f"{len(disk) - len(dcounts)} returns to a module left before")
    for mod, n in dcounts.most_common():
        print(f"  {mod:32s} {n}")


if __name__ == "__main__":
    main()
