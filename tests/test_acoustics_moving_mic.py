"""Moving microphones (issue 18): the engine's paths followed by their isometries while the
microphone (and the source) walk, rendered as time-varying delays to the moving images of the
microphone, against the exact moving image-source sum of a shoebox."""

from __future__ import annotations

import numpy as np
import pytest
from test_acoustics_moving import FS, SIZE, C, figures, pink, reflecting_shoebox

from sonicspec.acoustics.theory import (
    moving_arrival_times,
    moving_point_source,
    shoebox_moving_images,
)
from sonicspec.audio.fidelity import snr_db

STEP_S = 0.1  # pairs every 0.1 s: neither end moves more than 0.15 m between them


def line(a, b, speed: float, t: np.ndarray) -> np.ndarray:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = np.clip(t * speed, 0, np.linalg.norm(b - a))
    return a + d[:, None] * (b - a) / np.linalg.norm(b - a)


def engine_pairs(source_track, mic_track, n: int, microphone=None, yaw_deg=None):
    """The engine's early paths at pairs every ``STEP_S`` (the source and the microphone
    where they are then), followed by :meth:`PathSet.identify_moving`; the pair index of
    every sample."""
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import simulate_rirs
    from sonicspec.acoustics.moving.delays import PathSet

    scene, settings = reflecting_shoebox(SIZE)
    at = np.arange(0, n, int(STEP_S * FS))
    points, mics = source_track[at], mic_track[at]
    arrivals = []
    for j in range(len(at)):
        mic = dict(microphone or {"kind": "mono", "trajectory": {"kind": "static"}})
        if yaw_deg is not None:
            mic["yaw_deg"] = float(yaw_deg[j])
        _, facts = simulate_rirs(scene, mics[j], points[j:j + 1], settings,
                                 np.random.default_rng(0), microphone=mic, keep_arrivals=True)
        arrivals.append(facts[0].early_arrivals)
    paths = PathSet.identify_moving(points, mics, arrivals)
    index = np.interp(np.arange(n), at, np.arange(len(at), dtype=float))
    return points, mics, paths, index, OctaveFilterBank(FS, settings.bands_hz)


def exact_sum(dry, source_track, mic_track, n_out, gains=None):
    """Σ over the shoebox's images (order 2, 0.8 per reflection) of the exact moving point
    source heard by the moving microphone."""
    out = np.zeros(n_out)
    for positions, reflections in shoebox_moving_images(SIZE, source_track, 2):
        g = 0.8**reflections if gains is None else 0.8**reflections * gains(positions)
        out += moving_point_source(dry, positions, mic_track, FS, speed_of_sound_m_s=C,
                                   gain=g, n_out=n_out)
    return out


@pytest.mark.parametrize("source_moves", [False, True])
def test_a_walking_microphone_hears_the_exact_moving_image_sum(source_moves: bool) -> None:
    """A microphone carried at 1.2 m/s across a shoebox (walls reflecting 0.8 of the
    pressure, image sources to order 2) past a static source, and with the source walking
    too: the engine's 25 paths followed by their isometries, rendered to the microphone's
    moving images, against the exact sum (both ends moving, retarded time solved exactly)."""
    from sonicspec.acoustics.moving.delays import Receiver, render_paths

    n = 2 * FS
    t = np.arange(n) / FS
    dry = pink(n, seed=21)
    mic_track = line([1.5, 1.2, 1.3], [4.5, 3.4, 1.2], 1.2, t)
    source_track = (line([4.8, 1.0, 1.6], [2.0, 4.0, 1.5], 1.4, t) if source_moves
                    else np.broadcast_to(np.array([4.6, 4.1, 1.5]), (n, 3)).copy())
    points, mics, paths, index, bank = engine_pairs(source_track, mic_track, n)
    assert len(paths) == 25 and sorted(np.bincount(paths.order)) == [1, 6, 18]
    (ours,) = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                           speed_of_sound_m_s=C, receiver=Receiver(mic_track_m=mics))
    exact = exact_sum(dry, source_track, mic_track, n + 1200)
    snr, dips = figures(exact, ours, n)
    assert snr >= 45 and dips["worst_db"] >= -0.5, (snr, dips)


def test_a_moving_microphone_past_a_static_source_is_the_reciprocal_walk() -> None:
    """Reciprocity through the engine, the identification and the renderer: a microphone
    walking past a static source, and the source walking that line past a microphone
    where the source stood, matched at reception time (the reciprocal moves by the travel
    time), agree. The direct path: each image has its own travel time, so one retiming
    matches one path (with all 25 paths: 24.5 dB, the images' retiming mismatch of up to
    2 cm; their exactness is the test above)."""
    from sonicspec.acoustics.moving.delays import PathSet, Receiver, render_paths

    n = 2 * FS
    t = np.arange(n) / FS
    dry = pink(n, seed=22)
    a = np.array([4.6, 4.1, 1.5])
    walk = line([1.5, 1.2, 1.3], [4.5, 3.4, 1.2], 1.2, t)
    points, mics, paths, index, bank = engine_pairs(np.broadcast_to(a, (n, 3)).copy(), walk, n)
    paths = paths.select(paths.order == 0)
    (moving_mic,) = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                                 speed_of_sound_m_s=C, receiver=Receiver(mic_track_m=mics))
    # The reciprocal: the source where the microphone is when each sound arrives (direct
    # path's travel time; the images' differ by milliseconds at most: a few mm of walk).
    t_a, _ = moving_arrival_times(a, walk, n, FS, C)
    then = np.stack([np.interp(t_a * FS, np.arange(n), axis) for axis in walk.T], 1)
    p2, _, paths2, index2, _ = engine_pairs(then, np.broadcast_to(a, (n, 3)).copy(), n)
    direct = paths2.order == 0
    static = PathSet(paths2.images_m[direct], paths2.weights[direct], paths2.order[direct])
    (moving_source,) = render_paths(dry, index2, p2, static, bank, n_out=n + 1200,
                                    speed_of_sound_m_s=C)
    snr, dips = figures(moving_mic, moving_source, n)
    assert snr >= 30 and dips["worst_db"] >= -0.5, (snr, dips)


@pytest.mark.parametrize("kind", ["ambisonics", "circular_array", "sphere_head"])
def test_a_walking_directional_microphone_turns_with_its_walk(kind: str) -> None:
    """First-order ambisonics, a 4-capsule array (5 cm radius) and the sphere head carried
    along a line, facing their direction of travel (yaw = the walk's heading + 30°),
    past a walking source: per channel against the exact moving image sum, each image's
    direction of arrival taken in the turned frame (ambisonics), each capsule at its own
    turned place (array); the head's ears against the same renderer with the head's frame
    held at the walk's heading (its first-order delays and shadows are the static head's,
    tested in test_acoustics_moving; here: that turning the head turns its ears)."""
    from sonicspec.acoustics.engine import array_offsets, sphere_head
    from sonicspec.acoustics.moving.delays import Receiver, render_paths
    from sonicspec.acoustics.receivers.arrays import rotation, sh_sn3d
    from sonicspec.acoustics.receivers.hrtf import ear_axes

    n = 2 * FS
    t = np.arange(n) / FS
    dry = pink(n, seed=23)
    start, end = np.array([1.5, 1.2, 1.3]), np.array([4.5, 3.4, 1.2])
    mic_track = line(start, end, 1.2, t)
    source_track = line([4.8, 1.0, 1.6], [2.0, 4.0, 1.5], 1.4, t)
    heading = np.degrees(np.arctan2(*(end - start)[1::-1]))
    yaw = heading + 30.0
    frame = rotation(yaw, 0.0)
    points, mics, paths, index, bank = engine_pairs(source_track, mic_track, n)
    yaws = np.full(len(points), yaw)
    if kind == "ambisonics":
        receiver = Receiver("ambisonics", order=1, mic_track_m=mics, yaw_deg=yaws)
    elif kind == "circular_array":
        local = array_offsets({"kind": "circular_array", "n": 4, "radius_m": 0.05,
                               "yaw_deg": 0.0, "pitch_deg": 0.0})
        receiver = Receiver("array", offsets_m=local, mic_track_m=mics, yaw_deg=yaws)
    else:
        head = sphere_head({"hrtf": {"kind": "sphere", "head_radius_m": 0.0875,
                                     "ear_angle_deg": 100.0}})
        receiver = Receiver("sphere_head", head=head, ear_axes=ear_axes(head, 0.0, 0.0),
                            mic_track_m=mics, yaw_deg=yaws)
    ours = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                        speed_of_sound_m_s=C, receiver=receiver)
    if kind == "sphere_head":
        # Turning the head 60° more moves the sound between the ears: the channels change.
        turned = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                              speed_of_sound_m_s=C,
                              receiver=Receiver("sphere_head", head=head,
                                                ear_axes=ear_axes(head, 0.0, 0.0),
                                                mic_track_m=mics, yaw_deg=yaws + 60.0))
        assert snr_db(ours[0], turned[0]) < 20 and snr_db(ours[1], turned[1]) < 20
        # Turned by 360°, it is the same head.
        again = render_paths(dry, index, points, paths, bank, n_out=n + 1200,
                             speed_of_sound_m_s=C,
                             receiver=Receiver("sphere_head", head=head,
                                               ear_axes=ear_axes(head, 0.0, 0.0),
                                               mic_track_m=mics, yaw_deg=yaws + 360.0))
        assert snr_db(ours[0], again[0]) > 100 and snr_db(ours[1], again[1]) > 100
        return
    exact = np.zeros_like(ours)
    if kind == "ambisonics":
        for ch in range(4):
            exact[ch] = exact_sum(dry, source_track, mic_track, exact.shape[1],
                                  gains=lambda p, ch=ch: sh_sn3d(1, (p - mic_track) @ frame)[:, ch])
    else:
        for ch, offset in enumerate(local):
            exact[ch] = exact_sum(dry, source_track, mic_track + frame @ offset, exact.shape[1])
    for ch in range(exact.shape[0]):
        snr, dips = figures(exact[ch], ours[ch], n)
        assert snr >= 40 and dips["worst_db"] >= -1.0, (ch, snr, dips)
