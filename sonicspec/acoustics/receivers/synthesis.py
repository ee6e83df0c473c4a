"""RIR synthesis for an omnidirectional receiver: discrete early arrivals plus a late tail.

* **Early part** (direct sound, image sources, diffracted paths): each arrival is a
  fractional-delay tap (a Hann-windowed sinc, ``taps`` long, so the peak sits at the exact
  arrival time, not the nearest sample). An arrival with the same amplitude in every band is
  that tap, scaled; any other goes through its own minimum-phase shaping filter, whose
  magnitude is the octave bank's bands weighted by its amplitudes
  (:meth:`~sonicspec.acoustics.bands.OctaveFilterBank.shaping_spectra`). The filter is
  causal, so nothing of an arrival precedes its delay by more than the tap's half-width
  (``taps // 2`` samples); zero-phase band filters rang before it (issue 28).
* **Late part** (the ray tracer's energy histogram): independent white Gaussian noise per band,
  band-filtered by the same bank (drawn directly in the frequency domain, where white Gaussian
  noise is white complex Gaussian noise, over the band's support only: the same random
  process, at a fraction of the cost); in every band the noise is scaled so that the energy it
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
* **Length**: past the last arrival (with its shaping filter's ringing) and the last bin holding
  energy, capped at ``max_length_s``.

Amplitudes are sound pressure for a unit point source: the free-field direct sound is
``1/(4πr)`` at ``r/c`` (DESIGN.md §5). All randomness comes from the generator passed in.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.errors import AcousticsError
from sonicspec.units import seconds_to_samples_ceil

DEFAULT_TAPS = 65
# Band responses below this are zero for the noise (the crossovers' cos² ends at ~1e-33).
_SUPPORT_FLOOR = 1e-12
# Rows per matrix-vector product of the per-bin sums (BLAS would thread larger ones).
_GEMV_ROWS = 1 << 14
# Shaped arrivals per batch of FFTs (bounds the memory: rows × the shaping FFT's length).
_SHAPED_CHUNK = 64


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
    """The early part (discrete arrivals), ``(n_samples,)``.

    An arrival with the same amplitude in every band is its fractional-delay tap, scaled.
    Any other is that tap through its minimum-phase shaping filter
    (:meth:`~sonicspec.acoustics.bands.OctaveFilterBank.shaping_spectra`: the magnitude of
    the bank's bands weighted by its amplitudes), so nothing of it comes before its delay
    by more than the tap's half-width (``taps // 2`` samples) — zero-phase band filters rang
    up to 6 ms early.
    """
    if len(arrivals) == 0:
        return np.zeros(n_samples)
    if arrivals.n_bands != bank.n_bands:
        raise AcousticsError(f"arrivals: expected {bank.n_bands} bands like the filter bank, "
                             f"got {arrivals.n_bands}")
    idx, w = _fractional_taps(arrivals.times_s, bank.sample_rate_hz, taps)
    amplitudes = arrivals.amplitudes
    flat = np.all(amplitudes == amplitudes[:, :1], axis=1)
    kernels = np.ones((len(arrivals), 1))  # a flat arrival's kernel is its tap
    return _place_kernels(idx, w, amplitudes, flat, kernels, bank, n_samples)[0]


def _place_kernels(idx: np.ndarray, w: np.ndarray, amplitudes: np.ndarray, flat: np.ndarray,
                   kernels: np.ndarray, bank: OctaveFilterBank, n_samples: int) -> np.ndarray:
    """``(channels, n_samples)``: each arrival's fractional tap ``w`` (from sample
    ``idx[:, 0]``) convolved with its kernel per channel (``kernels`` ``(n, channels, K)``, or
    ``(n, K)`` for one) and scaled by its amplitude — the flat arrivals' one amplitude, the
    others' minimum-phase shaping filter — added into the output (causal: from the tap's
    first sample on)."""
    kernels = kernels[:, None, :] if kernels.ndim == 2 else kernels
    _, channels, k_len = kernels.shape
    taps = w.shape[1]
    out = np.zeros((channels, n_samples))
    # Flat arrivals: tap ⊛ kernel, all at once.
    rows = np.flatnonzero(flat)
    if rows.size:
        span = taps + k_len - 1
        if k_len == 1:
            shaped = w[rows, None, :] * kernels[rows]
        else:
            n_fft = 1 << math.ceil(math.log2(span))
            shaped = np.fft.irfft(np.fft.rfft(w[rows], n_fft)[:, None, :]
                                  * np.fft.rfft(kernels[rows], n_fft, axis=-1),
                                  n_fft, axis=-1)[..., :span]
        _add_at(out, idx[rows, 0], shaped * amplitudes[rows, :1, None])
    rows = np.flatnonzero(~flat)
    if rows.size:
        n_fft = bank.shaping_fft_size()
        while n_fft < 2 * bank.padding() + taps + k_len:
            n_fft *= 2
        span = 2 * bank.padding() + taps + k_len - 2
        for chunk in np.array_split(rows, max(1, math.ceil(rows.size / _SHAPED_CHUNK))):
            spectra = bank.shaping_spectra(amplitudes[chunk], n_fft) * np.fft.rfft(
                w[chunk], n_fft)
            if k_len > 1:
                spectra = spectra[:, None, :] * np.fft.rfft(kernels[chunk], n_fft, axis=-1)
            else:
                spectra = spectra[:, None, :] * kernels[chunk, :, :1]
            _add_at(out, idx[chunk, 0], np.fft.irfft(spectra, n_fft, axis=-1)[..., :span])
    return out


def _add_at(out: np.ndarray, start: np.ndarray, pieces: np.ndarray) -> None:
    """``out[c, start[n] + j] += pieces[n, c, j]`` where that lies inside ``out``."""
    n_samples = out.shape[1]
    length = pieces.shape[-1]
    for n, s0 in enumerate(start.tolist()):
        lo, hi = max(0, -s0), min(length, n_samples - s0)
        if lo < hi:
            out[:, s0 + lo:s0 + hi] += pieces[n, :, lo:hi]


def _fft_size(n: int) -> int:
    """Smallest ``2^a``, ``3·2^a``, ``5·2^a`` or ``15·2^a`` >= ``n``: a fast FFT length, from a
    coarse set so that the bank's cached responses are reused across RIRs."""
    best = 1 << max(0, math.ceil(math.log2(max(n, 1))))
    for odd in (3, 5, 15):
        size = odd << max(0, math.ceil(math.log2(max(n, 1) / odd)))
        best = min(best, size)
    return best


@functools.lru_cache(maxsize=32)
def _band_support(bank: OctaveFilterBank, n_fft: int) -> tuple[tuple[tuple[int, int], ...],
                                                               tuple[np.ndarray, ...]]:
    """Per band, the rfft bins ``[lo, hi)`` where its response is not (numerically) zero, and
    the response there (float32, read-only)."""
    resp = bank.responses(n_fft)
    spans, values = [], []
    for b in range(bank.n_bands):
        nz = np.flatnonzero(resp[b] > _SUPPORT_FLOOR)
        lo, hi = int(nz[0]), int(nz[-1]) + 1
        part = resp[b, lo:hi].astype(np.float32)
        part.flags.writeable = False
        spans.append((lo, hi))
        values.append(part)
    return tuple(spans), tuple(values)


@functools.lru_cache(maxsize=32)
def _flat_energy_shares(bank: OctaveFilterBank) -> np.ndarray:
    shares = bank.flat_energy_shares()
    shares.flags.writeable = False
    return shares


def _band_noises(bank: OctaveFilterBank, n_samples: int, rng: np.random.Generator
                 ) -> np.ndarray:
    """Independent Gaussian noises ``(n_bands, n_samples)`` in float32, row ``b`` with band
    ``b``'s spectrum: white Gaussian noise through that band's filter alone.

    Drawn in the frequency domain: the DFT of white Gaussian noise is white complex Gaussian
    noise (real at DC and Nyquist), so each band's spectrum is drawn only where its response
    is non-zero, weighted by it and transformed once. The noise is circular over the FFT
    frame (no edge transients, no padding). float32: the noise is rescaled bin by bin to the
    histogram, so only its shape matters, and the RIRs are stored in float32.
    """
    n_fft = _fft_size(n_samples)
    n_freq = n_fft // 2 + 1
    spans, resp = _band_support(bank, n_fft)
    z = rng.standard_normal(2 * sum(hi - lo for lo, hi in spans), dtype=np.float32)
    z = z.view(np.complex64)
    spectrum = np.zeros((bank.n_bands, n_freq), dtype=np.complex64)
    start = 0
    for b, (lo, hi) in enumerate(spans):
        np.multiply(z[start:start + hi - lo], resp[b], out=spectrum[b, lo:hi])
        start += hi - lo
    # Real DC and Nyquist bins with the variance of the others' modulus.
    edges = [0, n_freq - 1] if n_fft % 2 == 0 else [0]
    spectrum[:, edges] = math.sqrt(2.0) * spectrum[:, edges].real
    return np.fft.irfft(spectrum, n=n_fft, axis=-1)[:, :n_samples]


class _Bins:
    """Samples ``0…n-1`` of a signal against histogram bins of ``bin_len`` samples: per-bin
    sums of squares, and per-bin values interpolated linearly between bin centres (constant
    before the first centre and after the last), as :func:`numpy.interp` would.

    With a whole number of samples per bin (1 ms at 16 kHz: 16) both avoid gathers: sums
    are a product with a vector of ones over (bin, sample) blocks, and the interpolation is
    ``V[j] + D·(r/L - 0.5)`` for sample ``r`` of bin ``j`` (``D`` the slope towards the
    neighbouring centre), built from repeats.
    """

    def __init__(self, n_bins: int, bin_len: float, n_samples: int) -> None:
        t = np.arange(min(n_samples, math.ceil(n_bins * bin_len)))
        t = t[t < n_bins * bin_len]  # samples inside the histogram
        self.n = t.size
        self.n_bins = n_bins
        self.length = int(bin_len) if float(bin_len).is_integer() and bin_len >= 1 else 0
        if self.length:
            length = self.length
            self.full = self.n // length  # bins with all their samples
            self.m = -(-self.n // length)  # bins with any
            r = np.arange(length) / length - 0.5  # offset from the bin centre, in bins
            self.offset = np.tile(r.astype(np.float32), self.m)[:self.n]
            self.ones = np.ones(length, dtype=np.float32)
            return
        k = np.minimum((t / bin_len).astype(np.int64), n_bins - 1)
        starts = np.flatnonzero(np.diff(k, prepend=-1))
        # Every bin up to the last one reached holds a sample: sums are one reduceat.
        self.k = k
        self.starts = starts if self.n and len(starts) == k[-1] + 1 else None
        pos = t / bin_len - 0.5
        self.j0 = np.clip(np.floor(pos).astype(np.int64), 0, max(n_bins - 2, 0))
        self.frac = np.clip(pos - self.j0, 0.0, 1.0).astype(np.float32)

    def energies(self, x: np.ndarray) -> np.ndarray:
        """Σ x² over each bin's samples, per row, ``(rows, n_bins)`` float64."""
        sq = x * x
        rows = x.shape[0]
        out = np.zeros((rows, self.n_bins))
        if self.n == 0:
            return out
        if self.length:
            length, full = self.length, self.full
            blocks = sq[:, :full * length].reshape(rows * full, length)
            sums = np.empty(rows * full, dtype=sq.dtype)
            for i in range(0, len(blocks), _GEMV_ROWS):  # (BLAS threads larger products)
                sums[i:i + _GEMV_ROWS] = blocks[i:i + _GEMV_ROWS] @ self.ones
            out[:, :full] = sums.reshape(rows, full)
            if self.m > full:
                out[:, full] = sq[:, full * length:].sum(axis=1)
            return out
        if self.starts is not None:
            out[:, :len(self.starts)] = np.add.reduceat(sq, self.starts, axis=1)
            return out
        flat = (np.arange(rows)[:, None] * self.n_bins + self.k[None, :]).ravel()
        return np.bincount(flat, weights=sq.ravel(), minlength=rows * self.n_bins
                           ).reshape(rows, self.n_bins)

    def interpolate(self, values: np.ndarray) -> np.ndarray:
        """Per-bin ``values`` (rows, n_bins) -> per-sample (rows, n) float32."""
        values = values.astype(np.float32)
        nb = values.shape[1]
        if not self.length:
            lo = np.take(values, self.j0, axis=1)
            hi = np.take(values, np.minimum(self.j0 + 1, nb - 1), axis=1)
            hi -= lo
            hi *= self.frac
            hi += lo
            return hi
        # Sample r of bin j lies between centres j-1 and j (r < L/2) or j and j+1: the value
        # is V[j] + D·(r/L - 0.5), D = V[j] - V[j-1] or V[j+1] - V[j] (0 beyond the ends).
        length, m = self.length, self.m
        last = min(m, nb - 1)
        clamped = np.concatenate([values[:, :1], values[:, :m], values[:, last:last + 1]],
                                 axis=1)  # V[-1…m], clamped to the histogram
        slopes = clamped[:, 1:] - clamped[:, :-1]  # D between centres j-1 and j, j = 0…m
        shift = length - (length + 1) // 2
        out = np.repeat(slopes, length, axis=1)[:, shift:shift + self.n]
        out *= self.offset
        out += np.repeat(clamped[:, 1:m + 1], length, axis=1)[:, :self.n]
        return out


@functools.lru_cache(maxsize=16)
def _bins(n_bins: int, bin_len: float, n_samples: int) -> _Bins:
    """Cached: every RIR of a trace has the same bins and, mostly, the same length."""
    return _Bins(n_bins, bin_len, n_samples)


def synthesize_late(histogram: EnergyHistogram, bank: OctaveFilterBank, n_samples: int,
                    rng: np.random.Generator) -> np.ndarray:
    """The late part: band noise whose energy per bin and band matches the histogram."""
    e = np.asarray(histogram.energy, dtype=np.float64)
    if e.ndim != 2 or e.shape[1] != bank.n_bands:
        raise AcousticsError(f"histogram: expected (n_bins, {bank.n_bands}) energies, got "
                             f"{e.shape}")
    bins = _bins(e.shape[0], float(histogram.bin_s * bank.sample_rate_hz), n_samples)
    # Independent noise per band: bands of one noise would correlate in the crossovers and
    # add energy there; with independent noises the band energies simply add.
    noise = _band_noises(bank, n_samples, rng)[:, :bins.n]
    e = (e * _flat_energy_shares(bank)[None, :]).T  # (n_bands, n_bins)
    with np.errstate(divide="ignore", invalid="ignore"):
        # Energy of the band noise in each bin, then the gain that brings it to the histogram.
        noise_energy = bins.energies(noise)
        gain = np.where(noise_energy > 0, np.sqrt(e / noise_energy), 0.0)
        band = noise * bins.interpolate(gain)
        # Interpolating the gains between bin centres moves energy between neighbouring bins
        # of a steep decay; one correction pass puts each bin's energy back on the histogram.
        got = bins.energies(band)
        fix = np.where(got > 0, np.sqrt(e / got), 0.0)
    band *= bins.interpolate(fix)
    out = np.zeros(n_samples)
    out[:bins.n] = band.sum(axis=0, dtype=np.float64)
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
    n = seconds_to_samples_ceil(end_s, sample_rate_hz) + taps + ring
    return max(taps, min(n, seconds_to_samples_ceil(max_length_s, sample_rate_hz)))


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
