"""Binaural receivers: Woodworth ITD and ILD sign of the sphere head, SOFA nearest lookup."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.arrivals import KIND_DIRECT, Arrivals, EnergyHistogram
from sonicspec.acoustics.hrtf import (
    HrirSet,
    SphereHead,
    hrir_set_from_sofa,
    synthesize_hrir_binaural_rir,
    synthesize_sphere_binaural_rir,
)
from sonicspec.errors import AcousticsError
from sonicspec.testing.hrtf import write_tiny_sofa

FS = 48000


def plane_wave(direction: tuple[float, float, float], t_s: float = 0.01,
               n_bands: int = 7) -> Arrivals:
    """One arrival with a flat spectrum (7 octave bands at 48 kHz)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    return Arrivals(np.array([t_s]), np.full((1, n_bands), 0.1), d[None], np.array([0]),
                    np.array([KIND_DIRECT], np.int8), np.array([t_s * 343]))


def hf_lag_s(left: np.ndarray, right: np.ndarray, fs: float, up: int = 32) -> float:
    """Delay of right behind left, from the cross-correlation above 3 kHz (where the
    head-shadow filter is a constant gain with no group delay), upsampled by ``up``."""
    n = 1 << math.ceil(math.log2(2 * left.size))
    f = np.fft.rfftfreq(n, 1 / fs)
    cross = np.conj(np.fft.rfft(left, n)) * np.fft.rfft(right, n) * (f > 3000)
    xc = np.fft.irfft(cross, n * up)
    lag = int(np.argmax(xc))
    if lag > n * up // 2:
        lag -= n * up
    return lag / (up * fs)


@pytest.mark.parametrize("azimuth_deg", [90.0, -90.0])
def test_sphere_itd_woodworth_and_ild(azimuth_deg: float) -> None:
    head = SphereHead(head_radius_m=0.0875, ear_angle_deg=90.0)
    az = math.radians(azimuth_deg)
    out = synthesize_sphere_binaural_rir(plane_wave((math.cos(az), math.sin(az), 0.0)), None,
                                         head, FS, np.random.default_rng(0), max_length_s=0.1)
    assert out.shape[0] == 2 and np.all(np.isfinite(out))
    expected = 0.0875 / 343 * (math.pi / 2 + 1)
    itd = hf_lag_s(out[0], out[1], FS)   # > 0: right ear later (source on the left)
    assert abs(itd) == pytest.approx(expected, rel=0.05)
    assert np.sign(itd) == np.sign(azimuth_deg)
    # The near ear is louder at high frequency.
    spec = np.abs(np.fft.rfft(out, axis=1)) ** 2
    f = np.fft.rfftfreq(out.shape[1], 1 / FS)
    hf = spec[:, (f > 4000) & (f < 8000)].sum(axis=1)
    near, far = (0, 1) if azimuth_deg > 0 else (1, 0)
    assert 10 * np.log10(hf[near] / hf[far]) > 10


def test_sphere_frontal_source_is_symmetric_and_yaw_turns_head() -> None:
    head = SphereHead()
    rng = np.random.default_rng(0)
    out = synthesize_sphere_binaural_rir(plane_wave((1, 0, 0)), None, head, FS, rng,
                                         max_length_s=0.1)
    assert np.allclose(out[0], out[1], atol=1e-12)
    # A head turned 90° left hears a source at +x on its right.
    turned = synthesize_sphere_binaural_rir(plane_wave((1, 0, 0)), None, head, FS, rng,
                                            yaw_deg=90.0, max_length_s=0.1)
    assert np.sum(turned[1] ** 2) > np.sum(turned[0] ** 2)


def test_sphere_low_frequency_gain_is_unity() -> None:
    # Head shadow is 1 at DC for every direction: the ear's DC gain equals the arrival's.
    out = synthesize_sphere_binaural_rir(plane_wave((0, 1, 0)), None, SphereHead(), FS,
                                         np.random.default_rng(0), max_length_s=0.2)
    assert out.sum(axis=1) == pytest.approx([0.1, 0.1], rel=0.02)


def test_binaural_late_energy_equals_mono_and_is_deterministic() -> None:
    from sonicspec.acoustics.synthesis import synthesize_rir

    bins = np.arange(100)
    hist = EnergyHistogram(0.005, np.outer(np.exp(-bins / 20), np.full(6, 1e-4)),
                           np.zeros((100, 3)), np.zeros((100, 3)))
    empty = Arrivals(np.zeros(0), np.zeros((0, 6)), np.zeros((0, 3)), np.zeros(0, np.int64),
                     np.zeros(0, np.int8), np.zeros(0))
    a = synthesize_sphere_binaural_rir(empty, hist, SphereHead(), 16000,
                                       np.random.default_rng(3), max_length_s=0.6)
    b = synthesize_sphere_binaural_rir(empty, hist, SphereHead(), 16000,
                                       np.random.default_rng(3), max_length_s=0.6)
    assert np.array_equal(a, b)
    mono = synthesize_rir(empty, hist, 16000, np.random.default_rng(4), max_length_s=0.6)
    e_mono = np.sum(mono**2)
    assert np.sum(a**2, axis=1) == pytest.approx([e_mono, e_mono], rel=0.05)
    assert abs(np.corrcoef(a[0], a[1])[0, 1]) < 0.1


def test_sofa_nearest_direction(tmp_path) -> None:
    import sofar

    write_tiny_sofa(str(tmp_path / "tiny.sofa"), FS)
    hset = hrir_set_from_sofa(sofar.read_sofa(str(tmp_path / "tiny.sofa")))
    assert hset.directions[1] == pytest.approx([0, 1, 0], abs=1e-12)
    # A source at azimuth 80° is nearest to the "left" measurement (index 1).
    az = math.radians(80)
    t_s = 0.01
    out = synthesize_hrir_binaural_rir(plane_wave((math.cos(az), math.sin(az), 0), t_s), None,
                                       hset, FS, np.random.default_rng(0), max_length_s=0.1)
    peaks = np.argmax(np.abs(out), axis=1)
    base = round(t_s * FS)
    assert list(peaks) == [base + 3, base + 12]
    assert np.max(np.abs(out[1])) / np.max(np.abs(out[0])) == pytest.approx(0.5, rel=0.02)
    assert np.max(np.abs(out[0])) == pytest.approx(0.1, rel=0.02)
    # Yaw the head by 90°: the same source now comes from the front-ish (index 0).
    out = synthesize_hrir_binaural_rir(plane_wave((math.cos(az), math.sin(az), 0), t_s), None,
                                       hset, FS, np.random.default_rng(0), yaw_deg=90.0,
                                       max_length_s=0.1)
    assert list(np.argmax(np.abs(out), axis=1)) == [base + 2, base + 10]


def test_sofa_resampled(tmp_path) -> None:
    import sofar

    write_tiny_sofa(str(tmp_path / "tiny.sofa"), 2 * FS)
    hset = hrir_set_from_sofa(sofar.read_sofa(str(tmp_path / "tiny.sofa")))
    out = synthesize_hrir_binaural_rir(plane_wave((1, 0, 0)), None, hset, FS,
                                       np.random.default_rng(0), max_length_s=0.1)
    assert hset.resampled(FS).hrirs.shape[-1] == 16
    assert np.all(np.isfinite(out))
    # Left impulse at 2 samples of 96 kHz = 1 sample at 48 kHz after the arrival.
    assert int(np.argmax(np.abs(out[0]))) == round(0.01 * FS) + 1


def test_errors() -> None:
    with pytest.raises(AcousticsError, match="head_radius_m: expected"):
        SphereHead(head_radius_m=0.0)
    with pytest.raises(AcousticsError, match="ear_angle_deg: expected"):
        SphereHead(ear_angle_deg=200.0)
    with pytest.raises(AcousticsError, match="HRIR set: expected directions"):
        HrirSet(np.zeros((2, 3)), np.zeros((2, 1, 4)), FS)
    with pytest.raises(AcousticsError, match="HRIR set: expected at least one"):
        HrirSet(np.zeros((0, 3)), np.zeros((0, 2, 4)), FS)
    with pytest.raises(AcousticsError, match="HRIR set: expected non-zero"):
        HrirSet(np.zeros((1, 3)), np.zeros((1, 2, 4)), FS)
    with pytest.raises(AcousticsError, match="sample_rate_hz: expected"):
        synthesize_sphere_binaural_rir(plane_wave((1, 0, 0)), None, SphereHead(), 0.0,
                                       np.random.default_rng(0))

    class NotHrir:
        GLOBAL_SOFAConventions = "GeneralFIR"

    with pytest.raises(AcousticsError, match="SOFA convention: expected"):
        hrir_set_from_sofa(NotHrir())
