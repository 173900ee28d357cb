"""Check that a refactor changed no output: ``simulate``, ``process``, ``export`` (ROS 1, ROS 2 and
HDF5) and ``import`` run with two source trees on the same inputs must write the same bytes.

The base tree is a ``git worktree`` of ``--base`` (default ``main``) checked out under a temporary
folder; the new tree is this checkout. Each command runs as ``python -m coloradar ...`` with
``PYTHONPATH`` pointing at the tree's ``src``. ``process``, ``export`` and ``import`` read the run
(and bag) the *base* tree wrote, so that every command is compared on the very same input.

Every output file is compared byte for byte, except an ``export --format hdf5`` file, whose groups,
datasets (dtype, shape, every value) and attributes are compared instead (HDF5 records object
creation times in the file), and the fields of ``process_report.json`` that are
inherently variable — wall-clock and per-process values: ``seconds``, ``worker_seconds``,
``frames_per_second``, ``executor`` (names the pool), ``workers`` (``host:pid`` → peak memory) and
the ``started``/``finished`` dates — which are removed from both reports before they are compared
(every other field of the report, frames done/skipped/failed included, must match). Both trees
write into the same scratch path (then moved aside), so that paths recorded in files agree.

Run:  python benchmarks/check_refactor_identical.py [--base main] [--duration 1.5] [--keep]
Exit status 0 when everything is identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
# Fields of process_report.json that vary from one run to the next whatever the code.
VARIABLE_REPORT_KEYS = {"seconds", "worker_seconds", "frames_per_second", "executor", "workers",
                        "started", "finished", "wall_seconds", "peak_memory"}


def _run(tree: Path, args: list[str], cwd: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(tree / "src"), PYTHONHASHSEED="0")
    proc = subprocess.run([sys.executable, "-m", "coloradar", *args], cwd=cwd, env=env,
                          capture_output=True, text=True)
    if proc.returncode not in (0,):
        raise SystemExit(f"{tree}: coloradar {' '.join(args)} failed ({proc.returncode}):\n"
                         f"{proc.stdout}\n{proc.stderr}")


def _move(scratch: Path, dest: Path) -> None:
    """Move everything under ``scratch`` into ``dest`` and remove ``scratch``."""
    dest.mkdir(exist_ok=True)
    for p in scratch.iterdir():
        p.rename(dest / p.name)
    scratch.rmdir()


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k not in VARIABLE_REPORT_KEYS}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def _same_h5(a: Path, b: Path) -> bool:
    """Same groups, datasets (dtype, shape, values) and attributes. HDF5 stores object creation
    times in the file, so its bytes differ from one write to the next whatever the code."""
    import h5py
    import numpy as np

    def items(f) -> dict:
        out: dict = {}
        f.visititems(lambda n, o: out.__setitem__(n, o))
        return out

    def same_attrs(x, y) -> bool:
        return set(x.attrs) == set(y.attrs) and all(
            np.array_equal(np.asarray(x.attrs[k]), np.asarray(y.attrs[k])) for k in x.attrs)

    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        ia, ib = items(fa), items(fb)
        if set(ia) != set(ib) or not same_attrs(fa, fb):
            return False
        for n, oa in ia.items():
            ob = ib[n]
            if not same_attrs(oa, ob) or isinstance(oa, h5py.Dataset) != isinstance(ob, h5py.Dataset):
                return False
            if isinstance(oa, h5py.Dataset) and not (
                    oa.dtype == ob.dtype and oa.shape == ob.shape
                    and np.array_equal(oa[()], ob[()], equal_nan=oa.dtype.kind == "f")):
                return False
    return True


def _files(root: Path) -> dict[str, Path]:
    return {str(p.relative_to(root)): p for p in sorted(root.rglob("*")) if p.is_file()}


def _compare(a: Path, b: Path) -> list[str]:
    fa, fb = _files(a), _files(b)
    problems = [f"only in base: {n}" for n in sorted(set(fa) - set(fb))]
    problems += [f"only in new: {n}" for n in sorted(set(fb) - set(fa))]
    for name in sorted(set(fa) & set(fb)):
        if name.endswith(".h5"):
            if not _same_h5(fa[name], fb[name]):
                problems.append(f"differs (datasets or attributes): {name}")
        elif Path(name).name == "process_report.json":
            ja, jb = (_strip(json.loads(p.read_text())) for p in (fa[name], fb[name]))
            if ja != jb:
                problems.append(f"differs (beyond wall-clock fields): {name}")
        elif not filecmp.cmp(fa[name], fb[name], shallow=False):
            problems.append(f"differs: {name}")
    return problems


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="main", help="git revision of the base tree (default main)")
    ap.add_argument("--duration", type=float, default=1.5, help="simulated seconds (default 1.5)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="coloradar_identical_"))
    base_tree = tmp / "base_tree"
    subprocess.run(["git", "-C", str(HERE), "worktree", "add", "--detach", str(base_tree),
                    args.base], check=True, capture_output=True)
    trees = {"base": base_tree, "new": HERE}
    try:
        for label, tree in trees.items():
            o = tmp / "o"
            o.mkdir()
            _run(tree, ["simulate", str(o / "sim"), "--duration", str(args.duration),
                        "--seed", "3", "--vicon", "--name", "run", "--quiet"], tmp)
            _move(o, tmp / label)
        src_run = tmp / "base" / "sim" / "run"
        for label, tree in trees.items():
            o = tmp / "o"
            o.mkdir()
            _run(tree, ["process", str(src_run), "--out", str(o / "process"), "--quiet"], tmp)
            # A resume over complete output (nothing to do) must also write the same files.
            _run(tree, ["process", str(src_run), "--out", str(o / "process_resume"), "--quiet",
                        "--frames", "0:3"], tmp)
            _run(tree, ["process", str(src_run), "--out", str(o / "process_resume"), "--quiet"],
                 tmp)
            for fmt, name in (("ros1", "run.bag"), ("ros2", "run_ros2"), ("hdf5", "run.h5")):
                _run(tree, ["export", str(src_run), str(o / "export" / name), "--format", fmt,
                            *(["--radar-points", "auto"] if fmt != "hdf5" else []), "--quiet"],
                     tmp)
            _move(o, tmp / label)
        for label, tree in trees.items():
            o = tmp / "o"
            o.mkdir()
            for name in ("run.bag", "run_ros2"):
                _run(tree, ["import", str(tmp / "base" / "export" / name),
                            str(o / "import" / name.replace(".", "_")), "--quiet"], tmp)
            _move(o, tmp / label)
        problems = _compare(tmp / "base", tmp / "new")
        n = len(_files(tmp / "base"))
        if problems:
            print(f"{len(problems)} difference(s) among {n} files:")
            for p in problems:
                print("  " + p)
            return 1
        print(f"identical: {n} files from simulate, process (fresh and resumed), export "
              f"(ros1, ros2, hdf5) and import (ros1, ros2); base {args.base}, new {HERE}")
        return 0
    finally:
        subprocess.run(["git", "-C", str(HERE), "worktree", "remove", "--force", str(base_tree)],
                       capture_output=True)
        if args.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    raise SystemExit(main())
