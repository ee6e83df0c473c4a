"""The SonicSim paper's separation and enhancement metrics, on arrays.

SI-SNR is written here (a projection and a ratio). SDR is BSS Eval's through
``fast_bss_eval`` (``sdr``: the estimate projected on its reference through a 512-tap
distortion filter, as ``mir_eval.separation.bss_eval_sources`` computes it). PESQ is ITU-T
P.862 through ``pesq`` (narrow band P.862.1 at 8 or 16 kHz, wide band P.862.2 at 16 kHz;
other rates are resampled to 16 kHz first); STOI through ``pystoi``. Long clips are scored the
paper's way: 6 s windows every 3 s, each metric averaged over the windows (:func:`windows`).

The packages are optional (the ``eval`` extra) and imported when a metric is asked for.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np

from sonicspec.errors import AudioError

EPS = 1e-12
SDR_MAX_DB = 200.0
SILENT_TARGET_DB = -70.0  # RMS, dBFS: a window whose target is quieter is not scored
METRICS = ("si_snr", "si_snri", "sdr", "sdri", "pesq_nb", "pesq_wb", "stoi")
_INSTALL = "pip install 'sonicspec[eval]'"


def _need(module: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise AudioError(f"the {module} package is needed for this metric; {_INSTALL}") from None


def si_snr(estimate: np.ndarray, target: np.ndarray) -> float:
    """Scale-invariant SNR of ``estimate`` against ``target`` (1-D), dB.

    Both are made zero-mean; the target part of the estimate is its projection on the target,
    the rest is noise: ``10 log10(|s|² / |e - s|²)`` with ``s = <e, t> t / |t|²``.
    """
    e = np.asarray(estimate, dtype=np.float64) - np.mean(estimate)
    t = np.asarray(target, dtype=np.float64) - np.mean(target)
    s = (np.dot(e, t) / (np.dot(t, t) + EPS)) * t
    return float(10.0 * np.log10((np.dot(s, s) + EPS) / (np.dot(e - s, e - s) + EPS)))


def sdr(estimate: np.ndarray, target: np.ndarray, filter_length: int = 512) -> float:
    """BSS Eval SDR of ``estimate`` against ``target`` (1-D), dB, through fast_bss_eval.

    A silent target or a silent (all-zero) estimate has no SDR: NaN (the window is left out of
    the mean); an estimate that is the target scaled scores ``SDR_MAX_DB``.
    """
    t = np.asarray(target, dtype=np.float64)
    e = np.asarray(estimate, dtype=np.float64)
    if not np.any(t) or not np.any(e):  # 0 / 0 either way (a silent estimate was "perfect")
        return math.nan
    residual = e - (np.dot(e, t) / np.dot(t, t)) * t
    if np.dot(residual, residual) <= 1e-20 * np.dot(e, e):
        # A scaled copy of the target: no distortion to measure (fast_bss_eval 0.1.4 fails on
        # the infinite ratio), so the ceiling.
        return SDR_MAX_DB
    fbe = _need("fast_bss_eval")
    # One reference: no permutation to solve. (fast_bss_eval 0.1.4's bss_eval_sources fails
    # on one source under numpy 2; its sdr does the same projection and works.)
    value = fbe.sdr(t[None, :], e[None, :],
                    filter_length=filter_length)
    return float(value[0])


def _to_16k(x: np.ndarray, rate: int) -> np.ndarray:
    from scipy.signal import resample_poly

    g = math.gcd(int(rate), 16000)
    return resample_poly(x, 16000 // g, int(rate) // g)


def pesq(estimate: np.ndarray, target: np.ndarray, sample_rate_hz: int, mode: str) -> float:
    """PESQ (``mode`` ``"nb"`` or ``"wb"``) through the ``pesq`` package; NaN when it finds no
    speech in the window (its ``NoUtterancesError``) or the estimate is silent (all zeros)."""
    lib = _need("pesq")
    rate = int(sample_rate_hz)
    ref, deg = np.asarray(target, np.float64), np.asarray(estimate, np.float64)
    if not np.any(deg):  # P.862 levels the signal first: a silent one has no level (it crashed)
        return math.nan
    if rate not in (8000, 16000) or (mode == "wb" and rate != 16000):
        ref, deg, rate = _to_16k(ref, rate), _to_16k(deg, rate), 16000
    try:
        return float(lib.pesq(rate, ref, deg, mode))
    except lib.NoUtterancesError:
        return math.nan


def stoi(estimate: np.ndarray, target: np.ndarray, sample_rate_hz: int) -> float:
    """STOI (0…1) through ``pystoi`` (which resamples to 10 kHz itself)."""
    lib = _need("pystoi")
    return float(lib.stoi(np.asarray(target, np.float64), np.asarray(estimate, np.float64),
                          int(sample_rate_hz), extended=False))


def windows(num_samples: int, sample_rate_hz: int, window_s: float = 6.0,
            hop_s: float = 3.0) -> list[tuple[int, int]]:
    """``[start, stop)`` of the scoring windows over a clip: ``window_s`` long every ``hop_s``,
    plus one last window ending at the clip's end if the hops stop short of it; a clip shorter
    than a window is one window."""
    win = round(window_s * sample_rate_hz)
    hop = round(hop_s * sample_rate_hz)
    if win <= 0 or hop <= 0:
        raise AudioError(f"windows: expected positive window and hop, got {window_s} s, "
                         f"{hop_s} s")
    if num_samples <= win:
        return [(0, num_samples)]
    out = [(s, s + win) for s in range(0, num_samples - win + 1, hop)]
    if out[-1][1] < num_samples:
        out.append((num_samples - win, num_samples))
    return out


def best_permutation(estimates: np.ndarray, targets: np.ndarray,
                     score: Callable[[np.ndarray, np.ndarray], float] = si_snr
                     ) -> tuple[int, ...]:
    """The order of ``estimates`` (k, T) that maximises the mean ``score`` against
    ``targets`` (k, T): ``perm[i]`` is the estimate matched to target ``i``."""
    k = targets.shape[0]
    if estimates.shape[0] != k:
        raise AudioError(f"permutation: {estimates.shape[0]} estimates for {k} targets")
    table = np.array([[score(estimates[j], targets[i]) for j in range(k)] for i in range(k)])
    return max(itertools.permutations(range(k)),
               key=lambda p: sum(table[i, p[i]] for i in range(k)))


def score_pair(estimate: np.ndarray, target: np.ndarray, mixture: np.ndarray,
               sample_rate_hz: int, metrics: Sequence[str] = METRICS) -> dict[str, float]:
    """Every metric of one estimate against its target on one window; the improvements are
    against ``mixture`` taken as the estimate."""
    unknown = [m for m in metrics if m not in METRICS]
    if unknown:
        raise AudioError(f"metrics: expected names from {list(METRICS)}, got {unknown[0]!r}")
    out: dict[str, float] = {}
    for base, fn in (("si_snr", si_snr), ("sdr", sdr)):
        if base in metrics or f"{base}i" in metrics:
            value = fn(estimate, target)
            if base in metrics:
                out[base] = value
            if f"{base}i" in metrics:
                out[f"{base}i"] = value - fn(mixture, target)
    for mode in ("nb", "wb"):
        if f"pesq_{mode}" in metrics:
            out[f"pesq_{mode}"] = pesq(estimate, target, sample_rate_hz, mode)
    if "stoi" in metrics:
        out["stoi"] = stoi(estimate, target, sample_rate_hz)
    return {m: out[m] for m in metrics}


def windowed_scores(estimate: np.ndarray, target: np.ndarray, mixture: np.ndarray,
                    sample_rate_hz: int, metrics: Sequence[str] = METRICS,
                    window_s: float = 6.0, hop_s: float = 3.0) -> dict[str, float]:
    """:func:`score_pair` on every window of the clip, averaged per metric.

    A window where the target is silent (RMS below ``SILENT_TARGET_DB``: the speaker has not
    begun or has finished) scores nothing, as do windows where a metric is undefined (NaN):
    they are left out of that mean. A window where the *estimate* is silent (all zeros: a
    model that output nothing there) has every metric undefined — SI-SNR and SDR are 0 / 0,
    P.862 cannot level silence — so it scores nothing either, but it is counted:
    ``silent_estimate`` (of the ``scored`` windows), which ``sonicspec evaluate`` reports.
    ``windows`` counts every window, ``scored`` those of a heard target.
    """
    spans = windows(len(target), sample_rate_hz, window_s, hop_s)
    heard = [_level_db(target[a:b]) >= SILENT_TARGET_DB for a, b in spans]
    silent = [h and not np.any(estimate[a:b]) for h, (a, b) in zip(heard, spans, strict=True)]
    rows = [score_pair(estimate[a:b], target[a:b], mixture[a:b], sample_rate_hz, metrics)
            if h and not quiet else dict.fromkeys(metrics, math.nan)
            for h, quiet, (a, b) in zip(heard, silent, spans, strict=True)]
    out = {}
    for name in metrics:
        values = np.array([r[name] for r in rows], dtype=np.float64)
        out[name] = float(np.nanmean(values)) if np.any(np.isfinite(values)) else math.nan
    out["windows"] = len(spans)
    out["scored"] = sum(heard)
    out["silent_estimate"] = sum(silent)
    return out


def _level_db(x: np.ndarray) -> float:
    return 10.0 * math.log10(max(1e-30, float(np.mean(np.square(x, dtype=np.float64)))))
