"""Binaural receivers: Woodworth ITD and ILD sign of the sphere head, SOFA nearest lookup,
diffuse-field interaural coherence of the late tail."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.arrivals import KIND_DIRECT, Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.receivers.hrtf import (
    HrirSet,
    SphereHead,
    _counted_weights,
    binaural_diffuse_coherence,
    diffuse_binaural_tails,
    hrir_set_coherence,
    hrir_set_from_sofa,
    nearest_direction_weights,
    sphere_head_coherence,
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
    from sonicspec.acoustics.receivers.synthesis import synthesize_rir

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


def first_zero_hz(freqs: np.ndarray, gamma: np.ndarray) -> float:
    """Frequency where Γ first crosses zero (linear interpolation between grid points)."""
    k = int(np.argmax(gamma < 0))
    return float(np.interp(0.0, [gamma[k], gamma[k - 1]], [freqs[k], freqs[k - 1]]))


def test_sphere_head_coherence_is_physical() -> None:
    """The diffuse-field interaural coherence of the default head (a = 8.75 cm, ears at ±100°).

    Reference: Lindevald & Benade (1986), "Two-ear correlation in the statistical sound fields
    of rooms", JASA 80(2):661-664, measured on real heads in a reverberant room: a fit
    sinc(2.2 kd)/√(1 + (0.5 kd)⁴), d = 15 cm, first zero ("decoupling frequency") near 500 Hz,
    about half the free-field zero of two microphones a head-width apart. The Woodworth delay
    of our model gives a lateral ITD of (π/2 + 1) a/c, 0.86 of a real sphere's low-frequency
    3a/c (Kuhn 1977, JASA 62:157), so its zero sits somewhat higher (~650 Hz): 500-900 Hz.
    The same fit gives Γ ≈ 0.91 at 125 Hz, so "≈ 1" holds up to ~100 Hz only.
    """
    head = SphereHead()
    freqs, gamma = binaural_diffuse_coherence(head, FS)
    assert np.all(gamma[freqs <= 100] >= 0.95) and np.all(gamma[freqs <= 150] >= 0.9)
    f0 = first_zero_hz(freqs, gamma)
    assert 500 <= f0 <= 900
    # The head lowers the zero below that of two free-field points at the ears (c / 2d).
    ear_distance = 2 * 0.0875 * math.sin(math.radians(100))
    assert f0 < 343 / (2 * ear_distance) * 0.8
    assert np.all(np.diff(gamma[freqs <= f0]) < 0)  # falls monotonically to its first zero
    assert np.all(np.abs(gamma[(freqs >= 2000) & (freqs <= 0.9 * FS / 2)]) < 0.2)
    # The same model at another rate (the bilinear filters change only near Nyquist).
    f16, g16 = binaural_diffuse_coherence(head, 16000)
    low = f16 <= 4000
    assert g16[low] == pytest.approx(np.interp(f16[low], freqs, gamma), abs=0.01)
    # Converged in the number of directions.
    dense = sphere_head_coherence(head, freqs, FS, n_directions=8192)
    assert gamma == pytest.approx(dense, abs=0.01)


def test_tiny_sphere_head_is_coherent() -> None:
    """Ears at (almost) one point hear the same field: Γ ≈ 1 (up to where the bilinear
    head-shadow filter, whose corner lies far above Nyquist, warps into the top octave)."""
    f = np.linspace(0, 0.8 * FS / 2, 400)
    assert np.all(sphere_head_coherence(SphereHead(head_radius_m=1e-4), f, FS) > 0.99)
    # Larger heads decorrelate earlier.
    g = [sphere_head_coherence(SphereHead(head_radius_m=r), np.array([500.0]), FS)[0]
         for r in (0.02, 0.05, 0.0875, 0.12)]
    assert np.all(np.diff(g) < 0)


def assert_band_coherence(rir: np.ndarray, freqs: np.ndarray, gamma: np.ndarray, fs: float,
                          duration_s: float) -> list[tuple[float, float, float]]:
    """Octave-band coherence of a binaural tail against the model's band average.

    Tolerance: the sampling standard deviation of a correlation coefficient estimated from N
    independent samples is (1 − Γ²)/√N, and a band B Hz wide over T seconds gives N ≈ 2BT
    (B = 0.71 fc for octaves; 2 s of tail). 3σ + 0.01 (interpolation of Γ) covers one seed
    with margin; measured deviations are below 1σ because the tails' band energies per bin are
    pinned to the histogram, leaving only the cross term to fluctuate.
    """
    bank = OctaveFilterBank(fs)
    bands = bank.split(rir, axis=-1)
    n_fft = 1 << 14
    weights = bank.responses(n_fft) ** 2
    g = np.interp(np.fft.rfftfreq(n_fft, 1 / fs), freqs, gamma)
    rows = []
    for b, fc in enumerate(bank.bands_hz):
        x, y = bands[b]
        measured = float(np.sum(x * y) / np.sqrt(np.sum(x * x) * np.sum(y * y)))
        expected = float(np.sum(weights[b] * g) / np.sum(weights[b]))
        sigma = (1 - expected**2) / math.sqrt(2 * 0.71 * fc * duration_s)
        assert measured == pytest.approx(expected, abs=3 * sigma + 0.01), fc
        rows.append((fc, expected, measured))
    return rows


def flat_tail(n_bands: int, duration_s: float = 2.0) -> EnergyHistogram:
    """A histogram of constant energy: a stationary diffuse field, many degrees of freedom."""
    bins = round(duration_s / 0.01)
    return EnergyHistogram(0.01, np.full((bins, n_bands), 1e-4), np.zeros((bins, 3)),
                           np.zeros((bins, 3)))


@pytest.mark.parametrize("fs", [16000, 48000])
def test_sphere_binaural_tail_has_the_head_coherence(fs: int) -> None:
    bank = OctaveFilterBank(fs)
    hist = flat_tail(bank.n_bands)
    args = (Arrivals.empty(bank.n_bands), hist, SphereHead(), fs)
    rir = synthesize_sphere_binaural_rir(*args, np.random.default_rng(3), max_length_s=2.0)
    assert np.array_equal(rir, synthesize_sphere_binaural_rir(*args, np.random.default_rng(3),
                                                              max_length_s=2.0))
    freqs, gamma = binaural_diffuse_coherence(SphereHead(), fs)
    rows = assert_band_coherence(rir, freqs, gamma, fs, 2.0)
    assert rows[0][2] > 0.95 and abs(rows[3][2]) < 0.25  # 125 Hz coherent, 1 kHz not
    # Each ear keeps the tail's energy; the mixing does not depend on which ear is which.
    e = np.sum(rir**2, axis=1)
    assert e[0] == pytest.approx(e[1], rel=0.02)


def sphere_hrir_set(fs: float, step_deg: float = 10.0) -> tuple[HrirSet, np.ndarray]:
    """The sphere head's own responses on a latitude-longitude grid (dense at the poles, so
    a plain average would over-weight them), rendered in one call as well-separated arrivals."""
    el = np.radians(np.arange(-80, 81, step_deg))
    az = np.radians(np.arange(0, 360, step_deg))
    e, a = (g.ravel() for g in np.meshgrid(el, az, indexing="ij"))
    dirs = np.vstack([np.column_stack([np.cos(a) * np.cos(e), np.sin(a) * np.cos(e), np.sin(e)]),
                      [[0, 0, 1], [0, 0, -1]]])
    n, span, lead = len(dirs), 256, 64
    times = (lead + span * np.arange(n)) / fs
    arrivals = Arrivals(times, np.ones((n, OctaveFilterBank(fs).n_bands)), dirs,
                        np.zeros(n, np.int64), np.full(n, KIND_DIRECT, np.int8), times * 343)
    out = synthesize_sphere_binaural_rir(arrivals, None, SphereHead(), fs,
                                         np.random.default_rng(0),
                                         max_length_s=(n + 1) * span / fs)
    cut = out[:, span * np.arange(n)[:, None] + np.arange(span)[None, :]]  # (2, n, span)
    assert np.max(np.abs(cut[..., -16:])) < 1e-9  # each response fits in its window
    return HrirSet(dirs, np.transpose(cut, (1, 0, 2)), fs), dirs


def test_hrir_set_coherence_of_the_sphere_heads_own_responses() -> None:
    fs = 16000
    hset, _ = sphere_hrir_set(fs)
    f = np.fft.rfftfreq(512, 1 / fs)
    model = sphere_head_coherence(SphereHead(), f, fs)
    measured = hrir_set_coherence(hset, f)
    band = f <= 0.9 * fs / 2  # the fractional-delay taps roll off at Nyquist
    assert measured[band] == pytest.approx(model[band], abs=0.02)
    # Without the cell-area weights the polar rings (both ears equidistant) count too much.
    plain = hrir_set_coherence(hset, f, weights=np.ones(len(hset.directions)))
    at = np.searchsorted(f, 500)
    assert plain[at] - model[at] > 0.1 > abs(measured[at] - model[at]) * 10
    # The cached grid at the set's rate, and above a set's own Nyquist the ears are
    # incoherent when it serves a higher rate.
    freqs, gamma = binaural_diffuse_coherence(hset, fs)
    assert np.interp(f, freqs, gamma)[band] == pytest.approx(measured[band], abs=0.01)
    freqs48, gamma48 = binaural_diffuse_coherence(hset, 48000)
    assert np.all(gamma48[freqs48 > fs / 2] == 0)
    low = freqs48 <= 4000
    assert gamma48[low] == pytest.approx(np.interp(freqs48[low], freqs, gamma), abs=1e-9)


def test_hrir_binaural_tail_has_the_sets_coherence() -> None:
    fs = 16000
    hset, _ = sphere_hrir_set(fs)
    bank = OctaveFilterBank(fs)
    args = (Arrivals.empty(bank.n_bands), flat_tail(bank.n_bands), hset, fs)
    rir = synthesize_hrir_binaural_rir(*args, np.random.default_rng(5), max_length_s=2.0)
    assert np.array_equal(rir, synthesize_hrir_binaural_rir(*args, np.random.default_rng(5),
                                                            max_length_s=2.0))
    freqs, gamma = binaural_diffuse_coherence(hset, fs)
    assert_band_coherence(rir, freqs, gamma, fs, 2.0)


def test_diffuse_binaural_tails_keep_power_and_set_coherence() -> None:
    """Mixing white noises: per-ear power unchanged, cross-spectrum Γ(f) (Welch estimate)."""
    from scipy import signal as sps

    fs = 16000
    rng = np.random.default_rng(11)
    x = rng.standard_normal((2, 8 * fs))
    y = diffuse_binaural_tails(x, SphereHead(), fs)
    assert np.sum(y**2, axis=1) == pytest.approx(np.sum(x**2, axis=1), rel=0.03)
    f, cross = sps.csd(y[0], y[1], fs=fs, nperseg=512)
    _, p0 = sps.welch(y[0], fs=fs, nperseg=512)
    _, p1 = sps.welch(y[1], fs=fs, nperseg=512)
    grid, gamma = binaural_diffuse_coherence(SphereHead(), fs)
    # 8 s in 512-sample Hann segments: ~500 averages, σ ≈ 1/√500 ≈ 0.045 at Γ = 0
    assert (cross.real / np.sqrt(p0 * p1))[1:-1] == pytest.approx(
        np.interp(f, grid, gamma)[1:-1], abs=0.15)


def test_nearest_direction_weights() -> None:
    octahedron = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    assert nearest_direction_weights(octahedron) == pytest.approx(np.full(6, 1 / 6), abs=1e-9)
    # A duplicate gets nothing (the renderer's argmax picks the first), lengths do not matter.
    dup = np.vstack([octahedron[:1], 2.0 * octahedron])
    assert nearest_direction_weights(dup) == pytest.approx([1 / 6, 0] + [1 / 6] * 5, abs=1e-9)
    # No spherical Voronoi diagram: two directions, one great circle; counted instead.
    assert nearest_direction_weights(np.array([[0, 1, 0], [0, -1, 0]])) == pytest.approx(
        [0.5, 0.5], abs=1e-3)
    ring = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [1, 1, 0]], float)
    assert nearest_direction_weights(ring) == pytest.approx([3 / 16, 3 / 16, 1 / 4, 1 / 4, 1 / 8],
                                                            abs=2e-3)
    assert nearest_direction_weights(np.array([[0, 0, 1]])) == pytest.approx([1.0])
    # The counted estimate agrees with scipy's spherical Voronoi areas on a random grid.
    rng = np.random.default_rng(2)
    d = rng.standard_normal((300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    exact = nearest_direction_weights(d)
    assert exact.sum() == pytest.approx(1.0)
    assert np.median(np.abs(_counted_weights(d) / exact - 1)) < 0.02


def test_coherence_errors() -> None:
    with pytest.raises(AcousticsError, match=r"freqs_hz: expected frequencies in 0\.\.24000"):
        sphere_head_coherence(SphereHead(), np.array([30000.0]), FS)
    with pytest.raises(AcousticsError, match="freqs_hz: expected a 1-d array"):
        sphere_head_coherence(SphereHead(), np.zeros((2, 2)), FS)
    with pytest.raises(AcousticsError, match="n_directions: expected >= 1"):
        sphere_head_coherence(SphereHead(), np.array([100.0]), FS, n_directions=0)
    hset = HrirSet(np.eye(3), np.zeros((3, 2, 8)), FS)
    with pytest.raises(AcousticsError, match="weights: expected 3 non-negative"):
        hrir_set_coherence(hset, np.array([100.0]), weights=np.array([1.0, -1.0, 1.0]))
    with pytest.raises(AcousticsError, match="directions: expected at least one vector"):
        nearest_direction_weights(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    with pytest.raises(AcousticsError, match="directions: expected at least one vector"):
        nearest_direction_weights(np.zeros((0, 3)))
    with pytest.raises(AcousticsError, match="tails: expected two signals"):
        diffuse_binaural_tails(np.zeros((3, 10)), SphereHead(), FS)
    with pytest.raises(AcousticsError, match="sample_rate_hz: expected"):
        binaural_diffuse_coherence(SphereHead(), 0.0)
    # A set with no power anywhere: nothing to correlate, Γ = 0 rather than NaN.
    assert np.all(hrir_set_coherence(hset, np.array([0.0, 100.0])) == 0)
