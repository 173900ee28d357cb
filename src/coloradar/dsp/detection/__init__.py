"""Detection: range–Doppler cube → points, one module per stage, composed by :class:`Detector`.

============  ===========================================================================
cfar_stage    detection statistic (channels whitened by their noise), CFAR, peak grouping
alias         the Doppler alias of each cell (TDM-MIMO range rates beyond ±v_max)
peaks         the angle peaks of each cell (Bartlett row profile or Capon spectrum)
resolve       Newton refinement; which secondary peaks are sources (several per cell)
guard         beam grouping over the 3 × 3 neighbourhood, range edge, sidelobe guard
points        range, range rate and position of each kept source
beams         steering, focusing and elevation search shared by the angle stages
detector      the composition
============  ===========================================================================

Each stage is a class built once per radar from the calibration and its settings group
(:mod:`coloradar.dsp.settings`), with typed inputs and outputs (:class:`CFARCells`,
:class:`Cells`, :class:`Peaks`, :class:`Sources`, :class:`~coloradar.dsp.detect.Detections`).
A new stage goes between two of these: it takes the output of the one before and gives the
input of the one after (docs/conventions.md §4).
"""

from __future__ import annotations

from .alias import AliasStage
from .beams import Beams
from .cfar_stage import CFARCells, CFARStage
from .detector import Detector
from .guard import Explainers, GuardStage, Sources
from .peaks import Cells, Peaks, PeakStage
from .points import PointStage
from .resolve import ResolveStage

__all__ = ["AliasStage", "Beams", "CFARCells", "CFARStage", "Cells", "Detector", "Explainers",
           "GuardStage", "PeakStage", "Peaks", "PointStage", "ResolveStage", "Sources"]
