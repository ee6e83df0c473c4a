"""How close a rendered signal is to an exact one: issue 18's yardsticks for moving sources.

* :func:`snr_db` — the energy of the reference over the energy of the difference, no scaling
  and no alignment: a renderer must get the level and the delay right, not only the shape.
* :func:`spectral_deviation_db` — per short-time frame, the rendered signal's power spectrum
  over the reference's, each smoothed over a fraction of an octave, in dB on a log-spaced
  frequency grid inside a band. A crossfade of two delayed copies is a comb filter: its
  notches show here as dips (negative values), which an SNR alone does not locate.
* :func:`dip_figures` — the worst dip and the 5th percentile over every frame and frequency.

Only frames whose reference is within ``floor_db`` of the loudest frame (in the band) count,
and, when ``active`` is given, only frames centred inside it (e.g. while the source moves).
"""

from __future__ import annotations

import numpy as np

from sonicspec.errors import AudioError


def snr_db(reference: np.ndarray, estimate: np.ndarray) -> float:
    """``10 log10(Σ ref² / Σ (ref − est)²)`` over the common length, dB."""
    ref, est = _pair(reference, estimate)
    noise = float(np.sum((ref - est) ** 2))
    signal = float(np.sum(ref**2))
    if signal == 0:
        raise AudioError("reference: expected a signal, got silence")
    return float("inf") if noise == 0 else 10 * np.log10(signal / noise)


def _pair(reference: np.ndarray, estimate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ref = np.asarray(reference, dtype=np.float64)
    est = np.asarray(estimate, dtype=np.float64)
    if ref.ndim != 1 or est.ndim != 1:
        raise AudioError(f"expected 1-D signals, got shapes {ref.shape} and {est.shape}")
    n = min(ref.size, est.size)
    return ref[:n], est[:n]


def spectral_deviation_db(reference: np.ndarray, estimate: np.ndarray, sample_rate_hz: float,
                          *, band_hz: tuple[float, float] = (200.0, 5000.0),
                          octave_fraction: int = 6, frame_s: float = 0.064,
                          hop_s: float = 0.016, points_per_octave: int = 24,
                          active: tuple[int, int] | None = None, floor_db: float = 40.0
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed power ratio estimate / reference per frame and frequency, dB.

    Returns ``(deviation (frames, freqs), frame_centres (samples), freqs_hz)`` for the frames
    that count (see the module docstring).
    """
    ref, est = _pair(reference, estimate)
    fs = float(sample_rate_hz)
    lo, hi = band_hz
    if not 0 < lo < hi <= fs / 2:
        raise AudioError(f"band_hz: expected 0 < low < high <= {fs / 2:g}, got {band_hz}")
    frame = round(frame_s * fs)
    hop = round(hop_s * fs)
    if frame < 16 or hop < 1 or ref.size < frame:
        raise AudioError(f"frame_s, hop_s: expected frames of >= 16 samples within the "
                         f"{ref.size}-sample signal, got {frame} and {hop}")
    starts = np.arange(0, ref.size - frame + 1, hop)
    window = np.hanning(frame)
    idx = starts[:, None] + np.arange(frame)[None, :]
    p_ref = np.abs(np.fft.rfft(ref[idx] * window, axis=1)) ** 2
    p_est = np.abs(np.fft.rfft(est[idx] * window, axis=1)) ** 2
    bins = np.fft.rfftfreq(frame, 1 / fs)
    n_points = int(np.floor(np.log2(hi / lo) * points_per_octave)) + 1
    freqs = lo * 2.0 ** (np.arange(n_points) / points_per_octave)
    half = 2.0 ** (1.0 / (2 * octave_fraction))
    # Smoothing: the mean power of the bins within 1/octave_fraction of an octave.
    weights = ((bins[None, :] >= freqs[:, None] / half)
               & (bins[None, :] <= freqs[:, None] * half)).astype(np.float64)
    if np.any(weights.sum(axis=1) == 0):
        raise AudioError("frame_s: frames too short to resolve the smoothing bands; use a "
                         "longer frame")
    weights /= weights.sum(axis=1, keepdims=True)
    s_ref = p_ref @ weights.T
    s_est = p_est @ weights.T
    centres = starts + frame // 2
    level = s_ref.sum(axis=1)
    keep = level >= level.max() * 10 ** (-floor_db / 10) if level.max() > 0 else level > 0
    if active is not None:
        keep &= (centres >= active[0]) & (centres < active[1])
    tiny = np.finfo(np.float64).tiny
    dev = 10 * np.log10(np.maximum(s_est[keep], tiny) / np.maximum(s_ref[keep], tiny))
    return dev, centres[keep], freqs


def dip_figures(deviation_db: np.ndarray) -> dict[str, float]:
    """``{"worst_db", "p5_db"}``: the deepest dip and the 5th percentile of the deviation."""
    d = np.asarray(deviation_db, dtype=np.float64)
    if d.size == 0:
        raise AudioError("deviation_db: no frame counted (is the reference silent?)")
    return {"worst_db": float(d.min()), "p5_db": float(np.percentile(d, 5))}
