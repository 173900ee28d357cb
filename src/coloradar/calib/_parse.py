"""Small parsing helpers shared by the calibration readers."""

from __future__ import annotations

import math

import numpy as np

from .._arrays import readonly  # noqa: F401  (re-exported for the calib modules)
from ..errors import CalibrationError


def strip_comment(line: str) -> str:
    return line.split("#", 1)[0].strip()


def key_values(text: str, name: str, sep: str | None = None) -> dict[str, list[str]]:
    """Parse ``key value…`` (or ``key<sep>value``) lines; comments after ``#``; blank lines skipped.

    A repeated key is an error; values keep their tokens.
    """
    out: dict[str, list[str]] = {}
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = strip_comment(raw)
        if not line:
            continue
        if sep is None:
            parts = line.split()
            key, vals = parts[0], parts[1:]
        else:
            if sep not in line:
                raise CalibrationError(f"{name}, line {lineno}: expected 'key{sep}value', got {line[:60]!r}")
            key, _, rest = line.partition(sep)
            key, vals = key.strip(), [rest.strip()]
        if key in out:
            raise CalibrationError(f"{name}, line {lineno}: key {key!r} appears twice")
        out[key] = vals
    return out


def get_number(kv: dict[str, list[str]], key: str, name: str, kind: type = float):
    if key not in kv:
        raise CalibrationError(f"{name}: missing key {key!r} (present: {', '.join(sorted(kv))})")
    vals = kv[key]
    if len(vals) != 1:
        raise CalibrationError(f"{name}: key {key!r} should have one value, has {len(vals)}")
    try:
        v = float(vals[0])
    except ValueError:
        raise CalibrationError(f"{name}: key {key!r} should be a number, got {vals[0]!r}") from None
    if not math.isfinite(v):
        # NaN passes every comparison check downstream and turns into NaN heatmaps.
        raise CalibrationError(f"{name}: key {key!r} should be a finite number, got {vals[0]!r}")
    if kind is int:
        if v != int(v):
            raise CalibrationError(f"{name}: key {key!r} should be an integer, got {vals[0]!r}")
        return int(v)
    return v


def get_floats(kv: dict[str, list[str]], key: str, name: str) -> np.ndarray:
    if key not in kv:
        raise CalibrationError(f"{name}: missing key {key!r}")
    try:
        values = np.array([float(v) for v in kv[key]], dtype=np.float64)
    except ValueError:
        raise CalibrationError(f"{name}: key {key!r} should be a list of numbers") from None
    check_finite(values, name, key)
    return values


def check_finite(values: np.ndarray, name: str, what: str) -> None:
    """Refuse NaN or infinite entries of ``values`` (read from file ``name``, as ``what``)."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise CalibrationError(f"{name}: {what} should hold finite numbers; entry {int(bad[0])} "
                               f"is {values.ravel()[bad[0]].item()} ({bad.size} such entries)")
