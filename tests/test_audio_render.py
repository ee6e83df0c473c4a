"""Moving-source rendering: block-wise crossfade equals the naive reference; physics checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import fftconvolve

from sonicspec.audio.render import (
    INTERPOLATIONS,
    path_position_from_distances,
    render_moving,
    render_naive,
    render_sample_crossfade,
    render_segment_ola,
    render_stft_crossfade,
    split_rir,
)
from sonicspec.errors import AudioError

FS = 16000


def rel_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("monotone", [True, False])
def test_block_wise_equals_naive(channels: int, monotone: bool) -> None:
    rng = np.random.default_rng(channels + 10 * monotone)
    dry = rng.standard_normal(6000)
    rirs = rng.standard_normal((9, channels, 700)) * np.exp(-np.arange(700) / 150)
    if monotone:
        pos = np.linspace(0, 8, dry.size)
    else:
        pos = 4 + 4 * np.sin(np.linspace(0, 3 * np.pi, dry.size))
    assert rel_error(render_sample_crossfade(dry, rirs, pos),
                     render_naive(dry, rirs, pos)) < 1e-5


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 6), length=st.integers(1, 300),
       samples=st.integers(1, 900))
def test_block_wise_equals_naive_on_random_cases(seed: int, n: int, length: int,
                                                 samples: int) -> None:
    rng = np.random.default_rng(seed)
    dry = rng.standard_normal(samples)
    rirs = rng.standard_normal((n, 2, length))
    pos = np.clip(np.cumsum(rng.normal(0, 0.05, samples)) + rng.uniform(0, n - 1), 0, n - 1)
    ref = render_naive(dry, rirs, pos)
    got = render_sample_crossfade(dry, rirs, pos)
    assert got.shape == ref.shape == (2, samples + length - 1)
    assert np.linalg.norm(got - ref) <= 1e-5 * max(np.linalg.norm(ref), 1e-30)


def test_static_source_is_a_plain_convolution() -> None:
    rng = np.random.default_rng(3)
    dry, rir = rng.standard_normal(5000), rng.standard_normal((1, 2, 400))
    got = render_sample_crossfade(dry, rir, np.zeros(dry.size))
    assert np.allclose(got, fftconvolve(dry[None], rir[0], axes=-1), atol=1e-12, rtol=0)


def free_field_gains(distances_m: np.ndarray, length: int) -> np.ndarray:
    """Free-field levels 1/(4πr), all at one delay.

    The delay is held fixed on purpose: blending two copies of white noise delayed by
    different amounts decorrelates them and dips the level between RIR points (by up to 3 dB
    halfway), a property of the crossfade itself that dense RIR spacing keeps small; this test
    checks the distance law alone.
    """
    rirs = np.zeros((len(distances_m), 1, length))
    rirs[:, 0, 40] = 1 / (4 * math.pi * np.asarray(distances_m))
    return rirs


def test_level_follows_distance_of_a_receding_source() -> None:
    r = np.linspace(1, 8, 29)  # every 0.25 m
    rirs = free_field_gains(r, 512)
    dry = np.random.default_rng(4).standard_normal(4 * FS)
    pos = path_position_from_distances(r - r[0], dry.size)
    y = render_sample_crossfade(dry, rirs, pos)[0, : dry.size]
    for frac in (0.25, 0.5, 0.75):
        t = int(frac * dry.size)
        win = slice(t - 800, t + 800)
        expected = 1 / (4 * math.pi * np.interp(frac * 7, r - 1, r))
        got = np.sqrt(np.mean(y[win] ** 2) / np.mean(dry[win] ** 2))
        assert 20 * math.log10(got / expected) == pytest.approx(0.0, abs=0.5)


def test_no_jumps_at_rir_boundaries() -> None:
    # Dense RIRs that differ slightly: the output is smooth across the switch points.
    rng = np.random.default_rng(5)
    base = rng.standard_normal(300) * np.exp(-np.arange(300) / 60)
    rirs = np.stack([base * (1 + 0.02 * j) for j in range(20)])[:, None, :]
    dry = np.sin(2 * np.pi * 200 * np.arange(2 * FS) / FS)
    pos = np.linspace(0, 19, dry.size)
    y = render_sample_crossfade(dry, rirs, pos)[0, 400:dry.size - 400]
    step = np.abs(np.diff(y))
    switches = np.flatnonzero(np.diff(np.floor(pos)) > 0) - 400  # index into y
    is_near = np.zeros(step.size, bool)
    for s in switches[(switches > 2) & (switches < step.size - 2)]:
        is_near[s - 2:s + 3] = True
    # A jump at a switch would stand out from the sine's ordinary sample-to-sample steps.
    assert step[is_near].max() <= 1.01 * np.percentile(step[~is_near], 99.9)


def test_position_helper_spans_the_active_part() -> None:
    d = np.array([0.0, 0.5, 1.0, 1.5])
    pos = path_position_from_distances(d, 1000, active=(100, 900))
    assert pos[0] == 0 and pos[100] == 0 and pos[899] == pytest.approx(3.0) and pos[-1] == 3.0
    walk = path_position_from_distances(d, 1000, speed_m_s=1.0, sample_rate_hz=1000)
    assert walk[500] == pytest.approx(1.0) and walk[-1] == pytest.approx(1.998)


def test_bad_inputs_are_named() -> None:
    rirs = np.zeros((2, 1, 10))
    with pytest.raises(AudioError, match="expected values in \\[0, 1\\]"):
        render_sample_crossfade(np.zeros(5), rirs, np.full(5, 1.5))
    with pytest.raises(AudioError, match="one position per dry sample"):
        render_sample_crossfade(np.zeros(5), rirs, np.zeros(4))
    with pytest.raises(AudioError, match="finite"):
        render_sample_crossfade(np.array([0.0, np.nan]), rirs, np.zeros(2))
    with pytest.raises(AudioError, match="non-decreasing"):
        path_position_from_distances(np.array([1.0, 0.0]), 10)


# --- interpolation options (stft_crossfade, segment_ola), split_rir ------------------------------

C_SOUND = 343.0


def stft_reference(dry: np.ndarray, rirs: np.ndarray, pos: np.ndarray, frame: int,
                   hop: int) -> np.ndarray:
    """The definition, literally: windowed frames, each multiplied in the frequency domain by
    the RIR spectrum interpolated at the frame centre (FFT long enough for the whole RIR),
    inverse FFT, overlap-add."""
    n, c, length = rirs.shape
    size = dry.size
    window = np.sin(np.pi * (np.arange(frame) + 0.5) / frame) ** 2
    starts = list(range(-(-(-frame // hop) - 1) * hop, size, hop))
    cover = np.zeros(size)
    for s in starts:
        k = np.arange(max(s, 0), min(s + frame, size))
        cover[k] += window[k - s]
    nfft = frame + length - 1
    spectra = np.fft.rfft(rirs, nfft, axis=-1)
    out = np.zeros((c, size + length - 1 + frame))
    for s in starts:
        p = np.interp(s + (frame - 1) / 2, np.arange(size), pos)
        j = min(int(p), n - 2) if n > 1 else 0
        a = p - j
        spectrum = spectra[j] * (1 - a) + (spectra[j + 1] * a if n > 1 else 0)
        x = np.zeros(frame)
        k = np.arange(max(s, 0), min(s + frame, size))
        x[k - s] = dry[k] * window[k - s] / cover[k]
        y = np.fft.irfft(np.fft.rfft(x, nfft) * spectrum, nfft, axis=-1)
        lo = max(s, 0)
        out[:, lo:s + nfft] += y[:, lo - s:]
    return out[:, :size + length - 1]


def segment_reference(dry: np.ndarray, rirs: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """gpuRIR's definition: runs of equal rounded position, each convolved with its RIR."""
    n, c, length = rirs.shape
    out = np.zeros((c, dry.size + length - 1))
    nearest = [min(math.floor(p + 0.5), n - 1) for p in pos]
    start = 0
    for k in range(1, dry.size + 1):
        if k == dry.size or nearest[k] != nearest[start]:
            for ch in range(c):
                seg = np.convolve(dry[start:k], rirs[nearest[start], ch])
                out[ch, start:start + seg.size] += seg
            start = k
    return out


def delayed_impulses(distances_m: np.ndarray, length: int) -> np.ndarray:
    """Free-field RIRs: 1/(4πr) at the delay r/c (nearest sample)."""
    rirs = np.zeros((len(distances_m), 1, length))
    for j, r in enumerate(distances_m):
        rirs[j, 0, round(r / C_SOUND * FS)] = 1 / (4 * math.pi * r)
    return rirs


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_static_source_is_a_plain_convolution_for_every_interpolation(
        interpolation: str) -> None:
    rng = np.random.default_rng(11)
    dry, rirs = rng.standard_normal(3000), rng.standard_normal((5, 2, 250))
    ref = fftconvolve(dry[None], rirs[3], axes=-1)
    scale = np.abs(ref).max()
    for one, pos in ((rirs, np.full(dry.size, 3.0)), (rirs[3:4], np.zeros(dry.size))):
        got = render_moving(dry, one, pos, interpolation)
        assert got.shape == ref.shape
        assert np.abs(got - ref).max() <= 1e-10 * scale


def test_constant_fractional_position_is_the_interpolated_rir() -> None:
    # stft_crossfade and sample_crossfade agree whenever the position does not move.
    rng = np.random.default_rng(12)
    dry, rirs = rng.standard_normal(3000), rng.standard_normal((4, 2, 250))
    ref = fftconvolve(dry[None], 0.7 * rirs[1] + 0.3 * rirs[2], axes=-1)
    pos = np.full(dry.size, 1.3)
    for got in (render_stft_crossfade(dry, rirs, pos, frame_size=256, hop=100),
                render_sample_crossfade(dry, rirs, pos)):
        assert np.abs(got - ref).max() <= 1e-10 * np.abs(ref).max()
    # A rounded position: segment_ola uses the nearest RIR alone.
    assert np.allclose(render_segment_ola(dry, rirs, pos),
                       fftconvolve(dry[None], rirs[1], axes=-1), rtol=0, atol=1e-10)


@pytest.mark.parametrize(("frame", "hop"), [(512, None), (64, 64), (100, 33), (1, 1)])
def test_stft_crossfade_equals_its_frame_by_frame_definition(frame: int,
                                                             hop: int | None) -> None:
    rng = np.random.default_rng(frame)
    dry = rng.standard_normal(2500)
    rirs = rng.standard_normal((6, 2, 300)) * np.exp(-np.arange(300) / 80)
    pos = np.clip(2.5 + 3 * np.sin(np.linspace(0, 2 * np.pi, dry.size)), 0, 5)
    got = render_stft_crossfade(dry, rirs, pos, frame_size=frame, hop=hop)
    ref = stft_reference(dry, rirs, pos, frame, hop or frame // 2)
    assert rel_error(got, ref) < 1e-10



@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 5), length=st.integers(1, 60),
       samples=st.integers(1, 400), frame=st.integers(1, 70), hop_fraction=st.floats(0, 1))
def test_stft_and_segment_equal_their_definitions_on_random_cases(
        seed: int, n: int, length: int, samples: int, frame: int, hop_fraction: float) -> None:
    rng = np.random.default_rng(seed)
    dry, rirs = rng.standard_normal(samples), rng.standard_normal((n, 2, length))
    pos = np.clip(np.cumsum(rng.normal(0, 0.05, samples)) + rng.uniform(0, n - 1), 0, n - 1)
    hop = max(1, round(hop_fraction * frame))
    got = render_stft_crossfade(dry, rirs, pos, frame_size=frame, hop=hop)
    assert got.shape == (2, samples + length - 1)
    assert rel_error(got, stft_reference(dry, rirs, pos, frame, hop)) < 1e-10
    assert rel_error(render_segment_ola(dry, rirs, pos), segment_reference(dry, rirs, pos)) < 1e-10


@pytest.mark.parametrize("monotone", [True, False])
def test_segment_ola_equals_its_per_segment_definition(monotone: bool) -> None:
    rng = np.random.default_rng(20 + monotone)
    dry = rng.standard_normal(2000)
    rirs = rng.standard_normal((7, 2, 120))
    pos = (np.linspace(0, 6, dry.size) if monotone
           else np.clip(3 + 3.2 * np.sin(np.linspace(0, 5, dry.size)), 0, 6))
    assert rel_error(render_segment_ola(dry, rirs, pos), segment_reference(dry, rirs, pos)) < 1e-12


def receding_source() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 100 Hz tone walking from 1 m to 8 m in 4 s past free-field RIRs every 0.25 m.

    Low frequency on purpose: blending two RIRs whose delays differ by 0.25 m / c = 0.7 ms
    decorrelates higher frequencies and dips the level between RIR points (see
    free_field_gains); at 100 Hz the dip stays below 0.2 dB.
    """
    r = np.linspace(1, 8, 29)
    dry = np.sin(2 * np.pi * 100 * np.arange(4 * FS) / FS)
    return r, delayed_impulses(r, 512), dry, path_position_from_distances(r - r[0], dry.size)


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_level_follows_distance_for_every_interpolation(interpolation: str) -> None:
    r, rirs, dry, pos = receding_source()
    y = render_moving(dry, rirs, pos, interpolation)[0, :dry.size]

    def level_db(frac: float) -> float:
        win = slice(int(frac * dry.size) - 1600, int(frac * dry.size) + 1600)  # 0.2 s
        return 10 * math.log10(np.mean(y[win] ** 2) / np.mean(dry[win] ** 2))

    for frac in (0.1, 0.25, 0.5, 0.75, 0.9):
        expected = -20 * math.log10(4 * math.pi * np.interp(frac * 7, r - 1, r))
        assert level_db(frac) == pytest.approx(expected, abs=0.5)
    # 1.7 m -> 7.3 m: the inverse-distance law's 12.7 dB.
    assert level_db(0.1) - level_db(0.9) == pytest.approx(20 * math.log10(7.3 / 1.7), abs=0.3)


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_no_clicks_where_the_rir_changes(interpolation: str) -> None:
    """A crossfade's output cannot step faster than its inputs allow.

    For ``y = Σ_j w_j (s ∗ h_j)`` with ``Σ_j w_j = 1`` and ``Σ_j |Δw_j| ≤ 2·max|Δp|``:
    ``|Δy| ≤ max_j ‖h_j‖₁ · (max|Δs| + 2·max|Δp|·max|s|)``; the frame-wise crossfade's
    Hann-interpolated weights change at most π/2 times as fast, hence the 4 below. A hard
    switch between RIRs (segment_ola) steps by up to ``‖h‖·|s|`` and breaks the bound.
    """
    _, rirs, dry, pos = receding_source()
    y = render_moving(dry, rirs, pos, interpolation)[0]
    bound = np.abs(rirs).sum(axis=-1).max() * (
        np.abs(np.diff(dry)).max() + 4 * np.abs(np.diff(pos)).max() * np.abs(dry).max())
    worst = np.abs(np.diff(y)).max()
    if interpolation == "segment_ola":
        assert worst > 5 * bound  # documented: the delay jumps 0.7 ms at each boundary
    else:
        assert worst <= bound


def test_render_moving_dispatches_and_names_a_bad_interpolation() -> None:
    rng = np.random.default_rng(30)
    dry, rirs = rng.standard_normal(800), rng.standard_normal((3, 1, 50))
    pos = np.linspace(0, 2, dry.size)
    assert np.array_equal(render_moving(dry, rirs, pos), render_sample_crossfade(dry, rirs, pos))
    assert np.array_equal(render_moving(dry, rirs, pos, "stft_crossfade"),
                          render_stft_crossfade(dry, rirs, pos))
    assert np.array_equal(render_moving(dry, rirs, pos, "segment_ola"),
                          render_segment_ola(dry, rirs, pos))
    with pytest.raises(AudioError, match="interpolation: expected one of sample_crossfade, "
                                         "stft_crossfade, segment_ola, got 'linear'"):
        render_moving(dry, rirs, pos, "linear")


def test_stft_crossfade_bad_frames_are_named() -> None:
    dry, rirs, pos = np.zeros(10), np.zeros((2, 1, 4)), np.zeros(10)
    with pytest.raises(AudioError, match="frame_size: expected an integer >= 1"):
        render_stft_crossfade(dry, rirs, pos, frame_size=0)
    with pytest.raises(AudioError, match="frame_size: expected an integer >= 1"):
        render_stft_crossfade(dry, rirs, pos, frame_size=256.0)  # type: ignore[arg-type]
    with pytest.raises(AudioError, match="hop: expected an integer in \\[1, frame_size=64\\]"):
        render_stft_crossfade(dry, rirs, pos, frame_size=64, hop=65)
    with pytest.raises(AudioError, match=r"hop: .*got 0"):
        render_stft_crossfade(dry, rirs, pos, frame_size=64, hop=0)
    with pytest.raises(AudioError, match="one position per dry sample"):
        render_segment_ola(dry, rirs, np.zeros(9))


def test_direct_part_of_a_free_field_rir_is_the_whole_rir() -> None:
    r = np.array([1.0, 2.5, 6.0])
    rirs = np.repeat(delayed_impulses(r, 800), 2, axis=1)  # two channels
    delays = r / C_SOUND * FS
    direct, early = split_rir(rirs, delays, FS)
    assert np.array_equal(direct, rirs) and np.array_equal(early, rirs)
    # A fractional delay (the tracer's 65-tap windowed sinc, ±2 ms) loses < 1e-7 of its energy.
    d = 200.3
    x = np.arange(800) - d
    sinc = np.where(np.abs(x) <= 32.5, np.sinc(x) * 0.5 * (1 + np.cos(np.pi * x / 33)), 0.0)
    direct, _ = split_rir(sinc[None, None, :], np.array([d]), FS)
    assert np.sum((direct - sinc) ** 2) < 1e-7 * np.sum(sinc**2)


def test_split_rir_windows_end_where_they_say() -> None:
    rng = np.random.default_rng(40)
    length = 4000
    rirs = rng.standard_normal((3, 2, length)) * np.exp(-np.arange(length) / 1500)
    delays = np.array([100.0, 333.6, 870.25])
    direct, early = split_rir(rirs, delays, FS, direct_window_ms=2.5, early_ms=50.0)
    n = np.arange(length)
    for j, d in enumerate(delays):
        for part, ms in ((direct, 2.5), (early, 50.0)):
            end = d + ms * FS / 1000
            assert not np.any(part[j][:, n >= end])  # no energy after the window
            whole = n <= end - FS / 1000  # untouched until the 1 ms fade
            assert np.array_equal(part[j][:, whole], rirs[j][:, whole])
            fade = part[j][:, ~whole & (n < end)] / rirs[j][:, ~whole & (n < end)]
            assert np.all((fade >= 0) & (fade <= 1)) and np.all(np.diff(fade, axis=-1) <= 0)
    # The fade has no click: each gain step is at most π/(2·16) (a 16-sample half-Hann).
    gain = split_rir(np.ones((1, 1, 200)), np.array([10.0]), FS)[0][0, 0]
    assert np.abs(np.diff(gain)).max() <= math.pi / 32 + 1e-12


def test_split_rir_bad_inputs_are_named() -> None:
    rirs = np.zeros((2, 1, 100))
    with pytest.raises(AudioError, match="rirs: expected \\(N points"):
        split_rir(np.zeros((2, 100)), np.zeros(2), FS)
    with pytest.raises(AudioError, match="one delay per RIR \\(2,\\)"):
        split_rir(rirs, np.zeros(3), FS)
    with pytest.raises(AudioError, match="direct_delay_samples: expected finite values in "
                                         "\\[0, 100\\)"):
        split_rir(rirs, np.array([0.0, 100.0]), FS)
    with pytest.raises(AudioError, match="sample_rate_hz: expected > 0"):
        split_rir(rirs, np.zeros(2), 0)
    with pytest.raises(AudioError, match="direct_window_ms: expected > 0"):
        split_rir(rirs, np.zeros(2), FS, direct_window_ms=0.0)
    with pytest.raises(AudioError, match="early_ms: expected >= direct_window_ms"):
        split_rir(rirs, np.zeros(2), FS, direct_window_ms=5.0, early_ms=2.0)
