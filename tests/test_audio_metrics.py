"""The paper's metrics against independent computations on signals made here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.audio import metrics
from sonicspec.errors import AudioError

RATE = 16000


def speechlike(seconds: float, seed: int = 0) -> np.ndarray:
    """Noise shaped by a syllable-rate envelope and a formant-ish band: PESQ finds speech in
    it."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds * RATE)) / RATE
    carrier = np.convolve(rng.standard_normal(t.size), np.hanning(24), mode="same")
    envelope = 0.5 * (1 + np.sin(2 * np.pi * 4.0 * t)) ** 2
    voiced = np.sin(2 * np.pi * 140 * t) * (1 + 0.3 * np.sin(2 * np.pi * 3 * t))
    return 0.1 * envelope * (carrier + voiced)


def test_si_snr_of_a_scaled_target_is_over_100_db() -> None:
    x = speechlike(2.0)
    assert metrics.si_snr(0.37 * x, x) >= 100.0
    assert metrics.si_snr(-2.5 * x + 0.0, x) >= 100.0


@pytest.mark.parametrize("snr_db", [-5.0, 0.0, 10.0, 20.0])
def test_si_snr_of_target_plus_white_noise_at_known_snr(snr_db: float) -> None:
    rng = np.random.default_rng(1)
    x = rng.standard_normal(5 * RATE)
    noise = rng.standard_normal(x.size)
    # noise orthogonal to x and zero-mean, so the projection removes none of it
    x -= x.mean()
    noise -= noise.mean()
    noise -= (noise @ x) / (x @ x) * x
    noise *= math.sqrt((x @ x) / (noise @ noise) / 10 ** (snr_db / 10))
    assert metrics.si_snr(x + noise, x) == pytest.approx(snr_db, abs=0.1)
    # SDR's 512-tap distortion filter counts the white noise's share in its 512 dimensions
    # (L/N of its energy) as target: SDR = (S + L/N P) / ((1 - L/N) P).
    r, share = 10 ** (-snr_db / 10), 512 / x.size
    expected = 10 * math.log10((1 + r * share) / (r * (1 - share)))
    assert metrics.sdr(x + noise, x) == pytest.approx(expected, abs=0.02)
    assert abs(expected - snr_db) < 0.15


def test_sdr_is_fast_bss_eval_and_mir_eval() -> None:
    fast_bss_eval = pytest.importorskip("fast_bss_eval")
    mir_eval = pytest.importorskip("mir_eval")
    rng = np.random.default_rng(2)
    x = speechlike(3.0, seed=2)
    est = np.convolve(x, [0.8, 0.3, -0.1], mode="same") + 0.02 * rng.standard_normal(x.size)
    ours = metrics.sdr(est, x)
    assert ours == pytest.approx(float(fast_bss_eval.sdr(x[None], est[None])[0]), abs=1e-9)
    with pytest.warns(FutureWarning):  # bss_eval_sources is deprecated in mir_eval 0.8
        reference = mir_eval.separation.bss_eval_sources(x[None], est[None])[0][0]
    assert ours == pytest.approx(reference, abs=1e-3)
    assert metrics.sdr(2.0 * x, x) == metrics.SDR_MAX_DB
    assert math.isnan(metrics.sdr(est, np.zeros_like(x)))


def test_pesq_and_stoi_of_identical_signals_are_at_their_maxima() -> None:
    x = speechlike(4.0)
    assert metrics.pesq(x, x, RATE, "wb") == pytest.approx(4.644, abs=1e-3)
    assert metrics.pesq(x, x, RATE, "nb") == pytest.approx(4.549, abs=1e-3)
    assert metrics.stoi(x, x, RATE) == pytest.approx(1.0, abs=1e-6)
    noisy = x + 0.05 * np.random.default_rng(3).standard_normal(x.size)
    assert metrics.pesq(noisy, x, RATE, "wb") < 4.0
    assert metrics.stoi(noisy, x, RATE) < 1.0


def test_pesq_resamples_other_rates() -> None:
    x = speechlike(4.0)
    from scipy.signal import resample_poly

    x48 = resample_poly(x, 3, 1)
    assert metrics.pesq(x48, x48, 48000, "wb") == pytest.approx(4.644, abs=1e-3)


def test_windows_6s_every_3s_with_a_last_window_at_the_end() -> None:
    assert metrics.windows(12 * RATE, RATE) == [(0, 96000), (48000, 144000), (96000, 192000)]
    # 10 s: hops at 0 and 3 s stop at 9 s, so one more window ends at 10 s
    assert metrics.windows(10 * RATE, RATE) == [(0, 96000), (48000, 144000), (64000, 160000)]
    assert metrics.windows(4 * RATE, RATE) == [(0, 64000)]
    with pytest.raises(AudioError, match="positive window"):
        metrics.windows(RATE, RATE, window_s=0)


def test_window_protocol_averages_the_windows_by_hand() -> None:
    """12 s whose halves differ: the first 6 s at 0 dB SNR, the last 6 s at 20 dB. Windows
    [0, 6), [3, 9), [6, 12): SNRs 0 dB, the mix of both halves, 20 dB; the mean of the
    three."""
    rng = np.random.default_rng(4)
    x = rng.standard_normal(12 * RATE)
    noise = rng.standard_normal(x.size)
    half = 6 * RATE
    est = x.copy()
    est[:half] += noise[:half] * math.sqrt(1.0)
    est[half:] += noise[half:] * math.sqrt(0.01)
    by_hand = np.mean([metrics.si_snr(est[a:b], x[a:b])
                       for a, b in [(0, half), (3 * RATE, 9 * RATE), (half, 12 * RATE)]])
    scores = metrics.windowed_scores(est, x, est, RATE, ["si_snr", "si_snri"])
    assert scores["windows"] == 3
    assert scores["si_snr"] == pytest.approx(by_hand, abs=1e-9)
    assert scores["si_snri"] == pytest.approx(0.0, abs=1e-9)
    # the halves themselves: about 0 and 20 dB, so the middle window is in between
    assert metrics.si_snr(est[:half], x[:half]) == pytest.approx(0.0, abs=0.2)
    assert metrics.si_snr(est[half:], x[half:]) == pytest.approx(20.0, abs=0.2)


def test_permutation_is_solved_on_swapped_outputs() -> None:
    a, b, c = speechlike(2.0, 5), speechlike(2.0, 6), speechlike(2.0, 7)
    targets = np.stack([a, b, c])
    assert metrics.best_permutation(np.stack([b, c, a]), targets) == (2, 0, 1)
    assert metrics.best_permutation(targets, targets) == (0, 1, 2)
    with pytest.raises(AudioError, match="2 estimates for 3 targets"):
        metrics.best_permutation(targets[:2], targets)


def test_unknown_metric_is_named() -> None:
    x = speechlike(1.0)
    with pytest.raises(AudioError, match="got 'snr'"):
        metrics.score_pair(x, x, x, RATE, ["snr"])


def test_windows_where_the_target_is_silent_are_not_scored() -> None:
    """A target silent for its first 6 s (a speaker who starts late): only the windows that
    hear it count; scoring the silent one would add about -200 dB to the mean."""
    x = speechlike(12.0, seed=8)
    x[:6 * RATE] = 0.0
    est = x + 0.01 * np.random.default_rng(9).standard_normal(x.size)
    scores = metrics.windowed_scores(est, x, est, RATE, ["si_snr"])
    assert (scores["windows"], scores["scored"]) == (3, 2)
    by_hand = np.mean([metrics.si_snr(est[a:b], x[a:b])
                       for a, b in [(3 * RATE, 9 * RATE), (6 * RATE, 12 * RATE)]])
    assert scores["si_snr"] == pytest.approx(by_hand, abs=1e-9)
    silent = metrics.windowed_scores(est, np.zeros_like(x), est, RATE, ["si_snr"])
    assert math.isnan(silent["si_snr"]) and silent["scored"] == 0
