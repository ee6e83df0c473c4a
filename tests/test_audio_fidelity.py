"""The yardsticks of moving-source rendering (``audio.fidelity``): SNR and smoothed dips."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.audio.fidelity import dip_figures, snr_db, spectral_deviation_db
from sonicspec.errors import AudioError

FS = 16000


def noise(n: int = 2 * FS, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(n)


def test_identical_signals_have_no_deviation_and_infinite_snr() -> None:
    x = noise()
    dev, centres, freqs = spectral_deviation_db(x, x, FS)
    assert np.all(dev == 0) and dev.shape == (len(centres), len(freqs))
    assert freqs[0] == 200 and freqs[-1] <= 5000
    assert snr_db(x, x) == float("inf")


def test_half_the_amplitude_is_six_db_down_everywhere() -> None:
    x = noise()
    dev, _, _ = spectral_deviation_db(x, 0.5 * x, FS)
    assert np.allclose(dev, 20 * np.log10(0.5))
    assert snr_db(x, 0.5 * x) == pytest.approx(20 * np.log10(2))


def test_a_comb_filter_dips_at_its_notch() -> None:
    """``x + x`` delayed by 8 samples notches 1 kHz (and 3 kHz): 1/6-octave smoothing of
    4 cos²(π f / 2 kHz) around 1 kHz leaves about −19 dB."""
    x = noise()
    comb = x + np.concatenate([np.zeros(8), x[:-8]])
    dev, _, freqs = spectral_deviation_db(x, comb, FS)
    worst = np.unravel_index(np.argmin(dev), dev.shape)
    assert abs(np.log2(freqs[worst[1]] / 1000.0)) < 1 / 12 or abs(
        np.log2(freqs[worst[1]] / 3000.0)) < 1 / 12
    figures = dip_figures(dev)
    assert -25 < figures["worst_db"] < -15
    assert figures["p5_db"] > figures["worst_db"]


def test_only_loud_frames_inside_the_active_span_count() -> None:
    x = noise(3 * FS)
    x[: FS] *= 1e-4  # a quiet first second: 80 dB down, below the 40 dB floor
    _, centres, _ = spectral_deviation_db(x, x, FS)
    assert centres.min() >= FS - 512
    _, centres, _ = spectral_deviation_db(x, x, FS, active=(2 * FS, 3 * FS))
    assert centres.min() >= 2 * FS and centres.max() < 3 * FS


def test_bad_inputs_are_named() -> None:
    with pytest.raises(AudioError, match="band_hz: expected 0 < low < high <= 8000"):
        spectral_deviation_db(noise(), noise(), FS, band_hz=(200, 9000))
    with pytest.raises(AudioError, match="reference: expected a signal, got silence"):
        snr_db(np.zeros(10), np.ones(10))
    with pytest.raises(AudioError, match="no frame counted"):
        dip_figures(np.zeros((0, 3)))
    with pytest.raises(AudioError, match="expected 1-D signals"):
        snr_db(np.zeros((2, 3)), np.zeros(3))
