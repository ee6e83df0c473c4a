"""The exact moving point source (``theory.moving_point_source``): the reference the moving-source
renderer is measured against (issue 18), checked here against what is known in closed form."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import hilbert

from sonicspec.acoustics.theory import (
    moving_arrival_times,
    moving_point_source,
    shoebox_moving_images,
    windowed_sinc,
)
from sonicspec.errors import AcousticsError

FS = 16000
C = 343.0


def band_limited_noise(n: int, seed: int = 0, top: float = 0.8) -> np.ndarray:
    """White noise with nothing above ``top`` × Nyquist (set to zero in the spectrum)."""
    spec = np.fft.rfft(np.random.default_rng(seed).standard_normal(n))
    spec[int(top * len(spec)):] = 0
    return np.fft.irfft(spec, n)


def fft_delay(x: np.ndarray, delay: float, n_out: int) -> np.ndarray:
    """``x`` delayed by a fractional number of samples, exactly (periodic, zero-padded)."""
    n = 4 * n_out
    spec = np.fft.rfft(x, n) * np.exp(-2j * np.pi * np.fft.rfftfreq(n) * delay)
    return np.fft.irfft(spec, n)[:n_out]


def frequency_hz(y: np.ndarray, centre: int, half: int) -> float:
    """Mean frequency of ``y`` around sample ``centre``: slope of its analytic phase."""
    phase = np.unwrap(np.angle(hilbert(y)))
    n = np.arange(centre - half, centre + half)
    return float(np.polyfit(n / FS, phase[n], 1)[0] / (2 * np.pi))


def amplitude(y: np.ndarray, centre: int, half: int, f_hz: float) -> float:
    """Amplitude of the tone ``f_hz`` in ``y`` around sample ``centre`` (least squares)."""
    n = np.arange(centre - half, centre + half)
    basis = np.stack([np.sin(2 * np.pi * f_hz * n / FS), np.cos(2 * np.pi * f_hz * n / FS)], 1)
    coef = np.linalg.lstsq(basis, y[n], rcond=None)[0]
    return float(np.hypot(*coef))


def snr_db(ref: np.ndarray, est: np.ndarray) -> float:
    return 10 * np.log10(np.sum(ref**2) / np.sum((ref - est) ** 2))


def test_a_static_source_is_a_fractional_delay_and_1_over_4_pi_r() -> None:
    x = band_limited_noise(4000)
    src, mic = np.array([1.0, 2.0, 1.5]), np.array([4.3, 2.7, 1.2])
    r = np.linalg.norm(src - mic)
    y = moving_point_source(x, src, mic, FS, speed_of_sound_m_s=C)
    exact = fft_delay(x, r / C * FS, len(y)) / (4 * np.pi * r)
    core = slice(int(r / C * FS) + 40, int(r / C * FS) + 3900)  # away from the ends' windows
    assert snr_db(exact[core], y[core]) > 80


def test_each_sample_arrives_at_its_emission_time_plus_r_over_c() -> None:
    # 2.14375 m is exactly 100 samples at 16 kHz: one tap carries the whole impulse.
    x = np.zeros(64)
    x[10] = 1.0
    y = moving_point_source(x, [0.0, 0.0, 0.0], [2.14375, 0.0, 0.0], FS, speed_of_sound_m_s=C)
    assert np.argmax(np.abs(y)) == 110
    assert y[110] == pytest.approx(1 / (4 * np.pi * 2.14375), rel=1e-12)
    assert np.max(np.abs(np.delete(y, 110))) < 1e-12
    # Moving: the arrival follows the position at emission, not at reception.
    path = np.zeros((64, 3))
    path[:, 0] = np.linspace(0.0, -0.63, 64)  # receding at ~160 m/s (a large, clear effect)
    t_a, r = moving_arrival_times(path, [2.14375, 0.0, 0.0], 64, FS, C)
    assert r[10] == pytest.approx(2.14375 + 0.63 * 10 / 63)
    assert t_a[10] * FS == pytest.approx(10 + r[10] / C * FS)


def test_doppler_shift_of_a_passing_tone_is_f_c_over_c_minus_v_r() -> None:
    f0, v = 1000.0, 10.0
    n = 4 * FS
    t = np.arange(n) / FS
    path = np.stack([-20.0 + v * t, np.full(n, 5.0), np.zeros(n)], axis=1)  # passes at 2 s
    mic = np.zeros(3)
    y = moving_point_source(np.sin(2 * np.pi * f0 * t), path, mic, FS, speed_of_sound_m_s=C)
    t_a, r = moving_arrival_times(path, mic, n, FS, C)
    v_r = -np.einsum("ij,ij->i", np.gradient(path, 1 / FS, axis=0), path - mic) / r  # approach
    shifted = f0 * C / (C - v_r)
    for emitted_at in (0.5, 1.0, 1.8, 2.2, 3.0, 3.5):
        k = int(emitted_at * FS)
        j = round(t_a[k] * FS)
        # Near the pass the shift changes fast: a short window (10 ms), compared with the
        # shift's mean over the emissions heard in it.
        heard = (t_a * FS >= j - 80) & (t_a * FS < j + 80)
        assert frequency_hz(y, j, 80) == pytest.approx(np.mean(shifted[heard]), abs=0.05), \
            emitted_at
    # And the shift is the textbook one far from the pass: f c / (c ∓ v cos θ).
    k = int(0.5 * FS)
    cos = (path[k, 0] - 0.0) / r[k] * -1
    assert np.mean((f0 * C / (C - v_r))[k - 10:k + 10]) == pytest.approx(
        f0 * C / (C - v * cos), abs=0.05)


def test_a_moving_receiver_hears_f_times_c_plus_v_over_c() -> None:
    f0, v = 1000.0, 10.0
    n = 3 * FS
    t = np.arange(n) / FS
    receiver = np.stack([30.0 - v * t, np.zeros(n), np.zeros(n)], axis=1)  # walks towards
    y = moving_point_source(np.sin(2 * np.pi * f0 * t), np.zeros(3), receiver, FS,
                            speed_of_sound_m_s=C, n_out=n)
    assert frequency_hz(y, int(1.5 * FS), FS // 2) == pytest.approx(f0 * (C + v) / C, abs=1e-3)
    # Its level is 1/(4π r), r the path the sound travelled, times the density of the
    # arrivals dt_e/dt_a = (c + v)/c (the Dirac sum's Doppler factor; see the theory module).
    t_a, r = moving_arrival_times(np.zeros(3), receiver, n, FS, C)
    k = FS
    j = round(t_a[k] * FS)
    level = amplitude(y, j, 16, f0 * (C + v) / C)
    assert level == pytest.approx((C + v) / C / (4 * np.pi * r[k]), rel=1e-3)


def test_shoebox_images_of_a_static_source_are_allen_and_berkley() -> None:
    size, src = [5.0, 4.0, 3.0], np.array([1.0, 1.5, 1.2])
    images = shoebox_moving_images(size, src, 2)
    counts = np.bincount([n for _, n in images])
    assert list(counts) == [1, 6, 18]  # 1 source, 6 first-order and 18 second-order images
    first = {tuple(np.round(p[0], 9)) for p, n in images if n == 1}
    assert first == {(-1.0, 1.5, 1.2), (9.0, 1.5, 1.2), (1.0, -1.5, 1.2), (1.0, 6.5, 1.2),
                     (1.0, 1.5, -1.2), (1.0, 1.5, 4.8)}
    # A moving source's images move as its mirrors.
    path = np.stack([np.linspace(1, 2, 5), np.full(5, 1.5), np.full(5, 1.2)], axis=1)
    moved = shoebox_moving_images(size, path, 1)
    xs = sorted(p[:, 0].tolist() for p, n in moved if n == 1 and p[0, 1] == 1.5
                and p[0, 2] == 1.2)
    assert xs == [[-1.0, -1.25, -1.5, -1.75, -2.0], [9.0, 8.75, 8.5, 8.25, 8.0]]


def test_windowed_sinc_is_an_interpolator() -> None:
    assert windowed_sinc(np.array([0.0]))[0] == 1.0
    assert np.allclose(windowed_sinc(np.arange(1, 40, dtype=float)), 0.0, atol=1e-15)
    # A sub-sample shift: the taps sum to ~1 (DC passes) for any offset.
    for frac in (0.1, 0.37, 0.5):
        assert np.sum(windowed_sinc(np.arange(-40, 40) - frac)) == pytest.approx(1.0, abs=1e-4)


def test_bad_inputs_are_named() -> None:
    with pytest.raises(AcousticsError, match="source_m: expected a point"):
        moving_point_source(np.ones(5), np.zeros((4, 3)), np.ones(3), FS)
    with pytest.raises(AcousticsError, match="passes through the receiver"):
        moving_point_source(np.ones(5), np.zeros(3), np.zeros(3), FS)
    with pytest.raises(AcousticsError, match="dry: expected a 1-D signal"):
        moving_point_source(np.ones((2, 5)), np.zeros(3), np.ones(3), FS)
    with pytest.raises(AcousticsError, match="order: expected an integer >= 0"):
        shoebox_moving_images([1, 1, 1], np.zeros(3), -1)


def test_a_source_coming_straight_at_the_receiver_is_louder_by_the_doppler_factor() -> None:
    f0, v = 500.0, 20.0
    n = 2 * FS
    t = np.arange(n) / FS
    path = np.stack([40.0 - v * t, np.zeros(n), np.zeros(n)], axis=1)
    y = moving_point_source(np.sin(2 * np.pi * f0 * t), path, np.zeros(3), FS,
                            speed_of_sound_m_s=C)
    t_a, r = moving_arrival_times(path, np.zeros(3), n, FS, C)
    k = FS
    j = round(t_a[k] * FS)
    shifted = f0 * C / (C - v)
    assert frequency_hz(y, j, 400) == pytest.approx(shifted, abs=0.01)
    assert amplitude(y, j, 32, shifted) == pytest.approx(C / (C - v) / (4 * np.pi * r[k]),
                                                         rel=1e-3)
