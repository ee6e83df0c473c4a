"""Diffuse (isotropic) backgrounds at every receiver against the exact references of
``theory`` (issue 30): the coherence of omni pairs 5, 10 and 20 cm apart within 0.05 RMS of
sinc(kd) (J0(kd) in the cylindrical field) over 100–4000 Hz, the head's against its own
transfer functions integrated over directions, ambisonic channels' diffuse powers, the
level, and determinism."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from sonicspec.acoustics import theory
from sonicspec.acoustics.bands import default_bands
from sonicspec.acoustics.engine import (
    SimulationSettings,
    direction_responses,
    receiver_aperture_m,
)
from sonicspec.acoustics.receivers.diffuse import (
    cross_spectral_matrix,
    direction_count,
    frame_samples,
    hermitian_root,
    isotropic_directions,
    isotropic_roots,
    render_isotropic,
)
from sonicspec.errors import AcousticsError

FS = 16000
C = 343.0
SETTINGS = SimulationSettings(
    sample_rate_hz=FS, bands_hz=default_bands(FS), rays=1, image_source_order=0,
    max_rir_length_s=1.0, energy_threshold_db=60.0, air_absorption=False, temperature_c=20.0,
    relative_humidity_pct=50.0, transmission=False, diffuse_rain=False, receiver_radius_m=0.1,
    histogram_bin_s=0.001, speed_of_sound_m_s=C)  # fmt: skip
ARRAY = {"kind": "custom", "positions_m": [[0, 0, 0], [0.05, 0, 0], [0.1, 0, 0], [0, 0.2, 0]],
         "yaw_deg": 25.0, "pitch_deg": 0.0}
HEAD = {"kind": "binaural", "yaw_deg": 30.0, "pitch_deg": 0.0,
        "hrtf": {"kind": "sphere", "head_radius_m": 0.0875, "ear_angle_deg": 100.0}}


def diffuse(mic, field, seconds=30.0, seed=2):
    n = direction_count(field, receiver_aperture_m(mic), FS, C)
    roots = isotropic_roots(direction_responses(isotropic_directions(field, n), SETTINGS, mic),
                            FS)
    x = np.random.default_rng(1).standard_normal(round(seconds * FS))
    return x, render_isotropic(x, roots, np.random.default_rng(seed))


def coherence(a, b):
    f, pab = signal.csd(a, b, FS, nperseg=512)
    _, paa = signal.welch(a, FS, nperseg=512)
    _, pbb = signal.welch(b, FS, nperseg=512)
    band = (f >= 100) & (f <= 4000)
    return f[band], (pab.real / np.sqrt(paa * pbb))[band]


@pytest.mark.parametrize("field", ["spherical", "cylindrical"])
def test_omni_pairs_have_the_isotropic_coherence(field):
    _, y = diffuse(ARRAY, field)
    exact = (theory.spherical_isotropic_coherence if field == "spherical"
             else theory.cylindrical_isotropic_coherence)
    for ch, d in ((1, 0.05), (2, 0.1), (3, 0.2)):
        f, g = coherence(y[0], y[ch])
        rms = float(np.sqrt(np.mean((g - exact(f, d, C)) ** 2)))
        assert rms < 0.05, (field, d, rms)
    # and not a point source's (|Γ| = 1): the 20 cm pair is far from coherent above 1.5 kHz
    f, g = coherence(y[0], y[3])
    assert np.max(np.abs(g[f > 1500])) < (0.3 if field == "spherical" else 0.45)


@pytest.mark.parametrize("field", ["spherical", "cylindrical"])
def test_the_head_has_its_models_interaural_coherence(field):
    _, y = diffuse(HEAD, field)
    f, g = coherence(y[0], y[1])
    exact = theory.brown_duda_diffuse_coherence(f, field=field, sample_rate_hz=FS,
                                                speed_of_sound_m_s=C)
    assert float(np.sqrt(np.mean((g - exact) ** 2))) < 0.05


def test_cross_spectra_of_the_receivers_responses_are_sinc():
    # The quadrature alone (no random signals): Φ of the responses against sinc up to 7 kHz.
    n = direction_count("spherical", receiver_aperture_m(ARRAY), FS, C)
    phi = cross_spectral_matrix(
        direction_responses(isotropic_directions("spherical", n), SETTINGS, ARRAY), 512)
    f = np.fft.rfftfreq(512, 1 / FS)
    band = f <= 7000
    gamma = phi[:, 0, 3].real / np.sqrt(phi[:, 0, 0].real * phi[:, 3, 3].real)
    assert np.max(np.abs(gamma - theory.spherical_isotropic_coherence(f, 0.2, C))[band]) < 0.01
    # An omni capsule hears the diffuse field at unit power (the fractional delays' droop
    # near Nyquist aside).
    assert np.allclose(phi[f <= 6000, 1, 1].real, 1.0, atol=0.01)
    root = hermitian_root(phi)
    assert np.allclose(root @ np.conj(np.swapaxes(root, 1, 2)), phi, atol=1e-9)


def test_ambisonic_channels_have_diffuse_sn3d_powers_and_no_correlation():
    x, y = diffuse({"kind": "ambisonics", "order": 2, "yaw_deg": 0.0, "pitch_deg": 0.0},
                   "spherical", seconds=10.0)
    power = np.mean(y**2, axis=1) / np.mean(x**2)
    degree = np.floor(np.sqrt(np.arange(9))).astype(int)
    assert np.allclose(power, 1 / (2 * degree + 1), rtol=0.03)
    r = np.corrcoef(y)
    assert np.max(np.abs(r - np.eye(9))) < 0.03


def test_level_and_a_mono_receiver_is_the_signal_itself():
    x, y = diffuse({"kind": "mono"}, "spherical", seconds=5.0)
    assert y.shape == (1, x.size)
    assert np.max(np.abs(y[0] - x)) < 1e-9  # Φ = 1: no draws, the STFT round trip exact
    x, y = diffuse(ARRAY, "spherical", seconds=10.0)
    db = 10 * np.log10(np.mean(y**2, axis=1) / np.mean(x**2))
    assert np.all(np.abs(db) < 0.15), db


def test_same_seed_same_bytes():
    _, a = diffuse(ARRAY, "cylindrical", seconds=3.0, seed=7)
    _, b = diffuse(ARRAY, "cylindrical", seconds=3.0, seed=7)
    _, c = diffuse(ARRAY, "cylindrical", seconds=3.0, seed=8)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)


def test_frames_and_counts():
    assert frame_samples(16000) == 512 and frame_samples(48000) == 2048
    assert direction_count("spherical", 0.0, FS, C) == 1024
    assert direction_count("spherical", 0.2, FS, C) > direction_count("spherical", 0.05, FS, C)
    assert direction_count("cylindrical", 100.0, FS, C) == 4096
    d = isotropic_directions("cylindrical", 8)
    assert np.allclose(d[:, 2], 0) and np.allclose(np.linalg.norm(d, axis=1), 1)


def test_bad_inputs_are_named():
    with pytest.raises(AcousticsError, match="field: expected 'spherical' or 'cylindrical'"):
        isotropic_directions("planar", 8)
    with pytest.raises(AcousticsError, match="responses: expected"):
        cross_spectral_matrix(np.zeros((4, 2)), 512)
    with pytest.raises(AcousticsError, match="signal: expected one channel"):
        render_isotropic(np.zeros((2, 10)), np.zeros((257, 2, 2)), np.random.default_rng(0))
    with pytest.raises(AcousticsError, match="root: expected"):
        render_isotropic(np.zeros(10), np.zeros((257, 2, 3)), np.random.default_rng(0))


def test_a_measured_hrir_set_has_its_own_diffuse_coherence():
    # A synthetic "measured" set (two free-field points 18 cm apart, 600 directions, heard by
    # nearest direction): the rendered ears against the set's own diffuse-field coherence
    # (hrtf.hrir_set_coherence, its directions weighted by their Voronoi cells).
    from sonicspec.acoustics.directions import fibonacci_sphere
    from sonicspec.acoustics.receivers.hrtf import HrirSet, hrir_set_coherence

    dirs = fibonacci_sphere(600)
    t = np.arange(64)
    ears = np.array([[0.0, 0.09, 0.0], [0.0, -0.09, 0.0]])
    delay = 32 - (dirs @ ears.T) / C * FS  # (n, 2) samples
    hrirs = np.sinc(t[None, None, :] - delay[:, :, None]) * np.hanning(64)
    hset = HrirSet(dirs, hrirs, float(FS))
    mic = {"kind": "binaural", "yaw_deg": 0.0, "pitch_deg": 0.0,
           "hrtf": {"kind": "sofa", "path": "set.sofa"}}
    n = direction_count("spherical", receiver_aperture_m(mic), FS, C)
    roots = isotropic_roots(direction_responses(isotropic_directions("spherical", n), SETTINGS,
                                                mic, hset), FS)
    x = np.random.default_rng(1).standard_normal(30 * FS)
    y = render_isotropic(x, roots, np.random.default_rng(3))
    f, g = coherence(y[0], y[1])
    assert float(np.sqrt(np.mean((g - hrir_set_coherence(hset, f)) ** 2))) < 0.05
    with pytest.raises(AcousticsError, match="SOFA HRTF needs its HRIR set"):
        direction_responses(isotropic_directions("spherical", 8), SETTINGS, mic)
