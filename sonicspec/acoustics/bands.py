"""Octave bands and a filter bank whose bands sum back exactly to the input.

The bank is zero-phase and works in the FFT domain: between neighbouring bands an
amplitude-complementary crossover at the band edge (a raised cosine in log-frequency,
``transition_octaves`` wide), the lowest band taking everything below its upper edge (DC
included) and the highest everything up to Nyquist. The band responses therefore add up to one
at every frequency, so splitting a signal and summing the bands returns it to float precision —
what RIR synthesis from per-band parts needs. Each response is real, non-negative and exactly 1
at its band centre (transitions narrower than an octave never reach a centre).

Splitting is for analysis (band figures of an RIR). A *path* shaped by per-band gains is not
split and re-summed: zero-phase band filters ring before the path's delay (a diffracted arrival
behind a screen rose up to 0.4 ms early, −40…−60 dB energy up to 6 ms early). Its filter is the
minimum-phase one of the same magnitude ``|Σ_b g_b·R_b(f)|``
(:meth:`OctaveFilterBank.shaping_filters`): causal, it starts at the path's delay, and a flat
path (all gains equal) is a plain scaled impulse.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sonicspec.errors import AcousticsError
from sonicspec.units import OCTAVE_BANDS_HZ, bands_below_nyquist


def band_edges_hz(centres_hz: Sequence[float]) -> np.ndarray:
    """(n, 2) lower and upper edge of each octave band: centre / √2, centre · √2."""
    c = np.asarray(centres_hz, dtype=np.float64)
    return np.column_stack([c / math.sqrt(2.0), c * math.sqrt(2.0)])


def default_bands(sample_rate_hz: float) -> tuple[float, ...]:
    """The octave bands 125 Hz… whose upper edge lies below Nyquist."""
    return bands_below_nyquist(sample_rate_hz, OCTAVE_BANDS_HZ)


def _lowpass(freqs: np.ndarray, edge_hz: float, width_oct: float) -> np.ndarray:
    """1 below the transition, 0 above, raised cosine in log2(f) across it."""
    with np.errstate(divide="ignore"):
        x = (np.log2(np.maximum(freqs, 1e-30) / edge_hz) + width_oct / 2) / width_oct
    x = np.clip(x, 0.0, 1.0)
    out = np.cos(0.5 * np.pi * x) ** 2
    out[freqs <= 0] = 1.0
    return out


@functools.lru_cache(maxsize=32)
def _responses(sample_rate_hz: float, bands_hz: tuple[float, ...], transition_octaves: float,
               n_fft: int) -> np.ndarray:
    freqs = np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz)
    edges = [c * math.sqrt(2.0) for c in bands_hz[:-1]]  # between band k and k + 1
    lows = [_lowpass(freqs, e, transition_octaves) for e in edges]
    out = np.empty((len(bands_hz), freqs.size))
    for k in range(len(bands_hz)):
        below = lows[k] if k < len(lows) else np.ones_like(freqs)
        above = 1.0 - lows[k - 1] if k > 0 else np.ones_like(freqs)
        out[k] = below * above
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class OctaveFilterBank:
    """Zero-phase octave filter bank, bands summing exactly to one (see the module docstring).

    Parameters
    ----------
    sample_rate_hz : float
        Sample rate of the signals, Hz.
    bands_hz : sequence of float, optional
        Band centres, Hz (default: the octave bands below Nyquist).
    transition_octaves : float
        Width of each crossover, octaves, in (0, 1].
    """

    sample_rate_hz: float
    bands_hz: tuple[float, ...] = ()
    transition_octaves: float = 0.5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
            raise AcousticsError(f"OctaveFilterBank.sample_rate_hz: expected > 0, got "
                                 f"{self.sample_rate_hz!r}")
        bands = tuple(float(b) for b in self.bands_hz) or default_bands(self.sample_rate_hz)
        if not bands:
            raise AcousticsError(f"OctaveFilterBank: no octave band fits below Nyquist at "
                                 f"{self.sample_rate_hz:g} Hz")
        if any(b2 <= b1 for b1, b2 in itertools.pairwise(bands)) or bands[0] <= 0:
            raise AcousticsError(f"OctaveFilterBank.bands_hz: expected increasing positive "
                                 f"centres, got {list(bands)}")
        if bands[-1] >= self.sample_rate_hz / 2:
            raise AcousticsError(f"OctaveFilterBank.bands_hz: {bands[-1]:g} Hz is not below "
                                 f"Nyquist ({self.sample_rate_hz / 2:g} Hz)")
        if not 0 < self.transition_octaves <= 1:
            raise AcousticsError(f"OctaveFilterBank.transition_octaves: expected a width in "
                                 f"(0, 1], got {self.transition_octaves!r}")
        object.__setattr__(self, "bands_hz", bands)

    @property
    def n_bands(self) -> int:
        return len(self.bands_hz)

    def responses(self, n_fft: int) -> np.ndarray:
        """Magnitude (= real, zero-phase) response of each band on the rfft grid, (n_bands, F).

        Cached (read-only): synthesis asks for the same grid for every RIR it makes.
        """
        return _responses(self.sample_rate_hz, self.bands_hz, self.transition_octaves,
                          int(n_fft))

    def flat_energy_shares(self, n_fft: int = 1 << 16) -> np.ndarray:
        """Share of a flat spectrum's energy that falls in each band, ``(n_bands,)``.

        An impulse of amplitude ``A`` has energy ``A²``; band ``b`` holds ``A² · share_b`` of it
        (Parseval over the band's response). Energies quoted "per band" for a flat source —
        the ray tracer's histograms — must be weighted by these shares to become band energies
        of a signal.
        """
        resp = self.responses(n_fft) ** 2
        weights = np.full(resp.shape[1], 2.0)  # rfft bins stand for two full-spectrum bins
        weights[0] = 1.0
        if n_fft % 2 == 0:
            weights[-1] = 1.0
        return (resp * weights).sum(axis=1) / n_fft

    def padding(self) -> int:
        """Samples of zero padding that keep circular wrap-around negligible.

        The lowest crossover's impulse response is the longest; its decay scales with the
        inverse of the transition width at that edge.
        """
        lowest_edge = self.bands_hz[0] * math.sqrt(2.0)
        half = self.transition_octaves / 2
        width_hz = lowest_edge * (2**half - 2**-half)
        return math.ceil(8.0 * self.sample_rate_hz / max(width_hz, 1e-9))

    def split(self, x: np.ndarray, axis: int = -1) -> np.ndarray:
        """Band signals of ``x``, shape ``(n_bands, *x.shape)``; they sum back to ``x``."""
        x = np.asarray(x, dtype=np.float64)
        if x.size == 0:
            raise AcousticsError("OctaveFilterBank.split: expected a non-empty signal")
        if not np.all(np.isfinite(x)):
            raise AcousticsError("OctaveFilterBank.split: expected finite samples")
        x = np.moveaxis(x, axis, -1)
        n = x.shape[-1]
        pad = self.padding()
        n_fft = 1 << math.ceil(math.log2(n + 2 * pad))
        # Centre the signal in the padded frame so the non-causal tails have room both sides.
        frame = np.zeros((*x.shape[:-1], n_fft))
        frame[..., pad:pad + n] = x
        spectrum = np.fft.rfft(frame, axis=-1)
        resp = self.responses(n_fft)
        bands = np.fft.irfft(spectrum[None] * resp.reshape((self.n_bands,) + (1,) * (x.ndim - 1)
                                                           + (-1,)), n=n_fft, axis=-1)
        bands = bands[..., pad:pad + n]
        return np.moveaxis(bands, -1, axis + 1 if axis >= 0 else axis)

    def shaping_fft_size(self) -> int:
        """FFT length of :meth:`shaping_spectra`: room for the shaping filters' ringing
        (``2·padding()``) and a fractional tap after it."""
        return 1 << math.ceil(math.log2(2 * self.padding() + 128))

    def shaping_spectra(self, gains: np.ndarray, n_fft: int | None = None) -> np.ndarray:
        """Spectra of the causal filters that shape a path by band gains, ``(N, n_fft//2+1)``.

        Row ``n`` has the magnitude ``Π_b |g_b|^R_b(f)`` — each band's gain at its centre, the
        gains interpolated in dB across the crossovers (the bands' responses sum to one) — and
        minimum phase: ``exp(Σ_b log|g_b|·K_b(f))``, ``K_b`` the bank's responses made
        analytic (their folded real cepstra), so its impulse response starts at t = 0 and
        nothing of it comes earlier. A row of one sign throughout gets that sign; a row mixing
        signs is shaped as its positive part minus its negative part (each minimum-phase).
        Gains are floored at -100 dB of the row's largest.
        """
        from sonicspec.acoustics._band_kernels import band_sums

        g = np.atleast_2d(np.asarray(gains, dtype=np.float64))
        if g.ndim != 2 or g.shape[1] != self.n_bands:
            raise AcousticsError(f"shaping gains: expected (N, {self.n_bands}), got "
                                 f"{g.shape}")
        n_fft = int(n_fft or self.shaping_fft_size())
        level_basis, phase_basis = _analytic_responses(self.sample_rate_hz, self.bands_hz,
                                                       self.transition_octaves, n_fft)
        out = np.zeros((g.shape[0], level_basis.shape[1]), dtype=np.complex128)
        for sign in (1.0, -1.0):
            part = np.maximum(sign * g, 0.0)
            rows = np.flatnonzero(part.any(axis=1))
            if rows.size:
                part = part[rows]
                floor = _SHAPING_FLOOR * part.max(axis=1, keepdims=True)
                logs = np.log(np.maximum(part, floor))
                # log-magnitude and phase, band by band (real arithmetic in one compiled
                # pass; no BLAS, whose threads fight the build's other jobs)
                level = np.empty((rows.size, level_basis.shape[1]))
                phase = np.empty_like(level)
                band_sums(logs, level_basis, phase_basis, level, phase)
                np.exp(level, out=level)
                real = np.cos(phase)
                real *= level
                imag = np.sin(phase, out=phase)
                imag *= level
                if sign < 0:
                    np.negative(real, out=real)
                    np.negative(imag, out=imag)
                if rows.size == g.shape[0]:  # every row: added in place, no temporaries
                    out.real += real
                    out.imag += imag
                else:
                    out.real[rows] += real
                    out.imag[rows] += imag
        return out

    def shaping_filters(self, gains: np.ndarray) -> list[np.ndarray]:
        """Causal impulse responses of :meth:`shaping_spectra`, one per row of ``gains``,
        cut where less than 1e-10 of its energy is left; a row of equal gains is the
        one-sample filter ``[g]`` (exactly what it was)."""
        g = np.atleast_2d(np.asarray(gains, dtype=np.float64))
        flat = np.all(g == g[:, :1], axis=1)
        out: list[np.ndarray] = [np.array([row[0]]) for row in g[:, :1]]
        shaped = np.flatnonzero(~flat)
        if shaped.size:
            n_fft = self.shaping_fft_size()
            h = np.fft.irfft(self.shaping_spectra(g[shaped], n_fft), n_fft, axis=-1)
            for n, row, length in zip(shaped, h, _decayed_lengths(h, n_fft), strict=True):
                out[n] = row[:length]
        return out

    @staticmethod
    def merge(bands: np.ndarray) -> np.ndarray:
        """Sum of the bands (the inverse of :meth:`split`)."""
        return np.asarray(bands).sum(axis=0)


_SHAPING_FLOOR = 1e-5  # -100 dB of the largest magnitude: where the log stops following it
_SHAPING_TAIL = 1e-10  # energy share left in a cut shaping filter


@functools.lru_cache(maxsize=32)
def _analytic_responses(sample_rate_hz: float, bands_hz: tuple[float, ...],
                        transition_octaves: float, n_fft: int
                        ) -> tuple[np.ndarray, np.ndarray]:
    """``K_b(f)``: band ``b``'s response as the log-magnitude of a minimum-phase filter
    (the causal part of its real cepstrum, doubled), on the rfft grid of ``n_fft``; computed
    on a 16× finer grid so the cepstrum does not alias, read back every 16th bin. Its real
    part (the response) and imaginary part (the phase it brings), each contiguous."""
    fine = 16 * n_fft
    resp = _responses(sample_rate_hz, bands_hz, transition_octaves, fine)
    cep = np.fft.irfft(resp, fine, axis=-1)
    half = fine // 2
    cep[:, 1:half] *= 2.0
    cep[:, half + 1:] = 0.0
    spectrum = np.fft.rfft(cep, axis=-1)[:, ::16]
    level, phase = np.ascontiguousarray(spectrum.real), np.ascontiguousarray(spectrum.imag)
    level.flags.writeable = False
    phase.flags.writeable = False
    return level, phase


def _decayed_lengths(h: np.ndarray, cap: int) -> np.ndarray:
    """Samples of each row of ``h`` ``(N, n)`` before all but ``_SHAPING_TAIL`` of its energy
    has come, capped at ``cap`` (1 for a silent row); compiled
    (:func:`~sonicspec.acoustics._band_kernels.decayed_lengths`)."""
    from sonicspec.acoustics._band_kernels import decayed_lengths

    out = np.empty(h.shape[0], dtype=np.int64)
    decayed_lengths(np.ascontiguousarray(h, dtype=np.float64), _SHAPING_TAIL, cap, out)
    return out
