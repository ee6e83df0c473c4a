"""The exact turning directional source above one reflecting plane (acoustics.theory, issue 30)."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.acoustics.theory import directional_source_with_plane, moving_point_source
from sonicspec.errors import AcousticsError

FS = 16000
C = 343.0


def cardioid(local: np.ndarray) -> np.ndarray:
    return 0.5 + 0.5 * local[:, 0]


def test_an_omni_source_is_the_point_source_plus_its_image():
    rng = np.random.default_rng(0)
    dry = rng.standard_normal(4000)
    src, mic = np.array([1.0, 0.5, 1.6]), np.array([3.0, 1.5, 1.2])
    ours = directional_source_with_plane(dry, src, 0.0, mic, FS, lambda d: np.ones(len(d)),
                                         plane_point_m=[0, 0, 0], plane_normal=[0, 0, 2.0],
                                         reflection=0.7, speed_of_sound_m_s=C, n_out=5000)
    image = src * [1, 1, -1]
    ref = (moving_point_source(dry, src, mic, FS, speed_of_sound_m_s=C, n_out=5000)
           + moving_point_source(dry, image, mic, FS, speed_of_sound_m_s=C, gain=0.7,
                                 n_out=5000))
    np.testing.assert_allclose(ours, ref, atol=1e-12)


def test_a_turning_cardioid_scales_each_emitted_click_by_its_gain_then():
    """Clicks every 200 samples from a source turning once a second about z, at a distance
    of exactly 100 samples (integer delay: the band-limited click is one sample); the direct
    click k has 0.5 (1 + cos(yaw_k − bearing)) / (4π r); the floor's reflection leaves
    downwards-forward, its gain the cardioid of that direction."""
    n = 16000
    dry = np.zeros(n)
    clicks = np.arange(100, n - 400, 200)
    dry[clicks] = 1.0
    yaw = 360.0 * np.arange(n) / FS
    r = C * 100 / FS
    src = np.array([0.0, 0.0, 1.5])
    mic = src + np.array([r, 0.0, 0.0])  # bearing 0
    direct_only = directional_source_with_plane(dry, src, yaw, mic, FS, cardioid,
                                                speed_of_sound_m_s=C, n_out=n + 400)
    expect = 0.5 * (1 + np.cos(np.radians(yaw[clicks]))) / (4 * np.pi * r)
    np.testing.assert_allclose(direct_only[clicks + 100], expect, atol=1e-12)
    assert np.all(np.abs(np.delete(direct_only, clicks + 100)) < 1e-9)
    both = directional_source_with_plane(dry, src, yaw, mic, FS, cardioid,
                                         plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1],
                                         reflection=0.5, speed_of_sound_m_s=C,
                                         n_out=n + 400)
    reflected = both - direct_only
    # the floor point seen from the source: halfway (mirror geometry), 1.5 m down
    leave = np.array([r / 2, 0.0, -1.5])
    leave /= np.linalg.norm(leave)
    length = np.hypot(r, 3.0)
    gain = 0.5 * (1 + np.cos(np.radians(yaw[clicks])) * leave[0])
    energy = np.array([np.sum(reflected[k + int(length / C * FS) - 40:
                                        k + int(length / C * FS) + 40] ** 2) for k in clicks])
    np.testing.assert_allclose(np.sqrt(energy), 0.5 * np.abs(gain) / (4 * np.pi * length),
                               rtol=2e-3)


def test_a_source_facing_away_is_silent_directly_but_heard_off_the_floor():
    dry = np.random.default_rng(1).standard_normal(3000)
    src, mic = np.array([0.0, 0.0, 1.5]), np.array([2.0, 0.0, 1.5])
    away = directional_source_with_plane(dry, src, 180.0, mic, FS, cardioid,
                                         speed_of_sound_m_s=C)
    assert np.max(np.abs(away)) < 1e-12
    floor = directional_source_with_plane(dry, src, 180.0, mic, FS, cardioid,
                                          plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1],
                                          speed_of_sound_m_s=C)
    assert np.max(np.abs(floor)) > 1e-3


def _passing(n_out: int, speed: float = 40.0) -> np.ndarray:
    """A receiver passing the origin along y = 6, z = 1.2 at ``speed`` m/s, at every output
    sample."""
    t = np.arange(n_out) / FS
    return np.stack([-8.0 + speed * t, np.full(n_out, 6.0), np.full(n_out, 1.2)], axis=1)


def test_an_omni_source_heard_by_a_moving_receiver_is_the_point_source_plus_its_image():
    dry = np.random.default_rng(2).standard_normal(4000)
    src = np.array([1.0, 0.5, 1.6])
    rcv = _passing(5000, 1.5)
    ours = directional_source_with_plane(dry, src, 30.0, rcv, FS, lambda d: np.ones(len(d)),
                                         plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1],
                                         reflection=0.7, speed_of_sound_m_s=C, n_out=5000)
    ref = (moving_point_source(dry, src, rcv, FS, speed_of_sound_m_s=C, n_out=5000)
           + moving_point_source(dry, src * [1, 1, -1], rcv, FS, speed_of_sound_m_s=C,
                                 gain=0.7, n_out=5000))
    np.testing.assert_allclose(ours, ref, atol=1e-12)


def test_a_receiver_that_stands_still_gives_the_static_solution():
    """The same receiver given as one point and as a track that does not move."""
    dry = np.random.default_rng(3).standard_normal(3000)
    src = np.array([0.2, -0.4, 1.5])
    yaw = 90.0 * np.arange(3000) / FS
    mic = np.array([2.0, 1.0, 1.2])
    kw = dict(plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1], reflection=0.6,
              speed_of_sound_m_s=C, n_out=3500)
    point = directional_source_with_plane(dry, src, yaw, mic, FS, cardioid, **kw)
    track = directional_source_with_plane(dry, src, yaw, np.tile(mic, (3500, 1)), FS,
                                          cardioid, **kw)
    np.testing.assert_allclose(track, point, atol=1e-12)


def _reception_s(position: np.ndarray, t_e: float, rcv: np.ndarray) -> float:
    """When the sound emitted at ``t_e`` from ``position`` reaches the receiver track ``rcv``
    (at every output sample), by bracketing root search: independent of the solver under
    test (fixed-point iteration)."""
    from scipy.optimize import brentq

    grid = np.arange(len(rcv)) / FS

    def at(t: float) -> np.ndarray:
        return np.array([np.interp(t, grid, rcv[:, i]) for i in range(3)])

    return brentq(lambda t: C * (t - t_e) - np.linalg.norm(at(t) - position), t_e, t_e + 1.0,
                  xtol=1e-15), at


@pytest.mark.parametrize("plane", [False, True])
def test_each_click_leaves_towards_where_the_moving_receiver_hears_it(plane: bool):
    """Clicks from a cardioid at the origin facing +y, heard by a receiver passing at 40 m/s
    (it moves 0.7–1.2 m while a click flies): each click's gain is the pattern's towards the
    receiver — or, off the floor, towards the floor point on the way to it — where the
    receiver is at the click's reception time, found by a root search; with the receiver
    where it was at the emission some clicks would be 3.5–3.7 % off (so the test tells)."""
    n = 6400
    dry = np.zeros(n)
    clicks = np.arange(50, n - 50, 400)
    dry[clicks] = 1.0
    src = np.array([0.0, 0.0, 1.5])
    rcv = _passing(n + 1200)
    kw = dict(speed_of_sound_m_s=C, n_out=n + 1200)
    direct = directional_source_with_plane(dry, src, 90.0, rcv, FS, cardioid, **kw)
    position, sign = src, 1.0
    heard = direct
    if plane:
        heard = directional_source_with_plane(dry, src, 90.0, rcv, FS, cardioid,
                                              plane_point_m=[0, 0, 0], plane_normal=[0, 0, 1],
                                              reflection=0.5, **kw) - direct
        position, sign = src * [1, 1, -1], 0.5
    gains, then = np.zeros(n), np.zeros(n)
    for k in clicks:
        t_a, at = _reception_s(position, k / FS, rcv)
        receiver = at(t_a)
        if plane:  # the floor point: where the line from the source to the mirrored receiver
            mirrored = receiver * [1, 1, -1]  # meets z = 0 (the receiver mirrored, not the source)
            leave = src + (mirrored - src) * src[2] / (src[2] - mirrored[2]) - src
        else:
            leave = receiver - src
        leave = leave / np.linalg.norm(leave)
        gains[k] = sign * (0.5 + 0.5 * leave[1])  # the front is +y
        early = at(k / FS) * ([1, 1, -1] if plane else 1) - src
        then[k] = sign * (0.5 + 0.5 * early[1] / np.linalg.norm(early))
    expect = moving_point_source(dry, position, rcv, FS, gain=gains, **kw)
    np.testing.assert_allclose(heard, expect, atol=1e-12 * np.max(np.abs(expect)) + 1e-15)
    assert np.max(np.abs(then[clicks] / gains[clicks] - 1)) > 0.03  # 0.035–0.037


def test_bad_inputs_are_named():
    with pytest.raises(AcousticsError, match=r"receiver_m: expected a point \(3,\) or finite"):
        directional_source_with_plane(np.ones(10), [0, 0, 0], 0.0, np.zeros((2, 2)), FS,
                                      cardioid)
    with pytest.raises(AcousticsError, match="plane_normal: expected a non-zero"):
        directional_source_with_plane(np.ones(10), [0, 0, 0], 0.0, [1, 0, 0], FS, cardioid,
                                      plane_point_m=[0, 0, -1], plane_normal=[0, 0, 0])
