"""Filter bank, ISO 9613-1 air absorption, ISO 3382-1 figures and diffuse-field closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.air import air_absorption_db_per_m, air_energy_coefficient_per_m
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.metrics import (
    decay_times_from_histogram,
    direct_to_reverberant_db,
    figures_from_energy,
    room_acoustic_figures,
)
from sonicspec.acoustics.theory import (
    barron_clarity_db,
    barron_reflected_energy,
    critical_distance_m,
    eyring_t60,
    kuttruff_t60,
    mean_free_path_m,
    sabine_t60,
    shoebox_decay_t60,
    shoebox_free_paths,
)
from sonicspec.errors import AcousticsError

FS = 16000


def decaying_noise(t60_s: float, seconds: float, rng: np.random.Generator,
                   fs: int = FS) -> np.ndarray:
    t = np.arange(int(seconds * fs)) / fs
    return rng.standard_normal(t.size) * np.exp(-3 * math.log(10) * t / t60_s)


# --- filter bank ---------------------------------------------------------------------------

def test_bank_reconstructs_exactly() -> None:
    bank = OctaveFilterBank(FS)
    assert bank.bands_hz == (125, 250, 500, 1000, 2000, 4000)
    rng = np.random.default_rng(0)
    x = rng.standard_normal((2, 3000))
    bands = bank.split(x)
    assert bands.shape == (6, 2, 3000)
    assert np.max(np.abs(bank.merge(bands) - x)) < 1e-10 * np.max(np.abs(x))
    impulse = np.zeros(800)
    impulse[400] = 1.0
    assert np.max(np.abs(bank.split(impulse).sum(axis=0) - impulse)) < 1e-12


def test_bank_responses_and_selectivity() -> None:
    bank = OctaveFilterBank(48000)
    n = 1 << 16
    resp = bank.responses(n)
    freqs = np.fft.rfftfreq(n, 1 / 48000)
    assert np.all(resp >= 0) and np.allclose(resp.sum(axis=0), 1.0)
    for k, c in enumerate(bank.bands_hz):
        assert resp[k, np.argmin(np.abs(freqs - c))] == pytest.approx(1.0, abs=1e-3)
    # Octave-band-limited noise: its energy lands in its own band.
    rng = np.random.default_rng(1)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    for k, c in enumerate(bank.bands_hz):
        inside = (freqs > c / 2**0.35) & (freqs < c * 2**0.35)
        x = np.fft.irfft(spectrum * inside, n)
        energy = (bank.split(x) ** 2).sum(axis=-1)
        assert energy[k] / energy.sum() > 0.9


def test_bank_errors() -> None:
    with pytest.raises(AcousticsError, match="not below Nyquist"):
        OctaveFilterBank(16000, (125, 8000))
    with pytest.raises(AcousticsError, match="transition_octaves"):
        OctaveFilterBank(16000, transition_octaves=2)
    with pytest.raises(AcousticsError, match="finite samples"):
        OctaveFilterBank(16000).split(np.array([0.0, np.nan]))


# --- air -----------------------------------------------------------------------------------

@pytest.mark.parametrize(
    ("temperature_c", "expected_db_per_km"),
    [
        # ISO 9613-2 Table 2 (computed with ISO 9613-1 at the exact mid-band frequencies).
        (20.0, [0.3, 1.1, 2.8, 5.0, 9.0, 22.9, 76.6]),
        (10.0, [0.4, 1.0, 1.9, 3.7, 9.7, 32.8, 117.0]),
    ],
)
def test_air_absorption_matches_the_standard(temperature_c: float,
                                             expected_db_per_km: list[float]) -> None:
    freqs = 1000 * 10 ** (0.3 * np.arange(-3, 4))  # exact mid-band frequencies
    got = air_absorption_db_per_m(freqs, temperature_c, 70.0) * 1000
    assert got == pytest.approx(expected_db_per_km, abs=0.06, rel=0.01)


def test_energy_coefficient_is_db_over_4_343() -> None:
    a = air_absorption_db_per_m([1000.0])[0]
    m = air_energy_coefficient_per_m([1000.0])[0]
    assert 10 * math.log10(math.exp(m * 1000.0)) == pytest.approx(a * 1000.0)
    with pytest.raises(AcousticsError, match="relative_humidity_pct"):
        air_absorption_db_per_m([1000.0], relative_humidity_pct=120)


# --- metrics -------------------------------------------------------------------------------

@pytest.mark.parametrize("t60", [0.5, 2.0])
def test_decay_times_of_exponential_noise(t60: float) -> None:
    x = decaying_noise(t60, 1.5 * t60 + 0.3, np.random.default_rng(2))
    fig = room_acoustic_figures(x, FS)
    for key in ("t20_s", "t30_s", "edt_s"):
        assert fig.broadband[key] == pytest.approx(t60, rel=0.03), key
    # Octave bands of one noise realisation fluctuate more (few cycles at 125 Hz): 8 %.
    assert np.nanmax(np.abs(fig.t30_s / t60 - 1)) < 0.08


def test_per_band_decay_times_follow_the_bands() -> None:
    bank = OctaveFilterBank(FS)
    rng = np.random.default_rng(3)
    t60s = np.linspace(1.2, 0.4, bank.n_bands)
    x = sum(bank.split(decaying_noise(t, 2.0, rng))[k] for k, t in enumerate(t60s))
    fig = room_acoustic_figures(x, FS)
    assert fig.t30_s == pytest.approx(t60s, rel=0.06)


def test_clarity_of_a_pure_exponential_decay() -> None:
    t60 = 0.8
    t = np.arange(int(2.0 * FS)) / FS
    energy = np.exp(-6 * math.log(10) * t / t60)
    fig = room_acoustic_figures(np.sqrt(energy), FS)
    expected = 10 * math.log10(math.exp(6 * math.log(10) * 0.05 / t60) - 1)
    assert fig.broadband["c50_db"] == pytest.approx(expected, abs=0.05)


def test_drr_of_impulse_plus_tail() -> None:
    rng = np.random.default_rng(4)
    tail = 0.05 * decaying_noise(0.5, 1.0, rng)
    tail[:200] = 0.0
    x = tail.copy()
    x[10] = 1.0
    expected = 10 * math.log10(1.0 / np.sum(tail**2))
    assert direct_to_reverberant_db(x, FS) == pytest.approx(expected, abs=0.01)


def test_noise_floor_does_not_bias_t30() -> None:
    rng = np.random.default_rng(5)
    x = decaying_noise(0.6, 2.0, rng)
    noisy = x + 10 ** (-60 / 20) * rng.standard_normal(x.size)
    clean_t30 = room_acoustic_figures(x, FS).broadband["t30_s"]
    assert room_acoustic_figures(noisy, FS).broadband["t30_s"] == pytest.approx(clean_t30,
                                                                                  rel=0.05)


def test_too_short_decay_gives_nan_not_an_error() -> None:
    x = decaying_noise(5.0, 0.2, np.random.default_rng(6))
    fig = room_acoustic_figures(x, FS)
    assert math.isnan(fig.broadband["t30_s"])
    assert fig.to_dict()["broadband"]["t30_s"] is None
    with pytest.raises(AcousticsError, match="only zeros"):
        room_acoustic_figures(np.zeros(100), FS)


def test_agrees_with_pyroomacoustics() -> None:
    import pyroomacoustics as pra

    x = decaying_noise(0.7, 1.5, np.random.default_rng(7))
    ours = room_acoustic_figures(x, FS).broadband["t30_s"]
    theirs = pra.experimental.measure_rt60(x, fs=FS, decay_db=30)
    assert ours == pytest.approx(theirs, rel=0.05)


def test_decay_times_from_histograms() -> None:
    bin_s = 0.001
    t = np.arange(2000) * bin_s
    energy = np.stack([np.exp(-13.8155 * t / 0.5), np.exp(-13.8155 * t / 1.0)], axis=1)
    got = decay_times_from_histogram(energy, bin_s)
    assert got["t30_s"] == pytest.approx([0.5, 1.0], rel=1e-3)



def test_figures_from_energy_of_exponential_decays() -> None:
    """T30 and EDT of an exact exponential are its decay time; C50 the ratio of the two
    geometric sums (the first 50 bins after the onset against the rest); leading empty bins
    (the time of flight) are skipped; a band with no late energy gives None, not an error."""
    bin_s, t60 = 0.001, (0.5, 1.0)
    t = np.arange(2000) * bin_s
    decays = np.stack([np.exp(-6 * math.log(10) * t / t60[0]),
                       np.exp(-6 * math.log(10) * t / t60[1])], axis=1)
    energy = np.vstack([np.zeros((17, 2)), decays])
    got = figures_from_energy(energy, bin_s)
    assert got["t30_s"] == pytest.approx(list(t60), rel=1e-3)
    assert got["edt_s"] == pytest.approx(list(t60), rel=1e-3)
    q = np.exp(-6 * math.log(10) * bin_s / np.array(t60))
    c50 = 10 * np.log10((1 - q**50) / (q**50 - q**2000))
    assert got["c50_db"] == pytest.approx(c50.tolist(), abs=1e-6)
    one_bin = np.zeros((100, 1))
    one_bin[3] = 1.0
    assert figures_from_energy(one_bin, bin_s)["c50_db"] == [None]
    with pytest.raises(AcousticsError, match="n_bins, n_bands"):
        figures_from_energy(np.ones(10), bin_s)

# --- theory --------------------------------------------------------------------------------

def test_closed_forms_for_a_10_by_7_by_3_room() -> None:
    v, s = 210.0, 2 * (70 + 30 + 21)
    # By hand: 0.1611 V / (-S ln 0.8) = 33.83 / 54.00 = 0.6265 s; Sabine 33.83 / 48.4 = 0.699 s.
    assert eyring_t60(v, s, 0.2) == pytest.approx(0.6265, abs=5e-4)
    assert sabine_t60(v, s, 0.2) == pytest.approx(0.6990, abs=5e-4)
    m = air_energy_coefficient_per_m([4000.0])[0]
    assert eyring_t60(v, s, 0.2, m) < eyring_t60(v, s, 0.2)
    assert mean_free_path_m(v, s) == pytest.approx(840 / 242)
    # Barron: reflected energy at r = 0 equals 31200 T / V within c's rounding.
    assert barron_reflected_energy(1e-9, v, 1.0, 0.0) == pytest.approx(31200 / v, rel=2e-3)
    assert critical_distance_m(v, 0.6265) == pytest.approx(
        math.sqrt(0.161 * v / 0.6265 / (16 * math.pi)), rel=2e-3)
    assert barron_clarity_db(2.0, v, 0.6) > barron_clarity_db(8.0, v, 0.6)
    # Kuttruff: no path spread is Eyring; by hand with γ² = 0.4, A = 54.00 · (1 − 0.2 · 0.2231).
    assert kuttruff_t60(v, s, 0.2, 0.0) == pytest.approx(eyring_t60(v, s, 0.2))
    assert kuttruff_t60(v, s, 0.2, 0.4) == pytest.approx(33.83 / (54.00 * 0.95537), abs=5e-4)
    with pytest.raises(AcousticsError, match="path_variance"):
        kuttruff_t60(v, s, 0.2, -0.1)


def test_shoebox_free_paths_have_mean_4v_over_s() -> None:
    """Sampled diffuse free paths of a shoebox: mean 4V/S (a theorem for convex rooms), and
    γ² = var/mean² near the values Kuttruff quotes for rectangular rooms (≈ 0.34 for a cube,
    larger for flat or long rooms); different seeds agree."""
    paths = shoebox_free_paths((10.0, 7.0, 3.0))
    assert paths.mean() == pytest.approx(840 / 242, rel=2e-3)
    gamma2 = paths.var() / paths.mean() ** 2
    assert 0.37 < gamma2 < 0.42
    other = shoebox_free_paths((10.0, 7.0, 3.0), seed=1)
    assert other.var() / other.mean() ** 2 == pytest.approx(gamma2, rel=0.01)
    cube = shoebox_free_paths((5.0, 5.0, 5.0))
    assert cube.mean() == pytest.approx(5 * 4 / 6, rel=2e-3)
    assert 0.32 < cube.var() / cube.mean() ** 2 < gamma2
    with pytest.raises(AcousticsError, match="size_m"):
        shoebox_free_paths((10.0, -1.0, 3.0))


def test_shoebox_decay_follows_kuttruff_when_diffuse_and_outlasts_it_when_specular() -> None:
    """The analytic particle walk: with Lambert walls (s = 1) the field is diffuse and its T30
    is Kuttruff's (Eyring corrected for γ²) within 1 %; with specular memory (s = 0.2, 0)
    it decays slower — +6 % and +38 % here. Per band arrays, air absorption as Eyring's
    ``4mV`` term, and seeds agree."""
    size, src = (10.0, 7.0, 3.0), (2.1, 3.3, 1.4)
    paths = shoebox_free_paths(size)
    kuttruff = kuttruff_t60(210.0, 242.0, 0.2, paths.var() / paths.mean() ** 2)
    diffuse = shoebox_decay_t60(size, src, 0.2, 1.0)
    assert diffuse == pytest.approx(kuttruff, rel=0.01)
    assert shoebox_decay_t60(size, src, 0.2, 1.0, seed=1) == pytest.approx(diffuse, rel=0.01)
    assert shoebox_decay_t60(size, src, 0.2, 0.2) > 1.04 * kuttruff
    assert shoebox_decay_t60(size, src, 0.2, 0.0) > 1.3 * kuttruff
    bands = shoebox_decay_t60(size, src, [0.1, 0.2, 0.4], 1.0, air_m_per_m=[0.0, 0.0, 0.01])
    assert bands.shape == (3,) and bands[1] == pytest.approx(diffuse, rel=2e-3)
    assert bands[0] > 1.8 * bands[1]
    with_air = 1 / (1 / shoebox_decay_t60(size, src, 0.4, 1.0) + 0.01 * 343.0 / 13.8155)
    assert bands[2] == pytest.approx(with_air, rel=0.01)
    for bad, match in (((size, (2.1, 8.0, 1.4), 0.2, 0.5), "source_m"),
                       ((size, src, 1.2, 0.5), "absorption"),
                       ((size, src, 0.2, 1.5), "scattering"),
                       ((size, src, [0.2, 0.3], 0.5, [0.0, 0.1, 0.2]), "air_m_per_m"),
                       (((10.0, 0.0, 3.0), src, 0.2, 0.5), "size_m"),
                       ((size, src, 0.2, 0.5, 0.0, 343.0, 10), "n_paths")):
        with pytest.raises(AcousticsError, match=match):
            shoebox_decay_t60(*bad)
