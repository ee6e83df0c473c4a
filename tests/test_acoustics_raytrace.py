"""Ray tracing with diffuse rain: leaks, Eyring, live rooms, counting once, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from numba import njit

from sonicspec.acoustics.arrivals import Arrivals
from sonicspec.acoustics.late import _trace_kernels as K
from sonicspec.acoustics.late import raytrace
from sonicspec.acoustics.late.raytrace import RayTraceSettings, trace_rays
from sonicspec.acoustics.metrics import room_acoustic_figures
from sonicspec.acoustics.paths.direct import direct_sound
from sonicspec.acoustics.paths.image_sources import image_sources
from sonicspec.acoustics.receivers.synthesis import synthesize_rir
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.acoustics.theory import (
    barron_clarity_db,
    kuttruff_t60,
    shoebox_decay_t60,
    shoebox_free_paths,
)
from sonicspec.errors import AcousticsError
from sonicspec.testing import rooms
from sonicspec.testing.rooms import extruded_room, shoebox

BANDS_HZ = np.array([125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0])


def uniform_scene(verts, faces, alpha, s, tau=0.0, n_bands=7):
    return rooms.uniform_scene(verts, faces, alpha, s, tau, n_bands)


def iso9613_energy_per_m(f_hz, temperature_c=20.0, rh_pct=50.0):
    """ISO 9613-1 air attenuation (eq. 3–5), converted from dB/m to the energy coefficient m."""
    t, t0, t01 = temperature_c + 273.15, 293.15, 273.16
    psat = 10 ** (-6.8346 * (t01 / t) ** 1.261 + 4.6151)
    h = rh_pct * psat
    fr_o = 24 + 4.04e4 * h * (0.02 + h) / (0.391 + h)
    fr_n = (t / t0) ** -0.5 * (9 + 280 * h * np.exp(-4.170 * ((t / t0) ** (-1 / 3) - 1)))
    alpha_db = (
        8.686
        * f_hz**2
        * (
            1.84e-11 * (t / t0) ** 0.5
            + (t / t0) ** -2.5
            * (
                0.01275 * np.exp(-2239.1 / t) / (fr_o + f_hz**2 / fr_o)
                + 0.1068 * np.exp(-3352.0 / t) / (fr_n + f_hz**2 / fr_n)
            )
        )
    )
    return alpha_db / (10 * math.log10(math.e))


def test_iso9613_helper_matches_the_standard_table():
    # ISO 9613-1 Table 1, 20 °C, 50 % RH: 1 kHz 4.66 dB/km, 8 kHz 105 dB/km
    db_per_km = iso9613_energy_per_m(np.array([1000.0, 8000.0])) * 10 * math.log10(math.e) * 1e3
    np.testing.assert_allclose(db_per_km, [4.66, 105.0], rtol=0.02)


def schroeder_t30(energy, bin_s):
    """ISO 3382-1 T30: Schroeder backward integral, regression from -5 to -35 dB."""
    edc = np.cumsum(energy[::-1], axis=0)[::-1]
    t = np.arange(len(energy)) * bin_s
    out = []
    for b in range(energy.shape[1]):
        with np.errstate(divide="ignore"):
            db = 10 * np.log10(edc[:, b] / edc[0, b])
        sel = (db <= -5) & (db >= -35)
        out.append(-60.0 / np.polyfit(t[sel], db[sel], 1)[0])
    return np.array(out)


def eyring_t60(volume, surface, alpha, air_m):
    return (
        24 * math.log(10) * volume / (343.0 * (-surface * math.log(1 - alpha) + 4 * air_m * volume))
    )


def total_histogram(scene, src, rcv, rng, settings, air, order=3):
    """Direct + image sources + ray tracing summed into one per-band energy histogram."""
    ism = image_sources(scene, src, rcv, max_order=order, air_m_per_band=air)
    (direct,) = direct_sound(scene, src, rcv, air_m_per_band=air)
    settings = RayTraceSettings(**{**settings.__dict__, "specular_order_excluded": ism.max_order})
    (res,) = trace_rays(scene, src, rcv, rng, settings, air_m_per_band=air)
    h = res.histogram
    return (
        h.energy
        + ism.arrivals[0].energy_histogram(h.bin_s, h.n_bins)
        + direct.energy_histogram(h.bin_s, h.n_bins),
        res,
    )


SRC = np.array([2.1, 3.3, 1.4])
RCV = np.array([[7.2, 4.9, 1.6]])


# The `sonicset` preset's estimators at the flutter tests' ray count.
PRESET_ESTIMATORS = {"n_rays": 4000, "splitting": 2.0, "roulette_db": 20.0,
                     "free_air_volume": True, "max_receiver_radius_m": 4.0}


def flutter_windows(n_seeds: int, edges_bins: tuple[int, ...], **options):
    """Traces of the flutter room (absorbing ceiling, hard walls, scattering 0.1, a little
    transmission) to 0.6 s, seeds 0…n_seeds-1, with ``RayTraceSettings(**options)``: per seed,
    the energy per band in the windows the bin ``edges_bins`` cut the histogram into
    ``(n_seeds, windows, bands)``, and the mean reflections per ray ``(n_seeds,)``."""
    scene = rooms.flutter_scene(tau_high_band=0.02)
    src, rcv = np.array([2.0, 2.0, 1.5]), np.array([[7.5, 5.0, 1.5]])
    settings = RayTraceSettings(max_time_s=0.6, specular_order_excluded=1, **options)
    sums, hits = [], []
    for seed in range(n_seeds):
        (res,) = trace_rays(scene, src, rcv, np.random.default_rng(seed), settings)
        sums.append(np.add.reduceat(res.histogram.energy, (0, *edges_bins), axis=0))
        hits.append(res.mean_reflections)
    return np.array(sums), np.array(hits)


@pytest.fixture(scope="module")
def shoebox_t30():
    """T30 per band of the 10 × 7 × 3 m room (α 0.2, s 0.5, ISO air), 2,000 rays: traced once
    for the Eyring and the Kuttruff test."""
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.5)
    air = iso9613_energy_per_m(BANDS_HZ)
    settings = RayTraceSettings(n_rays=2000, max_time_s=1.2)
    energy, res = total_histogram(scene, SRC, RCV, np.random.default_rng(7), settings, air)
    return schroeder_t30(energy, res.histogram.bin_s), res, air


def test_t30_within_10_percent_of_eyring_with_air_absorption(shoebox_t30):
    t30, res, air = shoebox_t30
    eyring = np.array([eyring_t60(210.0, 242.0, 0.2, m) for m in air])
    assert np.all(np.abs(t30 / eyring - 1) < 0.10), (t30, eyring)
    assert res.escaped_ray_fraction == 0.0


def test_t30_follows_kuttruffs_path_length_correction(shoebox_t30):
    """Eyring assumes every free path is 4V/S long; their spread (γ² ≈ 0.40 in this room,
    sampled without the tracer) lengthens the decay by 1/(1 + γ²/2 · ln(1 − α)) ≈ +4.6 %.
    The tracer's T30 follows the corrected formula within 2 % in every band."""
    t30, _, air = shoebox_t30
    paths = shoebox_free_paths((10.0, 7.0, 3.0))
    kuttruff = kuttruff_t60(210.0, 242.0, 0.2, paths.var() / paths.mean() ** 2, air)
    assert np.all(np.abs(t30 / kuttruff - 1) < 0.02), (t30, kuttruff)


@pytest.mark.slow
def test_t30_against_pyroomacoustics_hybrid_in_the_same_room():
    """Whole RIRs of both tools (16 kHz, image sources to order 3 + rays; air absorption off in
    both, as their air models differ), T30 per octave band by our ISO 3382-1 routine, ours
    averaged over 4 RIRs and pyroomacoustics over 32 runs — it is not reproducible even with
    numpy's seed (its C++ side draws from its own generator).

    pyroomacoustics stops each ray when its energy falls below ``energy_thres`` (default 10⁻⁷,
    −70 dB): in this room its RIR then ends at 0.85 s and its T30 comes out ~5 % below Eyring
    in every band — a truncated decay, like RLR's 200-reflection cap. With the threshold at
    10⁻¹² its RIR runs to 1.4 s and the mean T30 of 32 runs lands −2…+2 % from Eyring per
    band (one run's moves by up to ~10 % in the low bands; asserted within 8 %, a check that
    its run is sound), ours within 3 % of the exact shoebox decay (:func:`shoebox_decay_t60`,
    +5 % on Eyring: the spread of path lengths, Kuttruff); the two tools agree within 10 % in
    every band: +1…+8 % over 20 runs of this test (with the mean of only 8 pyroomacoustics
    runs, 125 Hz went to +11.5 % in 2 of 30). Asserted too: the default threshold does
    truncate (its T30 the shorter over the bands)."""
    pra = pytest.importorskip("pyroomacoustics")
    from sonicspec.acoustics import engine
    from sonicspec.acoustics.bands import default_bands

    fs = 16_000
    bands = default_bands(fs)
    size, n_faces = (10.0, 7.0, 3.0), 12
    scene = AcousticScene(*shoebox(*size), np.full((n_faces, len(bands)), 0.2),
                          np.full((n_faces, len(bands)), 0.5), np.zeros((n_faces, len(bands))))
    settings = engine.SimulationSettings(
        rays=5_000, sample_rate_hz=fs, bands_hz=bands, image_source_order=3,
        max_rir_length_s=1.5, energy_threshold_db=80.0, air_absorption=False,
        temperature_c=20.0, relative_humidity_pct=50.0, transmission=False,
        diffuse_rain=True, receiver_radius_m=0.1, histogram_bin_s=0.001,
        speed_of_sound_m_s=343.0)  # fmt: skip
    # Four RIRs (their mean): one RIR's band-noise draw moves its T30 by 2–3 % per band,
    # which next to pyroomacoustics' own run-to-run spread left the 10 % with a thin margin
    # (one run in ~20 failed at 500 Hz with a single 20,000-ray RIR).
    ours = np.mean([room_acoustic_figures(
        engine.simulate_rirs(scene, RCV[0], SRC[None], settings,
                             np.random.default_rng(seed))[0][0][0].astype(np.float64),
        fs, bands).t30_s for seed in range(4)], axis=0)

    def pyroomacoustics_t30(seed: int, **ray_tracing) -> np.ndarray:
        np.random.seed(seed)  # noqa: NPY002 (pyroomacoustics has no generator argument)
        room = pra.ShoeBox(list(size), fs=fs, materials=pra.Material(0.2, 0.5), max_order=3,
                           ray_tracing=True, air_absorption=False)
        room.set_ray_tracing(n_rays=10_000, **ray_tracing)
        room.add_source(list(SRC))
        room.add_microphone(list(RCV[0]))
        room.compute_rir()
        rir_pra = np.asarray(room.rir[0][0], dtype=np.float64)
        return np.array(room_acoustic_figures(rir_pra, fs, bands).t30_s)

    # 32 of its runs: the mean of 8 still moved by ±5 % at 125 Hz (sd 2.3 %), enough to
    # take the 5 % the two reflection laws differ by past 10 % about one run in 15.
    theirs = np.mean([pyroomacoustics_t30(seed, energy_thres=1e-12) for seed in range(32)],
                     axis=0)
    eyring = eyring_t60(210.0, 242.0, 0.2, 0.0)
    assert np.all(np.abs(theirs / eyring - 1) < 0.08), (theirs, eyring)
    assert np.all(np.abs(ours / theirs - 1) < 0.10), (ours, theirs)
    # Its 125 Hz band alone varies by ~5 % over 8 of its runs: compared over the bands.
    truncated = np.mean([pyroomacoustics_t30(seed) for seed in range(8)], axis=0)
    assert truncated.mean() < theirs.mean(), (truncated, theirs)


def test_c50_follows_barrons_revised_theory():
    """C50 of synthesised RIRs (our ISO 3382-1 routine) against Barron & Lee's revised theory.

    Tolerance, 1.5 dB on the ISO 3382-1 single number (mean of the 500 Hz and 1 kHz bands),
    against a JND of 1 dB. What the physics adds to the JND, as measured in this room:
    * Barron's theory is a diffuse-field idealisation: reflected energy decaying exponentially
      from the direct sound on. The tracer's own histograms (20 000 rays, no synthesis) match
      an exact image-lattice sum for specular walls to 0.3 % in both windows, and with s = 0.5
      give C50 0.6 dB below the theory at 5.35 m (scattering moves early energy later); at
      1.6 m, where the direct sound weighs more, 0.05 dB.
    * One band-noise realisation of the tail fluctuates in a 50 ms window (bandwidth × time is
      9 at 250 Hz, 35 at 1 kHz): C50 per realisation varies by 1–2 dB per band. The mean over
      24 realisations (the equivalent of ISO 3382-1's averaging over positions) leaves ±0.2 dB.
    * Our per-band time zero (first sample within 20 dB of the band's peak) falls before the
      direct sound where the zero-phase band filters ring ahead of it: 3 ms early at 500 Hz,
      5 ms at 250 Hz, which lowers C50 there by 0.4 and 0.8 dB.
    T for the theory is the RIRs' own T30 (as Barron used measured T): the T30-vs-Eyring error,
    tested above, is kept out of the clarity comparison. 125 Hz is left out: the Schroeder
    frequency 2000·sqrt(T/V) is 110 Hz here, so the 88–177 Hz band is modal, not diffuse.
    Measured with a correct tail: the single number within 0.4 dB (1.6 m) and 1.2 dB
    (5.35 m) of the theory over 6 seeds; per band 500 Hz–4 kHz within 1.6 dB.
    Broken early/late splits miss by 1.9–3.7 dB (80 ms or 35 ms instead of 50 ms; time zero at
    the RIR's first sample), and so did the tail before its band level was weighted by the
    band's share of a flat spectrum (about −2.2 and −3.0 dB).
    """
    fs, bands = 16_000, tuple(BANDS_HZ[:6])  # 8 kHz is not below Nyquist at 16 kHz
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.5, n_bands=len(bands))
    air = iso9613_energy_per_m(np.array(bands))
    rcvs = np.array([RCV[0], [3.5, 4.0, 1.2]])  # 5.35 m and 1.58 m from the source
    direct = direct_sound(scene, SRC, rcvs, air_m_per_band=air)
    ism = image_sources(scene, SRC, rcvs, max_order=3, air_m_per_band=air)
    settings = RayTraceSettings(n_rays=2000, max_time_s=1.2, specular_order_excluded=ism.max_order)
    traces = trace_rays(scene, SRC, rcvs, np.random.default_rng(7), settings, air_m_per_band=air)
    rng = np.random.default_rng(8)
    for k, rcv in enumerate(rcvs):
        early = Arrivals.concatenate([direct[k], ism.arrivals[k]])
        figs = [
            room_acoustic_figures(
                synthesize_rir(early, traces[k].histogram, fs, rng, max_length_s=1.2,
                               bands_hz=bands),
                fs, bands,
            )
            for _ in range(24)
        ]  # fmt: skip
        c50 = np.mean([f.c50_db for f in figs], axis=0)
        t30 = np.mean([f.t30_s for f in figs], axis=0)
        r = float(np.linalg.norm(rcv - SRC))
        theory_mid = barron_clarity_db(r, 210.0, float(t30[2:4].mean()))
        assert abs(c50[2:4].mean() - theory_mid) < 1.5, (r, c50, theory_mid)
        # Single bands from 500 Hz: 0.5 dB more for the per-band time zero and noise.
        theory = np.array([barron_clarity_db(r, 210.0, t) for t in t30])
        assert np.all(np.abs(c50[2:] - theory[2:]) < 2.0), (r, c50, theory)


@pytest.mark.parametrize("scattering, tolerance", [(0.0, 0.04), (0.2, 0.03), (0.5, 0.03)])
def test_t30_follows_the_exact_shoebox_decay_for_any_scattering(scattering, tolerance):
    """Eyring and Kuttruff assume a diffuse field; with little scattering the field keeps
    specular memory and decays slower (the issue: with s = 0 T30 must exceed Eyring). The
    reference here is the particle walk of :func:`shoebox_decay_t60` (the same reflection
    law followed analytically between the six planes, no receiver): direct + image sources +
    12,000 rays follow it within 3 % (4 % at s = 0, where one point of a specular room is not
    the room's average: measured +1.3…+3.1 % over 4 seeds, −1.5…+0.2 % at s = 0.2 and 0.5)."""
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=scattering, n_bands=1)
    settings = RayTraceSettings(n_rays=12_000, max_time_s=1.5)
    energy, _ = total_histogram(scene, SRC, RCV, np.random.default_rng(4), settings, None)
    t30 = schroeder_t30(energy, settings.bin_s)[0]
    exact = shoebox_decay_t60((10.0, 7.0, 3.0), SRC, 0.2, scattering)
    assert abs(t30 / exact - 1) < tolerance, (t30, exact)
    if scattering == 0.0:
        assert t30 > 1.4 * eyring_t60(210.0, 242.0, 0.2, 0.0)


def test_live_room_decay_is_not_truncated():
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.02, s=0.5)
    air = iso9613_energy_per_m(BANDS_HZ)
    eyring = np.array([eyring_t60(210.0, 242.0, 0.02, m) for m in air])
    assert 6.5 < eyring[0] < 7.0
    settings = RayTraceSettings(n_rays=1000, max_time_s=7.5, energy_threshold_db=70.0)
    energy, res = total_histogram(scene, SRC, RCV, np.random.default_rng(3), settings, air)
    t30 = schroeder_t30(energy, res.histogram.bin_s)
    assert np.all(np.abs(t30 / eyring - 1) < 0.10), (t30, eyring)
    # hundreds of reflections per ray: no reflection-count cap
    assert res.mean_reflections > 500
    assert energy[7000:, 0].sum() > 0


def l_room_fine():
    poly = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    verts, faces = extruded_room(poly, [(3, 4, 5), (3, 5, 0), (3, 0, 1), (3, 1, 2)], 3.0)
    verts, faces = trimesh.remesh.subdivide(verts, faces)
    return trimesh.remesh.subdivide(verts, faces)


def test_closed_room_leaks_less_than_one_ray_in_ten_thousand():
    verts, faces = l_room_fine()
    scene = uniform_scene(verts, faces, alpha=0.1, s=0.3, n_bands=1)
    settings = RayTraceSettings(n_rays=20_000, max_time_s=0.15, batch_size=20_000)
    (res,) = trace_rays(
        scene, np.array([5.0, 1.0, 1.5]), np.array([[1.0, 5.0, 1.5]]), np.random.default_rng(0),
        settings,
    )  # fmt: skip
    assert res.escaped_ray_fraction < 1e-4
    assert res.mean_reflections > 10


def test_escaped_rays_are_counted_in_an_open_box():
    verts, faces = shoebox(4.0, 4.0, 3.0)
    up = np.einsum(
        "ij,ij->i", uniform_scene(verts, faces, 0.1, 0.1, n_bands=1).normals, [[0, 0, -1]]
    )
    faces = faces[up < 0.5]  # remove the ceiling
    scene = uniform_scene(verts, faces, alpha=0.0, s=0.0, n_bands=1)
    settings = RayTraceSettings(n_rays=4000, max_time_s=1.0)
    (res,) = trace_rays(
        scene, np.array([2.0, 2.0, 1.5]), np.array([[1.0, 1.0, 1.0]]), np.random.default_rng(0),
        settings,
    )  # fmt: skip
    # lossless, specular walls and floor: all but near-horizontal rays leave through the top
    assert 0.95 < res.escaped_ray_fraction <= 1.0


def test_energy_is_counted_once_whatever_the_image_source_order():
    """ISM order K + rays excluding order <= K must equal rays alone (K = 0)."""
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.2, n_bands=1)
    settings = RayTraceSettings(
        n_rays=20_000, max_time_s=0.3, batch_size=20_000, radius_growth=0.04
    )
    totals = []
    for order in (0, 3):
        energy, _ = total_histogram(
            scene, SRC, RCV, np.random.default_rng(11), settings, None, order
        )
        totals.append(energy.sum())
    ism_part = (image_sources(scene, SRC, RCV, 3).arrivals[0].amplitudes ** 2).sum()
    # the image sources carry ~25 % of the energy: counting them twice or not at all shows
    assert ism_part / totals[1] > 0.2
    assert totals[0] == pytest.approx(totals[1], rel=0.05)


def test_transmission_carries_energy_into_a_closed_neighbouring_room():
    verts, faces = rooms.partitioned_shoebox(8.0, 4.0, 3.0, 4.0)
    src, rcv = np.array([1.5, 2.0, 1.5]), np.array([[6.5, 2.2, 1.4]])
    settings = RayTraceSettings(n_rays=2000, max_time_s=0.5, specular_order_excluded=0)
    level = []
    for tau in (0.0, 0.1):
        f = len(faces)
        tr = np.zeros((f, 1))
        tr[-2:] = tau
        scene = AcousticScene(verts, faces, np.full((f, 1), 0.2), np.full((f, 1), 0.5), tr)
        (res,) = trace_rays(scene, src, rcv, np.random.default_rng(5), settings)
        level.append(res.histogram.energy.sum())
    # Opaque: nothing gets through but float32 cracks where the partition's edges meet the
    # walls (T-junctions), which leak a few rays in 10^4 at ~-100 dB re the transmitted level.
    assert level[0] < 1e-4 * level[1]
    assert level[1] > 0.0


def test_many_receivers_at_once_equal_one_by_one():
    verts, faces = shoebox(6.0, 5.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.3, s=0.4, n_bands=2)
    src = np.array([1.0, 1.0, 1.5])
    rcvs = np.array([[4.0, 3.0, 1.2], [5.0, 1.0, 2.0], [2.5, 4.0, 0.5]])
    settings = RayTraceSettings(n_rays=500, max_time_s=0.3)
    together = trace_rays(scene, src, rcvs, np.random.default_rng(2), settings)
    for i in range(3):
        (alone,) = trace_rays(scene, src, rcvs[i : i + 1], np.random.default_rng(2), settings)
        np.testing.assert_allclose(alone.histogram.energy, together[i].histogram.energy, rtol=1e-9)


def test_rain_onto_a_subset_of_receivers_is_unbiased():
    """Each hit raining onto every 3rd receiver (weighted by 3) matches raining onto all.

    Ray paths use their own random stream, so both runs trace the very same rays and only the
    rain subsampling differs.
    """
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.5, n_bands=1)
    rng = np.random.default_rng(0)
    rcvs = np.c_[rng.uniform(1, 9, 6), rng.uniform(1, 6, 6), rng.uniform(0.5, 2.5, 6)]
    full = trace_rays(
        scene, SRC, rcvs, np.random.default_rng(1),
        RayTraceSettings(n_rays=2000, max_time_s=1.0, rain_receivers_per_hit=0),
    )  # fmt: skip
    sub = trace_rays(
        scene, SRC, rcvs, np.random.default_rng(1),
        RayTraceSettings(n_rays=2000, max_time_s=1.0, rain_receivers_per_hit=2),
    )  # fmt: skip
    ratios = []
    for a, b in zip(full, sub, strict=True):
        ratios.append(b.histogram.energy.sum() / a.histogram.energy.sum())
        t_a = schroeder_t30(a.histogram.energy, 0.001)
        t_b = schroeder_t30(b.histogram.energy, 0.001)
        assert np.all(np.abs(t_b / t_a - 1) < 0.02)
    # subsampling noise: a few % per receiver, no bias on average
    assert np.all(np.abs(np.array(ratios) - 1) < 0.07)
    assert abs(np.mean(ratios) - 1) < 0.02


def test_receiver_volume_only_agrees_with_diffuse_rain():
    """The classic sphere-only estimator and diffuse rain estimate the same energy."""
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.7, n_bands=1)
    out = []
    for rain in (True, False):
        settings = RayTraceSettings(
            n_rays=4000, max_time_s=1.0, diffuse_rain=rain, receiver_radius_m=0.5,
            radius_growth=0.0, max_receiver_radius_m=0.5,
        )  # fmt: skip
        energy, _ = total_histogram(scene, SRC, RCV, np.random.default_rng(3), settings, None)
        out.append((energy[50:].sum(), schroeder_t30(energy, settings.bin_s)[0]))
    assert out[1][0] == pytest.approx(out[0][0], rel=0.08)
    assert out[1][1] == pytest.approx(out[0][1], rel=0.05)


def test_same_seed_gives_identical_bytes():
    verts, faces = shoebox(6.0, 5.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.3, s=0.4, n_bands=3)
    src, rcv = np.array([1.0, 1.0, 1.5]), np.array([[4.0, 3.0, 1.2], [5.0, 1.0, 2.0]])
    settings = RayTraceSettings(n_rays=700, max_time_s=0.3, batch_size=256)
    a = trace_rays(scene, src, rcv, np.random.default_rng(42), settings)
    b = trace_rays(scene, src, rcv, np.random.default_rng(42), settings)
    c = trace_rays(scene, src, rcv, np.random.default_rng(43), settings)
    for x, y in zip(a, b, strict=True):
        assert x.histogram.energy.tobytes() == y.histogram.energy.tobytes()
        assert x.histogram.direction_sum.tobytes() == y.histogram.direction_sum.tobytes()
        assert x.histogram.departure_sum.tobytes() == y.histogram.departure_sum.tobytes()
    assert a[0].histogram.energy.tobytes() != c[0].histogram.energy.tobytes()


@pytest.mark.parametrize("estimators", [{}, {"splitting": 2.0, "roulette_db": 30.0,
                                               "guiding": 0.5, "free_air_volume": True,
                                               "max_receiver_radius_m": 2.0}])
def test_result_bytes_do_not_depend_on_thread_count(estimators: dict):
    """Plain rays, and with every estimator on (splitting, roulette, guiding, the ball)."""
    verts, faces = shoebox(6.0, 5.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.3, s=0.4, n_bands=2)
    src, rcv = np.array([1.0, 1.0, 1.5]), np.array([[4.0, 3.0, 1.2], [5.0, 1.0, 2.0]])
    settings = RayTraceSettings(n_rays=901, max_time_s=0.3, batch_size=300, **estimators)
    one = trace_rays(scene, src, rcv, np.random.default_rng(9), settings, n_threads=1)
    two = trace_rays(scene, src, rcv, np.random.default_rng(9), settings, n_threads=2)
    three = trace_rays(scene, src, rcv, np.random.default_rng(9), settings, n_threads=3)
    for a, b, c in zip(one, two, three, strict=True):
        assert a.histogram.energy.tobytes() == b.histogram.energy.tobytes()
        assert a.histogram.energy.tobytes() == c.histogram.energy.tobytes()
        assert a.histogram.direction_sum.tobytes() == c.histogram.direction_sum.tobytes()


def test_swapping_source_and_receiver_changes_t30_by_less_than_5_percent():
    verts, faces = shoebox(10.0, 7.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.5, n_bands=2)
    settings = RayTraceSettings(n_rays=2000, max_time_s=1.0)
    forward, _ = total_histogram(scene, SRC, RCV, np.random.default_rng(1), settings, None)
    backward, _ = total_histogram(
        scene, RCV[0], SRC[None], np.random.default_rng(2), settings, None
    )
    t_f = schroeder_t30(forward, settings.bin_s)
    t_b = schroeder_t30(backward, settings.bin_s)
    assert np.all(np.abs(t_f / t_b - 1) < 0.05)
    # the first 30 ms (exactly reciprocal direct sound and image sources, plus the noisier
    # early ray-traced energy: ~5 % seed spread at 2 000 rays) agree too
    np.testing.assert_allclose(forward[:30].sum(axis=0), backward[:30].sum(axis=0), rtol=0.12)


def test_directions_late_field_is_diffuse_and_mean_direction_bounded():
    verts, faces = shoebox(6.0, 5.0, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.1, s=0.7, n_bands=1)
    settings = RayTraceSettings(n_rays=3000, max_time_s=0.5, bin_s=0.01)
    (res,) = trace_rays(scene, np.array([1.0, 1.0, 1.5]), np.array([[4.0, 3.0, 1.2]]),
                        np.random.default_rng(1), settings)  # fmt: skip
    mean = res.histogram.mean_direction()
    norm = np.linalg.norm(mean, axis=1)
    assert np.all(norm <= 1 + 1e-12)
    # after many diffuse reflections arrivals come from everywhere
    assert norm[20:40].mean() < 0.2


def test_settings_and_input_errors():
    with pytest.raises(AcousticsError, match=r"RayTraceSettings.n_rays: expected >= 1, got 0"):
        RayTraceSettings(n_rays=0)
    with pytest.raises(
        AcousticsError, match=r"RayTraceSettings.bin_s: expected in \(0, max_time_s\]"
    ):
        RayTraceSettings(bin_s=5.0, max_time_s=1.0)
    with pytest.raises(AcousticsError, match=r"RayTraceSettings\.receiver_radius_m: expected > 0"):
        RayTraceSettings(receiver_radius_m=0.0)
    with pytest.raises(AcousticsError, match=r"max_receiver_radius_m: expected >= receiver_radius"):
        RayTraceSettings(receiver_radius_m=0.5, max_receiver_radius_m=0.2)
    with pytest.raises(AcousticsError, match=r"rain_receivers_per_hit: expected >= 0"):
        RayTraceSettings(rain_receivers_per_hit=-1)
    with pytest.raises(AcousticsError, match=r"radius_growth: expected >= 0"):
        RayTraceSettings(radius_growth=-1.0)
    verts, faces = shoebox(4.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces, 0.2, 0.2, n_bands=1)
    with pytest.raises(AcousticsError, match=r"rng: expected a numpy\.random\.Generator"):
        trace_rays(scene, np.array([1.0, 1, 1]), np.array([[2.0, 2, 2]]), 42)  # type: ignore[arg-type]
    with pytest.raises(AcousticsError, match="source: expected one position"):
        trace_rays(scene, np.ones((2, 3)), np.array([[2.0, 2, 2]]), np.random.default_rng(0))
    with pytest.raises(AcousticsError, match="n_threads: expected an integer >= 1"):
        trace_rays(
            scene, np.ones(3), np.array([[2.0, 2, 2]]), np.random.default_rng(0), n_threads=0
        )


def spec_default_trace_settings(max_time_s: float) -> RayTraceSettings:
    """The tracer settings the spec's default ``acoustics`` section gives (roulette 30 dB,
    horizontal guiding 0.3, 20,000 rays)."""
    from sonicspec.acoustics.engine import SimulationSettings, ray_trace_settings
    from sonicspec.spec.acoustics import AcousticsSpec

    rir = SimulationSettings.from_spec(AcousticsSpec().model_dump(mode="json"), 16_000, 343.0)
    return RayTraceSettings(**{**ray_trace_settings(rir, 3).__dict__, "max_time_s": max_time_s})


@pytest.mark.slow
@pytest.mark.parametrize("defaults", ["tracer", "spec"])
def test_monte_carlo_honesty_default_rays_against_ten_times_more(defaults: str):
    """The default ray count's T30 per band is within 5 % of a 10× run, and its spread over
    seeds below 2.5 % (10 × 7 × 3 m, α 0.2, s 0.5, image sources to order 3, ISO air): with
    the tracer's own defaults (plain rays followed to 80 dB) and with the spec's (roulette and
    horizontal guiding, which has nothing to find in this diffuse room and must not hurt)."""
    scene = uniform_scene(*shoebox(10.0, 7.0, 3.0), alpha=0.2, s=0.5)
    air = iso9613_energy_per_m(BANDS_HZ)
    default = (RayTraceSettings(max_time_s=1.2) if defaults == "tracer"
               else spec_default_trace_settings(1.2))
    t30 = np.array([
        schroeder_t30(total_histogram(scene, SRC, RCV, np.random.default_rng(seed), default,
                                      air)[0], default.bin_s)
        for seed in range(4)
    ])  # fmt: skip
    ten_times = RayTraceSettings(**{**default.__dict__, "n_rays": 10 * default.n_rays})
    reference = schroeder_t30(
        total_histogram(scene, SRC, RCV, np.random.default_rng(99), ten_times, air)[0],
        default.bin_s,
    )
    assert np.all(np.abs(t30 / reference - 1) < 0.05), (t30, reference)
    spread = t30.std(axis=0, ddof=1) / t30.mean(axis=0)
    assert np.all(spread < 0.025), spread


def test_specular_splitting_is_unbiased():
    """A flutter room (absorbing ceiling, hard walls, scattering 0.1, a little transmission):
    the energy before and after 50 ms, averaged over 4 seeds, agrees between one continuing
    ray per hit and specular splitting at two rates (the seed-to-seed spread of each mean is
    1–2 %); a mistake in the children's weights shows as a bias of ~10 % or more."""
    windows = {rate: flutter_windows(4, (50,), n_rays=rays, splitting=rate)[0].mean(axis=0)
               for rate, rays in ((0.0, 20_000), (0.3, 8_000), (1.0, 4_000))}
    for rate in (0.3, 1.0):
        np.testing.assert_allclose(windows[rate], windows[0.0], rtol=0.05)
    with pytest.raises(AcousticsError, match="splitting"):
        RayTraceSettings(splitting=-1.0)


def test_russian_roulette_of_weak_rays_is_unbiased():
    """The same flutter room: stopping rays 20 dB down with probability 1 − E/E_r (survivors
    raised to E_r) keeps the energy of three windows (early, 50–300 ms, 300–600 ms), averaged
    over 8 seeds, within 3 %, 3 % and 6 % of following every ray to 80 dB (standard errors of
    each mean: 0.3, 0.3 and 1.5–2 %), while the rays take fewer than half the hits."""
    windows, hits = {}, {}
    for roulette in (0.0, 20.0):
        sums, n_hits = flutter_windows(8, (50, 300), n_rays=8000, roulette_db=roulette,
                                       splitting=1.0)
        windows[roulette], hits[roulette] = sums.mean(axis=0), n_hits.mean()
    np.testing.assert_allclose(windows[20.0][:2], windows[0.0][:2], rtol=0.03)
    np.testing.assert_allclose(windows[20.0][2], windows[0.0][2], rtol=0.06)
    assert hits[20.0] < 0.5 * hits[0.0]


def test_horizontal_guiding_is_unbiased_and_steadies_the_tail():
    """The same flutter room, where near-horizontal rays carry the tail: sending half of the
    launched directions and of each path's first diffuse reflection to thin horizontal bands
    (weighted by plain / mixed density) keeps the early, 50–300 ms and 300–600 ms energies of
    plain rays followed to 80 dB (8 seeds each; within 4 %, 3 % and 7 %). On top of the
    `sonicset` preset's estimators the 300–600 ms energy's seed-to-seed spread must not grow
    (a weight bug that leaves the means alone shows there); measured over 32 seeds it falls
    from 3.8–3.9 % to 2.8–2.9 % in this room (0.066 s per trace against 0.050 s; in the
    furnished apartment of bench_rlr, where the tail is more horizontal, several times more)."""
    windows, spread = [], []
    for options in ({"n_rays": 12_000}, PRESET_ESTIMATORS, {**PRESET_ESTIMATORS, "guiding": 0.5}):
        sums = flutter_windows(8, (50, 300), **options)[0]
        windows.append(sums.mean(axis=0))
        spread.append(sums.std(axis=0)[2] / windows[-1][2])
    plain, _, guided = windows
    np.testing.assert_allclose(guided[0], plain[0], rtol=0.04)
    np.testing.assert_allclose(guided[1], plain[1], rtol=0.03)
    np.testing.assert_allclose(guided[2], plain[2], rtol=0.07)
    assert np.all(spread[2] < spread[1]), spread
    for bad in (-0.1, 1.0):
        with pytest.raises(AcousticsError, match="guiding"):
            RayTraceSettings(guiding=bad)
    with pytest.raises(AcousticsError, match="guiding_widths"):
        RayTraceSettings(guiding=0.5, guiding_widths=(0.0,))


@njit  # not cached: a cache would not see edits of the kernel it inlines
def _scatter_many(normal, u, beta, widths):
    """The tracer's diffuse direction and weight for every row of draws ``u``."""
    out = np.empty((u.shape[0], 4))
    for i in range(u.shape[0]):
        out[i] = K._scatter(normal[0], normal[1], normal[2], u[i, 0], u[i, 1], u[i, 2], beta,
                            widths)
    return out


def test_guided_directions_carry_the_plain_densities():
    """Weights of guided directions (β = 0.5, the three bands) make their averages those of
    the plain densities: off a wall, a floor and a tilted face, E[w] = 1, E[w·cosθ] = 2/3
    (Lambert) and E[w·1(|z| < 0.01)] = the Lambert share of that band (from 4·10⁵ plain
    draws); launched from the source, E[w] = 1, E[w·z²] = 1/3 and E[w·1(|z| < 0.01)] = 0.01
    (uniform sphere)."""
    widths = np.array(RayTraceSettings().guiding_widths)
    rng = np.random.default_rng(3)
    n = 400_000
    for normal in ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.6, 0.0, 0.8)):
        u = rng.random((n, 3))
        guided = _scatter_many(np.array(normal), u, 0.5, widths)
        plain = _scatter_many(np.array(normal), u, 0.0, widths)[:, :3]
        plain /= np.linalg.norm(plain, axis=1, keepdims=True)
        w, d = guided[:, 3], guided[:, :3]
        band = np.mean(np.abs(plain[:, 2]) < 0.01)
        assert abs(w.mean() - 1) < 0.01, (normal, w.mean())
        assert abs(np.mean(w * (d @ np.array(normal))) - 2 / 3) < 0.01, normal
        assert abs(np.mean(w * (np.abs(d[:, 2]) < 0.01)) - band) < 0.1 * band + 2e-4, normal
        assert np.mean(np.abs(d[:, 2]) < 0.01) > 10 * band + 0.01  # the bands are visited
    dirs, w = raytrace._guided_launch(n, rng, 0.5, tuple(widths))
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, rtol=1e-12)
    assert abs(w.mean() - 1) < 0.002
    assert abs(np.mean(w * dirs[:, 2] ** 2) - 1 / 3) < 0.002
    assert abs(np.mean(w * (np.abs(dirs[:, 2]) < 0.01)) - 0.01) < 0.0005
    assert np.mean(np.abs(dirs[:, 2]) < 0.01) > 0.15
    for small in (1, 2, 3, 7):  # a batch's remainder: every ray gets a direction and a weight
        dirs, w = raytrace._guided_launch(small, rng, 0.9, tuple(widths))
        assert dirs.shape == (small, 3) and np.all(np.isfinite(w)) and np.all(w > 0)


def test_the_scan_estimators_together_are_unbiased():
    """The `sonicset` preset's tracer — specular splitting 2, a 4 m visible-air ball and
    roulette 20 dB down, each tested alone above — against plain rays followed to 80 dB, in
    the same flutter room (8 seeds each): the early, 50–300 ms and 300–600 ms energies agree
    within 3 %, 3 % and 7 % (standard errors of the means, first band: 0.7–0.8, 0.5–0.6 and
    1.2–2.5 %), with a third of the rays and 57 % of the CPU (0.050 against 0.088 s per
    trace; the 300–600 ms spread over 32 seeds 3.9 % against 13 %)."""
    plain, preset = (flutter_windows(8, (50, 300), **options)[0].mean(axis=0)
                     for options in ({"n_rays": 12_000}, PRESET_ESTIMATORS))
    np.testing.assert_allclose(preset[:2], plain[:2], rtol=0.03)
    np.testing.assert_allclose(preset[2], plain[2], rtol=0.07)
    with pytest.raises(AcousticsError, match="roulette_db"):
        RayTraceSettings(roulette_db=-1.0)
