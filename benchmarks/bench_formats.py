"""Reading ADC frames: coloradar against bare ``np.fromfile`` on the same files, in one run.

    python benchmarks/bench_formats.py [--frames 20]

Prints milliseconds per frame for: np.fromfile of the int16 file (the floor), np.fromfile plus
the int16 -> complex64 conversion every user needs, coloradar.formats.read_adc, the same frame
through a Sequence from a folder, and from a zip (stored, read in place).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

import coloradar as cr
from coloradar import formats as fm
from coloradar.calib import preset_calibration, write_calibration


def _best_ms(fn, paths, repeat=3):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for p in paths:
            fn(p)
        best = min(best, (time.perf_counter() - t0) / len(paths))
    return best * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args()
    cal = preset_calibration()
    shape = cal.cascade.frame_shape
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        run = root / "run0"
        data = run / "cascade" / "adc_samples" / "data"
        paths = []
        for i in range(args.frames):
            raw = rng.integers(-2000, 2000, int(np.prod(shape)) * 2, dtype=np.int16)
            p = data / f"frame_{i}.bin"
            fm.atomic_write_bytes(p, raw.tobytes())
            paths.append(p)
        fm.write_timestamps(run / "cascade" / "adc_samples" / "timestamps.txt",
                            1.6e9 + np.arange(args.frames) / 5.0)
        write_calibration(cal, root / "calib")
        with zipfile.ZipFile(root / "run0z.zip", "w", zipfile.ZIP_STORED) as zf:
            for p in run.rglob("*"):
                zf.write(p, p.relative_to(run).as_posix())
        seq_dir = cr.open_sequence(run).cascade.adc
        seq_zip = cr.open_sequence(root / "run0z.zip", calib=root / "calib").cascade.adc
        idx = list(range(args.frames))

        def fromfile_complex(p):
            return np.fromfile(p, dtype="<i2").astype(np.float32).view(np.complex64).reshape(shape)

        rows = [
            ("np.fromfile int16 (floor)", _best_ms(lambda p: np.fromfile(p, dtype="<i2"), paths)),
            ("np.fromfile + complex64", _best_ms(fromfile_complex, paths)),
            ("formats.read_adc", _best_ms(lambda p: fm.read_adc(p, shape), paths)),
            ("Sequence, folder", _best_ms(seq_dir.read, idx)),
            ("Sequence, zip (stored)", _best_ms(seq_zip.read, idx)),
        ]
    print(f"cascade ADC frame {shape}, {fm.adc_nbytes(shape):,} bytes, {args.frames} frames (best of 3)")
    base = rows[1][1]
    for name, ms in rows:
        print(f"  {name:<28}{ms:8.2f} ms/frame   {ms / base:5.2f}x np.fromfile+complex64")


if __name__ == "__main__":
    main()
