"""Issue 28 item 15: a path shaped by frequency-dependent band factors starts at its delay.

Zero-phase band filters let a diffracted arrival behind a screen rise 0.4 ms early (14 % of
its peak) and ring at -40…-60 dB up to 6 ms early. Every band shaping is causal now (DESIGN.md
§5): nothing of a path precedes its delay by more than the interpolation kernel's half-width
(``DEFAULT_TAPS // 2`` samples for the RIRs' fractional taps, ``moving.HALF_WIDTH`` for the
renderer's delay lines), and its band magnitudes are kept.
"""

from __future__ import annotations

import math

import numpy as np

from sonicspec.acoustics import engine
from sonicspec.acoustics.arrivals import KIND_DIFFRACTED, KIND_SPECULAR, Arrivals
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.moving.delays import HALF_WIDTH, PathSet, render_paths
from sonicspec.acoustics.receivers.synthesis import DEFAULT_TAPS, synthesize_early
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.testing.rooms import shoebox

FS = 16000
C = 343.0
BANDS = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0)
# Strongly frequency dependent: absorption rising from 2 % to 95 % over six octaves.
ALPHA = np.array([0.02, 0.1, 0.3, 0.6, 0.85, 0.95])


def screen_room() -> AcousticScene:
    """8 × 4 × 3 m, cut at x = 4 by a one-sided sheet 1.8 m high (as the diffraction tests),
    every surface absorbing :data:`ALPHA`: reflections dull, diffraction darkens further."""
    v, f = shoebox(8.0, 4.0, 3.0)
    sheet_v = np.array([[4.0, 0.0, 0.0], [4.0, 4.0, 0.0], [4.0, 4.0, 1.8], [4.0, 0.0, 1.8]])
    sheet_f = np.array([[0, 1, 2], [0, 2, 3]]) + len(v)
    vertices, faces = np.vstack([v, sheet_v]), np.vstack([f, sheet_f])
    n, b = len(faces), len(BANDS)
    return AcousticScene(vertices, faces, np.tile(ALPHA, (n, 1)), np.zeros((n, b)),
                         np.zeros((n, b)))


def settings() -> engine.SimulationSettings:
    return engine.SimulationSettings(
        rays=100, sample_rate_hz=FS, bands_hz=BANDS, image_source_order=1,
        max_rir_length_s=0.2, energy_threshold_db=60.0, air_absorption=True,
        temperature_c=20.0, relative_humidity_pct=50.0, transmission=False, diffuse_rain=True,
        receiver_radius_m=0.1, histogram_bin_s=0.001, speed_of_sound_m_s=C,
        diffraction=True)  # fmt: skip


def one(arrivals: Arrivals, i: int) -> Arrivals:
    return Arrivals(arrivals.times_s[i:i + 1], arrivals.amplitudes[i:i + 1],
                    arrivals.directions[i:i + 1], arrivals.order[i:i + 1],
                    arrivals.kind[i:i + 1], arrivals.path_length_m[i:i + 1])


def band_gains(h: np.ndarray, delay_samples: float, bank: OctaveFilterBank) -> np.ndarray:
    """|H| at each band centre, the path's delay taken out."""
    n = 1 << 16
    f = np.fft.rfftfreq(n, 1 / FS)
    spec = np.fft.rfft(h, n) * np.exp(2j * np.pi * f * delay_samples / FS)
    return np.array([abs(np.interp(c, f, spec.real) + 1j * np.interp(c, f, spec.imag))
                     for c in bank.bands_hz])


def test_diffracted_and_reflected_paths_start_at_their_delay() -> None:
    """Behind a screen: the arrival over its top edge and the reflections, each alone through
    the RIR synthesis, have nothing before ``delay - DEFAULT_TAPS // 2`` samples (exactly
    zero), nothing but the tap's sidelobes before the delay, and their band factors as
    magnitudes."""
    src, mic = np.array([2.5, 2.0, 1.0]), np.array([6.0, 2.0, 1.2])
    early = engine.early_arrivals(screen_room(), mic, src[None], settings())
    arrivals = early.at_mic[0]
    bank = OctaveFilterBank(FS, BANDS)
    kinds = set()
    for i in range(len(arrivals)):
        a = one(arrivals, i)
        g = a.amplitudes[0]
        if g.max() < 3 * g.min():  # only strongly frequency-dependent paths
            continue
        kinds.add(int(a.kind[0]))
        delay = a.times_s[0] * FS
        n = int(delay) + 4 * bank.padding()
        h = synthesize_early(a, bank, n)
        first = math.floor(delay) - DEFAULT_TAPS // 2
        assert np.all(h[:first] == 0.0), (i, np.abs(h[:first]).max() / np.abs(h).max())
        # within the tap's half-width, only its own sidelobes (the zero-phase bank: 7–22 %
        # of the peak 6 samples early)
        assert np.abs(h[:math.floor(delay) - 6]).max() < 0.03 * np.abs(h).max(), i
        # the magnitude is the band factors' (within 0.5 dB at each band centre)
        err = 20 * np.log10(band_gains(h, delay, bank) / np.abs(g))
        assert np.all(np.abs(err) < 0.5), (i, err)
    assert {KIND_DIFFRACTED, KIND_SPECULAR} <= kinds


def test_a_flat_arrival_is_a_plain_tap() -> None:
    """Equal band factors: the shaping is the identity (a flat arrival's RIR is its tap)."""
    bank = OctaveFilterBank(FS, BANDS)
    a = Arrivals(np.array([0.01234]), np.full((1, 6), 0.2), np.array([[1.0, 0, 0]]),
                 np.zeros(1, int), np.zeros(1, np.int8), np.array([4.2]))
    h = synthesize_early(a, bank, 1000)
    half = DEFAULT_TAPS // 2
    x = np.arange(1000) - 0.01234 * FS
    tap = np.floor(0.01234 * FS) + np.arange(-half, half + 1)  # the tap's samples
    window = 0.5 * (1 + np.cos(np.pi * x / (half + 1)))
    expected = np.where(np.isin(np.arange(1000), tap), 0.2 * np.sinc(x) * window, 0.0)
    np.testing.assert_allclose(h, expected, rtol=0, atol=1e-15)


def test_the_renderer_shapes_a_moving_path_causally() -> None:
    """The renderer: a click emitted by a walking source reaches the microphone over one
    strongly frequency-dependent path, nothing of it before its delay - ``HALF_WIDTH``;
    with equal band factors the path is the plain scaled delay line (as before)."""
    bank = OctaveFilterBank(FS, BANDS)
    n = FS // 2
    points = np.array([[1.0, 0.0, 0.0], [1.5, 0.0, 0.0], [2.0, 0.0, 0.0]])
    index = np.linspace(0, 2, n)
    image = np.array([0.0, 3.0, 0.0])  # a reflection's image of the microphone
    dull = np.array([1.0, 0.5, 0.2, 0.05, 0.01, 0.003])
    weights = np.stack([dull, dull * 0.8, dull[::-1]])[None]  # brighter at the last point
    paths = PathSet(image[None], weights, np.ones(1, int))
    for t0 in (1000, 4000, 6100):
        dry = np.zeros(n)
        dry[t0] = 1.0
        y = render_paths(dry, index, points, paths, bank, n_out=n + FS // 10,
                         speed_of_sound_m_s=C)[0]
        src = points[0] + (points[-1] - points[0]) * index[t0] / 2
        delay = t0 + np.linalg.norm(src - image) / C * FS
        first = math.floor(delay) - HALF_WIDTH
        # (FFT rounding of the filters' convolutions only: 1e-20)
        assert np.abs(y[:first]).max() < 1e-4 * np.abs(y).max(), (t0, np.abs(y[:first]).max())
        # a dull path peaks a little late (minimum phase: its group delay), never early
        assert -1 < np.argmax(np.abs(y)) - delay < FS / 1000
    flat = PathSet(image[None], np.full((1, 3, 6), 0.5), np.ones(1, int))
    one_band = PathSet(image[None], np.full((1, 3, 1), 0.5), np.ones(1, int))
    dry = np.random.default_rng(1).standard_normal(n)
    got = render_paths(dry, index, points, flat, bank, n_out=n, speed_of_sound_m_s=C)
    plain = render_paths(dry, index, points, one_band, OctaveFilterBank(FS, (1000.0,)),
                         n_out=n, speed_of_sound_m_s=C)
    np.testing.assert_allclose(got, plain, atol=1e-12)
