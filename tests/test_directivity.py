"""Directivity patterns: the cardioid family's closed forms, the talker table, SOFA sets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.directions import fibonacci_sphere
from sonicspec.acoustics.directivity import (
    CARDIOID_ALPHA,
    SPEECH,
    CardioidPattern,
    SofaPattern,
    cardioid_gain,
    emission_gains,
    local_directions,
    pattern_by_name,
    rotation,
)
from sonicspec.errors import AcousticsError

BANDS = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0)


@pytest.mark.parametrize("name", sorted(CARDIOID_ALPHA))
def test_cardioid_family_diffuse_power_is_the_sphere_mean(name):
    p = pattern_by_name(name)
    g = p.gains(fibonacci_sphere(20000), BANDS)
    np.testing.assert_allclose(np.mean(g ** 2, axis=0), p.diffuse_power(BANDS), rtol=2e-3)
    np.testing.assert_allclose(p.gains(np.array([[1.0, 0, 0]]), BANDS), 1.0)


def test_cardioid_nulls_and_known_directivity_factors():
    assert cardioid_gain(-1.0, 0.5) == 0.0
    assert pattern_by_name("hypercardioid").diffuse_power(BANDS)[0] == pytest.approx(0.25)
    assert pattern_by_name("cardioid").diffuse_power(BANDS)[0] == pytest.approx(1 / 3)
    with pytest.raises(AcousticsError, match="alpha: expected a value in"):
        CardioidPattern(alpha=1.5)
    with pytest.raises(AcousticsError, match="directivity pattern: expected one of"):
        pattern_by_name("trumpet")


def test_local_directions_match_the_microphone_rotation():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(20, 3))
    yaw, pitch = 37.0, -12.0
    np.testing.assert_allclose(local_directions(d, yaw, pitch), d @ rotation(yaw, pitch),
                               atol=1e-12)
    # a talker facing +y (yaw 90) hears its front along +y
    np.testing.assert_allclose(local_directions([[0, 1, 0]], 90.0), [[1, 0, 0]], atol=1e-12)


def test_speech_is_quieter_behind_and_more_directional_at_high_bands():
    front, back = np.array([[1.0, 0, 0]]), np.array([[-1.0, 0, 0]])
    g_front, g_back = SPEECH.gains(front, BANDS)[0], SPEECH.gains(back, BANDS)[0]
    np.testing.assert_allclose(g_front, 1.0)
    drop = 20 * np.log10(g_back)
    assert np.all(np.diff(drop) <= 0)
    assert drop[0] > -3 and -12 <= drop[-1] <= -8  # 4 kHz: 8–12 dB down behind (Chu & Warnock)
    di = -10 * np.log10(SPEECH.diffuse_power(BANDS))
    assert np.all(np.diff(di) > 0) and 0 < di[0] < 1.5 and 3 < di[-1] < 7
    # continuous across the horizontal plane and left-right symmetric
    eps = np.array([[0.0, 1.0, 1e-6], [0.0, 1.0, -1e-6], [0.0, -1.0, 0.0]])
    g = SPEECH.gains(eps, BANDS)
    np.testing.assert_allclose(g[0], g[1], rtol=1e-9)
    np.testing.assert_allclose(g[0], g[2], rtol=1e-9)
    assert not SPEECH.frequency_independent and pattern_by_name("cardioid").frequency_independent


def test_emission_gains_turn_with_the_talker_and_leave_no_path_alone():
    p = pattern_by_name("cardioid")
    d = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 0, 0]])
    g = emission_gains(p, d, np.array([0.0, 180.0, 0.0]), BANDS)
    np.testing.assert_allclose(g[:, 0], [1.0, 0.0, 1.0], atol=1e-12)


def _write_sofa(path, gains_of, freqs):
    import sofar as sf

    s = sf.Sofa("FreeFieldDirectivityTF")
    az, el = np.meshgrid(np.arange(0, 360, 10.0), np.arange(-80, 81, 10.0))
    pos = np.column_stack([az.ravel(), el.ravel(), np.ones(az.size)])
    pos = np.vstack([pos, [[0, 90, 1], [0, -90, 1]]])
    a, e = np.radians(pos[:, 0]), np.radians(pos[:, 1])
    dirs = np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    s.ReceiverPosition = pos
    s.N = freqs
    data = gains_of(dirs, freqs)[None]
    s.Data_Real = data
    s.Data_Imag = np.zeros_like(data)
    for optional in ("Description", "EmitterDescriptions"):  # netCDF4 cannot write them empty
        s.delete(optional)
    sf.write_sofa(str(path), s)
    return path


def test_sofa_pattern_reads_a_written_cardioid_back(tmp_path):
    import sofar as sf

    freqs = np.geomspace(50, 7000, 200)
    # a pattern that is a cardioid at high and omni at low frequencies
    def gains_of(dirs, f):
        a = np.where(f < 700, 1.0, 0.5)
        return a[None, :] + (1 - a[None, :]) * dirs[:, :1]

    path = _write_sofa(tmp_path / "talker.sofa", gains_of, freqs)
    p = SofaPattern.from_sofa(sf.read_sofa(str(path)), BANDS)
    test = fibonacci_sphere(300)
    g = p.gains(test, BANDS)
    np.testing.assert_allclose(g[:, 0], 1.0, atol=1e-9)
    np.testing.assert_allclose(g[:, -1], 0.5 + 0.5 * test[:, 0], atol=0.03)
    np.testing.assert_allclose(p.diffuse_power(BANDS)[-1], 1 / 3, rtol=0.03)
    assert not p.frequency_independent


def test_sofa_of_another_convention_is_refused():
    import sofar as sf

    with pytest.raises(AcousticsError, match="expected a SOFA FreeFieldDirectivityTF"):
        SofaPattern.from_sofa(sf.Sofa("SimpleFreeFieldHRIR"), BANDS)


def test_supercardioid_has_the_best_front_to_back_ratio():
    def ratio(alpha):
        d = fibonacci_sphere(20000)
        g2 = cardioid_gain(d[:, 0], alpha) ** 2
        return g2[d[:, 0] > 0].sum() / g2[d[:, 0] < 0].sum()

    best = max(np.linspace(0.2, 0.6, 81), key=ratio)
    assert best == pytest.approx(CARDIOID_ALPHA["supercardioid"], abs=0.01)
    assert math.isclose(CARDIOID_ALPHA["supercardioid"], 0.366, abs_tol=1e-3)


def test_compute_rir_takes_a_talker_that_faces_away() -> None:
    """The Python API: the same RIR (one seed) of a cardioid talker facing the microphone and
    facing away — the direct sound the same and gone, the tail the cardioid's diffuse power."""
    import sonicspec as ss
    from sonicspec.acoustics.directivity import SourceDirectivity

    room = ss.Scene.shoebox([5.0, 4.0, 3.0], {"walls": "plaster_on_brick"})
    settings = ss.RirSettings(rays=500, image_source_order=1, max_rir_length_s=0.3,
                              sample_rate_hz=16000, diffraction=False)
    src, mic = [1.0, 2.0, 1.5], [4.0, 2.0, 1.5]
    cardioid = pattern_by_name("cardioid")

    def rir(directivity):
        return ss.compute_rir(room, src, mic, settings, directivity=directivity).rir[0]

    omni = rir(None)
    toward, away = rir(SourceDirectivity(cardioid, 0.0)), rir(SourceDirectivity(cardioid, 180.0))
    arrive = round(3.0 / 343.0 * 16000)
    direct = slice(arrive - 3, arrive + 4)  # the first reflection (the floor) is 58 samples later
    np.testing.assert_allclose(toward[direct], omni[direct], atol=1e-6)
    assert np.max(np.abs(away[direct])) < 0.02 * np.max(np.abs(omni[direct]))
    tail = slice(int(0.1 * 16000), omni.size)
    ratio = np.sum(away[tail] ** 2) / np.sum(omni[tail] ** 2)
    assert ratio == pytest.approx(1 / 3, rel=0.05)
