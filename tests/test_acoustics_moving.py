"""Moving sources rendered as time-varying delays (``acoustics.moving.delays.render_path``),
measured against the exact moving point source of ``acoustics.theory`` (issue 18's bars)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import hilbert

from sonicspec.acoustics.moving.delays import PathSet, render_path
from sonicspec.acoustics.theory import (
    moving_arrival_times,
    moving_point_source,
    shoebox_moving_images,
)
from sonicspec.audio.fidelity import dip_figures, snr_db, spectral_deviation_db
from sonicspec.errors import AcousticsError

FS = 16000
C = 343.0


def pink(n: int, seed: int = 7) -> np.ndarray:
    spec = np.fft.rfft(np.random.default_rng(seed).standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / FS)
    spec[1:] /= np.sqrt(f[1:] / 100.0)
    spec[f > 0.8 * FS / 2] = 0
    x = np.fft.irfft(spec, n)
    return x / np.max(np.abs(x))


def walk(points: list[list[float]], speed: float, n: int) -> np.ndarray:
    """Positions per sample along a polyline at constant speed (held at the end)."""
    p = np.asarray(points, dtype=np.float64)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    d = np.clip(np.arange(n) / FS * speed, 0, along[-1])
    return np.stack([np.interp(d, along, p[:, i]) for i in range(3)], axis=1)


def figures(ref: np.ndarray, est: np.ndarray, n: int) -> tuple[float, dict[str, float]]:
    core = slice(int(0.1 * FS), n - int(0.1 * FS))
    dev, _, _ = spectral_deviation_db(ref, est, FS, active=(core.start, core.stop))
    return snr_db(ref[core], est[core]), dip_figures(dev)


@pytest.mark.parametrize("shape", ["line", "turn"])
def test_a_walking_source_in_free_field_matches_the_exact_solution(shape: str) -> None:
    n = 3 * FS
    dry = pink(n)
    mic = np.array([0.0, 1.0, 1.5])
    corners = ([[-2.25, 0, 1.5], [2.25, 0, 1.5]] if shape == "line"
               else [[-2.0, -1.0, 1.5], [0.0, 0.6, 1.5], [2.0, -0.5, 1.5]])  # 0.4 m away
    path = walk(corners, 1.5, n)
    exact = moving_point_source(dry, path, mic, FS, speed_of_sound_m_s=C, n_out=n + 300)
    y = render_path(dry, path, mic, FS, speed_of_sound_m_s=C, n_out=n + 300)
    snr, dips = figures(exact, y, n)
    assert snr >= 30 and dips["worst_db"] >= -1.0, (snr, dips)


def test_a_passing_tone_is_shifted_by_doppler_within_half_a_hertz() -> None:
    f0, v, n = 1000.0, 10.0, 4 * FS
    t = np.arange(n) / FS
    path = walk([[-20.0, 5.0, 0.0], [20.0, 5.0, 0.0]], v, n)
    y = render_path(np.sin(2 * np.pi * f0 * t), path, np.zeros(3), FS, speed_of_sound_m_s=C)
    t_a, r = moving_arrival_times(path, np.zeros(3), n, FS, C)
    v_r = -np.einsum("ij,ij->i", np.gradient(path, 1 / FS, axis=0), path) / r
    phase = np.unwrap(np.angle(hilbert(y)))
    for emitted_at in (0.5, 1.5, 2.5, 3.5):
        k = int(emitted_at * FS)
        j = round(t_a[k] * FS)
        idx = np.arange(j - 80, j + 80)
        measured = np.polyfit(idx / FS, phase[idx], 1)[0] / (2 * np.pi)
        heard = (t_a * FS >= j - 80) & (t_a * FS < j + 80)
        assert measured == pytest.approx(np.mean(f0 * C / (C - v_r[heard])), abs=0.5)


def test_image_sources_of_a_moving_source_in_a_shoebox_match_the_exact_sum() -> None:
    """Order 2 (25 paths), each image moving as the mirror of the source, walls reflecting
    0.8 of the pressure: the paths' sum against the exact time-varying image-source sum."""
    n = 2 * FS
    dry = pink(n, seed=3)
    size = [6.0, 5.0, 3.0]
    path = walk([[1.0, 1.0, 1.5], [4.0, 3.5, 1.5]], 1.5, n)
    mic = np.array([3.0, 2.0, 1.2])
    exact = np.zeros(n + 1200)
    ours = np.zeros(n + 1200)
    images = shoebox_moving_images(size, path, 2)
    assert len(images) == 25
    for positions, reflections in images:
        exact += moving_point_source(dry, positions, mic, FS, speed_of_sound_m_s=C,
                                     gain=0.8**reflections, n_out=exact.size)
        ours += render_path(dry, positions, mic, FS, speed_of_sound_m_s=C,
                            gain=0.8**reflections, n_out=ours.size)
    snr, _ = figures(exact, ours, n)
    assert snr >= 25, snr


def test_a_moving_microphone_past_a_static_source_is_the_reciprocal_case() -> None:
    """Swap the ends: a microphone walking past a static source hears what the microphone at
    the source's place hears from a source walking where the microphone is when each sound
    arrives (the positions matched at reception: the reciprocal of a moving source is moving
    by the travel time, v·r/c, a few millimetres at walking speed; with the times matched the
    two agree to the last digits, through the two branches of the retarded-time solver)."""
    n = 3 * FS
    dry = pink(n, seed=5)
    a = np.array([0.0, 1.0, 1.5])
    path = walk([[-2.25, 0, 1.5], [2.25, 0, 1.5]], 1.5, n)
    moving_mic = render_path(dry, a, path, FS, speed_of_sound_m_s=C, n_out=n + 300)
    t_a, _ = moving_arrival_times(a, path, n, FS, C)
    mic_then = np.stack([np.interp(t_a * FS, np.arange(n), axis) for axis in path.T], 1)
    moving_source = render_path(dry, mic_then, a, FS, speed_of_sound_m_s=C, n_out=n + 300)
    snr, dips = figures(moving_mic, moving_source, n)
    assert snr >= 60 and dips["worst_db"] >= -0.01, (snr, dips)
    # Unmatched (the same path at emission instead of reception) they differ by the
    # travel-time offset: about 20 dB, still without a comb (dips within 0.1 dB).
    unmatched, dips = figures(moving_mic, render_path(dry, path, a, FS, n_out=n + 300), n)
    assert 10 < unmatched < 30 and dips["worst_db"] >= -0.1


def test_a_static_source_is_the_exact_fractional_delay() -> None:
    dry = pink(FS)
    exact = moving_point_source(dry, [1.0, 2.0, 1.5], [4.3, 2.7, 1.2], FS, n_out=FS + 300)
    y = render_path(dry, [1.0, 2.0, 1.5], [4.3, 2.7, 1.2], FS, n_out=FS + 300)
    assert snr_db(exact[400:FS - 400], y[400:FS - 400]) >= 60


def test_bad_inputs_are_named() -> None:
    with pytest.raises(AcousticsError, match="dry: expected a 1-D signal of >= 2 samples"):
        render_path(np.ones(1), np.zeros(3), np.ones(3), FS)
    with pytest.raises(AcousticsError, match="passes through the receiver"):
        render_path(np.ones(8), np.zeros(3), np.zeros(3), FS)


SIZE = [6.0, 5.0, 3.0]
MIC = np.array([3.0, 2.0, 1.2])
# A slanted walk: on the level one at 1.5 m, a path to the image mirrored in x = 0 and z = 3
# meets the wall-ceiling edge exactly at one point, where the validity test may drop it
# (measure-zero, but it costs that point's path).
ENDS = np.array([[1.0, 1.1, 1.45], [4.0, 3.5, 1.6]])


def reflecting_shoebox(size=SIZE):
    """A shoebox whose walls reflect 0.8 of the pressure, and settings for its early paths
    (image sources to order 2, no air, no diffraction): ``(scene, settings)``."""
    import sonicspec as ss
    from sonicspec.acoustics.engine import acoustic_scene

    room = ss.Scene.shoebox(size, {"walls": "r08", "floor": "r08", "ceiling": "r08"},
                            custom_materials={"r08": {"absorption": 0.36, "scattering": 0.0}})
    settings = ss.RirSettings(rays=200, image_source_order=2, air_absorption=False,
                              max_rir_length_s=0.3, speed_of_sound_m_s=C, sample_rate_hz=FS,
                              diffraction=False).simulation_settings()
    return acoustic_scene(room.mesh, room.library, settings), settings


def engine_walk(microphone=None):
    """The engine's paths of a walk at 1.5 m/s through RIR points every 0.25 m in
    :func:`reflecting_shoebox`, and the fractional point index of each sample as the render
    stage reads it: ``(points, paths, index, bank)``."""
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import simulate_rirs
    from sonicspec.acoustics.moving.delays import PathSet
    from sonicspec.geometry.navigation import resample_polyline

    points = resample_polyline(ENDS, 0.25)
    scene, settings = reflecting_shoebox()
    _, facts = simulate_rirs(scene, MIC, points, settings, np.random.default_rng(0),
                             microphone=microphone, keep_arrivals=True)
    paths = PathSet.identify(points, [f.early_arrivals for f in facts],
                             at_mic=None if microphone is None else
                             [f.early_arrivals_at_mic for f in facts])
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    index = np.interp(np.clip(np.arange(2 * FS) / FS * 1.5, 0, along[-1]), along,
                      np.arange(len(points)))
    return points, paths, index, OctaveFilterBank(FS, settings.bands_hz)


def test_the_engines_paths_of_a_walking_source_match_the_exact_image_sum() -> None:
    """The pipeline's way (issue 18): the engine traces the early arrivals at RIR points every
    0.25 m, :class:`PathSet` follows each path across the points (its image of the microphone
    is fixed), :func:`render_paths` renders them as time-varying delays. In a shoebox whose
    walls reflect 0.8 of the pressure, against the exact moving image-source sum."""
    from sonicspec.acoustics.moving.delays import render_paths

    n = 2 * FS
    dry = pink(n, seed=3)
    points, paths, index, bank = engine_walk()
    assert len(paths) == 25 and sorted(np.bincount(paths.order)) == [1, 6, 18]
    assert np.allclose(paths.weights, 0.8 ** paths.order[:, None, None])  # valid everywhere
    (ours,) = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                           speed_of_sound_m_s=C)
    path = walk(ENDS.tolist(), 1.5, n)
    exact = np.zeros(n + 1200)
    for positions, reflections in shoebox_moving_images(SIZE, path, 2):
        exact += moving_point_source(dry, positions, MIC, FS, speed_of_sound_m_s=C,
                                     gain=0.8**reflections, n_out=exact.size)
    snr, dips = figures(exact, ours, n)
    assert snr >= 50 and dips["worst_db"] >= -0.1, (snr, dips)


@pytest.mark.parametrize("kind", ["mono", "binaural"])
def test_paths_and_late_part_of_a_static_source_are_its_rir(kind: str) -> None:
    """A source that does not move: its exact paths (rendered as delays) plus its late part
    (the RIR less :func:`early_part`) convolved is the RIR convolved — the split loses and
    adds nothing (the two fractional-delay kernels differ only near Nyquist). Binaural: the
    sphere head's delays and shadow filter per ear, at a static source, as its RIRs have."""
    import sonicspec as ss
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import acoustic_scene, early_part, simulate_rirs
    from sonicspec.acoustics.moving.delays import PathSet, render_paths
    from sonicspec.spec.microphone import BinauralMicSpec, MonoMicSpec
    from sonicspec.stages.render import path_receiver

    n = FS
    dry = pink(n, seed=11)
    room = ss.Scene.shoebox([5.0, 4.0, 2.8], {"walls": "plaster_on_brick"})
    settings = ss.RirSettings(rays=2000, image_source_order=2, max_rir_length_s=0.5,
                              sample_rate_hz=FS, diffraction=False).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    # (Not y = 1.1: mirrored in y = 4 the microphone at y = 2.9 is as far as the point, and
    # paths of equal length and order cannot be paired: a static source has no other point.)
    point = np.array([[1.3, 1.05, 1.55]])
    mic = np.array([3.5, 2.9, 1.3])
    spec = (MonoMicSpec(kind="mono") if kind == "mono"
            else BinauralMicSpec(kind="binaural", yaw_deg=30.0))
    microphone = spec.model_dump(mode="json")
    rirs, facts = simulate_rirs(scene, mic, point, settings, np.random.default_rng(1),
                                microphone=microphone, keep_arrivals=True)
    rir = rirs[0].astype(np.float64)
    late = rir - early_part(facts[0].early_arrivals_at_mic, settings, rir.shape[1],
                            microphone)
    bank = OctaveFilterBank(FS, settings.bands_hz)
    paths = PathSet.identify(point, [facts[0].early_arrivals],
                             at_mic=[facts[0].early_arrivals_at_mic])
    assert paths.order.max() == 2 and np.all(np.any(paths.directions[:, 0] != 0, axis=1))
    ours = render_paths(dry, np.zeros(n), point, paths, bank, n_out=n,
                        receiver=path_receiver(spec, mic))
    band = slice(int(0.05 * FS), n)
    for ch in range(rir.shape[0]):
        whole = np.convolve(dry, rir[ch])[:n]
        mine = ours[ch] + np.convolve(dry, late[ch])[:n]
        assert snr_db(whole[band], mine[band]) >= 60, (ch, snr_db(whole[band], mine[band]))


def vectorised_path(dry: np.ndarray, path: np.ndarray, mic: np.ndarray, gain: np.ndarray,
                    n_out: int) -> np.ndarray:
    """One path's time-varying delay as the vectorised numpy sum the compiled loops replaced
    (the naive reference of bench/bench_render_paths.py), written out here."""
    from sonicspec.acoustics.theory import windowed_sinc

    n = dry.size
    t_a, r = moving_arrival_times(path, mic, n, FS, C)
    tau, j, k = t_a * FS, np.arange(float(n_out)), np.arange(float(n))
    u = np.interp(j, tau, k)
    acc = np.zeros(j.size)
    base = np.floor(u).astype(np.int64)
    for offset in range(-7, 9):
        m = base + offset
        ok = (m >= 0) & (m < n)
        acc[ok] += dry[m[ok]] * windowed_sinc(u[ok] - m[ok], 8, 6.0)
    heard = (j >= tau[0] - 8) & (j <= tau[-1] + 8)
    return np.where(heard, acc * np.interp(u, k, gain / (4 * np.pi * r))
                    * np.interp(j, tau, 1.0 / np.gradient(tau)), 0.0)


def test_the_compiled_loop_is_the_vectorised_sum() -> None:
    """render_path's compiled loop (a sinc table phase by phase, a pointer over the arrival
    times) against the vectorised sum it replaced: the same signal to 120 dB."""
    n = 2 * FS
    dry = pink(n, seed=2)
    path = walk([[-2.0, 0.0, 1.5], [2.0, 0.3, 1.4]], 1.5, n)
    mic = np.array([0.0, 1.0, 1.5])
    gain = np.linspace(1.0, 0.5, n)
    ours = render_path(dry, path, mic, FS, speed_of_sound_m_s=C, gain=gain, n_out=n + 200)
    assert snr_db(vectorised_path(dry, path, mic, gain, n + 200), ours) >= 120


def test_channels_that_differ_in_gain_are_the_vectorised_sum_each() -> None:
    """The loop that renders one path for several channels at once (ambisonic channels, a
    sphere-head ear and its shadowed part: one pass of arrivals and taps, a gain per
    channel) against the vectorised sum of each channel alone, to 120 dB."""
    from sonicspec.acoustics.moving.delays import _render_into

    n = 2 * FS
    dry = pink(n, seed=5)
    path = walk([[-2.0, 0.5, 1.5], [1.0, -0.5, 1.6], [2.5, 0.3, 1.4]], 1.5, n)
    mic = np.array([0.0, 1.2, 1.4])
    gains = np.stack([np.ones(n), np.linspace(1.0, -0.5, n), np.cos(np.arange(n) / FS)], 1)
    ours = np.zeros((3, n + 200))
    _render_into(dry, path, mic, FS, C, gains, ours)
    for ch in range(3):
        assert snr_db(vectorised_path(dry, path, mic, gains[:, ch], n + 200), ours[ch]) >= 120


def test_directions_from_an_image_are_the_numpy_form() -> None:
    """The compiled directions of arrival (the direction the image sees the source in,
    mapped back by the path's mirrors) against numpy's normalise-and-multiply."""
    from sonicspec.acoustics.moving._delay_kernels import image_directions

    rng = np.random.default_rng(8)
    track = rng.uniform(-3, 3, (500, 3))
    image = np.array([7.0, -1.0, 2.0])
    mirror, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    ours = np.empty_like(track)
    image_directions(track, image, mirror, ours)
    away = track - image
    assert np.allclose(ours, (away / np.linalg.norm(away, axis=1, keepdims=True)) @ mirror,
                       rtol=0, atol=1e-14)


def test_a_path_valid_over_part_of_the_walk_renders_what_the_whole_would() -> None:
    """render_paths renders a path only over the emissions it is heard from (its band
    factors are zero elsewhere), a few silent ones kept each side: the same signal as the
    whole walk rendered, the points' shaping filters interpolated between them in numpy."""
    from sonicspec.acoustics.moving.delays import render_paths

    n = 2 * FS
    dry = pink(n, seed=6)
    points, paths, index, bank = engine_walk()
    one = paths.select(paths.order == 0)
    weights = one.weights.copy()
    valid = (np.arange(len(points)) >= 3) & (np.arange(len(points)) <= 6)
    weights[:, ~valid] = 0.0
    weights[0, valid] *= np.outer(np.linspace(0.5, 1.0, 4), np.linspace(1.0, 0.3, bank.n_bands))
    (ours,) = render_paths(dry, index, points, one.with_weights(weights), bank, n_out=n + 600,
                           speed_of_sound_m_s=C)
    at = np.arange(len(points), dtype=np.float64)
    # each point's causal shaping filter on the dry signal, weighted linearly between points
    x = np.zeros(n)
    for p, h in enumerate(bank.shaping_filters(weights[0])):
        hat = np.interp(index, at, np.eye(len(points))[p])
        x += hat * np.convolve(dry, h)[:n]
    track = np.stack([np.interp(index, at, points[:, i]) for i in range(3)], axis=1)
    whole = render_path(x, track, one.images_m[0], FS, speed_of_sound_m_s=C, n_out=n + 600)
    assert np.count_nonzero(x) < n / 2  # the path is silent over most of the walk
    assert snr_db(whole, ours) >= 150


@pytest.mark.parametrize("kind", ["ambisonics", "circular_array"])
def test_the_paths_of_a_walking_source_at_a_directional_receiver(kind: str) -> None:
    """First-order ambisonics and a 4-capsule array (5 cm radius): the engine's paths of a
    walk in a shoebox (order 2, walls reflecting 0.8), rendered per channel, against the
    exact moving image sum per channel: each image's spherical harmonics at its direction
    from the microphone at emission; each capsule the exact moving source at its own place.
    Each path's mirrors are recovered from the data (order 0 and 1 by construction, order 2
    by the Kabsch fit), so directions and capsule images are exact along the walk."""
    from sonicspec.acoustics.engine import array_offsets
    from sonicspec.acoustics.moving.delays import Receiver, render_paths
    from sonicspec.acoustics.receivers.arrays import sh_sn3d

    n = 2 * FS
    dry = pink(n, seed=4)
    mic = MIC
    microphone = ({"kind": "ambisonics", "order": 1, "yaw_deg": 0.0, "pitch_deg": 0.0,
                   "trajectory": {"kind": "static"}} if kind == "ambisonics" else
                  {"kind": "circular_array", "n": 4, "radius_m": 0.05, "yaw_deg": 0.0,
                   "pitch_deg": 0.0, "trajectory": {"kind": "static"}})
    points, paths, index, bank = engine_walk(microphone)
    assert len(paths) == 25
    offsets = array_offsets(microphone) if kind != "ambisonics" else None
    receiver = (Receiver("ambisonics", order=1, center_m=mic) if kind == "ambisonics"
                else Receiver("array", offsets_m=offsets, center_m=mic))
    ours = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                        speed_of_sound_m_s=C, receiver=receiver)
    path = walk(ENDS.tolist(), 1.5, n)
    exact = np.zeros_like(ours)
    for positions, reflections in shoebox_moving_images(SIZE, path, 2):
        if kind == "ambisonics":
            gains = sh_sn3d(1, positions - mic)
            for ch in range(4):
                exact[ch] += moving_point_source(dry, positions, mic, FS, speed_of_sound_m_s=C,
                                                 gain=0.8**reflections * gains[:, ch],
                                                 n_out=exact.shape[1])
        else:
            for m, offset in enumerate(offsets):
                exact[m] += moving_point_source(dry, positions, mic + offset, FS,
                                                speed_of_sound_m_s=C, gain=0.8**reflections,
                                                n_out=exact.shape[1])
    for ch in range(exact.shape[0]):
        snr, dips = figures(exact[ch], ours[ch], n)
        assert snr >= 55 and dips["worst_db"] >= -0.1, (ch, snr, dips)


def test_an_ambisonic_path_with_no_known_direction_between_two_points_stays_finite() -> None:
    """Bug: where a path was valid at neither point around an emission, its interpolated
    direction of arrival is zero, and the spherical harmonics of 0 / 0 made the whole
    ambisonic render NaN (directions interpolated: no microphone position to recover the
    mirrors from). Now those emissions, silent anyway, get zero gain: the W channel is the
    mono render of the same paths."""
    from sonicspec.acoustics.moving.delays import Receiver, render_paths

    n = 2 * FS
    dry = pink(n, seed=9)
    points, paths, index, bank = engine_walk({"kind": "ambisonics", "order": 1, "yaw_deg": 0.0,
                                              "pitch_deg": 0.0,
                                              "trajectory": {"kind": "static"}})
    weights, directions = paths.weights.copy(), paths.directions.copy()
    weights[paths.order == 2, :5] = 0.0
    directions[paths.order == 2, :5] = 0.0
    partly = PathSet(paths.images_m, weights, paths.order, directions)
    foa = render_paths(dry, index, points, partly, bank, n_out=n + 1200, speed_of_sound_m_s=C,
                       receiver=Receiver("ambisonics", order=1))
    (mono,) = render_paths(dry, index, points, partly, bank, n_out=n + 1200,
                           speed_of_sound_m_s=C)
    assert np.all(np.isfinite(foa))
    assert snr_db(mono, foa[0]) >= 150
