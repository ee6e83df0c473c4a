"""The render step's hot paths (issue 27) give the same bytes as the numpy/scipy code they
replaced: the per-point convolution (:func:`~sonicspec.acoustics.moving.delays.oaconvolve_1d`
against ``scipy.signal.oaconvolve``) and the shaping filters (the compiled band sums and tail
cut against the numpy sums, written out here as they were)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from sonicspec.acoustics.bands import _SHAPING_FLOOR, _SHAPING_TAIL, OctaveFilterBank
from sonicspec.acoustics.moving.delays import oaconvolve_1d

BANDS_HZ = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0)


@pytest.mark.parametrize(("n1", "n2"), [
    (5500, 2000),  # one FFT (the usual piece and filter)
    (3000, 3000),  # equal lengths: fftconvolve
    (20000, 300),  # a short filter on a long piece: overlap-add blocks (scipy's own)
    (300, 20000),  # the same, swapped
    (1, 700), (700, 1), (1, 1), (2, 3), (8192, 4097), (6271, 100),
])
def test_oaconvolve_1d_is_scipys_bytes(n1: int, n2: int) -> None:
    rng = np.random.default_rng(n1 * 7919 + n2)
    x, h = rng.standard_normal(n1), rng.standard_normal(n2)
    ours = oaconvolve_1d(x, h)
    assert ours.shape == (n1 + n2 - 1,)
    assert np.array_equal(ours, signal.oaconvolve(x, h))


def test_oaconvolve_1d_is_scipys_bytes_at_random_sizes() -> None:
    rng = np.random.default_rng(27)
    for _ in range(60):
        x = rng.standard_normal(int(rng.integers(1, 12000)))
        h = rng.standard_normal(int(rng.integers(1, 9000)))
        assert np.array_equal(oaconvolve_1d(x, h), signal.oaconvolve(x, h)), (x.size, h.size)


def numpy_shaping_spectra(bank: OctaveFilterBank, g: np.ndarray, n_fft: int) -> np.ndarray:
    """``shaping_spectra`` as numpy summed it before the compiled loop (the reference)."""
    from sonicspec.acoustics.bands import _analytic_responses

    level_basis, phase_basis = _analytic_responses(bank.sample_rate_hz, bank.bands_hz,
                                                   bank.transition_octaves, n_fft)
    out = np.zeros((g.shape[0], level_basis.shape[1]), dtype=np.complex128)
    for sign in (1.0, -1.0):
        part = np.maximum(sign * g, 0.0)
        rows = np.flatnonzero(part.any(axis=1))
        if rows.size:
            part = part[rows]
            logs = np.log(np.maximum(part, _SHAPING_FLOOR * part.max(axis=1, keepdims=True)))
            level = logs[:, :1] * level_basis[0]
            phase = logs[:, :1] * phase_basis[0]
            for b in range(1, bank.n_bands):
                level += logs[:, b:b + 1] * level_basis[b]
                phase += logs[:, b:b + 1] * phase_basis[b]
            np.exp(level, out=level)
            spectra = np.empty(level.shape, dtype=np.complex128)
            spectra.real = level * np.cos(phase)
            spectra.imag = level * np.sin(phase)
            out[rows] += sign * spectra
    return out


@pytest.mark.parametrize(("rate", "n_fft"), [(16000, 2048), (48000, 16384)])
def test_shaping_spectra_at_other_sizes_are_the_numpy_bytes(rate: int, n_fft: int) -> None:
    """RIR synthesis asks for its own FFT sizes (and 48 kHz has a 7th band)."""
    bank = OctaveFilterBank(rate, (*BANDS_HZ, 8000.0) if rate > 16000 else BANDS_HZ)
    g = np.random.default_rng(rate).uniform(-0.1, 1.0, (23, bank.n_bands))
    ours, ref = bank.shaping_spectra(g, n_fft), numpy_shaping_spectra(bank, g, n_fft)
    assert np.array_equal(ours, ref)
    assert np.array_equal(np.signbit(ours.imag), np.signbit(ref.imag))


def test_shaping_filters_of_some_rows_are_those_rows_of_all() -> None:
    """A row's filter does not depend on the rows made with it (each is computed alone)."""
    bank = OctaveFilterBank(16000, BANDS_HZ)
    rng = np.random.default_rng(11)
    g = rng.uniform(-0.02, 0.3, (41, bank.n_bands))
    every = bank.shaping_filters(g)
    some = np.flatnonzero(rng.random(len(g)) < 0.5)
    for n, h in zip(some, bank.shaping_filters(g[some]), strict=True):
        assert np.array_equal(h, every[n])


def numpy_decayed_length(h: np.ndarray, cap: int) -> int:
    """The cut of one shaping filter as numpy found it before (the reference)."""
    tail = np.cumsum((h * h)[::-1])[::-1]
    if tail[0] <= 0:
        return 1
    return int(min(cap, np.flatnonzero(tail > _SHAPING_TAIL * tail[0])[-1] + 1))


@pytest.mark.parametrize("mixed", [False, True])
def test_shaping_filters_are_the_numpy_bytes(mixed: bool) -> None:
    """Positive gains (every row summed in place) and rows mixing signs or all zero (a row
    subset, and the negative part subtracted): spectra equal to the bit, the sign of zeros
    included, and the filters cut at the same sample."""
    bank = OctaveFilterBank(16000, BANDS_HZ)
    rng = np.random.default_rng(5 + mixed)
    g = rng.uniform(-0.05 if mixed else 0.001, 0.3, (37, bank.n_bands))
    g[3] = 0.0  # a silent row
    g[4] = 0.2  # a flat row: the one-sample filter
    n_fft = bank.shaping_fft_size()
    ours, ref = bank.shaping_spectra(g, n_fft), numpy_shaping_spectra(bank, g, n_fft)
    assert np.array_equal(ours, ref)
    assert np.array_equal(np.signbit(ours.real), np.signbit(ref.real))
    assert np.array_equal(np.signbit(ours.imag), np.signbit(ref.imag))
    filters = bank.shaping_filters(g)
    h = np.fft.irfft(ref, n_fft, axis=-1)
    for n, f in enumerate(filters):
        if n == 4:
            assert np.array_equal(f, [0.2])
            continue
        assert np.array_equal(f, h[n, :numpy_decayed_length(h[n], n_fft)]), n
