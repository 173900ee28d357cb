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

    def room() -> str | None:
        for _code, mod, skipped in reversed(stack):
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
                stack.append((code, None, parent_skipped))
                return
            skipped = parent_skipped or code in seen_edges
            seen_edges.add(code)
            n = code.co_argcount + code.co_kwonlyargcount
            n += bool(code.co_flags & 4) + bool(code.co_flags & 8)
            args = [frame.f_locals.get(a) for a in code.co_varnames[:n]]
            about = any(_carries(a, out) for a in args)
            mod = (code.co_filename[len(pkg):].removesuffix(".py").replace(os.sep, ".")
                   if about else None)
            stack.append((code, mod, skipped))
            if not skipped:
                note()
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


if __name__ == "__main__":
    main()
