"""Run splits that do not move: stable hash assignment and the named splits of published work.

A run is assigned to a part by a hash of its name and a seed alone, so adding or removing a run
never moves another run between parts (what a train/test split across dataset versions needs).
Named splits (the run lists that published work on ColoRadar trained or evaluated on) are
shipped as data in ``named_splits.json`` beside this module, each with its source.
"""

from __future__ import annotations

import fnmatch
import hashlib
import json
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources

from ..errors import DataWarning, SettingsError

__all__ = ["NamedSplit", "named_split", "named_splits", "resolve_runs", "select_runs", "stable_split"]

DEFAULT_FRACTIONS: dict[str, float] = {"train": 0.8, "val": 0.1, "test": 0.1}


def _unit_hash(name: str, seed: int) -> float:
    """A number in [0, 1) fixed by ``name`` and ``seed`` (SHA-256, the same on every machine)."""
    digest = hashlib.sha256(f"{int(seed)}\x00{name}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2.0**64


def stable_split(runs: Iterable[str], fractions: Mapping[str, float] | None = None,
                 seed: int = 0) -> dict[str, list[str]]:
    """Assign run names to named parts by a stable hash of each name and ``seed``.

    Each run draws a number ``u`` in [0, 1) from SHA-256 of the seed and its name, and goes to
    the part whose interval of the cumulative (normalised) fractions holds ``u``. A run's part
    depends on nothing but its own name, the fractions and the seed: adding a run to the
    dataset moves no other run. The price is that part sizes follow the fractions only on
    average (a binomial draw), not exactly.

    Parameters
    ----------
    runs
        Run names (duplicates are ignored).
    fractions
        Part name -> share, normalised to sum 1; default ``{"train": 0.8, "val": 0.1,
        "test": 0.1}``. The order of the parts fixes the order of the intervals.
    seed
        Any integer; a different seed gives an independent assignment.

    Returns
    -------
    dict[str, list[str]]
        Every part name of ``fractions`` (empty parts too) -> sorted run names; every run in
        exactly one part. A part with a positive share that receives no run gives a
        :class:`~coloradar.DataWarning` naming it.

    Raises
    ------
    SettingsError
        Fractions that are negative, not finite or sum to zero.
    """
    fr = dict(DEFAULT_FRACTIONS if fractions is None else fractions)
    values = [float(v) for v in fr.values()]
    if not fr or any(not (v >= 0) or v == float("inf") for v in values) or sum(values) <= 0:
        raise SettingsError(f"fractions must be finite, non-negative and sum to more than 0, got {fr}")
    total = sum(values)
    edges, acc = [], 0.0
    for v in values:
        acc += v / total
        edges.append(acc)
    out: dict[str, list[str]] = {name: [] for name in fr}
    keys = list(fr)
    for run in sorted(set(runs)):
        u = _unit_hash(run, seed)
        # The last part with a positive share closes the interval at 1 (rounding of the sum).
        j = next((i for i, e in enumerate(edges) if u < e and values[i] > 0),
                 max(i for i, v in enumerate(values) if v > 0))
        out[keys[j]].append(run)
    empty = [k for k, v in zip(keys, values, strict=True) if v > 0 and not out[k]]
    if empty and out and any(out.values()):
        warnings.warn(f"split of {sum(map(len, out.values()))} run(s): no run fell into "
                      f"{', '.join(empty)} (assignment is by a stable hash, so small datasets "
                      "can leave a part empty; name the runs of each part to control it)",
                      DataWarning, stacklevel=2)
    return out


@dataclass(frozen=True)
class NamedSplit:
    """A run list used in published work on ColoRadar.

    Attributes
    ----------
    name
        Key in the registry (``named_split(name)``).
    parts
        Part name -> run names, as the source lists them.
    source
        The publication or repository the lists come from (citation text with a URL).
    note
        What was checked, and anything a user should know (e.g. runs the source names that
        the public release spells differently).
    """

    name: str
    parts: dict[str, tuple[str, ...]]
    source: str
    note: str = ""


@cache
def _registry() -> dict[str, NamedSplit]:
    text = resources.files(__package__).joinpath("named_splits.json").read_text(encoding="utf-8")
    raw = json.loads(text)
    return {name: NamedSplit(name=name,
                             parts={k: tuple(v) for k, v in entry["parts"].items()},
                             source=entry["source"], note=entry.get("note", ""))
            for name, entry in raw.get("splits", {}).items()}


def named_splits() -> list[str]:
    """The names of the shipped named splits, sorted."""
    return sorted(_registry())


def named_split(name: str) -> NamedSplit:
    """The named split ``name`` (see :func:`named_splits`).

    Raises
    ------
    SettingsError
        An unknown name; the message lists the known ones.
    """
    reg = _registry()
    if name not in reg:
        known = ", ".join(sorted(reg)) or "none shipped"
        raise SettingsError(f"unknown split {name!r}; known splits: {known}")
    return reg[name]


def select_runs(available: Iterable[str], patterns: str | Iterable[str] | None) -> list[str]:
    """Run names of ``available`` matching any of ``patterns`` (comma-separated glob patterns).

    ``None`` or an empty selection selects every run. A pattern that matches no run raises, so
    that a typo is never a silently smaller benchmark.

    Raises
    ------
    SettingsError
        A pattern that matches none of ``available``.
    """
    names = sorted(set(available))
    if patterns is None:
        return names
    pats = [p.strip() for p in (patterns.split(",") if isinstance(patterns, str) else patterns)]
    pats = [p for p in pats if p]
    if not pats:
        return names
    chosen: set[str] = set()
    for p in pats:
        hit = fnmatch.filter(names, p)
        if not hit:
            raise SettingsError(f"no run matches {p!r}; runs: {', '.join(names) or 'none'}")
        chosen.update(hit)
    return sorted(chosen)


_DATE_PREFIX = re.compile(r"^\d{1,2}_\d{1,2}_\d{4}_")


def resolve_runs(names: Iterable[str], available: Iterable[str]) -> dict[str, str | None]:
    """Match run names as a source spells them to the runs of a dataset.

    Published lists often drop the release's recording-date prefix (``ec_hallways_run0`` for
    ``12_21_2020_ec_hallways_run0``). A name matches a run of ``available`` with the same name,
    or else the one run that is ``<mm>_<dd>_<yyyy>_`` followed by the name.

    Returns
    -------
    dict[str, str | None]
        Source name -> the dataset's run name, None where the dataset has no such run.

    Raises
    ------
    SettingsError
        A name that matches more than one run (the same run recorded on two dates).
    """
    have = sorted(set(available))
    by_suffix: dict[str, list[str]] = {}
    for run in have:
        m = _DATE_PREFIX.match(run)
        if m:
            by_suffix.setdefault(run[m.end():], []).append(run)
    out: dict[str, str | None] = {}
    for name in names:
        if name in have:
            out[name] = name
            continue
        hits = by_suffix.get(name, [])
        if len(hits) > 1:
            raise SettingsError(f"run {name!r} matches several runs: {', '.join(hits)}")
        out[name] = hits[0] if hits else None
    return out
