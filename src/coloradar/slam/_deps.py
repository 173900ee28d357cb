"""The optional libraries of :mod:`coloradar.slam` (the ``[slam]`` extra), imported on demand."""

from __future__ import annotations

from types import ModuleType

from ..errors import MissingDependencyError

__all__ = ["gtsam", "small_gicp"]

_HINT = "pip install 'coloradar[slam]'"


def gtsam() -> ModuleType:
    """The ``gtsam`` module (pose graph), or :class:`MissingDependencyError` naming the extra."""
    try:
        import gtsam as mod
    except ImportError:
        raise MissingDependencyError(f"radar SLAM's pose graph needs GTSAM: {_HINT}") from None
    return mod


def small_gicp() -> ModuleType:
    """The ``small_gicp`` module (registration), or :class:`MissingDependencyError` naming the
    extra."""
    try:
        import small_gicp as mod
    except ImportError:
        raise MissingDependencyError(f"radar SLAM's registration needs small_gicp: {_HINT}") from None
    return mod
