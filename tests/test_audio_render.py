"""Moving-source rendering: block-wise crossfade equals the naive reference; physics checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import fftconvolve

from sonicspec.audio.render import (
    path_position_from_distances,
    render_naive,
    render_sample_crossfade,
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
