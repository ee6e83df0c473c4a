"""RIR synthesis for an omnidirectional receiver: discrete early arrivals plus a late tail.

* **Early part** (direct sound, image sources): each arrival is a fractional-delay tap (a
  Hann-windowed sinc, ``taps`` long, so the peak sits at the exact arrival time, not the nearest
  sample) with its per-band amplitude. The taps of each band are summed into one impulse train,
  and the trains are filtered once each by the octave bank of
  :class:`~sonicspec.acoustics.bands.OctaveFilterBank` and summed; as the bank's bands add up
  to one, an arrival with equal amplitude in every band comes out as a clean, flat tap.
* **Late part** (the ray tracer's energy histogram): independent white Gaussian noise per band,
  band-filtered by the same bank; in every band the noise is scaled so that the energy it
  carries in each histogram bin equals the histogram's times the band's share of a flat
  spectrum (gains interpolated linearly between bin centres, so the envelope has no steps), and
  the bands are summed. The share matters: the histogram, like an arrival's band amplitudes,
  quotes each band as if the whole flat spectrum were in it (the direct sound is ``1/(4πr)`` in
  every band), while the band of a flat tap holds only its share of the tap's energy — so the
  tail gets the same weighting, and the direct-to-reverberant ratio of the RIR is the
  histogram's. Gaussian noise has full
  reflection density from the first bin on; since the histogram holds only what the image
  sources do not render (late and diffuse energy), its first bins are weak, which limits the
  effect of this approximation. The histogram and the arrivals never hold the same energy (the
  tracer counts it once), so the two parts simply add: no crossfade is needed between them.
* **Length**: past the last arrival (with the band filters' ringing) and the last bin holding
  energy, capped at ``max_length_s``.

Amplitudes are sound pressure for a unit point source: the free-field direct sound is
``1/(4πr)`` at ``r/c`` (DESIGN.md §5). All randomness comes from the generator passed in.
"""

from __future__ import annotations

import math

import numpy as np

from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.errors import AcousticsError

DEFAULT_TAPS = 65


def _fractional_taps(times_s: np.ndarray, sample_rate_hz: float, taps: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices (n, taps) and weights (n, taps) of windowed-sinc fractional delays."""
    centre = times_s * sample_rate_hz
    half = taps // 2
    base = np.floor(centre).astype(np.int64)
    offsets = np.arange(-half, half + 1)
    idx = base[:, None] + offsets[None, :]
    x = idx - centre[:, None]
    window = 0.5 * (1 + np.cos(np.pi * x / (half + 1)))
    return idx, np.sinc(x) * window


def synthesize_early(arrivals: Arrivals, bank: OctaveFilterBank, n_samples: int,
                     taps: int = DEFAULT_TAPS) -> np.ndarray:
    """The early part (discrete arrivals), ``(n_samples,)``."""
    if len(arrivals) == 0:
        return np.zeros(n_samples)
    if arrivals.n_bands != bank.n_bands:
        raise AcousticsError(f"arrivals: expected {bank.n_bands} bands like the filter bank, "
                             f"got {arrivals.n_bands}")
    idx, w = _fractional_taps(arrivals.times_s, bank.sample_rate_hz, taps)
    keep = (idx >= 0) & (idx < n_samples)
    trains = np.zeros((bank.n_bands, n_samples))
    for b in range(bank.n_bands):
        np.add.at(trains[b], idx[keep], (w * arrivals.amplitudes[:, b][:, None])[keep])
    return _filter_bands(trains, bank)


def _filter_bands(trains: np.ndarray, bank: OctaveFilterBank) -> np.ndarray:
    """Σ_b band_b(trains[b]): each band's signal through its own filter, summed."""
    n = trains.shape[-1]
    pad = bank.padding()
    n_fft = 1 << math.ceil(math.log2(n + 2 * pad))
    frame = np.zeros((bank.n_bands, n_fft))
    frame[:, pad:pad + n] = trains
    spectrum = np.fft.rfft(frame, axis=-1) * bank.responses(n_fft)
    return np.fft.irfft(spectrum.sum(axis=0), n=n_fft)[pad:pad + n]


def _band_noises(white: np.ndarray, bank: OctaveFilterBank) -> np.ndarray:
    """Row ``b`` of ``white`` through band ``b``'s filter only (what ``bank.split(white[b])[b]``
    gives, without filtering every row through every band)."""
    n = white.shape[-1]
    pad = bank.padding()
    n_fft = 1 << math.ceil(math.log2(n + 2 * pad))
    frame = np.zeros((bank.n_bands, n_fft))
    frame[:, pad:pad + n] = white
    spectrum = np.fft.rfft(frame, axis=-1) * bank.responses(n_fft)
    return np.fft.irfft(spectrum, n=n_fft, axis=-1)[:, pad:pad + n]


def synthesize_late(histogram: EnergyHistogram, bank: OctaveFilterBank, n_samples: int,
                    rng: np.random.Generator) -> np.ndarray:
    """The late part: band noise whose energy per bin and band matches the histogram."""
    e = np.asarray(histogram.energy, dtype=np.float64)
    if e.ndim != 2 or e.shape[1] != bank.n_bands:
        raise AcousticsError(f"histogram: expected (n_bins, {bank.n_bands}) energies, got "
                             f"{e.shape}")
    fs = bank.sample_rate_hz
    bin_len = histogram.bin_s * fs
    # Independent noise per band: bands of one noise would correlate in the crossovers and
    # add energy there; with independent noises the band energies simply add.
    white = rng.standard_normal((bank.n_bands, n_samples))
    e = e * bank.flat_energy_shares()[None, :]
    noise_bands = _band_noises(white, bank)
    t = np.arange(n_samples)
    k = np.minimum((t / bin_len).astype(np.int64), e.shape[0] - 1)
    valid = t < e.shape[0] * bin_len
    out = np.zeros(n_samples)
    centres = (np.arange(e.shape[0]) + 0.5) * bin_len
    for b in range(bank.n_bands):
        # Energy of the band noise in each bin, then the gain that brings it to the histogram.
        noise_energy = np.bincount(k[valid], weights=noise_bands[b][valid] ** 2,
                                   minlength=e.shape[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            gain = np.where(noise_energy > 0, np.sqrt(e[:, b] / noise_energy), 0.0)
        band = noise_bands[b] * np.interp(t, centres, gain) * valid
        # Interpolating the gains between bin centres moves energy between neighbouring bins
        # of a steep decay; one correction pass puts each bin's energy back on the histogram.
        got = np.bincount(k[valid], weights=band[valid] ** 2, minlength=e.shape[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            fix = np.where(got > 0, np.sqrt(e[:, b] / got), 0.0)
        out += band * np.interp(t, centres, fix)
    return out


def rir_length_samples(arrivals: Arrivals, histogram: EnergyHistogram | None,
                       sample_rate_hz: float, max_length_s: float,
                       taps: int = DEFAULT_TAPS, ring: int = 0) -> int:
    """Samples needed: past the last arrival (plus the band filters' ``ring``) and the last
    bin with energy, at most the cap."""
    end_s = float(arrivals.times_s.max()) if len(arrivals) else 0.0
    if histogram is not None:
        filled = np.flatnonzero(histogram.energy.sum(axis=1) > 0)
        if filled.size:
            end_s = max(end_s, (filled[-1] + 1) * histogram.bin_s)
    n = math.ceil(end_s * sample_rate_hz) + taps + ring
    return max(taps, min(n, math.ceil(max_length_s * sample_rate_hz)))


def synthesize_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                   sample_rate_hz: float, rng: np.random.Generator, *,
                   max_length_s: float = 2.0, bands_hz: tuple[float, ...] = (),
                   taps: int = DEFAULT_TAPS) -> np.ndarray:
    """The omnidirectional RIR of one receiver, ``(n_samples,)``, pressure per unit source."""
    bank = OctaveFilterBank(sample_rate_hz, bands_hz)
    # Keep the band filters' ringing after the last arrival (a quarter of the bank's padding,
    # where the lowest crossover's response has decayed), or unequal band amplitudes would
    # be cut short.
    n = rir_length_samples(arrivals, histogram, sample_rate_hz, max_length_s, taps,
                           bank.padding() // 4)
    rir = synthesize_early(arrivals, bank, n, taps)
    if histogram is not None:
        rir += synthesize_late(histogram, bank, n, rng)
    return rir
