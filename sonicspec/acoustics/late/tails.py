"""Where a RIR's late tail ends: every band's decay 60 dB down, the rays' last 20 dB carried on.

The tracer's histogram (:class:`~sonicspec.acoustics.arrivals.EnergyHistogram`) holds the late
energy up to the longest RIR allowed (``max_rir_length_s``, or ``max_rir_cap_s`` with
``max_rir_length_s: auto``). This module reads, per band, how far its decay got and shapes the
envelope the RIR is synthesised from:

* **The decay curve** of a band is the Schroeder integral of its late energy, in dB re its
  start (the band's early level): ``D(t) = 10 log10(∫_t^∞ e / ∫_0^∞ e)``. For an exponential
  decay it falls exactly as the envelope does, and unlike the envelope it is smooth where few
  rays remain.
* **Where the traced energy stops** before the decay is over (the rays ran out: Russian
  roulette and few rays leave none alive past some level, or the histogram's end cut them),
  the integral lacks what came after and droops to −∞. The missing energy is estimated as
  Lundeby et al. (1995) do for a measured decay in noise: a line fitted to the corrected
  curve ``10 log10((∫_t e + C)/(∫_0 e + C))``, ``C`` the energy the line puts after the
  data's end, refitted until ``C`` settles (five rounds; the first line spans −5 … −25 dB,
  the others the last 20 dB of the decay above its last 10 dB, which the last few rays
  carry: with Russian roulette their envelope is unbiased but skewed, and a realisation's
  falls faster there than the mean does).
* **Complete** when that line is 60 dB down by the data's end: the band's decay ends where
  the corrected curve crosses −60 dB.
* **Continued** when the rays ran out before: from where the fitted line is 10 dB above the
  data's end level (the last 10 dB are carried by the last few rays) the envelope is the
  fitted decay, ``(∫_0 e + C) · 10^(line(t)/10) · (1 − 10^(g·Δ/10))`` per bin of width
  ``Δ`` (``g`` the slope, dB/s), until it is 60 dB down.
* **Cut** when the histogram's end comes first (the data reach it, or the continuation
  would pass it): the RIR ends there and the band is reported with the level its decay
  reached (the caller warns).

The RIR then ends where the last band's decay ends (past it every band is more than 60 dB
below its early level): :func:`shape_tail` returns the envelope trimmed there.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sonicspec.acoustics.arrivals import EnergyHistogram

__all__ = ["DECAY_RANGE_DB", "FIT_RANGE_DB", "BandDecay", "TailFacts", "TailReport", "band_decay",
           "cut_warning", "shape_tail"]

#: How far below its early level a band's decay must fall before the RIR may end, dB.
DECAY_RANGE_DB = 60.0
#: The stretch at the end of the traced decay its continuation is fitted to, dB.
FIT_RANGE_DB = 20.0
# The last stretch of traced data the continuation replaces (carried by the last rays), dB.
_REPLACED_DB = 10.0
# A fit needs at least this many bins.
_MIN_FIT_BINS = 5
# Rounds of the Lundeby-style refit of the missing energy.
_ROUNDS = 5


@dataclass(frozen=True)
class BandDecay:
    """How one band's late decay ends within the histogram.

    Attributes
    ----------
    status : {"complete", "continued", "cut", "empty"}
        Traced to 60 dB down (or, with no decay to fit, to the data's end); continued by
        its fitted decay after the rays ran out; cut by the histogram's end before 60 dB;
        no late energy at all.
    end_bin : int
        Bins the band needs: where its decay is 60 dB down (the histogram's length when cut,
        0 when empty).
    continued_from_bin : int or None
        First bin of the fitted continuation (``"continued"``, and ``"cut"`` when the
        continuation ran into the histogram's end).
    level_at_end_db : float or None
        ``"cut"``: the decay's level where the histogram ends, dB re its start (> −60).
    slope_db_per_s : float or None
        The line fitted to the last 20 dB of the traced decay (None: no fit possible).
    energy : (n_bins,) float
        The band's envelope with the continuation in place (the input where not continued).
    """

    status: str
    end_bin: int
    continued_from_bin: int | None
    level_at_end_db: float | None
    slope_db_per_s: float | None
    energy: np.ndarray


def _fit(t: np.ndarray, d: np.ndarray, upper_db: float, lower_db: float,
         last: int) -> tuple[float, float] | None:
    """Least-squares line ``(slope, intercept)`` of ``d`` against ``t`` over the bins up to
    ``last`` from the first at or below ``upper_db`` to the last at or above ``lower_db``."""
    below = np.flatnonzero(d[:last + 1] <= upper_db)
    if not below.size:
        return None
    i0 = int(below[0])
    above = np.flatnonzero(d[i0:last + 1] >= lower_db)
    if not above.size:
        return None
    i1 = i0 + int(above[-1])
    if i1 - i0 + 1 < _MIN_FIT_BINS:
        return None
    # The least-squares line in closed form (centred sums; np.polyfit's SVD gives the same
    # line to ~1e-15 and cost more than the rest of the tail's shaping).
    x, y = t[i0:i1 + 1], d[i0:i1 + 1]
    x_mean, y_mean = float(x.mean()), float(y.mean())
    dx = x - x_mean
    slope = float(dx @ (y - y_mean)) / float(dx @ dx)
    return slope, y_mean - slope * x_mean


def band_decay(energy: np.ndarray, bin_s: float, floor_db: float = DECAY_RANGE_DB,
               fit_db: float = FIT_RANGE_DB) -> BandDecay:
    """How the late decay ``energy`` (one band, per bin of ``bin_s`` s) ends; see the module
    docstring for the method.

    Parameters
    ----------
    energy : (n_bins,) float
        The band's late energy per bin (the histogram's length is the longest RIR allowed).
    bin_s : float
        Bin width, seconds.
    floor_db : float
        How far down the decay must get, dB (60).
    fit_db : float
        The stretch of the traced decay the continuation is fitted to, dB (20), above its
        last 10 dB.
    """
    e = np.asarray(energy, dtype=np.float64)
    n = len(e)
    filled = np.flatnonzero(e > 0)
    if not filled.size:
        return BandDecay("empty", 0, None, None, None, e)
    last = int(filled[-1])
    s = np.cumsum(e[::-1])[::-1]
    total = float(s[0])
    t = np.arange(n) * bin_s  # s[i]: the energy after t[i]
    t_end = (last + 1) * bin_s  # the data's end

    def missing_after_end(line: tuple[float, float]) -> float:
        # The energy after the data's end in the line's terms: the corrected curve there is
        # 10 log10(M / (total + M)) = line(t_end), solved for M.
        r = 10.0 ** ((line[0] * t_end + line[1]) / 10.0)
        return total * r / (1.0 - r) if r < 1.0 else 0.0

    def curve(missing: float, bins: int = n) -> np.ndarray:
        """The decay curve of the first ``bins`` bins (the fits read it up to the data's
        end only: the histogram runs to the longest RIR allowed, often 10× longer)."""
        with np.errstate(divide="ignore"):
            return 10.0 * np.log10((s[:bins] + missing) / (total + missing))

    d = curve(0.0, last + 1)
    line = _fit(t, d, -5.0, -25.0, last) or _fit(t, d, -1.0, float(d[last]) + 3.0, last)
    missing = 0.0
    if line is not None and line[0] < 0:
        for _ in range(_ROUNDS):
            d = curve(missing_after_end(line), last + 1)
            end_level = float(d[last])
            # The last 20 dB above the stretch the last few rays carry (replaced below).
            lower = end_level + _REPLACED_DB
            refit = _fit(t, d, min(-5.0, lower + fit_db), lower, last)
            if refit is None or refit[0] >= 0:
                break
            line = refit
        missing = missing_after_end(line)
        d = curve(missing, last + 1)
    if line is None or line[0] >= 0:
        # No decay to fit (a few bins, or not falling): the data as they are, to their end.
        down = np.flatnonzero(d[:last + 1] <= -floor_db)
        end = int(down[0]) + 1 if down.size else last + 1
        return BandDecay("complete", end, None, None, None, e)
    slope, intercept = line
    level_at_data_end = slope * t_end + intercept
    if level_at_data_end <= -floor_db:
        down = np.flatnonzero(curve(missing) <= -floor_db)
        end = int(down[0]) + 1 if down.size else last + 1
        return BandDecay("complete", min(end, n), None, None, slope, e)
    # The rays stopped above -60 dB: at the histogram's end (cut) or before it (ran out).
    # The smoothing of the envelope spreads the data's end over 2.5 % of its time: data
    # ending that close to the histogram's end reached it.
    reached_end = last >= n - 1 - math.ceil(0.025 * n)
    if reached_end:
        return BandDecay("cut", n, None, float(slope * n * bin_s + intercept), slope, e)
    start_level = level_at_data_end + _REPLACED_DB
    start = int(np.searchsorted(-(slope * t + intercept), -start_level))
    start = max(0, min(start, last))
    out = e.copy()
    scale = (total + missing) * (1.0 - 10.0 ** (slope * bin_s / 10.0))
    out[start:] = scale * 10.0 ** ((slope * t[start:] + intercept) / 10.0)
    # The fitted decay reaches -60 dB at this bin (the line at its start time).
    end = math.ceil(((-floor_db - intercept) / slope) / bin_s)
    if end > n:
        return BandDecay("cut", n, start, float(slope * n * bin_s + intercept), slope, out)
    out[end:] = 0.0
    return BandDecay("continued", end, start, None, slope, out)


@dataclass(frozen=True)
class TailReport:
    """How a RIR's length was chosen (the ``tail`` of the RIR facts).

    Attributes
    ----------
    rule : {"auto", "fixed"}
        ``max_rir_length_s: auto`` (the decay decides, at most ``max_rir_cap_s``) or a
        number (the decay decides, at most that number).
    limit_s : float
        The longest RIR allowed, seconds.
    limit_field : str
        The spec field that sets it (``max_rir_cap_s`` or ``max_rir_length_s``).
    bands_hz : tuple of float
    decays : tuple of BandDecay
        Per band.
    bin_s : float
        The histogram's bin width, seconds.
    """

    rule: str
    limit_s: float
    limit_field: str
    bands_hz: tuple[float, ...]
    decays: tuple[BandDecay, ...]
    bin_s: float

    @property
    def end_s(self) -> float:
        """Where the last band's late decay ends (the RIR's tail), seconds."""
        return max((d.end_bin for d in self.decays), default=0) * self.bin_s

    @property
    def cut_bands_hz(self) -> list[float]:
        return [b for b, d in zip(self.bands_hz, self.decays, strict=True) if d.status == "cut"
                and d.level_at_end_db is not None]

    @property
    def continued_bands_hz(self) -> list[float]:
        return [b for b, d in zip(self.bands_hz, self.decays, strict=True)
                if d.continued_from_bin is not None]

    def facts(self) -> TailFacts:
        """The summary the RIR facts keep (:class:`TailFacts`), rounded as stored."""

        def per_band(fn) -> tuple:
            return tuple(fn(d) for d in self.decays)

        return TailFacts(
            rule=self.rule, limit_s=self.limit_s, limit_field=self.limit_field,
            decay_end_s=round(self.end_s, 6),
            decay_60db_s=per_band(lambda d: None if d.status in ("cut", "empty")
                                  else round(d.end_bin * self.bin_s, 6)),
            continued_from_s=per_band(lambda d: None if d.continued_from_bin is None
                                      else round(d.continued_from_bin * self.bin_s, 6)),
            level_at_limit_db=per_band(lambda d: None if d.level_at_end_db is None
                                       else round(d.level_at_end_db, 2)),
            fitted_t60_s=per_band(lambda d: round(-60.0 / d.slope_db_per_s, 4)
                                  if d.slope_db_per_s and d.status in ("continued", "cut")
                                  else None),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: :meth:`facts` as a dict."""
        return self.facts().to_dict()


@dataclass(frozen=True)
class TailFacts:
    """How a RIR's length was chosen, as the RIR facts, the rir artifact and a dataset's
    ``metadata.json`` (``rir_tail``) keep it: the rule, the limit, where the last band's decay
    ends, and per band the time its decay is 60 dB down (None: not within the limit), where a
    fitted continuation starts (None: traced to the end), the level it reached where the limit
    cut it, and the 60 dB time of the line fitted to its last 20 dB where that line was used
    (a continuation, a cut). A plain frozen dataclass, so the artifact models
    (:mod:`sonicspec.artifacts`) validate and store it field by field.

    Attributes
    ----------
    rule : {"auto", "fixed"}
        ``max_rir_length_s: auto`` or a number of seconds.
    limit_s : float
        The longest RIR allowed, seconds.
    limit_field : str
        The spec field that sets it (``max_rir_cap_s`` or ``max_rir_length_s``).
    decay_end_s : float
        Where the last band's late decay ends, seconds (rounded to 1 µs).
    decay_60db_s, continued_from_s, level_at_limit_db, fitted_t60_s : tuple of float or None
        Per band: seconds, seconds, dB (0.01), seconds (0.1 ms).
    """

    rule: str
    limit_s: float
    limit_field: str
    decay_end_s: float
    decay_60db_s: tuple[float | None, ...]
    continued_from_s: tuple[float | None, ...]
    level_at_limit_db: tuple[float | None, ...]
    fitted_t60_s: tuple[float | None, ...]

    @property
    def cut_at_limit(self) -> bool:
        """A fixed limit cut some band while it still decayed (the rule ``auto`` warns
        where it cuts; a number of seconds is taken as asked, and reported here)."""
        return self.rule == "fixed" and any(v is not None for v in self.level_at_limit_db)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (lists for the per-band tuples)."""
        return {"rule": self.rule, "limit_s": self.limit_s, "limit_field": self.limit_field,
                "decay_end_s": self.decay_end_s, "decay_60db_s": list(self.decay_60db_s),
                "continued_from_s": list(self.continued_from_s),
                "level_at_limit_db": list(self.level_at_limit_db),
                "fitted_t60_s": list(self.fitted_t60_s)}


def shape_tail(histogram: EnergyHistogram, bands_hz: Sequence[float], rule: str,
               limit_s: float, limit_field: str) -> tuple[EnergyHistogram, TailReport]:
    """The late envelope a RIR is synthesised from, every band's decay carried to 60 dB
    down and trimmed where the last one gets there, and the report of how.

    Parameters
    ----------
    histogram : EnergyHistogram
        The tracer's (smoothed) late energy, as long as the longest RIR allowed.
    bands_hz : sequence of float
        The bands of its columns (for the report).
    rule, limit_s, limit_field
        As :class:`TailReport` reports them.

    Returns
    -------
    histogram : EnergyHistogram
        Continued where the rays ran out, and ending where every band is 60 dB down (or at
        the limit).
    report : TailReport
    """
    e = histogram.energy
    decays = tuple(band_decay(e[:, b], histogram.bin_s) for b in range(e.shape[1]))
    report = TailReport(rule=rule, limit_s=float(limit_s), limit_field=limit_field,
                        bands_hz=tuple(float(b) for b in bands_hz), decays=decays,
                        bin_s=histogram.bin_s)
    n = max(1, max((d.end_bin for d in decays), default=0))  # one bin even when silent
    energy = np.stack([d.energy for d in decays], axis=1)[:n] if decays else e[:0]
    directions = histogram.direction_sum[:n] if len(histogram.direction_sum) else \
        histogram.direction_sum
    departures = histogram.departure_sum[:n] if len(histogram.departure_sum) else \
        histogram.departure_sum
    return EnergyHistogram(histogram.bin_s, energy, directions, departures), report


def cut_warning(report: TailReport, where: str, positions: int = 1) -> str | None:
    """The warning for decays the limit cut short (None when none was): names ``where``
    (the scene), the bands, the level each reached and the field to raise."""
    cut = [(b, d) for b, d in zip(report.bands_hz, report.decays, strict=True)
           if d.status == "cut" and d.level_at_end_db is not None]
    if not cut:
        return None
    bands = ", ".join(f"the {b:g} Hz band at {d.level_at_end_db:.0f} dB" for b, d in cut)
    needed = max((-DECAY_RANGE_DB / d.slope_db_per_s for _, d in cut if d.slope_db_per_s),
                 default=None)
    hint = (f"; its decay needs about {needed:.1f} s" if needed and needed > report.limit_s
            else "")
    where_points = f" ({positions} positions)" if positions > 1 else ""
    return (f"{where}{where_points}: the RIR's late decay is cut at {report.limit_s:g} s "
            f"(acoustics.{report.limit_field}) before it is {DECAY_RANGE_DB:g} dB below its "
            f"early level: {bands}{hint}; raise acoustics.{report.limit_field}")
