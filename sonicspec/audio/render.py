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

Three interpolations (:data:`INTERPOLATIONS`, chosen by :func:`render_moving`) differ in *which
time* picks the RIR. Write ``h(p) = Σ_j w_j(p) h_j`` for the RIR linearly interpolated at
fractional index ``p`` (interpolating RIRs in time and interpolating their spectra are the same
linear operation).

``sample_crossfade`` (SonicSet, above) — *reception time*: ``y(t) = Σ_k s(k) h(p(t))(t − k)``;
every output sample hears the whole past through the RIR of the position at ``t``.

``stft_crossfade`` (DCASE2022 SELD generator, SpatialScaper) — *emission time*, at frame rate.
The dry track is cut into overlapping frames ``x_m(k) = a(k − s_m) s(k) / A(k)`` with a
window ``a`` of ``frame_size`` samples, frame starts ``s_m`` every ``hop`` samples, and
``A(k) = Σ_m a(k − s_m)`` so that ``Σ_m x_m = s`` exactly (a partition of unity; with
``a(n) = sin²(π(n + ½)/F)`` and ``hop = F/2``, ``A ≡ 1``). Each frame is filtered by the RIR
interpolated at the position of the frame centre, ``p_m = p(s_m + (F − 1)/2)``, and the
filtered frames overlap-add with their full ``F + L − 1``-sample tails:

    y = Σ_m x_m ∗ h(p_m) = Σ_j (v_j · s) ∗ h_j,   v_j(k) = Σ_m w_j(p_m) a(k − s_m) / A(k).

In the STFT domain this is "multiply each frame's spectrum by the interpolated RIR spectrum,
inverse-transform and overlap-add", with the FFT long enough (``≥ F + L − 1``) that the RIR
is not cut to one frame. The peers approximate the same operator by a convolutive transfer
function (the RIR's own STFT frames, FFT of ``2F``, each RIR frame weighted by the
interpolation weights of the input frame it multiplies), which keeps only the band-to-same-band
terms of the exact STFT-domain filter. The right-hand form above is exact and cheap: ``v_j``
is non-zero only near RIR ``j``, so each RIR convolves only its own stretch of input. The
weights ``v_j`` are smooth (Hann-interpolated frame weights), so the output has no clicks;
``Σ_j v_j = 1``, so a constant position gives ``s ∗ h(p)`` exactly, as ``sample_crossfade``
does. A moving source differs from ``sample_crossfade`` in when the position is read: when the
sound left the source, not when it arrives (earlier by the path's travel time, up to the RIR
length for late reverberation); with dense RIRs and walking speeds the two are close.
``frame_size = hop = 1`` is the per-sample emission-time crossfade.

``segment_ola`` (gpuRIR ``simulateTrajectory``) — emission time, no interpolation: the dry
track is cut where the rounded position ``r(k) = ⌊p(k) + ½⌋`` changes, and each segment is
convolved with its own RIR, the full tails overlap-added: ``y = Σ_j (1[r = j] · s) ∗ h_j``.
Cheapest, but the output jumps at segment boundaries (the direct sound's delay and level
step from one RIR to the next: gaps or doubled samples of about ``Δr/c``).

:func:`split_rir` windows RIRs into their direct-path and early parts; rendering those with
the same position track gives the direct-only and early-reverberation training targets.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import fftconvolve

from sonicspec.errors import AudioError

#: Interpolation names accepted by :func:`render_moving` (the spec option's values).
INTERPOLATIONS = ("sample_crossfade", "stft_crossfade", "segment_ola")

# Length of the half-Hann fade that ends a split_rir window (ms): long enough not to click.
_FADE_MS = 1.0


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


def walk_index(rir_distances_m, n_samples: int, active: tuple[int, int] | None,
               speed_m_s: float | None, sample_rate_hz: float) -> np.ndarray:
    """Where a source is at each sample: a fractional index into its RIR points, as every
    renderer and the exported position track read it (one point: 0 throughout)."""
    d = np.asarray(rir_distances_m, dtype=np.float64)
    if d.size < 2:
        return np.zeros(n_samples)
    return path_position_from_distances(d, n_samples, active, speed_m_s, sample_rate_hz)


def _first_last(index: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """First and last position in ``index`` (values in [0, n)) of each value; (n, -1) if absent."""
    at = np.arange(index.size)
    first = np.full(n, index.size)
    last = np.full(n, -1)
    np.minimum.at(first, index, at)
    np.maximum.at(last, index, at)
    return first, last


def _hat(p: np.ndarray, j: int) -> np.ndarray:
    return np.maximum(0.0, 1.0 - np.abs(p - j))


def render_stft_crossfade(dry: np.ndarray, rirs: np.ndarray, path_position: np.ndarray, *,
                          frame_size: int = 512, hop: int | None = None) -> np.ndarray:
    """Frame-wise RIR interpolation at emission time (DCASE/SpatialScaper), ``(C, T + L − 1)``.

    Each ``frame_size``-sample frame of the dry track (Hann-type window, ``hop`` apart,
    default ``frame_size // 2``) is convolved with the RIR interpolated at the frame centre's
    position and the full tails overlap-add (module docstring). Exact: no RIR is cut to a
    frame, a constant position gives the plain convolution with the interpolated RIR.
    """
    dry, rirs, position = _check(dry, rirs, path_position)
    if isinstance(frame_size, bool) or not isinstance(frame_size, (int, np.integer)) \
            or frame_size < 1:
        raise AudioError(f"frame_size: expected an integer >= 1 (samples), got {frame_size!r}")
    frame = int(frame_size)
    step = max(1, frame // 2) if hop is None else hop
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) \
            or not 1 <= step <= frame:
        raise AudioError(f"hop: expected an integer in [1, frame_size={frame}] (samples), "
                         f"got {hop!r}")
    step = int(step)
    n, c, length = rirs.shape
    size = dry.size
    q = -(-frame // step)  # frames covering each sample
    blocks = -(-size // step)
    # The window, zero-padded to q hops; sin²(π(n + ½)/F) never vanishes inside the frame, so
    # every sample is covered (A > 0) for any hop <= frame.
    window = np.zeros(q * step)
    window[:frame] = np.sin(np.pi * (np.arange(frame) + 0.5) / frame) ** 2
    pieces = window.reshape(q, step)
    norm = np.zeros(step)
    for r in range(q):
        norm += pieces[r]
    # Frame m starts at (m − q + 1)·hop; block b (samples b·hop …) is covered by frames b … b+q−1.
    starts = (np.arange(blocks + q - 1) - q + 1) * step
    p_frame = np.interp(starts + (frame - 1) / 2, np.arange(size, dtype=np.float64), position)
    lo = np.minimum(np.floor(p_frame).astype(np.int64), n - 1)
    first, last = _first_last(lo, n)
    out = np.zeros((c, size + length - 1))
    for j in range(n):
        m0 = int(min(first[max(j - 1, 0)], first[j]))
        m1 = int(max(last[max(j - 1, 0)], last[j]))
        if m1 < m0:
            continue
        b0, b1 = max(0, m0 - q + 1), min(blocks - 1, m1)
        w = _hat(p_frame[b0:b1 + q], j)  # frames b0 … b1 + q − 1
        if not np.any(w):
            continue
        nb = b1 - b0 + 1
        v = np.zeros((nb, step))
        for r in range(q):  # frame b + q − 1 − r holds block b at its r-th hop
            v += w[q - 1 - r:q - 1 - r + nb, None] * pieces[r]
        k0, k1 = b0 * step, min(size, (b1 + 1) * step)
        u = dry[k0:k1] * (v / norm).ravel()[:k1 - k0]
        part = fftconvolve(u[None, :], rirs[j], axes=-1)
        out[:, k0:k0 + part.shape[-1]] += part
    return out


def render_segment_ola(dry: np.ndarray, rirs: np.ndarray, path_position: np.ndarray
                       ) -> np.ndarray:
    """One RIR per segment, full tails overlap-added (gpuRIR), ``(C, T + L − 1)``.

    Segment ``j`` is the dry samples whose position rounds (half up) to ``j``. The output
    jumps at segment boundaries; a static source is the plain convolution.
    """
    dry, rirs, position = _check(dry, rirs, path_position)
    n, c, length = rirs.shape
    nearest = np.minimum(np.floor(position + 0.5).astype(np.int64), n - 1)
    first, last = _first_last(nearest, n)
    out = np.zeros((c, dry.size + length - 1))
    for j in range(n):
        k0, k1 = int(first[j]), int(last[j]) + 1
        if k1 <= k0:
            continue
        u = np.where(nearest[k0:k1] == j, dry[k0:k1], 0.0)
        part = fftconvolve(u[None, :], rirs[j], axes=-1)
        out[:, k0:k0 + part.shape[-1]] += part
    return out


def render_moving(dry: np.ndarray, rirs: np.ndarray, path_position: np.ndarray,
                  interpolation: str = "sample_crossfade") -> np.ndarray:
    """Render a source along its path with one of :data:`INTERPOLATIONS`, ``(C, T + L − 1)``.

    Parameters
    ----------
    dry : (T,) float
        The dry (anechoic) track.
    rirs : (N, C, L) float
        RIRs at N points along the path, C channels each.
    path_position : (T,) float
        Fractional RIR index of the source at each dry sample, in ``[0, N − 1]``.
    interpolation : str
        ``sample_crossfade`` (default), ``stft_crossfade`` or ``segment_ola``; see the module
        docstring for the maths of each.
    """
    if interpolation == "sample_crossfade":
        return render_sample_crossfade(dry, rirs, path_position)
    if interpolation == "stft_crossfade":
        return render_stft_crossfade(dry, rirs, path_position)
    if interpolation == "segment_ola":
        return render_segment_ola(dry, rirs, path_position)
    raise AudioError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
                     f"got {interpolation!r}")


EARLY_MS = 50.0
"""The early part (the ``early`` target): what arrives within this long after the direct
sound."""


def split_rir(rirs: np.ndarray, direct_delay_samples: np.ndarray, sample_rate_hz: int, *,
              direct_window_ms: float = 2.5, early_ms: float = EARLY_MS
              ) -> tuple[np.ndarray, np.ndarray]:
    """Direct-path and early parts of RIRs, the targets for dereverberation-style training.

    For RIR ``j`` with direct sound at ``d_j`` samples (fractional allowed), a part of length
    ``W`` ms keeps every sample before ``d_j + W − 1 ms`` unchanged, fades out over the
    last millisecond with a half-Hann (a hard cut would click) and is exactly zero from
    ``d_j + W`` on. The fade is shorter when ``W < 1 ms``.

    Parameters
    ----------
    rirs : (N, C, L) float
        RIRs, as for :func:`render_moving`.
    direct_delay_samples : (N,) float
        Arrival of the direct sound in each RIR, in samples (distance / c × rate).
    sample_rate_hz : int
        Sample rate of the RIRs.
    direct_window_ms, early_ms : float
        Lengths of the direct-path and early parts after the direct sound, in ms.

    Returns
    -------
    (direct_rirs, early_rirs) : two (N, C, L) arrays
        Render them with the same ``path_position`` as the full RIRs.
    """
    rirs = np.asarray(rirs, dtype=np.float64)
    if rirs.ndim != 3 or 0 in rirs.shape:
        raise AudioError(f"rirs: expected (N points, C channels, L samples), got {rirs.shape}")
    n, _, length = rirs.shape
    delay = np.asarray(direct_delay_samples, dtype=np.float64)
    if delay.shape != (n,):
        raise AudioError(f"direct_delay_samples: expected one delay per RIR ({n},), "
                         f"got shape {delay.shape}")
    if not np.all(np.isfinite(delay)) or delay.min() < 0 or delay.max() >= length:
        raise AudioError(f"direct_delay_samples: expected finite values in [0, {length}) "
                         f"(inside the RIR), got [{delay.min():g}, {delay.max():g}]")
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise AudioError(f"sample_rate_hz: expected > 0, got {sample_rate_hz!r}")
    if not (math.isfinite(direct_window_ms) and direct_window_ms > 0):
        raise AudioError(f"direct_window_ms: expected > 0, got {direct_window_ms!r}")
    if not (math.isfinite(early_ms) and early_ms >= direct_window_ms):
        raise AudioError(f"early_ms: expected >= direct_window_ms ({direct_window_ms:g}), "
                         f"got {early_ms!r}")
    t = np.arange(length, dtype=np.float64)[None, :]

    def gate(window_ms: float) -> np.ndarray:
        end = delay[:, None] + window_ms * 1e-3 * sample_rate_hz  # first sample that is zero
        fade = min(_FADE_MS, window_ms) * 1e-3 * sample_rate_hz
        x = np.clip((t - (end - fade)) / fade, 0.0, 1.0)
        return (0.5 + 0.5 * np.cos(np.pi * x))[:, None, :]

    return rirs * gate(direct_window_ms), rirs * gate(early_ms)
