"""Room-acoustic figures after ISO 3382-1: decay times, clarity, definition, DRR.

* **Time zero** is the first sample within 20 dB of the RIR's peak (ISO 3382-1 A.3.4).
* **Schroeder integration with noise handling** (a simplified Lundeby): the squared RIR is
  smoothed in 10 ms windows; the noise floor is the mean of its last 10 %; the integration stops
  where the smoothed envelope first meets noise + 5 dB, the noise energy is subtracted before
  that point, and the tail beyond it is replaced by the exponential continuation of the decay
  fitted just before it. Without measurable noise (a simulated RIR) it is plain backward
  integration to the end.
* **Decay times** (T20, T30, EDT) are least-squares lines over −5…−25, −5…−35 and 0…−10 dB of
  the energy decay curve, reported as 60 dB times; NaN when the curve does not reach the range.
* **C50, C80, D50** split the energy at 50 / 80 ms after time zero. **DRR** puts the direct
  sound in ±2.5 ms around the direct peak.

Per octave band through :class:`~sonicspec.acoustics.bands.OctaveFilterBank`, and broadband.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.errors import AcousticsError
from sonicspec.units import seconds_to_samples, seconds_to_samples_floor

DIRECT_WINDOW_S = 0.0025


def _check_rir(rir: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    x = np.asarray(rir, dtype=np.float64)
    if x.ndim != 1 or x.size < 2:
        raise AcousticsError(f"rir: expected a 1-D response with samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise AcousticsError("rir: expected finite samples, got NaN or inf")
    if not np.any(x):
        raise AcousticsError("rir: expected a response, got only zeros")
    if not sample_rate_hz > 0:
        raise AcousticsError(f"sample_rate_hz: expected > 0, got {sample_rate_hz!r}")
    return x


def onset_index(rir: np.ndarray) -> int:
    """First sample within 20 dB of the peak (ISO 3382-1 time zero)."""
    e = np.asarray(rir, dtype=np.float64) ** 2
    return int(np.argmax(e >= e.max() * 0.01))


def _smooth(energy: np.ndarray, width: int) -> np.ndarray:
    width = max(1, width)
    kernel = np.ones(width) / width
    return np.convolve(energy, kernel, mode="same")


def schroeder_energy(energy: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """Backward-integrated energy with the noise handling of the module docstring."""
    e = np.asarray(energy, dtype=np.float64)
    n = e.size
    env = _smooth(e, seconds_to_samples_floor(0.01, sample_rate_hz))
    tail = env[int(0.9 * n):]
    noise = float(tail.mean()) if tail.size else 0.0
    peak = float(env.max())
    if noise <= 0 or noise < peak * 1e-7:
        # No measurable noise floor (70 dB below the peak or more): integrate everything.
        return np.cumsum(e[::-1])[::-1]
    above = np.flatnonzero(env > noise * 10 ** 0.5)
    cross = int(above[-1]) + 1 if above.size else n
    cross = max(2, min(cross, n))
    clean = np.clip(e[:cross] - noise, 0.0, None)
    integral = np.cumsum(clean[::-1])[::-1]
    # Tail correction: continue the decay of the last 10 dB before the crossing point.
    window = seconds_to_samples_floor(0.01, sample_rate_hz)
    db = 10 * np.log10(np.maximum(_smooth(clean, window), 1e-300))
    start = int(np.argmax(db < db[:cross].max() - 10)) if np.any(db < db.max() - 10) else 0
    seg = np.arange(start, cross)
    if seg.size >= 8:
        slope, _ = np.polyfit(seg, db[seg], 1)
        if slope < 0:
            k = -slope * math.log(10) / 10  # energy decay rate per sample
            integral += clean[cross - 1] * math.exp(-k) / (1 - math.exp(-k))
    out = np.zeros(n)
    out[:cross] = integral
    return out


def edc_db(energy: np.ndarray, sample_rate_hz: float | None = None) -> np.ndarray:
    """Energy decay curve in dB re its start (Schroeder); plain integration without a rate."""
    e = np.asarray(energy, dtype=np.float64)
    integral = np.cumsum(e[::-1])[::-1] if sample_rate_hz is None else schroeder_energy(
        e, sample_rate_hz)
    with np.errstate(divide="ignore"):
        return 10 * np.log10(integral / integral[0]) if integral[0] > 0 else np.full(e.size,
                                                                                     -np.inf)


def decay_time_from_edc(edc: np.ndarray, dt_s: float, lo_db: float, hi_db: float) -> float:
    """60 dB decay time from a line fitted to the EDC between ``lo_db`` and ``hi_db`` (< 0)."""
    edc = np.asarray(edc, dtype=np.float64)
    if not np.any(edc <= hi_db):
        return math.nan
    i0 = int(np.argmax(edc <= lo_db))
    i1 = int(np.argmax(edc <= hi_db))
    if i1 - i0 < 2:
        return math.nan
    t = np.arange(i0, i1 + 1) * dt_s
    slope, _ = np.polyfit(t, edc[i0:i1 + 1], 1)
    return -60.0 / slope if slope < 0 else math.nan


def decay_times_from_histogram(energy: np.ndarray, bin_s: float) -> dict[str, np.ndarray]:
    """T20, T30 and EDT per band from an energy-time histogram ``(n_bins, n_bands)``."""
    e = np.asarray(energy, dtype=np.float64)
    if e.ndim == 1:
        e = e[:, None]
    out: dict[str, list[float]] = {"t20_s": [], "t30_s": [], "edt_s": []}
    for b in range(e.shape[1]):
        start = int(np.argmax(e[:, b] > 0)) if np.any(e[:, b] > 0) else 0
        edc = edc_db(e[start:, b])
        out["t20_s"].append(decay_time_from_edc(edc, bin_s, -5, -25))
        out["t30_s"].append(decay_time_from_edc(edc, bin_s, -5, -35))
        out["edt_s"].append(decay_time_from_edc(edc, bin_s, 0, -10))
    return {k: np.asarray(v) for k, v in out.items()}


def figures_from_energy(energy: np.ndarray, bin_s: float) -> dict[str, list[float | None]]:
    """T30, EDT and C50 per band of an energy-time histogram ``(n_bins, n_bands)`` whose
    first non-empty bin is the direct sound (JSON-ready: NaN becomes None).

    These are the figures a synthesised RIR is built to have (the direct sound, the image
    sources and the tracer's histogram): the same ISO 3382-1 fits, without the draw of the
    late noise, which moves one RIR's low-band figures by several percent (EDT at 125 Hz by
    ~20 % in a furnished scan).
    """
    e = np.asarray(energy, dtype=np.float64)
    if e.ndim != 2 or not bin_s > 0:
        raise AcousticsError(f"energy: expected (n_bins, n_bands) and bin_s > 0, got "
                             f"{e.shape} and {bin_s}")
    decay = decay_times_from_histogram(e, bin_s)
    filled = np.flatnonzero(e.sum(axis=1) > 0)
    onset = int(filled[0]) if filled.size else 0
    split = onset + round(0.05 / bin_s)
    c50 = np.array([_clarity(e[onset:, b], split - onset) for b in range(e.shape[1])])
    return {"t30_s": _json_ready(decay["t30_s"]), "edt_s": _json_ready(decay["edt_s"]),
            "c50_db": _json_ready(c50)}


def _json_ready(v):
    """Arrays as lists of floats and NaN as None (JSON has no NaN)."""
    if isinstance(v, np.ndarray):
        return [_json_ready(float(x)) for x in v]
    return None if isinstance(v, float) and math.isnan(v) else v


def _clarity(energy: np.ndarray, split: int) -> float:
    early, late = energy[:split].sum(), energy[split:].sum()
    return 10 * math.log10(early / late) if early > 0 and late > 0 else math.nan


@dataclass(frozen=True)
class RoomAcousticFigures:
    """ISO 3382-1 figures per band (arrays over ``bands_hz``) and broadband (scalars)."""

    bands_hz: tuple[float, ...]
    t20_s: np.ndarray
    t30_s: np.ndarray
    edt_s: np.ndarray
    c50_db: np.ndarray
    c80_db: np.ndarray
    d50: np.ndarray
    broadband: dict[str, float]
    drr_db: float

    def to_dict(self) -> dict:
        """JSON-ready (NaN becomes None)."""
        return {"bands_hz": list(self.bands_hz),
                **{k: _json_ready(getattr(self, k)) for k in ("t20_s", "t30_s", "edt_s",
                                                               "c50_db", "c80_db", "d50")},
                "broadband": {k: _json_ready(v) for k, v in self.broadband.items()},
                "drr_db": _json_ready(self.drr_db)}


def _single(x: np.ndarray, sample_rate_hz: float) -> dict[str, float]:
    t0 = onset_index(x)
    e = x[t0:] ** 2
    edc = edc_db(e, sample_rate_hz)
    dt = 1.0 / sample_rate_hz
    n50 = seconds_to_samples(0.05, sample_rate_hz)
    n80 = seconds_to_samples(0.08, sample_rate_hz)
    total = e.sum()
    return {
        "t20_s": decay_time_from_edc(edc, dt, -5, -25),
        "t30_s": decay_time_from_edc(edc, dt, -5, -35),
        "edt_s": decay_time_from_edc(edc, dt, 0, -10),
        "c50_db": _clarity(e, n50),
        "c80_db": _clarity(e, n80),
        "d50": float(e[:n50].sum() / total) if total > 0 else math.nan,
    }


def direct_to_reverberant_db(rir: np.ndarray, sample_rate_hz: float) -> float:
    """DRR: energy within ±2.5 ms of the direct peak over the rest, dB."""
    x = _check_rir(rir, sample_rate_hz)
    e = x**2
    peak = onset_index(x)
    reach = seconds_to_samples_floor(DIRECT_WINDOW_S, sample_rate_hz)
    peak = peak + int(np.argmax(e[peak:peak + reach + 1]))
    w = seconds_to_samples(DIRECT_WINDOW_S, sample_rate_hz)
    lo, hi = max(0, peak - w), peak + w + 1
    direct = e[lo:hi].sum()
    rest = e.sum() - direct
    return 10 * math.log10(direct / rest) if rest > 0 and direct > 0 else math.nan


def room_acoustic_figures(rir: np.ndarray, sample_rate_hz: float,
                          bands_hz: Sequence[float] | None = None) -> RoomAcousticFigures:
    """ISO 3382-1 figures of a single-channel RIR, per octave band and broadband."""
    x = _check_rir(rir, sample_rate_hz)
    bank = OctaveFilterBank(sample_rate_hz, tuple(bands_hz or ()))
    per_band = [_single(b, sample_rate_hz) for b in bank.split(x)]
    keys = ("t20_s", "t30_s", "edt_s", "c50_db", "c80_db", "d50")
    arrays = {k: np.array([pb[k] for pb in per_band]) for k in keys}
    return RoomAcousticFigures(bands_hz=bank.bands_hz, broadband=_single(x, sample_rate_hz),
                               drr_db=direct_to_reverberant_db(x, sample_rate_hz), **arrays)
