"""Run splits for training: a stable hash per run (see :mod:`coloradar.dataset.splits`)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from ..dataset.splits import named_split, named_splits, stable_split

__all__ = ["named_split", "named_splits", "split_runs"]


def split_runs(runs: Iterable[str], fractions: Mapping[str, float] | None = None,
               seed: int = 0) -> dict[str, list[str]]:
    """Split run names into named parts by a stable hash of each name and ``seed``.

    Splits are by run, never by frame: neighbouring frames of one run are nearly identical, so
    a frame-level split would leak. Each run's part depends only on its own name, the
    fractions and the seed (:func:`coloradar.dataset.splits.stable_split`), so adding a run to
    the dataset moves no other run, on every machine. Part sizes follow the fractions on
    average only; a part with a positive share that gets no run (a one-run dataset, say) is
    returned empty **and** said with a :class:`~coloradar.DataWarning`, never dropped.

    Parameters
    ----------
    runs
        Run names.
    fractions
        Part name -> share (normalised); default ``{"train": 0.8, "val": 0.1, "test": 0.1}``.
    seed
        Any integer.

    Returns
    -------
    dict[str, list[str]]
        Every part name -> sorted run names; every run in exactly one part.
    """
    return stable_split(runs, fractions, seed)
