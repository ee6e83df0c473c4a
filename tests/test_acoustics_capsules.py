"""Directional capsules and device presets (issue 30): the exact references first
(``acoustics.theory``: the first-order gain, the diffuse cross-spectrum by quadrature), then
the engine end to end (a cardioid's rear rejection, the patterns against the analytic gain for
a plane wave, the tail's diffuse-field power and cross-spectra), the moving-path renderer
against the exact moving image sum with the pattern at each emission, and the presets."""

from __future__ import annotations

import math

import numpy as np
import pytest

import sonicspec as ss
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.receivers.capsules import (
    PATTERNS,
    Capsules,
    diffuse_cross_spectra,
    diffuse_power,
    pattern_alpha,
)
from sonicspec.acoustics.theory import diffuse_cross_spectrum_quadrature, first_order_gain
from sonicspec.errors import AcousticsError

FS = 16000
C = 343.0
MIC = [3.0, 2.5, 1.5]


# --- the exact references -------------------------------------------------------------------

def test_first_order_gain_nulls_and_diffuse_power() -> None:
    assert first_order_gain(0.5, math.pi) == pytest.approx(0.0, abs=1e-15)  # cardioid rear
    assert first_order_gain(0.0, math.pi / 2) == pytest.approx(0.0, abs=1e-15)  # figure-8
    assert first_order_gain(0.25, math.acos(-1 / 3)) == pytest.approx(0.0, abs=1e-15)  # hyper
    # the diffuse power of one capsule at the centre, by quadrature: a² + (1 − a)²/3
    for a in PATTERNS.values():
        s = diffuse_cross_spectrum_quadrature([[0, 0, 0]], [[0.3, -0.2, 0.9]], [a], [0.0, 1e3])
        assert s[:, 0, 0].real == pytest.approx(a * a + (1 - a) ** 2 / 3, abs=1e-12)
    with pytest.raises(AcousticsError, match=r"alpha: expected 0 <= a <= 1, got 1\.5"):
        first_order_gain(1.5, 0.0)


def test_the_closed_form_cross_spectra_match_the_quadrature() -> None:
    rng = np.random.default_rng(3)
    offsets = rng.normal(size=(4, 3)) * 0.05
    axes = rng.normal(size=(4, 3))
    alphas = np.array([1.0, 0.5, 0.25, 0.0])
    f = np.array([0.0, 125.0, 1000.0, 4000.0, 8000.0])
    ours = diffuse_cross_spectra(Capsules(offsets, axes, alphas), f, C)
    exact = diffuse_cross_spectrum_quadrature(offsets, axes, alphas, f, speed_of_sound_m_s=C)
    assert np.max(np.abs(ours - exact)) < 1e-9
    # omni capsules: sinc(kd), the coherence the omni arrays mix to
    omni = diffuse_cross_spectra(Capsules(offsets[:2], axes[:2], [1.0, 1.0]), f, C)
    kd = 2 * np.pi * f / C * np.linalg.norm(offsets[0] - offsets[1])
    assert np.allclose(omni[:, 0, 1], np.sinc(kd / np.pi), atol=1e-12)
    np.testing.assert_allclose(np.diagonal(ours[0]).real, diffuse_power(alphas))


# --- end to end through the RIR engine --------------------------------------------------------

def _anechoic() -> ss.Scene:
    return ss.Scene.shoebox([6, 5, 3], {"walls": "open", "floor": "open", "ceiling": "open"},
                            custom_materials={"open": {"absorption": 1.0, "scattering": 0.0}})


def _settings(**kw) -> ss.RirSettings:
    return ss.RirSettings(rays=2000, sample_rate_hz=FS, speed_of_sound_m_s=C, **kw)


def _rir(scene, source, receiver, settings=None) -> np.ndarray:
    return ss.compute_rir(scene, source, MIC, settings or _settings(),
                          receiver=receiver).rir.astype(np.float64)


def _band_energies(rir: np.ndarray) -> np.ndarray:
    bank = OctaveFilterBank(FS, ())
    return np.sum(bank.split(rir) ** 2, axis=-1)


@pytest.mark.parametrize("turned", ["source behind", "capsule turned away"])
def test_a_cardioid_rejects_a_source_behind_it_by_20_db_in_every_band(turned: str) -> None:
    """Free field (a fully absorbing room): a cardioid facing +x hears a source 1.5 m in
    front in full and one 1.5 m behind not at all; turning the capsule (azimuth 180) with
    the source in front is the same. The bar is 20 dB in every octave band; the ideal
    capsule's null is exact, so the rear energy is at the level of rounding."""
    scene = _anechoic()
    front, behind = [4.5, 2.5, 1.5], [1.5, 2.5, 1.5]
    cardioid = {"kind": "mono", "capsule": {"pattern": "cardioid"}}
    heard = _band_energies(_rir(scene, front, cardioid)[0])
    if turned == "source behind":
        rear = _band_energies(_rir(scene, behind, cardioid)[0])
    else:
        rear = _band_energies(_rir(scene, front, {"kind": "mono", "capsule": {
            "pattern": "cardioid", "azimuth_deg": 180}})[0])
    rejection_db = 10 * np.log10(heard / np.maximum(rear, 1e-30))
    assert np.all(rejection_db >= 20.0), rejection_db
    omni = _band_energies(_rir(scene, front, {"kind": "mono"})[0])
    np.testing.assert_allclose(heard, omni, rtol=1e-5)  # on axis: the omni's level


@pytest.mark.parametrize("pattern", sorted(PATTERNS))
def test_each_pattern_against_the_analytic_gain_for_a_plane_wave(pattern: str) -> None:
    """A source 2 m away at azimuths 0…180° of a capsule facing +x (free field): the RIR is
    the omni's times ``a + (1 − a) cos θ``, sign included, to float32 rounding; the
    figure-eight's null at 90° and the cardioid's at 180° are exact."""
    scene = _anechoic()
    receiver = {"kind": "mono", "capsule": {"pattern": pattern}}
    for theta in (0.0, 45.0, 90.0, 135.0, 180.0):
        t = math.radians(theta)
        source = [MIC[0] + 2 * math.cos(t), MIC[1] + 2 * math.sin(t), MIC[2]]
        omni = _rir(scene, source, {"kind": "mono"})[0]
        ours = _rir(scene, source, receiver)[0]
        gain = float(first_order_gain(pattern_alpha(pattern), t))
        assert np.max(np.abs(ours - gain * omni)) <= 1e-6 * np.max(np.abs(omni)), theta
    if pattern == "figure_eight":  # the null at 90°, in the elevation too
        up = _rir(scene, [MIC[0], MIC[1], MIC[2] + 1.0], receiver)[0]
        assert np.max(np.abs(up)) == 0.0


def test_capsules_turn_with_the_array_and_face_out() -> None:
    """An array's capsules turn with its yaw; ``facing: outward`` points each capsule of a
    circle away from the centre (the one facing the source hears it, the opposite one not)."""
    scene = _anechoic()
    source = [4.5, 2.5, 1.5]  # +x of the array
    out = _rir(scene, source, {"kind": "circular_array", "n": 4, "radius_m": 0.05,
                               "capsule": {"pattern": "cardioid", "facing": "outward"}})
    level = np.sqrt(np.sum(out**2, axis=1))  # (a fractional tap's energy, not its peak)
    assert level[2] < 1e-6 * level[0]  # the capsule at 180° faces away
    assert level[1] == pytest.approx(0.5 * level[0], rel=0.03)  # 90°: half (a cardioid)
    assert level[3] == pytest.approx(level[1], rel=0.01)
    turned = _rir(scene, source, {"kind": "mono", "yaw_deg": 180.0,
                                  "capsule": {"pattern": "cardioid"}})
    assert np.max(np.abs(turned)) < 1e-9
    vector = _rir(scene, source, {"kind": "mono", "capsule": {"pattern": "cardioid",
                                                                  "axis": [-1, 0, 0]}})
    assert np.max(np.abs(vector)) < 1e-9


def test_the_late_tail_carries_the_patterns_diffuse_power() -> None:
    """In a reverberant room the tail is a diffuse field: a cardioid capsule hears 1/3 of
    the omni's late energy (−4.77 dB), a hypercardioid 1/4; the same draws, so exactly."""
    room = ss.Scene.shoebox([6, 5, 3])
    settings = _settings(max_rir_length_s=0.5)
    source = [1.5, 1.0, 1.4]
    omni = _rir(room, source, {"kind": "mono"}, settings)[0]
    late = slice(int(0.08 * FS), None)  # after the image sources' early part
    for pattern in ("cardioid", "hypercardioid"):
        ours = _rir(room, source, {"kind": "mono", "capsule": {"pattern": pattern}},
                    settings)[0]
        ratio = np.sum(ours[late] ** 2) / np.sum(omni[late] ** 2)
        assert ratio == pytest.approx(float(diffuse_power(pattern_alpha(pattern))), rel=0.05)


def test_the_tails_of_two_capsules_have_the_diffuse_cross_spectrum() -> None:
    """Back-to-back cardioids 5 cm apart and a figure-eight pair: independent noises mixed by
    ``directional_diffuse`` have the closed-form cross-spectra, within 0.05 (RMS over
    100–4000 Hz, normalised by the powers) in real and imaginary part."""
    from scipy.signal import csd

    from sonicspec.acoustics.receivers.arrays import directional_diffuse

    rng = np.random.default_rng(5)
    noise = rng.standard_normal((2, 1 << 18))
    for axes, alphas in (([[1, 0, 0], [-1, 0, 0]], [0.5, 0.5]),
                         ([[0, 1, 0], [1, 0, 0]], [0.0, 0.25])):
        caps = Capsules([[0.025, 0, 0], [-0.025, 0, 0]], axes, alphas)
        y = directional_diffuse(noise, caps, FS, C)
        f, s01 = csd(y[0], y[1], fs=FS, nperseg=512)
        _, s00 = csd(y[0], y[0], fs=FS, nperseg=512)
        _, s11 = csd(y[1], y[1], fs=FS, nperseg=512)
        measured = s01 / np.sqrt(s00.real * s11.real)
        exact = diffuse_cross_spectra(caps, f, C)
        expected = exact[:, 0, 1] / np.sqrt(exact[:, 0, 0].real * exact[:, 1, 1].real)
        band = (f >= 100) & (f <= 4000)
        # scipy's csd(x, y) is conj(X)·Y: the conjugate of E[Y_0 Y_1*]
        err = np.conj(measured[band]) - expected[band]
        assert np.sqrt(np.mean(err.real**2)) < 0.05 and np.sqrt(np.mean(err.imag**2)) < 0.05
        _, white = csd(noise[0], noise[0], fs=FS, nperseg=512)
        share = np.mean(s00.real[band]) / np.mean(white.real[band])
        assert share == pytest.approx(float(diffuse_power(alphas[0])), rel=0.05)


def test_omni_capsules_keep_the_arrays_bytes() -> None:
    """``capsule: {pattern: omni}`` (the default) renders with the plain array renderer:
    identical RIRs, and the microphone's data (its content key) leaves ``capsule`` out."""
    room = ss.Scene.shoebox([6, 5, 3])
    settings = _settings(max_rir_length_s=0.3)
    plain = {"kind": "circular_array", "n": 3, "radius_m": 0.04}
    a = _rir(room, [1.5, 1.0, 1.4], plain, settings)
    b = _rir(room, [1.5, 1.0, 1.4], {**plain, "capsule": {"pattern": "omni"}}, settings)
    assert np.array_equal(a, b)
    from pydantic import TypeAdapter

    from sonicspec.spec.microphone import MicrophoneSpec

    dumped = TypeAdapter(MicrophoneSpec).validate_python(
        {**plain, "capsule": {"pattern": "omni"}}).model_dump(mode="json")
    assert "capsule" not in dumped


# --- the moving-path renderer -----------------------------------------------------------------

def test_a_walking_source_at_cardioid_capsules_matches_the_exact_image_sum() -> None:
    """Two cardioids facing ±y, 5 cm apart, in the reflecting shoebox of the moving tests:
    the engine's paths rendered per capsule against the exact moving image sum, each image
    weighted by the capsule's gain for its direction at emission (the retarded-time
    solution with the pattern applied at each emission): SNR ≥ 40 dB per capsule."""
    from test_acoustics_moving import ENDS, SIZE, engine_walk, figures, pink, walk
    from test_acoustics_moving import MIC as MOVING_MIC

    from sonicspec.acoustics.engine import scene_capsules
    from sonicspec.acoustics.moving.delays import Receiver, render_paths
    from sonicspec.acoustics.theory import moving_point_source, shoebox_moving_images

    n = 2 * FS
    dry = pink(n, seed=4)
    microphone = {"kind": "custom", "positions_m": [[0, 0.025, 0], [0, -0.025, 0]],
                  "capsules": [{"pattern": "cardioid", "azimuth_deg": 90},
                               {"pattern": "cardioid", "azimuth_deg": -90}],
                  "yaw_deg": 0.0, "pitch_deg": 0.0, "trajectory": {"kind": "static"}}
    caps = scene_capsules(microphone)
    points, paths, index, bank = engine_walk(microphone)
    receiver = Receiver("array", offsets_m=caps.offsets_m, center_m=MOVING_MIC,
                        capsule_axes=caps.axes, capsule_alphas=caps.alphas)
    ours = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                        speed_of_sound_m_s=C, receiver=receiver)
    path = walk(ENDS.tolist(), 1.5, n)
    exact = np.zeros_like(ours)
    for positions, reflections in shoebox_moving_images(SIZE, path, 2):
        d = positions - MOVING_MIC
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        for m, offset in enumerate(caps.offsets_m):
            gain = first_order_gain(caps.alphas[m], np.arccos(np.clip(d @ caps.axes[m], -1, 1)))
            exact[m] += moving_point_source(dry, positions, MOVING_MIC + offset, FS,
                                            speed_of_sound_m_s=C,
                                            gain=0.8**reflections * gain, n_out=exact.shape[1])
    for m in range(2):
        snr, _ = figures(exact[m], ours[m], n)
        assert snr >= 40, (m, snr)


def test_a_walking_microphone_with_cardioids_turns_them_with_its_heading() -> None:
    """Four cardioids facing out on a 5 cm circle, carried along a line facing 30° off its
    heading, past a walking source: each capsule against the exact moving image sum at its
    own turned place, each image weighted by the capsule's gain for its direction in the
    turned frame (SNR ≥ 40 dB per capsule)."""
    from test_acoustics_moving import figures, pink
    from test_acoustics_moving_mic import engine_pairs, exact_sum, line

    from sonicspec.acoustics.engine import microphone_capsules
    from sonicspec.acoustics.moving.delays import Receiver, render_paths
    from sonicspec.acoustics.receivers.arrays import rotation

    n = 2 * FS
    t = np.arange(n) / FS
    dry = pink(n, seed=23)
    start, end = np.array([1.5, 1.2, 1.3]), np.array([4.5, 3.4, 1.2])
    mic_track = line(start, end, 1.2, t)
    source_track = line([4.8, 1.0, 1.6], [2.0, 4.0, 1.5], 1.4, t)
    yaw = np.degrees(np.arctan2(*(end - start)[1::-1])) + 30.0
    frame = rotation(yaw, 0.0)
    caps = microphone_capsules({"kind": "circular_array", "n": 4, "radius_m": 0.05,
                                "capsule": {"pattern": "cardioid", "facing": "outward"}})
    points, mics, paths, index, bank = engine_pairs(source_track, mic_track, n)
    receiver = Receiver("array", offsets_m=caps.offsets_m, mic_track_m=mics,
                        yaw_deg=np.full(len(points), yaw), capsule_axes=caps.axes,
                        capsule_alphas=caps.alphas)
    ours = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                        speed_of_sound_m_s=C, receiver=receiver)
    for m, offset in enumerate(caps.offsets_m):
        axis = frame @ caps.axes[m]

        def gain(p, axis=axis):
            d = p - mic_track
            return first_order_gain(0.5, np.arccos(np.clip(
                d @ axis / np.linalg.norm(d, axis=1), -1.0, 1.0)))

        exact = exact_sum(dry, source_track, mic_track + frame @ offset, ours.shape[1],
                          gains=gain)
        snr, _ = figures(exact, ours[m], n)
        assert snr >= 40, (m, snr)


# --- devices ----------------------------------------------------------------------------------

def test_every_preset_loads_with_its_source_and_geometry() -> None:
    from sonicspec.acoustics.receivers.devices import device, device_names
    from sonicspec.spec.microphone import DEVICE_NAMES, device_preset

    assert set(device_names()) == set(DEVICE_NAMES)
    expected = {"respeaker_4mic": 4, "respeaker_6mic": 6, "minidsp_uma8": 7,
                "smart_speaker_7mic": 7, "phone_2mic": 2, "phone_3mic": 3, "em32": 32}
    for name, count in expected.items():
        dev = device(name)
        assert len(dev.capsules) == count == len(device_preset(name)["capsules"])
        assert len(dev.source) > 60 and dev.title
    em32 = device("em32").capsules
    assert em32.sphere_radius_m == 0.042
    assert np.allclose(np.linalg.norm(em32.offsets_m, axis=1), 0.042, atol=1e-6)
    uma = device("minidsp_uma8").capsules.offsets_m
    assert np.allclose(np.linalg.norm(uma[1:], axis=1), 0.043) and not np.any(uma[0])
    with pytest.raises(AcousticsError, match=r"microphone\.device: expected one of em32"):
        device("echo")


def test_the_em32_hears_like_capsules_on_a_rigid_sphere() -> None:
    """Free field, a source on +x: the capsule facing it hears the direct sound first and
    brighter (the sphere's +6 dB at high frequency), the one facing away last and dull; two
    capsules' diffuse cross-spectrum is the sphere head's coherence for the same pair."""
    from sonicspec.acoustics.receivers.devices import device
    from sonicspec.acoustics.receivers.hrtf import (
        SphereHead,
        sphere_cross_spectra,
        sphere_head_coherence,
    )

    scene = _anechoic()
    rir = _rir(scene, [4.5, 2.5, 1.5], {"kind": "device", "device": "em32"})
    assert rir.shape[0] == 32
    caps = device("em32").capsules
    toward = int(np.argmax(caps.axes[:, 0]))
    away = int(np.argmin(caps.axes[:, 0]))
    onset = np.argmax(np.abs(rir) > 0.1 * np.max(np.abs(rir)), axis=1)
    assert onset[toward] < onset[away]
    high = OctaveFilterBank(FS, ()).split(rir)[-1]  # the 4 kHz band
    assert np.sum(high[toward] ** 2) > 10 * np.sum(high[away] ** 2)
    ears = np.array([[math.cos(a), math.sin(a), 0.0] for a in (math.radians(100),
                                                                 -math.radians(100))])
    pair = Capsules(ears * 0.042, ears, [1.0, 1.0], 0.042)
    f = np.linspace(0, 7000, 15)
    s = sphere_cross_spectra(pair, f, FS, C, n_directions=2048)
    gamma = s[:, 0, 1].real / np.sqrt(s[:, 0, 0].real * s[:, 1, 1].real)
    exact = sphere_head_coherence(SphereHead(0.042, 100.0), f, FS, speed_of_sound_m_s=C)
    assert np.max(np.abs(gamma - exact)) < 1e-6


def test_capsules_reject_bad_input() -> None:
    with pytest.raises(AcousticsError, match="capsule pattern: expected one of omni"):
        pattern_alpha("shotgun")
    with pytest.raises(AcousticsError, match="every axis needs a direction"):
        Capsules([[0, 0, 0]], [[0, 0, 0]], [0.5])
    with pytest.raises(AcousticsError, match="on a rigid sphere the capsules are omni"):
        Capsules([[0.04, 0, 0]], [[1, 0, 0]], [0.5], 0.04)
    with pytest.raises(AcousticsError, match="expected as many axes and patterns"):
        Capsules([[0, 0, 0]], [[1, 0, 0], [0, 1, 0]], [0.5])
