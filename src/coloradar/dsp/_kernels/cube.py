"""Compiled kernels of the cube stage (:mod:`coloradar.dsp.stages.cube`): the range pass's
coupling, DC removal, calibration and windows, and the channels' ``|·|²``."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._jit import _FM, _Announced, _jit

__all__ = ['power', 'prepare_chirps']


@_jit(nogil=True, fastmath={"contract"})
def prepare_chirps(adc: Any, channels: Any, coupling: Any, gain: Any, chirp_weight: Any,
                   dc_removal: bool, out: Any) -> None:  # pragma: no cover - compiled
    """``out[k, c, :ns] = (adc − coupling − mean_n(adc − coupling)) · gain · w[c]`` of channel
    ``channels[k]``.

    All complex arrays are passed as float32 views (re, im interleaved along the last axis),
    which lets LLVM vectorise the loops. Two passes over each chirp (its mean, then the
    result) replace four numpy passes over the frame; samples beyond ``ns`` (zero padding)
    are left untouched. ``adc`` is
    ``(tx, rx, chirp, 2·ns)``; ``channels`` int ``(K,)`` the flat ``tx·num_rx + rx``
    indices to prepare (all, or only those a heatmap reads); ``out`` ``(K, chirp, 2·nfft)``.
    ``coupling`` is ``(tx, rx, 2·ns)`` or empty (no coupling); ``gain`` ``(tx, rx, 2·ns)``
    (calibration × range window); ``chirp_weight`` ``(chirps,)`` (Doppler window × (−1)^c).
    """
    nrx, nc, ns2 = adc.shape[1], adc.shape[2], adc.shape[3]
    ns = ns2 // 2
    has_c = coupling.size > 0
    for k in range(channels.size):
        t, r = channels[k] // nrx, channels[k] % nrx
        # the coupling's own mean over samples, once per channel: mean(x − c) = mean(x) − mean(c)
        cmr = 0.0
        cmi = 0.0
        if has_c and dc_removal:
            for n in range(ns):
                cmr += coupling[t, r, 2 * n]
                cmi += coupling[t, r, 2 * n + 1]
        for c in range(nc):
            # two passes over the chirp: its mean, then (x − c − mean)·gain·w straight into out
            mr = np.float32(0.0)
            mi = np.float32(0.0)
            if dc_removal:
                # four partial sums per part: one running float64 sum is a chain of
                # dependent adds (latency-bound, most of this kernel's time); four chains
                # overlap. float64 throughout, so the float32 mean is the same but for
                # the rare sum that lies on a float32 rounding boundary.
                s0r = s1r = s2r = s3r = 0.0
                s0i = s1i = s2i = s3i = 0.0
                n4 = ns - ns % 4
                for n in range(0, 2 * n4, 8):
                    s0r += adc[t, r, c, n]
                    s0i += adc[t, r, c, n + 1]
                    s1r += adc[t, r, c, n + 2]
                    s1i += adc[t, r, c, n + 3]
                    s2r += adc[t, r, c, n + 4]
                    s2i += adc[t, r, c, n + 5]
                    s3r += adc[t, r, c, n + 6]
                    s3i += adc[t, r, c, n + 7]
                for n in range(n4, ns):
                    s0r += adc[t, r, c, 2 * n]
                    s0i += adc[t, r, c, 2 * n + 1]
                sr = (s0r + s1r) + (s2r + s3r)
                si = (s0i + s1i) + (s2i + s3i)
                mr = np.float32((sr - cmr) / ns)
                mi = np.float32((si - cmi) / ns)
            w = chirp_weight[c]
            if has_c:
                for n in range(ns):
                    vr = adc[t, r, c, 2 * n] - coupling[t, r, 2 * n] - mr
                    vi = adc[t, r, c, 2 * n + 1] - coupling[t, r, 2 * n + 1] - mi
                    gr = gain[t, r, 2 * n] * w
                    gi = gain[t, r, 2 * n + 1] * w
                    out[k, c, 2 * n] = vr * gr - vi * gi
                    out[k, c, 2 * n + 1] = vr * gi + vi * gr
            else:
                for n in range(ns):
                    vr = adc[t, r, c, 2 * n] - mr
                    vi = adc[t, r, c, 2 * n + 1] - mi
                    gr = gain[t, r, 2 * n] * w
                    gi = gain[t, r, 2 * n + 1] * w
                    out[k, c, 2 * n] = vr * gr - vi * gi
                    out[k, c, 2 * n + 1] = vr * gi + vi * gr




@_jit(nogil=True, fastmath=_FM)
def power(values: Any, out: Any) -> None:  # pragma: no cover - compiled
    """``out[i] = re² + im²`` of complex values given as interleaved float32 ``(2N,)``;
    ``out`` float32 ``(N,)`` (``|·|²`` without numpy's ``hypot`` and a second pass)."""
    for i in range(out.size):
        a = values[2 * i]
        b = values[2 * i + 1]
        out[i] = a * a + b * b


power = _Announced(power)
prepare_chirps = _Announced(prepare_chirps)
