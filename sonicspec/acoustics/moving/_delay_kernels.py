"""Compiled loops of the time-varying delay (:func:`sonicspec.acoustics.moving.delays.render_path`).

The same sums as the vectorised form it replaced (issue 18: ~20x slower than a crossfade),
in one pass over the output: for each output sample ``j``, the emission index ``u(j)`` heard
then (linear interpolation of the arrival times, which grow monotonically, so a pointer walks
them once), the ``2·half`` taps of the Kaiser-windowed sinc around it, read from a table with
linear interpolation (``TABLE_STEPS`` points per sample: error < 1e-6 of a tap), times the
path gain at ``u`` and the arrival density at ``j``. The table is stored phase by phase (the
``2·half`` taps of one fractional part in a row), so one output sample is two short dot
products over contiguous memory (3.7x the first loop, which looked each tap up on its own)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TABLE_STEPS = 1024


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def accumulate_path(x: np.ndarray, tau: np.ndarray, density: np.ndarray, amp: np.ndarray,
                    phase: np.ndarray, slope: np.ndarray, out: np.ndarray) -> None:
    """Add one path to ``out``: ``x`` emitted at samples ``k`` arrives at ``tau[k]``
    (increasing), with gain ``amp[k]`` and arrival density ``density[k]``.

    ``phase[p, t]`` is the windowed sinc's tap ``t`` (offsets ``1 − half … half`` from
    ``floor(u)``) at the fractional part ``p / TABLE_STEPS`` of ``u``, ``slope[p]`` the step
    to ``phase[p + 1]`` (``moving._sinc_table``): the taps of one output sample are a row, so
    the two dot products with the ``2·half`` input samples run over contiguous memory (and
    vectorise: ``reassoc`` only reorders their sums, ~1e-16).
    """
    n_out = out.size
    n = x.size
    taps = phase.shape[1]
    half = taps // 2
    k = 0
    for j in range(max(0, math.ceil(tau[0] - half)), min(n_out, math.floor(tau[n - 1] + half) + 1)):
        if j <= tau[0]:
            u = 0.0
            d = density[0]
        elif j >= tau[n - 1]:
            u = n - 1.0
            d = density[n - 1]
        else:
            while tau[k + 1] < j:
                k += 1
            f = (j - tau[k]) / (tau[k + 1] - tau[k])
            u = k + f
            d = density[k] + f * (density[k + 1] - density[k])
        ku = int(u)
        fu = u - ku
        pos = fu * TABLE_STEPS
        p = int(pos)
        r = pos - p
        first = ku + 1 - half
        acc0 = 0.0
        acc1 = 0.0
        if first >= 0 and first + taps <= n:
            for t in range(taps):
                acc0 += x[first + t] * phase[p, t]
                acc1 += x[first + t] * slope[p, t]
        else:  # the first and last samples: taps outside the signal read nothing
            for t in range(max(0, -first), min(taps, n - first)):
                acc0 += x[first + t] * phase[p, t]
                acc1 += x[first + t] * slope[p, t]
        heard = (acc0 + r * acc1) * d
        a = amp[ku] if ku >= n - 1 else amp[ku] + fu * (amp[ku + 1] - amp[ku])
        out[j] += heard * a


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def accumulate_channels(x: np.ndarray, tau: np.ndarray, density: np.ndarray, amp: np.ndarray,
                        phase: np.ndarray, slope: np.ndarray, out: np.ndarray) -> None:
    """:func:`accumulate_path` for channels that hear one path through the same arrivals
    and differ only in gain (ambisonic channels; a sphere-head ear and its shadowed part):
    ``amp[k, c]`` the gain of channel ``c``, ``out`` ``(C, n_out)``. The taps are summed
    once per output sample, not once per channel. (The loop is accumulate_path's, written
    out again: as a shared numba function it ran 5x slower, no longer vectorised.)"""
    n_out = out.shape[1]
    n = x.size
    taps = phase.shape[1]
    half = taps // 2
    k = 0
    for j in range(max(0, math.ceil(tau[0] - half)), min(n_out, math.floor(tau[n - 1] + half) + 1)):
        if j <= tau[0]:
            u = 0.0
            d = density[0]
        elif j >= tau[n - 1]:
            u = n - 1.0
            d = density[n - 1]
        else:
            while tau[k + 1] < j:
                k += 1
            f = (j - tau[k]) / (tau[k + 1] - tau[k])
            u = k + f
            d = density[k] + f * (density[k + 1] - density[k])
        ku = int(u)
        fu = u - ku
        pos = fu * TABLE_STEPS
        p = int(pos)
        r = pos - p
        first = ku + 1 - half
        acc0 = 0.0
        acc1 = 0.0
        if first >= 0 and first + taps <= n:
            for t in range(taps):
                acc0 += x[first + t] * phase[p, t]
                acc1 += x[first + t] * slope[p, t]
        else:  # the first and last samples: taps outside the signal read nothing
            for t in range(max(0, -first), min(taps, n - first)):
                acc0 += x[first + t] * phase[p, t]
                acc1 += x[first + t] * slope[p, t]
        heard = (acc0 + r * acc1) * d
        if ku >= n - 1:
            for c in range(out.shape[0]):
                out[c, j] += heard * amp[ku, c]
        else:
            for c in range(out.shape[0]):
                out[c, j] += heard * (amp[ku, c] + fu * (amp[ku + 1, c] - amp[ku, c]))


@njit(cache=True, nogil=True)
def fixed_receiver_arrivals(track: np.ndarray, receiver: np.ndarray, fs: float, c: float,
                            extra_s: np.ndarray, tau: np.ndarray, r: np.ndarray) -> None:
    """Arrival (output samples) ``tau[k] = k + (r_k / c + extra_s[k]) · fs`` and distance
    ``r[k]`` of each emission from ``track[k]`` to a receiver that does not move (the
    retarded-time equation is then explicit); ``extra_s`` of length 1 is one offset for all."""
    one = extra_s.size == 1
    for k in range(track.shape[0]):
        dx = track[k, 0] - receiver[0]
        dy = track[k, 1] - receiver[1]
        dz = track[k, 2] - receiver[2]
        r[k] = math.sqrt(dx * dx + dy * dy + dz * dz)
        tau[k] = k + (r[k] / c + (extra_s[0] if one else extra_s[k])) * fs


@njit(cache=True, nogil=True)
def gradient_inverse(tau: np.ndarray, out: np.ndarray) -> None:
    """``1 / numpy.gradient(tau)`` (central differences inside, one-sided at the ends)."""
    n = tau.size
    out[0] = 1.0 / (tau[1] - tau[0])
    out[n - 1] = 1.0 / (tau[n - 1] - tau[n - 2])
    for k in range(1, n - 1):
        out[k] = 2.0 / (tau[k + 1] - tau[k - 1])


@njit(cache=True, nogil=True)
def image_directions(track: np.ndarray, image: np.ndarray, mirror: np.ndarray,
                     out: np.ndarray) -> None:
    """``out[k] = (track[k] − image) / |track[k] − image| @ mirror``: a path's direction of
    arrival at the microphone at each emission, the direction its image sees the source in
    mapped back by the path's mirrors, on one thread (numpy's ``(T, 3) @ (3, 3)`` goes to
    BLAS, whose threads fight the build's other jobs: 240 ms a path on a loaded machine,
    this 4 ms)."""
    for k in range(track.shape[0]):
        dx = track[k, 0] - image[0]
        dy = track[k, 1] - image[1]
        dz = track[k, 2] - image[2]
        inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
        for i in range(3):
            out[k, i] = (dx * mirror[0, i] + dy * mirror[1, i] + dz * mirror[2, i]) * inv
