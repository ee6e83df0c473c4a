"""Arrays and ambisonics: inter-capsule delays, SN3D spherical harmonics, diffuse energy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.arrivals import KIND_DIRECT, Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.receivers.arrays import (
    capsule_offsets,
    diffuse_coherence,
    sh_sn3d,
    synthesize_ambisonic_rir,
    synthesize_array_rir,
)
from sonicspec.errors import AcousticsError

FS = 16000


def plane_wave(direction: tuple[float, float, float], t_s: float = 0.02) -> Arrivals:
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    return Arrivals(np.array([t_s]), np.full((1, 6), 0.1), d[None], np.array([0]),
                    np.array([KIND_DIRECT], np.int8), np.array([t_s * 343]))


def peak_time(x: np.ndarray, up: int = 64) -> float:
    """Sub-sample peak position: band-limited (FFT) upsampling by ``up``, then the maximum."""
    n = x.size
    spectrum = np.fft.rfft(x)
    fine = np.fft.irfft(spectrum, n * up) * up
    return float(np.argmax(fine)) / up


def test_sh_closed_forms() -> None:
    front, left, up = sh_sn3d(3, np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]))
    assert front[[0, 1, 2, 3]] == pytest.approx([1, 0, 0, 1])
    assert front[6] == pytest.approx(-0.5) and front[8] == pytest.approx(math.sqrt(3) / 2)
    assert front[13] == pytest.approx(-math.sqrt(3 / 8)) and front[15] == pytest.approx(
        math.sqrt(5 / 8))
    assert left[1] == pytest.approx(1) and left[8] == pytest.approx(-math.sqrt(3) / 2)
    assert left[9] == pytest.approx(-math.sqrt(5 / 8))
    assert up[2] == pytest.approx(1) and up[6] == pytest.approx(1) and up[12] == pytest.approx(1)


def test_sn3d_orthogonality() -> None:
    """∫ Y_i Y_j dΩ = 4π / (2l + 1) δ_ij for SN3D real harmonics."""
    el = (np.arange(400) + 0.5) / 400 * np.pi - np.pi / 2
    az = (np.arange(800) + 0.5) / 800 * 2 * np.pi
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)
    w = (np.cos(e) * (np.pi / 400) * (2 * np.pi / 800)).ravel()
    y = sh_sn3d(3, d)
    gram = (y * w[:, None]).T @ y
    degree = np.floor(np.sqrt(np.arange(16))).astype(int)
    assert gram == pytest.approx(np.diag(4 * np.pi / (2 * degree + 1)), abs=2e-4)


@pytest.mark.parametrize(("kind", "kw"), [("linear_array", {"n": 4, "spacing_m": 0.05}),
                                          ("circular_array", {"n": 6, "radius_m": 0.05})])
def test_array_delays_of_a_plane_wave(kind: str, kw: dict) -> None:
    direction = np.array([0.3, 0.9, 0.2])
    direction /= np.linalg.norm(direction)
    offsets = capsule_offsets(kind, yaw_deg=30.0, **kw)
    rir = synthesize_array_rir(plane_wave(tuple(direction)), None, offsets, FS,
                               np.random.default_rng(0))
    got = np.array([peak_time(ch) for ch in rir]) / FS
    expected = 0.02 - offsets @ direction / 343
    assert got == pytest.approx(expected, abs=0.05 / FS)


def test_ambisonics_encodes_with_sh_gains() -> None:
    direction = (0.2, -0.5, 0.6)
    rir = synthesize_ambisonic_rir(plane_wave(direction), None, 3, FS, np.random.default_rng(0))
    gains = sh_sn3d(3, np.array([direction]))[0]
    assert rir.shape[0] == 16
    for ch in range(16):
        assert np.allclose(rir[ch], gains[ch] * rir[0], atol=1e-12)


def test_diffuse_tail_energy_per_order() -> None:
    t = np.arange(600) * 0.001
    energy = 1e-4 * np.exp(-13.8 * t / 0.5)[:, None] * np.ones((1, 6)) * 0.001
    hist = EnergyHistogram(0.001, energy, np.zeros((600, 3)), np.zeros((600, 3)))
    empty = Arrivals.empty(6)
    rir = synthesize_ambisonic_rir(empty, hist, 2, FS, np.random.default_rng(1))
    e = (rir**2).sum(axis=1)
    # W carries the histogram's energy, each band weighted by its share of a flat spectrum.
    flat = float((energy * OctaveFilterBank(FS).flat_energy_shares()[None, :]).sum())
    assert e[0] == pytest.approx(flat, rel=0.05)
    assert e[1:4] / e[0] == pytest.approx(np.full(3, 1 / 3), rel=0.1)
    assert e[4:9] / e[0] == pytest.approx(np.full(5, 1 / 5), rel=0.1)
    mono_like = synthesize_array_rir(empty, hist, np.zeros((2, 3)), FS, np.random.default_rng(1))
    assert (mono_like**2).sum(axis=1) == pytest.approx([flat] * 2, rel=0.05)


def test_bad_receivers() -> None:
    with pytest.raises(AcousticsError, match=r"order: expected 0\.\.3"):
        sh_sn3d(4, np.array([[1.0, 0, 0]]))
    with pytest.raises(AcousticsError, match="array kind"):
        capsule_offsets("tetrahedral")


def test_array_tail_has_the_coherence_of_a_diffuse_field() -> None:
    """Capsules d apart hear a diffuse tail with coherence sin(kd)/(kd): nearly one at low
    frequencies for 2 cm, nearly zero above 1 kHz for 0.5 m, and each keeps its energy."""
    energy = np.full((1500, 6), 1e-7)  # flat: many degrees of freedom per band
    hist = EnergyHistogram(0.001, energy, np.zeros((1500, 3)), np.zeros((1500, 3)))
    offsets = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.5, 0.0, 0.0]])
    rir = synthesize_array_rir(Arrivals.empty(6), hist, offsets, FS, np.random.default_rng(3),
                               max_length_s=1.5)
    bank = OctaveFilterBank(FS)
    bands = bank.split(rir, axis=-1)  # (band, capsule, n)

    def coherence(b: int, i: int, j: int) -> float:
        x, y = bands[b, i], bands[b, j]
        return float(np.sum(x * y) / np.sqrt(np.sum(x * x) * np.sum(y * y)))

    # The coherence a band measures: sin(kd)/(kd) averaged over the band's power response.
    freqs = np.fft.rfftfreq(1 << 14, 1 / FS)
    weights = bank.responses(1 << 14) ** 2
    for b, fc in enumerate(bank.bands_hz):
        for j, dist in ((1, 0.02), (2, 0.5)):
            gamma = np.sinc(2 * freqs * dist / 343.0)  # sin(kd)/(kd), k = 2πf/c
            expected = float(np.sum(weights[b] * gamma) / np.sum(weights[b]))
            # Sampling spread of a correlation coefficient of band noise: (1 − γ²)/√(2BT),
            # B ≈ 0.71 fc (octave), T = 1.5 s; allow 3σ plus the band-edge approximation.
            sigma = (1 - expected**2) / math.sqrt(2 * 0.71 * fc * 1.5)
            assert coherence(b, 0, j) == pytest.approx(expected, abs=3 * sigma + 0.02), (
                fc, dist)
    assert coherence(0, 0, 1) > 0.95 and abs(coherence(4, 0, 2)) < 0.15
    e = np.sum(rir**2, axis=1)
    assert e / e.mean() == pytest.approx(np.ones(3), rel=0.1)


def test_array_coherence_filters_are_compact_in_time() -> None:
    """An impulse on one input leaves the mixer within about the array's travel time: the
    mixing filters change smoothly with frequency (no eigenvector reordering jumps)."""
    offsets = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.3, 0.0]])
    n = 4096
    x = np.zeros((4, n))
    x[1, n // 2] = 1.0
    y = diffuse_coherence(x, offsets, FS)
    reach = int(np.ceil(0.36 / 343.0 * FS)) + 8  # max spacing / c, plus the filters' skirt
    near = slice(n // 2 - 4 * reach, n // 2 + 4 * reach + 1)
    share = np.sum(y[:, near] ** 2) / np.sum(y**2)
    assert share > 0.995, share
    # And the mixing keeps the input's energy in total over the outputs (white input).
    assert np.sum(y**2) == pytest.approx(1.0, rel=0.05)


def test_local_directions_are_in_the_microphone_frame() -> None:
    from sonicspec.acoustics.receivers.arrays import local_directions

    # Facing +y (yaw 90): +y is straight ahead, +x to the right (azimuth -90), up is up.
    az, el, d = local_directions(np.array([[0, 2, 0], [3, 0, 0], [0, 0, 1]], float), 90, 0)
    np.testing.assert_allclose(az[:2], [0, -90], atol=1e-9)
    np.testing.assert_allclose(el, [0, 0, 90], atol=1e-9)
    np.testing.assert_allclose(d, [2, 3, 1])
    # Pitched up 30 degrees: a direction 30 degrees above the horizon is straight ahead.
    up30 = [[np.cos(np.radians(30)), 0, np.sin(np.radians(30))]]
    az, el, _ = local_directions(np.array(up30), 0, 30)
    np.testing.assert_allclose([az[0], el[0]], [0, 0], atol=1e-9)


def test_an_ambisonic_microphone_hears_in_its_own_frame() -> None:
    """Ambisonic channels are in the microphone's frame: turned by 90° (yaw), a plane wave
    from the scene's +y arrives from its front (+x); at yaw 0 the channels are the scene
    frame's to the last bit (the default gives what it gave before the frame was honoured)."""
    from sonicspec.acoustics.receivers.arrays import ambisonic_early

    bank = OctaveFilterBank(16000)
    side, front = plane_wave((0.0, 1.0, 0.0)), plane_wave((1.0, 0.0, 0.0))
    turned = ambisonic_early(side, 1, bank, 2048, yaw_deg=90.0)
    np.testing.assert_allclose(turned, ambisonic_early(front, 1, bank, 2048), atol=1e-12)
    from sonicspec.acoustics.receivers.synthesis import synthesize_early

    gains = sh_sn3d(1, side.directions)[0]  # the scene frame's channels, as before
    before = np.stack([synthesize_early(Arrivals(side.times_s, side.amplitudes * g, side.directions,
                                                 side.order, side.kind, side.path_length_m),
                                        bank, 2048) for g in gains])
    assert np.array_equal(ambisonic_early(side, 1, bank, 2048), before)
