"""The numba engine where numba cannot cache (read-only install, no cache folder) and the
notice on the first compile. Each case runs a fresh interpreter on a copy of the package."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

SRC = Path(__file__).resolve().parents[1] / "src" / "coloradar"

# Build a processor, compute one heatmap with the default engine and check it against the
# numpy engine (an independent implementation of the same definition).
SCRIPT = """
import numpy as np
from coloradar.calib import preset_radar
from coloradar.dsp import RadarProcessor
calib = preset_radar("single_chip")
g = np.random.default_rng(0)
adc = (g.standard_normal(calib.frame_shape) + 1j * g.standard_normal(calib.frame_shape)).astype(
    np.complex64)
proc = RadarProcessor(calib)
fast, ref = proc.heatmap(adc), RadarProcessor(calib, engine="numpy").heatmap(adc)
assert np.allclose(fast[..., 0], ref[..., 0], rtol=2e-4, atol=0), "heatmaps differ"
print("engine", proc.cube.engine)
"""


def _copy_package(dst: Path, blocked_pycache: bool) -> Path:
    root = dst / "pkg"
    shutil.copytree(SRC, root / "coloradar",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    if blocked_pycache:
        # a *file* named __pycache__ beside the kernels: numba cannot make its in-tree cache
        # there even as root (for whom a read-only mode bit would not stop writes)
        # (in every folder that holds kernels: the package coloradar/dsp/_kernels)
        for folder in (root / "coloradar" / "dsp", root / "coloradar" / "dsp" / "_kernels"):
            (folder / "__pycache__").write_text("")
        for p in [*sorted(root.rglob("*"), reverse=True), root]:
            p.chmod(p.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    return root


def _run(pkg: Path, env_extra: dict[str, str]) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(pkg), PYTHONDONTWRITEBYTECODE="1", **env_extra)
    return subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True,
                          text=True, timeout=300)


def _make_writable(root: Path) -> None:
    for p in [root, *root.rglob("*")]:
        p.chmod(p.stat().st_mode | stat.S_IWUSR)


def test_no_writable_cache_folder_falls_back_with_one_warning(tmp_path):
    pkg = _copy_package(tmp_path, blocked_pycache=True)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    nowhere = str(blocker / "cache")           # below a regular file: cannot be created
    try:
        res = _run(pkg, {"NUMBA_CACHE_DIR": nowhere, "HOME": nowhere,
                         "XDG_CACHE_HOME": nowhere})
    finally:
        _make_writable(pkg)
    assert res.returncode == 0, res.stderr
    assert "engine numba" in res.stdout
    assert "Traceback" not in res.stderr
    assert res.stderr.count("no writable folder for its cache") == 1, res.stderr
    assert "NUMBA_CACHE_DIR" in res.stderr


def test_first_compile_is_announced_once(tmp_path):
    pkg = _copy_package(tmp_path, blocked_pycache=False)
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    first, second = _run(pkg, env), _run(pkg, env)
    for res in (first, second):
        assert res.returncode == 0, res.stderr
        assert "engine numba" in res.stdout
    assert first.stderr.count("compiling the numba DSP kernels") == 1, first.stderr
    assert "compiling" not in second.stderr, second.stderr       # loaded from the cache
    assert "warning" not in (first.stderr + second.stderr).lower()
