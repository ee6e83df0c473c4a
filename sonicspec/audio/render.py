"""Moving-source rendering: a dry track through the RIRs along the source's path.

The recipe (SonicSet): RIRs ``h_0 … h_{N-1}`` at points along the path; at output sample ``t``
the source is at fractional RIR index ``p(t)``; with ``j = ⌊p⌋`` and ``α = p − j``

    y(t) = (1 − α(t)) · (s ∗ h_j)(t) + α(t) · (s ∗ h_{j+1})(t),

i.e. ``y(t) = Σ_j w_j(t) (s ∗ h_j)(t)`` with the hat weights ``w_j(t) = max(0, 1 − |p(t) − j|)``.
The output has the full reverberant tail, ``T + L − 1`` samples; during the tail (``t ≥ T``)
the weights hold those of the last input sample.

:func:`render_sample_crossfade` computes this block-wise: RIR ``j`` only matters where
``w_j > 0``, so only the input span that feeds those output samples is convolved with it (FFT),
weighted and added. The cost is about ``N·L + T`` samples of FFT work instead of the naive
``N·(T + L)`` (:func:`render_naive`, kept as the reference). Static sources are ``N = 1``: a
plain convolution.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import fftconvolve

from sonicspec.errors import AudioError


def _check(dry: np.ndarray, rirs: np.ndarray, position: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    dry = np.asarray(dry, dtype=np.float64)
    rirs = np.asarray(rirs, dtype=np.float64)
    position = np.asarray(position, dtype=np.float64)
    if dry.ndim != 1 or dry.size == 0:
        raise AudioError(f"dry: expected a mono track (T,), got shape {dry.shape}")
    if rirs.ndim != 3 or 0 in rirs.shape:
        raise AudioError(f"rirs: expected (N points, C channels, L samples), got {rirs.shape}")
    if position.shape != dry.shape:
        raise AudioError(f"path_position: expected one position per dry sample {dry.shape}, "
                         f"got {position.shape}")
    for name, x in (("dry", dry), ("rirs", rirs), ("path_position", position)):
        if not np.all(np.isfinite(x)):
            raise AudioError(f"{name}: expected finite values, got NaN or infinity")
    n = rirs.shape[0]
    if position.min() < 0 or position.max() > n - 1:
        raise AudioError(f"path_position: expected values in [0, {n - 1}] (RIR indices), got "
                         f"[{position.min():g}, {position.max():g}]")
    return dry, rirs, position


def _weights_track(position: np.ndarray, tail: int) -> np.ndarray:
    """p(t) over the whole output: the input's positions, then the last one held."""
    return np.concatenate([position, np.full(tail, position[-1])])


def render_naive(dry: np.ndarray, rirs: np.ndarray, path_position: np.ndarray) -> np.ndarray:
    """Reference: convolve the whole track with every RIR, then blend, ``(C, T + L − 1)``."""
    dry, rirs, position = _check(dry, rirs, path_position)
    n, c, length = rirs.shape
    p = _weights_track(position, length - 1)
    out = np.zeros((c, dry.size + length - 1))
    for j in range(n):
        w = np.maximum(0.0, 1.0 - np.abs(p - j))
        if np.any(w):
            out += w * fftconvolve(dry[None, :], rirs[j], axes=-1)
    return out


def render_sample_crossfade(dry: np.ndarray, rirs: np.ndarray, path_position: np.ndarray
                            ) -> np.ndarray:
    """The recipe's crossfade, block-wise (see the module docstring), ``(C, T + L − 1)``."""
    dry, rirs, position = _check(dry, rirs, path_position)
    n, c, length = rirs.shape
    total = dry.size + length - 1
    p = _weights_track(position, length - 1)
    out = np.zeros((c, total))
    lo = np.minimum(np.floor(p).astype(np.int64), n - 1)
    # First and last output sample at each integer part of p (one pass, not one per RIR):
    # RIR j has weight where floor(p) is j - 1 or j.
    t = np.arange(total)
    first = np.full(n + 1, total)
    last = np.full(n + 1, -1)
    np.minimum.at(first, lo, t)
    np.maximum.at(last, lo, t)
    for j in range(n):
        prev = max(j - 1, 0)
        t0 = int(min(first[prev], first[j]))
        t1 = int(max(last[prev], last[j]))
        if t1 < t0:
            continue
        w = np.maximum(0.0, 1.0 - np.abs(p[t0:t1 + 1] - j))
        # Input samples that reach outputs t0..t1 through an L-sample RIR.
        k0, k1 = max(0, t0 - length + 1), min(dry.size, t1 + 1)
        if k0 >= k1 or not np.any(w):
            continue
        part = fftconvolve(dry[None, k0:k1], rirs[j], axes=-1)  # output index k0 + m
        a, b = t0 - k0, min(t1 - k0 + 1, part.shape[-1])
        out[:, t0:k0 + b] += w[:b - a] * part[:, a:b]
    return out


def path_position_from_distances(rir_distances_m: np.ndarray, n_samples: int,
                                 active: tuple[int, int] | None = None,
                                 speed_m_s: float | None = None,
                                 sample_rate_hz: float = 16000.0) -> np.ndarray:
    """Fractional RIR index per sample for a walk along RIR points at known path distances.

    With ``speed_m_s`` None the walk spans the ``active`` sample range (default: the whole
    clip) at constant speed, as the recipe sets the speed so the path spans the clip; with a
    speed the source walks from the start of ``active`` until the path ends. Before and after
    the walk the position holds.
    """
    d = np.asarray(rir_distances_m, dtype=np.float64)
    if d.ndim != 1 or d.size == 0 or np.any(np.diff(d) < 0):
        raise AudioError("rir_distances_m: expected non-decreasing distances along the path")
    start, end = active if active is not None else (0, n_samples)
    if not 0 <= start < end <= n_samples:
        raise AudioError(f"active: expected 0 <= start < end <= {n_samples}, got {active}")
    t = np.arange(n_samples, dtype=np.float64)
    if d.size == 1 or d[-1] == 0:
        return np.zeros(n_samples)
    if speed_m_s is None:
        travelled = np.clip((t - start) / max(end - 1 - start, 1), 0.0, 1.0) * d[-1]
    else:
        if not (math.isfinite(speed_m_s) and speed_m_s > 0):
            raise AudioError(f"speed_m_s: expected > 0, got {speed_m_s!r}")
        travelled = np.clip((t - start) / sample_rate_hz * speed_m_s, 0.0, d[-1])
    return np.interp(travelled, d, np.arange(d.size, dtype=np.float64))
