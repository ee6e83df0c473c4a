"""Measured HRIRs (SOFA sets) under the paths renderer (issue 18): each path heard at the
head's centre as a time-varying delay, filtered by the HRIRs of its direction, blended by
``hrtf.hrir_weights`` so a source that turns round the head glides from one measurement to the
next."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import oaconvolve

from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.moving.delays import PathSet, Receiver, render_paths
from sonicspec.acoustics.receivers.arrays import rotation
from sonicspec.acoustics.receivers.hrtf import HrirSet, covering_angle_rad, hrir_weights
from sonicspec.acoustics.theory import moving_point_source
from sonicspec.audio.fidelity import snr_db

FS = 16000
C = 343.0


def ring_set(n: int = 72) -> HrirSet:
    """``n`` horizontal directions and four elevated ones; direction ``m``'s HRIRs: an
    impulse whose delay and level follow its azimuth (an ITD and an ILD), so a wrong
    measurement shows."""
    az = 2 * np.pi * np.arange(n) / n
    dirs = np.column_stack([np.cos(az), np.sin(az), np.zeros(n)])
    dirs = np.vstack([dirs, [[0, 0, 1.0], [0, 0, -1.0], [0.7, 0, 0.7], [-0.7, 0, 0.7]]])
    h = np.zeros((len(dirs), 2, 48))
    for m, d in enumerate(dirs):
        side = d[1]  # +1 on the left
        for ear, sign in ((0, 1.0), (1, -1.0)):
            lag = 16 - sign * side * 10  # up to 10 samples of ITD
            level = 1.0 + 0.5 * sign * side
            x = np.arange(48) - lag  # a windowed sinc centred on the lag
            h[m, ear] = level * np.sinc(x) * np.cos(np.pi * x / 18) ** 2 * (np.abs(x) < 9)
    return HrirSet(dirs, h, FS)


def test_hrir_weights_are_continuous_and_sum_to_one() -> None:
    hset = ring_set()
    radius = 1.25 * covering_angle_rad(hset)
    az = np.linspace(0, 2 * np.pi, 2000)
    d = np.column_stack([np.cos(az), np.sin(az), 0.1 * np.ones_like(az)])
    w = hrir_weights(hset, d, radius)
    total = sum(w.values())
    assert np.allclose(total, 1.0)
    step = max(np.abs(np.diff(v)).max() for v in w.values())
    assert step < 0.05  # 0.18° apart: no switch
    with pytest.raises(ValueError):
        HrirSet(np.zeros((0, 3)), np.zeros((0, 2, 4)), FS)


def test_a_source_circling_the_head_is_the_exact_moving_source_through_blended_hrirs() -> None:
    """A source walking a half circle 1.5 m round a head facing +x (free field, the direct
    path only): each ear against the exact moving point source at the head's centre,
    filtered by the blended HRIRs of its exact direction — within 35 dB."""
    n = 2 * FS
    t = np.arange(n) / FS
    az = np.pi * (0.1 + 0.8 * t / t[-1])  # 18° -> 162° round the left side
    centre = np.array([2.0, 2.0, 1.5])
    path = centre + 1.5 * np.column_stack([np.cos(az), np.sin(az), np.zeros(n)])
    spec = np.fft.rfft(np.random.default_rng(3).standard_normal(n))
    spec[np.fft.rfftfreq(n, 1 / FS) > 0.8 * FS / 2] = 0  # as the other moving tests
    dry = np.fft.irfft(spec, n)
    hset = ring_set()
    radius = 1.25 * covering_angle_rad(hset)
    bank = OctaveFilterBank(FS)
    points = path[:: FS // 20]  # RIR points every 50 ms (0.1 m)
    index = np.interp(np.arange(n), np.arange(0, n, FS // 20), np.arange(len(points)))
    paths = PathSet(centre[None], np.ones((1, len(points), bank.n_bands)), np.zeros(1, int),
                    np.zeros((1, len(points), 3)))
    yaw = 0.0
    ours = render_paths(dry, index, points, paths, bank, n_out=n, speed_of_sound_m_s=C,
                        receiver=Receiver("hrir", hrirs=hset, hrir_radius_rad=radius,
                                          center_m=centre, yaw_deg=yaw))
    # The walk as the renderer reads it: straight between its points (chords of the circle)
    walk = np.stack([np.interp(index, np.arange(len(points)), points[:, i])
                     for i in range(3)], axis=1)
    at_head = moving_point_source(dry, walk, centre, FS, speed_of_sound_m_s=C, n_out=n)
    local = (walk - centre) @ rotation(yaw, 0.0)
    exact = np.zeros((2, n))
    for m, w in hrir_weights(hset, local, radius).items():
        for ear in range(2):
            exact[ear] += oaconvolve(w * at_head, hset.hrirs[m, ear])[:n]
    core = slice(FS // 10, n - FS // 10)
    for ear in range(2):
        assert snr_db(exact[ear, core], ours[ear, core]) >= 35, snr_db(exact[ear, core],
                                                                        ours[ear, core])
    # The left ear (the source's side) is the louder all along.
    assert np.std(ours[0, core]) > 1.5 * np.std(ours[1, core])
