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

``process`` runs three times: with the default settings, with ``--set engine=numpy`` (the numpy
engine beside the default numba one) and with ``--set near_field=true`` (the near-field focused
beams). Then the **DSP check** calls :class:`~coloradar.dsp.RadarProcessor` directly, each tree
in its own interpreter on the very same saved frames (synthesised once, by
``benchmarks/bench_dsp.py``'s ``frames``), for both radars, both engines and a table of setting
variants (:data:`DSP_VARIANTS`: every switch of the detection chain, Capon, the
disambiguated heatmap, overlap averaging, forced focusing), plus, for the cascade, frames of
exact spherical waves with the release calibration as it is (focusing on by ``"auto"``, as on
real frames; needs ``../shared/reference/coloradar_calib``). Each heatmap, point cloud,
``products`` pair and every field of ``detect`` must be the same array (dtype, shape, bytes).

Run:  python benchmarks/check_refactor_identical.py [--base main | --base-tree DIR]
      [--duration 1.5] [--frames 2] [--only all|cli|dsp] [--keep]
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

import numpy as np

HERE = Path(__file__).resolve().parents[1]
# Fields of process_report.json that vary from one run to the next whatever the code.
VARIABLE_REPORT_KEYS = {"seconds", "worker_seconds", "frames_per_second", "executor", "workers",
                        "started", "finished", "wall_seconds", "peak_memory"}


# Settings variants of the DSP check (each run with both engines); {} = the defaults.
DSP_VARIANTS: dict[str, dict] = {
    "default": {},
    "heatmap_unwrap": {"heatmap_unwrap": True},
    "capon": {"angle_method": "capon"},
    "one_peak": {"multi_peak": False, "angle_refine": False},
    "plain": {"noise_weighting": "off", "cfar_excision": False, "doppler_unwrap": 0.0,
              "sidelobe_guard": False, "beam_doppler": False, "peak_grouping": False},
    "os_cfar": {"cfar_kind": "os", "phase_centre": False},
    "average": {"overlap": "average", "coupling_domain": "calibrated"},
    "focused": {"near_field": True},
    "padded": {"range_fft_size": 512, "doppler_fft_size": 255, "dc_removal": False,
               "range_window": "blackman"},
}

# Run in each tree's interpreter: every variant's outputs of the saved frames into OUT.
DSP_SCRIPT = r"""
import sys, warnings
from pathlib import Path
import numpy as np
sys.path.insert(0, sys.argv[3])
import bench_dsp
from coloradar.dsp import RadarProcessor
from coloradar.dsp.heatmap import available_engines
inp, out, variants = Path(sys.argv[1]), Path(sys.argv[2]), eval(sys.argv[4])
calib_dir = Path(sys.argv[5])
engines = [e for e in ("numba", "numpy") if e in available_engines()]
def save(name, arr):
    np.save(out / f"{name}.npy", np.ascontiguousarray(arr), allow_pickle=False)
def run(tag, calib, frames, variants):
    for vname, kw in variants.items():
        for eng in engines:
            proc = RadarProcessor(calib, engine=eng, **kw)
            for i, adc in enumerate(frames):
                key = f"{tag}_{vname}_{eng}_{i}"
                save(key + "_heatmap", proc.heatmap(adc))
                save(key + "_pointcloud", proc.pointcloud(adc))
                hm, pc = proc.products(adc)
                save(key + "_products_heatmap", hm)
                save(key + "_products_pointcloud", pc)
                det = proc.detect(adc)
                for f in ("range_bin", "doppler_bin", "range", "range_rate", "azimuth",
                          "elevation", "xyz", "intensity", "power", "snr"):
                    save(f"{key}_detect_{f}", getattr(det, f))
                if det.alias is not None:
                    save(f"{key}_detect_alias", det.alias)
for name in ("cascade", "single_chip"):
    calib, _ = bench_dsp.calibration(name, calib_dir)
    frames = list(np.load(inp / f"{name}.npy"))
    run(name, calib, frames, variants)
    nf = inp / f"{name}_near.npy"
    if nf.exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from coloradar.calib import load_calibration
            rc = load_calibration(calib_dir).radar(name)
        run(name + "_near", rc, list(np.load(nf)), {"auto": {}, "capon": {"angle_method": "capon"}})
"""


def _dsp_inputs(folder: Path, n: int) -> None:
    """The DSP check's frames, synthesised once with this tree's bench_dsp (far-field frames of
    both radars; for a calibration with near-field phases, exact spherical waves)."""
    sys.path.insert(0, str(HERE / "benchmarks"))
    sys.path.insert(0, str(HERE / "src"))
    import bench_dsp
    folder.mkdir(parents=True)
    for name in ("cascade", "single_chip"):
        calib, _ = bench_dsp.calibration(name, bench_dsp.REAL_CALIB)
        np.save(folder / f"{name}.npy", np.stack(bench_dsp.frames(calib, n)))
        near = bench_dsp.near_field_frames(name, bench_dsp.REAL_CALIB, n)
        if near is not None:
            np.save(folder / f"{name}_near.npy", np.stack(near[1]))


def _run_dsp(tree: Path, inputs: Path, out: Path) -> None:
    import bench_dsp
    out.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(tree / "src"), PYTHONHASHSEED="0")
    proc = subprocess.run([sys.executable, "-c", DSP_SCRIPT, str(inputs), str(out),
                           str(HERE / "benchmarks"), repr(DSP_VARIANTS),
                           str(bench_dsp.REAL_CALIB)], env=env, capture_output=True, text=True)
    if proc.returncode:
        raise SystemExit(f"{tree}: DSP check failed ({proc.returncode}):\n{proc.stderr}")


def _compare_arrays(a: Path, b: Path) -> list[str]:
    """Saved arrays of the DSP check: same names, dtypes, shapes and bytes."""
    fa, fb = _files(a), _files(b)
    problems = [f"only in base: {n}" for n in sorted(set(fa) - set(fb))]
    problems += [f"only in new: {n}" for n in sorted(set(fb) - set(fa))]
    for name in sorted(set(fa) & set(fb)):
        x, y = np.load(fa[name]), np.load(fb[name])
        if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
            problems.append(f"differs: {name}")
    return problems


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


def _cli_outputs(trees: dict[str, Path], tmp: Path) -> None:
    """simulate, process (three settings, fresh and resumed), export and import in each tree."""
    for label, tree in trees.items():
        o = tmp / "o"
        o.mkdir()
        _run(tree, ["simulate", str(o / "sim"), "--duration", str(_cli_outputs.duration),
                    "--seed", "3", "--vicon", "--name", "run", "--quiet"], tmp)
        _move(o, tmp / label)
    src_run = tmp / "base" / "sim" / "run"
    for label, tree in trees.items():
        o = tmp / "o"
        o.mkdir()
        _run(tree, ["process", str(src_run), "--out", str(o / "process"), "--quiet"], tmp)
        for folder, setting in (("process_numpy", "engine=numpy"),
                                ("process_focused", "near_field=true")):
            _run(tree, ["process", str(src_run), "--out", str(o / folder), "--quiet",
                        "--set", setting], tmp)
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


_cli_outputs.duration = 1.5  # type: ignore[attr-defined]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="main", help="git revision of the base tree (default main)")
    ap.add_argument("--base-tree", type=Path, default=None,
                    help="a folder holding the base tree (src/ inside) instead of --base")
    ap.add_argument("--duration", type=float, default=1.5, help="simulated seconds (default 1.5)")
    ap.add_argument("--frames", type=int, default=2, help="frames per radar, DSP check")
    ap.add_argument("--only", choices=("all", "cli", "dsp"), default="all")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="coloradar_identical_"))
    base_tree = args.base_tree.resolve() if args.base_tree else tmp / "base_tree"
    if args.base_tree is None:
        subprocess.run(["git", "-C", str(HERE), "worktree", "add", "--detach", str(base_tree),
                        args.base], check=True, capture_output=True)
    base_name = str(args.base_tree) if args.base_tree else args.base
    trees = {"base": base_tree, "new": HERE}
    _cli_outputs.duration = args.duration  # type: ignore[attr-defined]
    try:
        problems: list[str] = []
        done = []
        if args.only in ("all", "cli"):
            _cli_outputs(trees, tmp)
            problems += _compare(tmp / "base", tmp / "new")
            done.append(f"{len(_files(tmp / 'base'))} files from simulate, process (default, "
                        "numpy engine, near-field focused; fresh and resumed), export (ros1, "
                        "ros2, hdf5) and import (ros1, ros2)")
        if args.only in ("all", "dsp"):
            _dsp_inputs(tmp / "dsp_in", args.frames)
            for label, tree in trees.items():
                _run_dsp(tree, tmp / "dsp_in", tmp / f"dsp_{label}")
            problems += _compare_arrays(tmp / "dsp_base", tmp / "dsp_new")
            done.append(f"{len(_files(tmp / 'dsp_base'))} arrays of RadarProcessor (both "
                        f"radars, engines {', '.join(_engines())}, {len(DSP_VARIANTS)} setting "
                        "variants, near-field frames with the release calibration)")
        if problems:
            print(f"{len(problems)} difference(s):")
            for p in problems:
                print("  " + p)
            return 1
        print(f"identical: {'; '.join(done)}; base {base_name}, new {HERE}")
        return 0
    finally:
        if args.base_tree is None:
            subprocess.run(["git", "-C", str(HERE), "worktree", "remove", "--force",
                            str(base_tree)], capture_output=True)
        if args.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


def _engines() -> list[str]:
    from coloradar.dsp.heatmap import available_engines
    return [e for e in ("numba", "numpy") if e in available_engines()]


if __name__ == "__main__":
    raise SystemExit(main())
