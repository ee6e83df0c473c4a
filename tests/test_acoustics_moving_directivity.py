"""A turning, walking directional source rendered under ``paths`` against the exact
retarded-time solution with the pattern applied at each emission time (issue 30)."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.acoustics.directivity import SourceDirectivity, pattern_by_name
from sonicspec.acoustics.theory import directional_source_with_plane
from sonicspec.audio.fidelity import snr_db

FS = 16000
C = 343.0
MIC = np.array([0.5, 1.2, 1.3])
REFLECTION = 0.8  # the floor's pressure reflection factor: α = 1 − 0.8² = 0.36


def pink(n: int, seed: int = 7) -> np.ndarray:
    spec = np.fft.rfft(np.random.default_rng(seed).standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / FS)
    spec[1:] /= np.sqrt(f[1:] / 100.0)
    spec[f > 0.8 * FS / 2] = 0
    x = np.fft.irfft(spec, n)
    return x / np.max(np.abs(x))


def floor_paths(points: np.ndarray):
    """The engine's early paths (direct sound and the floor's reflection) of source points
    above one 400 m² reflecting plane z = 0 in free field: ``(paths, bank)``."""
    import sonicspec as ss
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import early_arrivals
    from sonicspec.acoustics.moving.delays import PathSet
    from sonicspec.testing.rooms import uniform_scene

    settings = ss.RirSettings(rays=100, image_source_order=1, air_absorption=False,
                              max_rir_length_s=0.3, speed_of_sound_m_s=C, sample_rate_hz=FS,
                              diffraction=False).simulation_settings()
    verts = np.array([[-10.0, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    scene = uniform_scene(verts, faces, alpha=1 - REFLECTION ** 2,
                          n_bands=len(settings.bands_hz))
    early = early_arrivals(scene, MIC, points, settings)
    return PathSet.identify(points, early.from_mic), OctaveFilterBank(FS, settings.bands_hz)


@pytest.mark.parametrize("name", ["cardioid", "hypercardioid"])
def test_a_turning_source_on_the_spot_matches_the_exact_solution(name: str) -> None:
    """A talker standing 2 m from the microphone turning round once in 3 s: every emission
    leaves with the pattern's gain of that moment, directly and off the floor."""
    from sonicspec.acoustics.moving.delays import render_paths

    n = 3 * FS
    dry = pink(n)
    point = np.array([[2.3, 0.4, 1.6]])
    yaw = 120.0 * np.arange(n) / FS
    paths, bank = floor_paths(point)
    assert sorted(paths.order) == [0, 1]
    pattern = pattern_by_name(name)
    (ours,) = render_paths(dry, np.zeros(n), point, paths, bank, n_out=n + 300,
                           speed_of_sound_m_s=C, source=SourceDirectivity(pattern, yaw))
    exact = directional_source_with_plane(
        dry, point[0], yaw, MIC, FS, lambda d: pattern.gains(d, (1000.0,))[:, 0],
        plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1], reflection=REFLECTION,
        speed_of_sound_m_s=C, n_out=n + 300)
    core = slice(int(0.1 * FS), n - int(0.1 * FS))
    assert snr_db(exact[core], ours[core]) >= 40, snr_db(exact[core], ours[core])


def test_a_walking_turning_source_matches_the_exact_solution() -> None:
    """A cardioid talker walking 1.5 m/s past the microphone through RIR points every 0.25 m,
    facing where it walks and turning its head ±40° twice a second."""
    from sonicspec.acoustics.moving.delays import render_paths
    from sonicspec.geometry.navigation import resample_polyline

    n = 2 * FS
    dry = pink(n, seed=5)
    ends = np.array([[-1.5, -0.6, 1.6], [1.5, -0.6, 1.6]])
    points = resample_polyline(ends, 0.25)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    walked = np.clip(np.arange(n) / FS * 1.5, 0, along[-1])
    index = np.interp(walked, along, np.arange(len(points)))
    track = np.stack([np.interp(walked, along, points[:, i]) for i in range(3)], axis=1)
    yaw = 40.0 * np.sin(2 * np.pi * 2.0 * np.arange(n) / FS)  # walking along +x: yaw 0
    paths, bank = floor_paths(points)
    pattern = pattern_by_name("cardioid")
    (ours,) = render_paths(dry, index, points, paths, bank, n_out=n + 300,
                           speed_of_sound_m_s=C, source=SourceDirectivity(pattern, yaw))
    exact = directional_source_with_plane(
        dry, track, yaw, MIC, FS, lambda d: pattern.gains(d, (1000.0,))[:, 0],
        plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1], reflection=REFLECTION,
        speed_of_sound_m_s=C, n_out=n + 300)
    core = slice(int(0.1 * FS), n - int(0.1 * FS))
    assert snr_db(exact[core], ours[core]) >= 40, snr_db(exact[core], ours[core])


def test_the_talker_pattern_per_band_matches_the_exact_solution_band_by_band() -> None:
    """The speech pattern (different in every band) on a talker turning on the spot: the
    level of every octave band follows the exact solution rendered band by band (the
    engine's per-point filters carry the spectral tilt, the emission gain the rest)."""
    from sonicspec.acoustics.moving.delays import render_paths

    n = 3 * FS
    dry = pink(n, seed=9)
    point = np.array([[2.3, 0.4, 1.6]])
    yaw = np.full(n, 200.0)  # facing away from the microphone (bearing about 170°)
    paths, bank = floor_paths(point)
    from sonicspec.acoustics.directivity import SPEECH

    (ours,) = render_paths(dry, np.zeros(n), point, paths, bank, n_out=n + 300,
                           speed_of_sound_m_s=C, source=SourceDirectivity(SPEECH, yaw))
    bands = bank.split(dry)
    exact = sum(directional_source_with_plane(
        bands[b], point[0], yaw, MIC, FS, lambda d, b=b: SPEECH.gains(d, bank.bands_hz)[:, b],
        plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1], reflection=REFLECTION,
        speed_of_sound_m_s=C, n_out=n + 300) for b in range(bank.n_bands))
    core = slice(int(0.1 * FS), n - int(0.1 * FS))
    ours_b, exact_b = bank.split(ours[core]), bank.split(exact[core])
    level = 10 * np.log10(np.sum(ours_b ** 2, axis=1) / np.sum(exact_b ** 2, axis=1))
    assert np.all(np.abs(level) < 0.5), level


def test_every_diffracted_path_leaves_the_source_towards_its_first_edge() -> None:
    """Over the screen's top edge the apex is known; with reflections and two edges, the
    departure still points at a point the path passes (its first apex or reflection point):
    walking along it by the path's first leg stays within the room."""
    from test_acoustics_diffraction_engine import BANDS as EDGE_BANDS
    from test_acoustics_diffraction_engine import C as EDGE_C
    from test_acoustics_diffraction_engine import screen_room

    from sonicspec.acoustics import engine
    from sonicspec.acoustics.directivity import departure_directions
    from sonicspec.acoustics.paths.edge_paths import diffracted_sound

    src, mic = np.array([[2.5, 2.0, 1.0]]), np.array([6.0, 2.0, 1.2])
    scene = screen_room()
    edges = engine.scene_edges(scene, 256)
    (a,) = diffracted_sound(scene, edges, src, mic, EDGE_BANDS, None, EDGE_C)
    assert len(a) > 3 and set(a.order) >= {1, 2}
    d = departure_directions(a, src[0], mic)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    k = int(np.argmin(a.times_s))  # over the top edge, at the apex (4, 2, 1.8)
    apex = np.array([4.0, 2.0, 1.8])
    np.testing.assert_allclose(d[k], (apex - src[0]) / np.linalg.norm(apex - src[0]), atol=1e-9)
    # first-order paths without a reflection: the departure and the arrival direction meet at
    # one apex, at the path's length
    for i in np.flatnonzero(a.order == 1):
        length = a.path_length_m[i]
        u = np.linalg.norm(src[0] - mic + length * d[i]) / np.linalg.norm(a.directions[i] + d[i])
        meet = mic + u * a.directions[i]
        np.testing.assert_allclose(np.linalg.norm(meet - src[0]) + u, length, atol=1e-6)


def test_a_talkers_rir_has_its_pattern_in_the_direct_sound_and_its_power_in_the_tail() -> None:
    """The engine's RIR of a talker facing away from the microphone: the direct sound carries
    the pattern's gain behind it in every band (the microphone straight behind, level with
    the mouth), the floor's and the ceiling's reflections the gains down- and upwards-behind,
    the late tail the pattern's diffuse-field power (the same noise draw)."""
    import sonicspec as ss
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.directivity import SPEECH
    from sonicspec.acoustics.engine import acoustic_scene, simulate_rirs

    room = ss.Scene.shoebox([6.0, 5.0, 3.0], {"walls": "plaster_on_brick"})
    settings = ss.RirSettings(rays=1500, image_source_order=1, max_rir_length_s=0.4,
                              sample_rate_hz=FS, diffraction=False).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    mic, point = np.array([4.5, 2.5, 1.5]), np.array([[1.5, 2.5, 1.5]])

    def rir(directivity):
        rirs, facts = simulate_rirs(scene, mic, point, settings, np.random.default_rng(0),
                                    directivity=directivity, keep_arrivals=True)
        return rirs[0][0].astype(np.float64), facts[0].early_arrivals_at_mic

    (omni, omni_paths), (away, away_paths) = rir(None), rir([SourceDirectivity(SPEECH, 180.0)])
    bands = settings.bands_hz
    ratio = away_paths.amplitudes / omni_paths.amplitudes
    direct = int(np.argmin(omni_paths.times_s))
    np.testing.assert_allclose(ratio[direct], SPEECH.gains(np.array([[-1.0, 0, 0]]), bands)[0],
                               rtol=1e-12)
    # floor and ceiling (1.5 m below and above): reflection points halfway, down or up behind
    for sign in (-1.0, 1.0):
        (k,) = np.flatnonzero(np.isclose(omni_paths.path_length_m, np.hypot(3.0, 3.0))
                              & (np.sign(omni_paths.directions[:, 2]) == sign))
        leaving = np.array([[-1.0, 0.0, sign]]) / np.sqrt(2.0)
        np.testing.assert_allclose(ratio[k], SPEECH.gains(leaving, bands)[0], rtol=1e-12)
    bank = OctaveFilterBank(FS, bands)
    tail = slice(int(0.1 * FS), omni.size)

    def level(x):
        return 10 * np.log10(np.sum(bank.split(x[tail]) ** 2, axis=1))

    power = 10 * np.log10(SPEECH.diffuse_power(bands))
    np.testing.assert_allclose(level(away) - level(omni), power, atol=0.3)


# --- a moving microphone ----------------------------------------------------------------------

PAIR_S = 0.1  # pairs every 0.1 s: neither end moves more than 0.15 m between them


def walk(a, b, speed: float, n: int) -> np.ndarray:
    """Positions along a line from ``a`` towards ``b`` at ``speed`` m/s, one per sample
    (held at ``b``)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = np.clip(np.arange(n) / FS * speed, 0, np.linalg.norm(b - a))
    return a + d[:, None] * (b - a) / np.linalg.norm(b - a)


def floor_pairs(source_track: np.ndarray, mic_track: np.ndarray):
    """The engine's early paths above the reflecting floor at pairs every :data:`PAIR_S`
    (the source and the microphone where they are then), followed by their isometries
    (:meth:`PathSet.identify_moving`): ``(points, mics, paths, index, bank)``."""
    import sonicspec as ss
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import early_arrivals
    from sonicspec.acoustics.moving.delays import PathSet
    from sonicspec.testing.rooms import uniform_scene

    settings = ss.RirSettings(rays=100, image_source_order=1, air_absorption=False,
                              max_rir_length_s=0.3, speed_of_sound_m_s=C, sample_rate_hz=FS,
                              diffraction=False).simulation_settings()
    verts = np.array([[-10.0, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]])
    scene = uniform_scene(verts, np.array([[0, 1, 2], [0, 2, 3]]), alpha=1 - REFLECTION ** 2,
                          n_bands=len(settings.bands_hz))
    n = len(source_track)
    at = np.arange(0, n, int(PAIR_S * FS))
    points, mics = source_track[at], mic_track[at]
    arrivals = [early_arrivals(scene, mics[j], points[j:j + 1], settings).from_mic[0]
                for j in range(len(at))]
    paths = PathSet.identify_moving(points, mics, arrivals)
    index = np.interp(np.arange(n), at, np.arange(len(at), dtype=float))
    return points, mics, paths, index, OctaveFilterBank(FS, settings.bands_hz)


def moving_mic_snr(source_track, mic_track, yaw, pattern, dry) -> float:
    """Our render of a directional source heard by a walking microphone against the exact
    solution (receiver at every sample, pattern at each emission towards where the
    microphone hears it), SNR in dB away from the ends."""
    from sonicspec.acoustics.moving.delays import Receiver, render_paths

    n = dry.size
    points, mics, paths, index, bank = floor_pairs(source_track, mic_track)
    assert sorted(paths.order) == [0, 1]
    (ours,) = render_paths(dry, index, points, paths, bank, n_out=n + 300,
                           speed_of_sound_m_s=C, receiver=Receiver(mic_track_m=mics),
                           source=SourceDirectivity(pattern, yaw))
    exact = directional_source_with_plane(
        dry, source_track, yaw, mic_track, FS, lambda d: pattern.gains(d, (1000.0,))[:, 0],
        plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1], reflection=REFLECTION,
        speed_of_sound_m_s=C, n_out=n + 300)
    core = slice(int(0.1 * FS), n - int(0.1 * FS))
    return snr_db(exact[core], ours[core])


@pytest.mark.parametrize("name", ["cardioid", "hypercardioid"])
def test_a_talker_turning_on_the_spot_heard_by_a_walking_microphone(name: str) -> None:
    """A talker standing still and turning round once in 3 s while the microphone is carried
    past at 1.2 m/s: every emission leaves with the gain of that moment towards where the
    microphone hears it, directly and off the floor (exact: 40 dB)."""
    n = 3 * FS
    mic_track = walk([-1.5, 1.2, 1.3], [2.5, 1.6, 1.2], 1.2, n + 300)
    source_track = np.broadcast_to(np.array([0.8, -0.9, 1.6]), (n, 3)).copy()
    yaw = 120.0 * np.arange(n) / FS
    snr = moving_mic_snr(source_track, mic_track[:n], yaw, pattern_by_name(name), pink(n, 11))
    assert snr >= 40, snr


@pytest.mark.parametrize("facing", ["walk", "toward_mic"])
def test_a_walking_talker_heard_by_a_walking_microphone(facing: str) -> None:
    """Both walk (the talker at 1.4 m/s, the microphone at 1.2 m/s the other way): a cardioid
    facing where it walks with ±40° head turns twice a second, or facing the microphone
    where it is at each emission (exact: 40 dB)."""
    n = 2 * FS
    mic_track = walk([2.0, 1.0, 1.3], [-1.0, 1.4, 1.2], 1.2, n + 300)
    source_track = walk([-1.5, -0.6, 1.6], [1.5, -0.6, 1.6], 1.4, n)
    if facing == "walk":
        yaw = 40.0 * np.sin(2 * np.pi * 2.0 * np.arange(n) / FS)  # walking along +x: yaw 0
    else:
        to_mic = mic_track[:n] - source_track
        yaw = np.degrees(np.unwrap(np.arctan2(to_mic[:, 1], to_mic[:, 0])))
    snr = moving_mic_snr(source_track, mic_track[:n], yaw, pattern_by_name("cardioid"),
                         pink(n, 13))
    assert snr >= 40, snr


def test_the_talker_pattern_per_band_heard_by_a_walking_microphone() -> None:
    """The speech pattern with its back to a microphone walking behind it: every octave
    band's level follows the exact solution rendered band by band (within 0.5 dB)."""
    from sonicspec.acoustics.directivity import SPEECH
    from sonicspec.acoustics.moving.delays import Receiver, render_paths

    n = 3 * FS
    dry = pink(n, seed=17)
    mic_track = walk([-2.0, 0.5, 1.3], [-2.0, -1.5, 1.3], 0.8, n + 300)
    source_track = np.broadcast_to(np.array([0.5, -0.3, 1.6]), (n, 3)).copy()
    yaw = np.full(n, 10.0)  # facing +x: the microphone is behind it
    points, mics, paths, index, bank = floor_pairs(source_track, mic_track[:n])
    (ours,) = render_paths(dry, index, points, paths, bank, n_out=n + 300,
                           speed_of_sound_m_s=C, receiver=Receiver(mic_track_m=mics),
                           source=SourceDirectivity(SPEECH, yaw))
    bands = bank.split(dry)
    exact = sum(directional_source_with_plane(
        bands[b], source_track, yaw, mic_track[:n], FS,
        lambda d, b=b: SPEECH.gains(d, bank.bands_hz)[:, b], plane_point_m=[0, 0, 0],
        plane_normal=[0, 0, 1], reflection=REFLECTION, speed_of_sound_m_s=C, n_out=n + 300)
        for b in range(bank.n_bands))
    core = slice(int(0.1 * FS), n - int(0.1 * FS))
    ours_b, exact_b = bank.split(ours[core]), bank.split(exact[core])
    level = 10 * np.log10(np.sum(ours_b ** 2, axis=1) / np.sum(exact_b ** 2, axis=1))
    assert np.all(np.abs(level) < 0.5), level
    # and the pattern is there: the high bands are well down on an omni source's
    omni = directional_source_with_plane(
        dry, source_track, yaw, mic_track[:n], FS, lambda d: np.ones(len(d)),
        plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1], reflection=REFLECTION,
        speed_of_sound_m_s=C, n_out=n + 300)
    down = 10 * np.log10(np.sum(ours_b ** 2, axis=1)
                         / np.sum(bank.split(omni[core]) ** 2, axis=1))
    assert down[list(bank.bands_hz).index(4000.0)] < -6, down


@pytest.mark.parametrize("kind", ["ambisonics", "array"])
def test_every_moving_receiver_hears_the_directional_source_the_mono_one_does(kind: str
                                                                            ) -> None:
    """The pattern weights each emission before the receiver: the ambisonic W channel (SN3D:
    gain 1) and a capsule at the array's centre hear what the mono microphone hears."""
    from sonicspec.acoustics.moving.delays import Receiver, render_paths

    n = FS
    dry = pink(n, seed=19)
    mic_track = walk([2.0, 1.0, 1.3], [-1.0, 1.4, 1.2], 1.2, n)
    source_track = walk([-1.5, -0.6, 1.6], [1.5, -0.6, 1.6], 1.4, n)
    points, mics, paths, index, bank = floor_pairs(source_track, mic_track)
    source = SourceDirectivity(pattern_by_name("cardioid"),
                               40.0 * np.sin(2 * np.pi * np.arange(n) / FS))
    moving = {"mic_track_m": mics, "yaw_deg": np.linspace(0.0, 30.0, len(mics))}

    def heard(receiver):
        return render_paths(dry, index, points, paths, bank, n_out=n + 300,
                            speed_of_sound_m_s=C, receiver=receiver, source=source)

    (mono,) = heard(Receiver(**moving))
    if kind == "ambisonics":
        channel = heard(Receiver("ambisonics", order=1, **moving))[0]
    else:
        channel = heard(Receiver("array", offsets_m=np.array([[0.0, 0, 0], [0.05, 0, 0]]),
                                 **moving))[0]
    omni = render_paths(dry, index, points, paths, bank, n_out=n + 300, speed_of_sound_m_s=C,
                        receiver=Receiver(**moving))[0]
    np.testing.assert_allclose(channel, mono, atol=1e-9 * np.max(np.abs(mono)))
    assert snr_db(omni, mono) < 20  # the pattern is heard
