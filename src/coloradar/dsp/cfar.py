"""Stage 8a: constant-false-alarm-rate detection (CA, GO, SO, OS; 1D, 2D or 3D).

Every cell under test (CUT) is compared with ``α · Z``, where ``Z`` is a noise statistic of the
*training* cells — a box of half-size ``guard + train`` around the CUT minus the guard box of
half-size ``guard`` (per axis):

* ``ca``: mean of the N training cells;
* ``go`` / ``so``: greater / smaller of the means of the two halves of the training cells
  split along ``split_axis`` (cells at offset 0 along that axis belong to neither half);
* ``os``: the k-th smallest training cell.

``α`` comes from the requested false-alarm probability for noise whose cell power is a sum of
``looks`` independent unit exponentials (square-law detector; ``looks`` = the number of
channels summed non-coherently). For one look, with n cells per half (Gandhi & Kassam 1988;
Rohling 1983):

* CA: ``Pfa = (1 + α/N)^−N``  →  ``α = N·(Pfa^(−1/N) − 1)``;
* SO: ``Pfa = 2·Σ_{i<n} C(n−1+i, i)·(2 + α/n)^−(n+i)``;  GO: ``Pfa = 2(1 + α/n)^−n − Pfa_SO``;
* OS: ``Pfa = Π_{i<k} (N − i)/(N − i + α)``;

GO, SO and OS are solved for ``α`` numerically. For several looks CA is an F-distribution
quantile, ``Pfa = P(F(2L, 2NL) > α)``, and GO/SO/OS are integrated numerically.

**Correlated training cells.** Windowed FFT bins are correlated (Hann: adjacent powers have
correlation 0.44), so the mean of ``N`` training cells fluctuates more than that of ``N``
independent ones, and a threshold computed for ``N`` fires too often. For complex Gaussian
noise the powers of two bins ``Δ`` apart correlate by ``|ρ(Δ)|²``, ``ρ(Δ) = Σ w_k² e^{−j2πΔk/n}
/ Σ w_k²`` (``w`` the window, ``n`` the FFT length); the mean of the training set ``T`` then has
the variance of ``N_eff = N² / Σ_{i,j∈T} |ρ(i−j)|²`` independent cells
(:func:`effective_train_cells`), and CA/GO/SO thresholds use ``N_eff`` (a Gamma
approximation of the correlated mean, exact in its first two moments). ``looks`` and
``num_train`` may therefore be non-integer.

**Effective looks.** A sum of ``L`` channels' powers is an ``L``-look Gamma only where the
channels' noise is independent. Where the cells' power is partly common to all channels —
clutter and phase-noise skirts of strong returns reach every channel through the same
scatterers and the shared LO, so their level varies from cell to cell alike in all channels
(compound-Gaussian clutter: speckle times a texture) — the sum fluctuates more: with a mean
cross-channel power correlation ``ρ̄`` its variance is that of ``L/(1 + (L − 1)ρ̄)``
independent looks. :func:`effective_looks` measures the looks from the map itself, by the
method of moments (a Gamma matched in its first two moments, as Welch–Satterthwaite) on the
ratio of every cell to its CA noise estimate: the ratio is scale-free, so a noise floor that
changes with range does not count as texture, and cells far above any threshold of ``1 … L``
looks (returns) are left out. Where the excess comes from one component common to every
channel, the sum is ``λ₁E₁ + λ₂·Gamma(L − 1)`` (the channels' covariance's eigenvalues), whose
common look carries the tail: the looks are then lowered to match that tail at the requested
false-alarm probability.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import comb, prod
from typing import Literal, get_args

import numpy as np
from scipy import integrate, optimize, special, stats
from scipy.ndimage import correlate1d, median_filter, rank_filter

from ..errors import SettingsError

__all__ = [
    "CFAR_EDGES",
    "CFAR_KINDS",
    "CFARConfig",
    "CFAREdge",
    "CFARKind",
    "CFARResult",
    "cfar",
    "cfar_scale",
    "cfar_window",
    "effective_looks",
    "effective_train_cells",
    "false_alarm_rate",
    "power_correlation",
    "range_floor",
    "run_cfar",
]

CFARKind = Literal["ca", "go", "so", "os"]
"""Cell-averaging, greatest-of, smallest-of, ordered-statistic."""
CFAR_KINDS: tuple[CFARKind, ...] = get_args(CFARKind)
CFAREdge = Literal["wrap", "mirror", "reflect", "truncate"]
"""Edge handling of one axis (see :func:`cfar`)."""
CFAR_EDGES: tuple[CFAREdge, ...] = get_args(CFAREdge)
# name -> (scipy.ndimage mode, np.pad mode)
_MODES: dict[CFAREdge, tuple[str, Literal["wrap", "reflect", "symmetric", "constant"]]] = {
    "wrap": ("wrap", "wrap"), "mirror": ("mirror", "reflect"), "reflect": ("reflect", "symmetric"),
    "truncate": ("constant", "constant")}


@dataclass(frozen=True)
class CFARResult:
    """Outcome of :func:`cfar`.

    Attributes
    ----------
    detections
        bool, the map's shape: cells above threshold.
    threshold
        float64: ``scale · noise`` per cell.
    noise
        float64: the noise statistic ``Z`` per cell.
    scale
        The multiplier ``α`` (a per-cell map with ``mode="truncate"``).
    """

    detections: np.ndarray
    threshold: np.ndarray
    noise: np.ndarray
    scale: float | np.ndarray


def range_floor(power: np.ndarray, quantile: float = 0.25, width: int | None = None
                ) -> np.ndarray:
    """The noise floor of every range bin of a ``(doppler, range)`` power map, up to a common
    factor: the ``quantile`` of the bin's Doppler cells, median-filtered along range over
    ``width`` bins.

    Dividing the map's columns by it flattens the floor along range, so that a CFAR window
    which straddles a change of floor (the IF filters' skirts) compares like with like; the
    common factor does not matter, the CFAR's own estimate sets the level. A low quantile
    ignores the returns of a bin unless they fill ``1 − quantile`` of its cells. The floor's
    own scatter adds to the cells' and raises the false-alarm rate, most at high looks where
    the threshold is close to the mean: a quantile of ``n`` cells scatters by about
    ``1.36/√n`` of a cell's standard deviation (normal approximation at the lower quartile),
    and a running median over ``w`` bins divides that by ``√(2w/π)``, so ``width`` defaults to
    the smallest odd ``w`` with ``n·w ≥ 290``: scatter ≤ 0.1 of a cell's (on white noise the
    chain's false-alarm rate rises by about 10–25 %, docs/dsp.md). A running median keeps a
    monotonic slope of the floor as it is (a mean would blur it); a dip narrower than ``w/2``
    bins is partly filled.

    Parameters
    ----------
    power
        float ``(doppler, range)``, non-negative.
    quantile
        In (0, 1).
    width
        Odd number of range bins of the running median (1: none); None: from the Doppler
        bins, as above.

    Returns
    -------
    np.ndarray
        float64 ``(range,)``, positive (1 where a bin's quantile is 0).
    """
    x = np.asarray(power, dtype=np.float64)
    if x.ndim != 2 or not 0.0 < quantile < 1.0:
        raise SettingsError(f"range_floor wants a 2-D map and a quantile in (0, 1); got shape "
                            f"{x.shape} and {quantile!r}")
    nd = x.shape[0]
    w = int(width) if width is not None else 2 * int(np.ceil((290.0 / nd - 1.0) / 2.0)) + 1
    if w < 1 or w % 2 == 0:
        raise SettingsError(f"range_floor's width must be a positive odd number, got {width!r}")
    k = int(quantile * (nd - 1))
    floor = np.partition(x, k, axis=0)[k]
    if w > 1:
        floor = median_filter(floor, size=w, mode="nearest")
    return np.where(floor > 0, floor, 1.0)


def _per_axis(v: int | tuple[int, ...], ndim: int, what: str) -> tuple[int, ...]:
    t = tuple(int(x) for x in v) if isinstance(v, tuple | list | np.ndarray) else (int(v),) * ndim
    if len(t) != ndim or min(t) < 0:
        raise SettingsError(f"{what} must be a non-negative int or one per axis ({ndim}), got {v!r}")
    return t


def cfar_window(guard: tuple[int, ...], train: tuple[int, ...], split_axis: int = -1
                ) -> tuple[int, int]:
    """Training cells ``N`` in total and ``n`` in each GO/SO half for a window geometry."""
    ax = split_axis % len(guard)
    h = [g + t for g, t in zip(guard, train, strict=True)]
    outer = prod(2 * x + 1 for x in h)
    inner = prod(2 * g + 1 for g in guard)
    half_outer = prod(2 * x + 1 for i, x in enumerate(h) if i != ax) * h[ax]
    half_inner = prod(2 * g + 1 for i, g in enumerate(guard) if i != ax) * guard[ax]
    return outer - inner, half_outer - half_inner


def power_correlation(window: np.ndarray, fft_size: int, max_lag: int) -> np.ndarray:
    """Correlation of noise powers ``|ρ(Δ)|²`` of FFT bins ``Δ = 0 … max_lag`` apart.

    Parameters
    ----------
    window
        float ``(n,)``: the taper applied before the FFT (any scale).
    fft_size
        FFT length (≥ ``n``; zero padding makes neighbouring bins more alike).
    max_lag
        Largest lag returned.

    Returns
    -------
    numpy.ndarray
        float64 ``(max_lag + 1,)``, 1 at lag 0.
    """
    w2 = np.asarray(window, dtype=np.float64) ** 2
    k = np.arange(w2.size)
    lags = np.arange(max_lag + 1)
    rho = (w2[None, :] * np.exp(-2j * np.pi * lags[:, None] * k[None, :] / fft_size)).sum(1)
    return np.abs(rho / w2.sum()) ** 2


def effective_train_cells(guard: tuple[int, ...], train: tuple[int, ...],
                          correlation: tuple[np.ndarray, ...], split_axis: int = -1,
                          wrap: tuple[int | None, ...] | None = None) -> tuple[float, float]:
    """Independent-cell equivalents ``N_eff`` of the training set and of one GO/SO half.

    Parameters
    ----------
    guard, train
        Half-widths per axis.
    correlation
        Per axis, ``|ρ(Δ)|²`` for ``Δ = 0, 1, …`` (:func:`power_correlation`); lags beyond
        the array count as uncorrelated. The map's correlation is their product (separable
        windows).
    split_axis
        GO/SO split axis.
    wrap
        Per axis, the axis length when it wraps (circular lags), else None.

    Returns
    -------
    tuple
        ``(N_eff, n_eff)`` as floats (``N²/Σ_{i,j}|ρ_ij|²`` over all / one half's cells).
    """
    nd = len(guard)
    h = [g + t for g, t in zip(guard, train, strict=True)]
    grids = np.meshgrid(*[np.arange(-x, x + 1) for x in h], indexing="ij")
    offs = np.stack([gr.ravel() for gr in grids], axis=1)
    inner = np.all(np.abs(offs) <= np.asarray(guard), axis=1)
    ax = split_axis % nd
    wraps = wrap or (None,) * nd

    def n_eff(sel: np.ndarray) -> float:
        o = offs[sel]
        c = np.ones((len(o), len(o)))
        for a in range(nd):
            lag = np.abs(o[:, None, a] - o[None, :, a])
            period = wraps[a]
            if period:
                lag = np.minimum(lag, int(period) - lag)
            r = np.asarray(correlation[a], dtype=np.float64)
            c *= np.where(lag < r.size, r[np.minimum(lag, r.size - 1)], 0.0)
        return float(len(o) ** 2 / c.sum()) if len(o) else 0.0

    return n_eff(~inner), n_eff(~inner & (offs[:, ax] < 0))


def effective_looks(ratio: np.ndarray, num_train: float, max_looks: float,
                    pfa: float | None = None, trim_pfa: float = 1e-6) -> float:
    """Looks of a Gamma that matches the first two moments of noise cells' CFAR ratios (and,
    with ``pfa``, the tail of a sum with one common look at that probability).

    For cells of ``k``-look Gamma noise divided by a CA estimate with the variance of
    ``num_train`` independent cells (``Z ~ Gamma(n·k)/(n·k)``, independent of the cell),
    ``y = X/Z`` has ``E[y²]/E[y]² = (1 + 1/k)·(nk − 1)/(nk − 2)``; solved for ``k`` with the
    sample moments. Cells above the one-look CA threshold at ``trim_pfa`` are returns under any
    number of looks in ``[1, max_looks]`` and are left out (for noise of ``max_looks``
    independent looks that removes far fewer than ``trim_pfa`` of the cells: no bias).

    Parameters
    ----------
    ratio
        float ``(...)``: cell power over its CA noise estimate (non-finite values are skipped).
    num_train
        Independent-cell equivalent ``N_eff`` of the CA training set.
    max_looks
        Channels summed (the independent-noise looks): the upper bound.
    pfa
        Where given, the looks are lowered to those whose Gamma has the tail, at ``pfa``, of the
        sum that has the measured variance when its excess comes from one component common
        to every channel (amplitude correlation ``ρ``): ``λ₁E₁ + λ₂·Gamma(L − 1)`` with
        ``λ₁ = 1 + (L − 1)ρ``, ``λ₂ = 1 − ρ`` (the channels' covariance's eigenvalues). The
        common look carries that sum's tail, which a Gamma of the same variance under-states.
    trim_pfa
        False-alarm probability of the one-look threshold above which cells are left out.

    Returns
    -------
    float
        The looks, in ``[1, max_looks]``; ``max_looks`` with fewer than 100 cells.
    """
    n, top = float(num_train), float(max_looks)
    y = np.asarray(ratio, dtype=np.float64).ravel()
    trim = stats.f.isf(trim_pfa, 2.0, 2.0 * n)
    y = y[np.isfinite(y) & (y >= 0) & (y < trim)]
    if y.size < 100 or top <= 1.0:
        return max(top, 1.0)
    m1 = y.mean()
    if not m1 > 0:
        return top
    r = float(np.mean(np.square(y / m1)))

    def excess(k: float) -> float:              # model minus measured normalised 2nd moment
        return (1.0 + 1.0 / k) * (n * k - 1.0) / (n * k - 2.0) - r

    lo = max(1.0, 2.5 / n)
    if excess(top) >= 0:
        return top
    if excess(lo) <= 0:
        return lo
    k = float(optimize.brentq(excess, lo, top, xtol=1e-6))
    return k if pfa is None else _tail_looks(k, top, pfa)


def _tail_looks(k: float, L: float, pfa: float) -> float:
    """Looks ``≤ k`` whose Gamma (mean ``L``) exceeds the same level at ``pfa`` as the sum of
    ``L`` channels with a common component whose variance is that of ``k`` looks."""
    if k >= L or L < 2:
        return k
    rho = np.sqrt((L / k - 1.0) / (L - 1.0))         # k = L/(1 + (L − 1)ρ²)
    l1, l2, m = 1.0 + (L - 1.0) * rho, 1.0 - rho, L - 1.0

    def log_sf(t: float) -> float:       # P(λ₁E₁ + λ₂G(m) > t), both terms positive
        a = special.gammaincc(m, t / l2) if l2 > 0 else 0.0
        x = t * (1.0 / l2 - 1.0 / l1) if l2 > 0 else np.inf
        p_m = special.gammainc(m, x)
        b = np.exp(-t / l1 - m * np.log1p(-l2 / l1) + np.log(p_m)) if p_m > 0 else 0.0
        return float(np.log(a + b))

    hi = L
    while log_sf(hi) > np.log(pfa):
        hi *= 2.0
    t = optimize.brentq(lambda v: log_sf(v) - np.log(pfa), 0.0, hi, xtol=1e-9 * hi)

    def gap(kk: float) -> float:          # Gamma(kk) of mean L over the level, log
        return float(np.log(special.gammaincc(kk, kk * t / L)) - np.log(pfa))

    if gap(k) >= 0:
        return k
    if gap(1.0) <= 0:
        return 1.0
    return float(optimize.brentq(gap, 1.0, k, xtol=1e-6))


def _os_rank(rank: float | int, n: int) -> int:
    if isinstance(rank, (int, np.integer)) and not isinstance(rank, bool) and rank >= 1:
        k = int(rank)
    else:
        k = round(float(rank) * n)
    if not 1 <= k <= n:
        raise SettingsError(f"OS rank {rank!r} gives k = {k}, outside 1..{n} training cells")
    return k


def false_alarm_rate(kind: CFARKind, scale: float, num_train: float, *, rank: int = 0,
                     looks: float = 1, numeric: bool = False) -> float:
    """False-alarm probability of a CFAR with multiplier ``scale`` on noise-only cells.

    Parameters
    ----------
    kind
        ``"ca"``, ``"go"``, ``"so"`` or ``"os"``.
    scale
        ``α``.
    num_train
        ``N`` for CA and OS; cells per half ``n`` for GO and SO (may be an effective,
        non-integer count for CA/GO/SO).
    rank
        ``k`` (1-based) for OS.
    looks
        Unit exponentials summed per cell (1 = square-law single look; non-integer = Gamma).
    numeric
        Integrate numerically even where a closed form exists (to cross-check them).
    """
    a, n, L = float(scale), float(num_train), float(looks)
    if kind == "os":
        n = round(n)
    if L == 1 and not numeric and n == int(n):
        n = int(n)
        if kind == "ca":
            return float((1.0 + a / n) ** (-n))
        if kind in ("so", "go"):
            x = 2.0 + a / n
            so = 2.0 * sum(comb(n - 1 + i, i) * x ** (-(n + i)) for i in range(n))
            return float(so if kind == "so" else 2.0 * (1.0 + a / n) ** (-n) - so)
        if kind == "os":
            i = np.arange(rank)
            return float(np.prod((n - i) / (n - i + a)))
    if kind == "ca" and not numeric:
        return float(stats.f.sf(a, 2 * L, 2 * n * L))
    return _numeric_pfa(kind, a, n, rank, L)


def _numeric_pfa(kind: CFARKind, a: float, n: float, k: int, L: float) -> float:
    """``E[Q(L, α·Z)]`` over the distribution of the statistic ``Z`` (unit-exponential looks)."""
    if kind == "ca":                       # Z = mean of n cells: Gamma(nL, scale 1/n)
        g = stats.gamma(n * L, scale=1.0 / n)
        dens = g.pdf
    elif kind in ("go", "so"):             # Z = max/min of two half means
        g = stats.gamma(n * L, scale=1.0 / n)
        if kind == "so":
            def dens(z):
                return 2.0 * g.pdf(z) * g.sf(z)
        else:
            def dens(z):
                return 2.0 * g.pdf(z) * g.cdf(z)
    elif kind == "os":                     # Z = k-th smallest of n cells of Gamma(L)
        g = stats.gamma(L)
        n = int(n)
        logc = special.gammaln(n + 1) - special.gammaln(k) - special.gammaln(n - k + 1)

        def dens(z):
            return np.exp(logc + (k - 1) * g.logcdf(z) + (n - k) * g.logsf(z) + g.logpdf(z))
    else:
        raise SettingsError(f"unknown CFAR kind {kind!r}")
    lo, hi = g.ppf(1e-14) * 0.5, g.ppf(1 - 1e-14) * 2.0

    def integrand(z):
        return special.gammaincc(L, a * z) * dens(z)

    val, _ = integrate.quad(integrand, lo, hi, limit=400, epsabs=0.0, epsrel=1e-10,
                            points=[float(g.mean())])
    return float(val)


@lru_cache(maxsize=256)
def cfar_scale(kind: CFARKind, num_train: float, pfa: float, *, rank: int = 0,
               looks: float = 1) -> float:
    """The multiplier ``α`` that gives false-alarm probability ``pfa``.

    Parameters are as in :func:`false_alarm_rate` (``num_train`` = cells per half for GO/SO).
    """
    if kind not in CFAR_KINDS:
        raise SettingsError(f"unknown CFAR kind {kind!r}; expected one of {', '.join(CFAR_KINDS)}")
    if not 0.0 < pfa < 1.0:
        raise SettingsError(f"pfa must lie in (0, 1), got {pfa!r}")
    if num_train < 1:
        raise SettingsError("a CFAR window needs at least one training cell")
    n, L = float(num_train), float(looks)
    if kind == "os":
        n = round(n)
    if kind == "ca" and L == 1:
        return float(n * (pfa ** (-1.0 / n) - 1.0))
    if kind == "ca":
        return float(stats.f.isf(pfa, 2 * L, 2 * n * L))
    if kind == "os" and not 1 <= rank <= n:
        raise SettingsError(f"OS rank {rank} outside 1..{n}")

    def f(log_a: float) -> float:
        return np.log(false_alarm_rate(kind, np.exp(log_a), n, rank=rank, looks=L)) - np.log(pfa)

    hi = 1.0
    while f(hi) > 0:
        hi += 2.0
        if hi > 60:
            raise SettingsError(f"no {kind.upper()}-CFAR threshold reaches pfa={pfa} with "
                                f"{n} training cells")
    return float(np.exp(optimize.brentq(f, -30.0, hi, xtol=1e-12)))


def _box_sum(x: np.ndarray, lo: list[int], hi: list[int], modes: tuple[CFAREdge, ...]
             ) -> np.ndarray:
    """Sum of ``x`` over offsets ``lo[a] … hi[a]`` along every axis (separable, no cancellation)."""
    out = x
    for ax, (a, b, mode) in enumerate(zip(lo, hi, modes, strict=True)):
        r = max(abs(a), abs(b))
        k = np.zeros(2 * r + 1)
        k[a + r: b + r + 1] = 1.0
        out = correlate1d(out, k, axis=ax, mode=_MODES[mode][0])
    return out


def _ring_sum(x: np.ndarray, g: tuple[int, ...], h: tuple[int, ...], modes: tuple[CFAREdge, ...],
              side: int = 0, axis: int = 0) -> np.ndarray:
    """Sum over the training cells (side 0), or over one half of them along ``axis``
    (side −1: offsets −h…−1, side +1: offsets 1…h)."""
    lo_o, hi_o = [-v for v in h], list(h)
    lo_i, hi_i = [-v for v in g], list(g)
    if side < 0:
        hi_o[axis] = hi_i[axis] = -1
    elif side > 0:
        lo_o[axis] = lo_i[axis] = 1
    s = _box_sum(x, lo_o, hi_o, modes)
    if all(b >= a for a, b in zip(lo_i, hi_i, strict=True)):
        s = s - _box_sum(x, lo_i, hi_i, modes)
    return s


@dataclass(frozen=True)
class CFARConfig:
    """Everything a CFAR run needs besides the map (the parameters of :func:`cfar`, and
    ``cell_factor``); :func:`run_cfar` runs it.

    Attributes
    ----------
    kind, guard, train, pfa, rank, looks, mode, split_axis, excise
        As :func:`cfar`.
    cell_factor
        Independent-cell equivalent of one training cell (``N_eff/N`` from
        :func:`effective_train_cells` for maps with correlated cells); ``α`` is computed for
        ``cell_factor`` times the training cells used.
    """

    kind: CFARKind = "ca"
    guard: int | tuple[int, ...] = 1
    train: int | tuple[int, ...] = 8
    pfa: float = 1e-3
    rank: float | int = 0.75
    looks: float = 1
    mode: CFAREdge | tuple[CFAREdge, ...] = "wrap"
    split_axis: int = -1
    cell_factor: float = 1.0
    excise: bool = False


def cfar(power: np.ndarray, kind: CFARKind = "ca", guard: int | tuple[int, ...] = 1,
         train: int | tuple[int, ...] = 8, pfa: float = 1e-3, *, rank: float | int = 0.75,
         looks: float = 1, mode: CFAREdge | tuple[CFAREdge, ...] = "wrap", split_axis: int = -1,
         excise: bool = False) -> CFARResult:
    """Run a CFAR detector on a power map of any dimension (:func:`run_cfar` with a
    :class:`CFARConfig`, which also takes the correlated maps' ``cell_factor``).

    Parameters
    ----------
    power
        Real, non-negative map (square-law power), e.g. ``(doppler, range)``.
    kind
        ``"ca"``, ``"go"``, ``"so"`` or ``"os"``.
    guard, train
        Guard and training half-widths in cells, an int for every axis or one per axis.
    pfa
        Requested false-alarm probability per cell.
    rank
        OS only: k as a fraction of the training cells (0.75) or an int ≥ 1.
    looks
        Independent exponentials summed per cell (see the module notes).
    mode
        Edge handling per axis: ``"wrap"`` (circular, e.g. Doppler), ``"mirror"``
        (``d c b | a b c d``), ``"reflect"`` (``c b a | a b c d``) or ``"truncate"`` (CA/GO/SO
        only: training cells beyond the edge are left out, the estimate is the mean of those
        inside and ``α`` is computed for their number, so ``pfa`` holds at the edges too;
        mirrored cells repeat cells and make the estimate noisier than its count says).
    split_axis
        GO/SO: axis along which the training cells are split into two halves.
    excise
        CA/GO/SO: run twice; cells above the first pass's threshold are replaced by their
        first-pass noise estimate before the second. A strong target inside another cell's
        training window otherwise raises that cell's estimate by its power over ``N`` (a
        60 dB target in 132 cells: +39 dB) and masks weaker targets near it. On noise alone
        a fraction ``pfa`` of cells is replaced by a local mean, which leaves the false-alarm
        rate as it was.

    Returns
    -------
    CFARResult
    """
    return run_cfar(power, CFARConfig(kind, guard, train, pfa, rank, looks, mode, split_axis,
                                      1.0, excise))


def run_cfar(power: np.ndarray, config: CFARConfig) -> CFARResult:
    """:func:`cfar` of ``power`` with the settings of ``config``.

    Returns
    -------
    CFARResult
    """
    kind, guard, train, pfa, rank = (config.kind, config.guard, config.train, config.pfa,
                                     config.rank)
    looks, mode, split_axis = config.looks, config.mode, config.split_axis
    cell_factor, excise = config.cell_factor, config.excise
    x = np.asarray(power, dtype=np.float64)
    nd = x.ndim
    g, t = _per_axis(guard, nd, "guard"), _per_axis(train, nd, "train")
    modes = (mode,) * nd if isinstance(mode, str) else tuple(mode)
    if len(modes) != nd or any(m not in _MODES for m in modes):
        raise SettingsError(f"mode must be one of {', '.join(_MODES)} (or one per axis), got {mode!r}")
    h = tuple(a + b for a, b in zip(g, t, strict=True))
    for ax, m in enumerate(modes):
        if m != "wrap" and x.shape[ax] <= h[ax]:
            raise SettingsError(f"axis {ax} has {x.shape[ax]} cells, too few for a window of "
                                f"half-width {h[ax]} with mode {m!r}")
    n_all, n_half = cfar_window(g, t, split_axis)
    truncate = "truncate" in modes
    if truncate and kind == "os":
        raise SettingsError("mode 'truncate' is for CA/GO/SO; OS needs a full window "
                         "('mirror' or 'reflect')")
    if excise and kind != "os":
        once = CFARConfig(kind, g, t, pfa, rank, looks, modes, split_axis, cell_factor)
        first = run_cfar(x, once)
        if first.detections.any():
            x = np.where(first.detections, first.noise, x)
            res = run_cfar(x, once)
            power = np.asarray(power, dtype=np.float64)
            return CFARResult(power > res.threshold, res.threshold, res.noise, res.scale)
        return first
    alpha: float | np.ndarray
    count: float | np.ndarray
    if kind == "ca":
        if truncate:
            count = _truncated_counts(x.shape, g, h, modes, 0, 0)
            alpha = _truncated_alpha(kind, x.shape, g, h, modes, 0, cell_factor, pfa, looks)
        else:
            count = float(n_all)
            alpha = _alpha_for(kind, count, cell_factor, pfa, 0, looks)
        noise = _ring_sum(x, g, h, modes) / count
    elif kind in ("go", "so"):
        if n_half < 1:
            raise SettingsError("GO/SO-CFAR needs training cells on both sides of split_axis")
        ax = split_axis % nd
        c_lead = _truncated_counts(x.shape, g, h, modes, -1, ax) if truncate else float(n_half)
        c_lag = _truncated_counts(x.shape, g, h, modes, 1, ax) if truncate else float(n_half)
        lead = _ring_sum(x, g, h, modes, -1, ax) / np.maximum(c_lead, 1.0)
        lag = _ring_sum(x, g, h, modes, 1, ax) / np.maximum(c_lag, 1.0)
        noise = np.maximum(lead, lag) if kind == "go" else np.minimum(lead, lag)
        if truncate:
            # A cell whose half lies wholly beyond the edge (the last range bin) has only the
            # other: CA of that half (α to match, _truncated_alpha); an empty half's zero mean
            # would otherwise make SO fire on every such cell.
            noise = np.where(c_lag == 0, lead, np.where(c_lead == 0, lag, noise))
        # Unequal halves at an edge: the threshold of the smaller one (conservative for GO).
        alpha = (_truncated_alpha(kind, x.shape, g, h, modes, ax, cell_factor, pfa, looks)
                 if truncate else _alpha_for(kind, float(n_half), cell_factor, pfa, 0, looks))
    elif kind == "os":
        k = _os_rank(rank, n_all)
        fp = np.ones([2 * v + 1 for v in h], dtype=bool)
        fp[tuple(slice(v - gv, v + gv + 1) for v, gv in zip(h, g, strict=True))] = False
        padded = x
        for ax, m in enumerate(modes):
            pw = [(0, 0)] * nd
            pw[ax] = (h[ax], h[ax])
            padded = np.pad(padded, pw, mode=_MODES[m][1])
        # A leading unit axis keeps SciPy off its 1-D rank-filter fast path, which treats a
        # footprint with holes (the guard cells) as solid (seen with SciPy 1.17).
        full = rank_filter(padded[None], rank=k - 1, footprint=fp[None], mode="constant")[0]
        noise = full[tuple(slice(v, v + s) for v, s in zip(h, x.shape, strict=True))]
        alpha = cfar_scale("os", n_all, pfa, rank=k, looks=looks)
    else:
        raise SettingsError(f"unknown CFAR kind {kind!r}; expected one of {', '.join(CFAR_KINDS)}")
    threshold = alpha * noise
    return CFARResult(x > threshold, threshold, noise, alpha)


@lru_cache(maxsize=64)
def _truncated_counts(shape: tuple[int, ...], g: tuple[int, ...], h: tuple[int, ...],
                      modes: tuple[CFAREdge, ...], side: int, axis: int) -> np.ndarray:
    """Training cells of every cell of a map of ``shape`` with truncated edges (as
    :func:`_ring_sum` of ones; read-only, cached: every frame of a radar has the same map)."""
    out = _ring_sum(np.ones(shape), g, h, modes, side, axis)
    out.setflags(write=False)
    return out


@lru_cache(maxsize=64)
def _truncated_alpha(kind: str, shape: tuple[int, ...], g: tuple[int, ...], h: tuple[int, ...],
                     modes: tuple[CFAREdge, ...], axis: int, factor: float, pfa: float,
                     looks: float) -> np.ndarray:
    """Per-cell ``α`` of a CA (GO/SO: the smaller half along ``axis``) CFAR with truncated
    edges (read-only, cached)."""
    if kind == "ca":
        count = _truncated_counts(shape, g, h, modes, 0, 0)
        out = np.asarray(_alpha_for(kind, count, factor, pfa, 0, looks))
    else:
        lead = _truncated_counts(shape, g, h, modes, -1, axis)
        lag = _truncated_counts(shape, g, h, modes, 1, axis)
        one_sided = (lead == 0) | (lag == 0)
        out = np.asarray(_alpha_for(kind, np.minimum(lead, lag), factor, pfa, 0, looks))
        if one_sided.any():
            ca = np.asarray(_alpha_for("ca", np.maximum(lead, lag), factor, pfa, 0, looks))
            out = np.where(one_sided, ca, out)
    out.setflags(write=False)
    return out


def _alpha_for(kind: str, count: float | np.ndarray, factor: float, pfa: float, rank: int,
               looks: float) -> float | np.ndarray:
    """``α`` for ``count`` training cells (a scalar or a per-cell map of counts)."""
    if not isinstance(count, np.ndarray):
        return cfar_scale(kind, float(count) * factor, pfa, rank=rank, looks=looks)
    counts = np.rint(count).astype(np.int64)
    values, inverse = np.unique(counts, return_inverse=True)
    # (an edge cell's empty GO/SO half counts as one cell: a factor < 1 must not take it
    # below the one cell cfar_scale needs)
    table = np.array([cfar_scale(kind, max(float(v) * factor, 1.0), pfa, rank=rank, looks=looks)
                      for v in values])
    return table[inverse].reshape(counts.shape)
