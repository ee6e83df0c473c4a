"""Compiled loops of the shaping filters (:meth:`sonicspec.acoustics.bands.OctaveFilterBank.
shaping_spectra` and ``shaping_filters``), tens of thousands of rows per render job.

The log-magnitude and phase of a row are sums over the bands of ``log|g_b| · K_b(f)``; numpy
made two temporaries and two passes over the whole ``(rows, bins)`` array per band. Here a row
is summed band by band while it stays in cache, in the same order with the same separate
multiply and add (no ``fastmath``: nothing is reassociated or fused), so the sums are the same
bits as numpy's. Likewise the energy left after each sample of a filter is accumulated from
its end in numpy's ``cumsum`` order (one add per sample, in sequence)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def band_sums(logs: np.ndarray, level_basis: np.ndarray, phase_basis: np.ndarray,
              level: np.ndarray, phase: np.ndarray) -> None:
    """``level[r, k] = Σ_b logs[r, b] · level_basis[b, k]`` (and ``phase`` with
    ``phase_basis``), summed from band 0 up, each product rounded before it is added."""
    rows, bands = logs.shape
    bins = level_basis.shape[1]
    for r in range(rows):
        c = logs[r, 0]
        for k in range(bins):
            level[r, k] = c * level_basis[0, k]
            phase[r, k] = c * phase_basis[0, k]
        for b in range(1, bands):
            c = logs[r, b]
            for k in range(bins):
                level[r, k] = level[r, k] + c * level_basis[b, k]
                phase[r, k] = phase[r, k] + c * phase_basis[b, k]


@njit(cache=True, nogil=True)
def decayed_lengths(h: np.ndarray, tail_share: float, cap: int, out: np.ndarray) -> None:
    """``out[r]``: the samples of row ``r`` of ``h`` before all but ``tail_share`` of its
    energy has come (those with more than that share still to come), capped at ``cap``; 1
    for a silent row. The energy still to come is summed from the row's end, sample by
    sample, as ``numpy.cumsum`` of the reversed squares sums it."""
    rows, n = h.shape
    tail = np.empty(n)
    for r in range(rows):
        acc = 0.0
        for k in range(n - 1, -1, -1):
            if k == n - 1:
                acc = h[r, k] * h[r, k]
            else:
                acc = acc + h[r, k] * h[r, k]
            tail[k] = acc
        total = tail[0]
        if total <= 0:
            out[r] = 1
            continue
        limit = tail_share * total
        count = 0
        for k in range(n):
            if tail[k] > limit:
                count += 1
        out[r] = min(cap, count)
