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


def test_bad_inputs_are_named():
    with pytest.raises(AcousticsError, match="receiver_m: expected a static point"):
        directional_source_with_plane(np.ones(10), [0, 0, 0], 0.0, np.zeros((2, 3)), FS,
                                      cardioid)
    with pytest.raises(AcousticsError, match="plane_normal: expected a non-zero"):
        directional_source_with_plane(np.ones(10), [0, 0, 0], 0.0, [1, 0, 0], FS, cardioid,
                                      plane_point_m=[0, 0, -1], plane_normal=[0, 0, 0])
