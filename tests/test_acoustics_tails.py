"""Tails that end where the sound ends (issue 19): ``max_rir_length_s: auto``, the cap and
its warning, and the decay carried on where the rays ran out."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics import engine
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.late.tails import band_decay
from sonicspec.acoustics.metrics import edc_db
from sonicspec.acoustics.theory import shoebox_decay_t60
from sonicspec.errors import AcousticsError, SonicspecWarning
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.testing import rooms

BIN_S = 0.001
SIXTY_DB = 6 * math.log(10)


def decay(t60_s: float, n_bins: int, stop_db: float | None = None,
          rng: np.random.Generator | None = None) -> np.ndarray:
    """An exponential late envelope with a 20 ms build-up, per 1 ms bin; ``stop_db``: the
    rays run out there (nothing after); ``rng``: each bin times an exponential draw (the
    noise of a handful of rays)."""
    t = np.arange(n_bins) * BIN_S
    e = np.exp(-SIXTY_DB * t / t60_s) * (1.0 - np.exp(-t / 0.02))
    if rng is not None:
        e = e * rng.exponential(1.0, n_bins)
    if stop_db is not None:
        e[t > t60_s * stop_db / 60.0] = 0.0
    return e


@pytest.mark.parametrize("noisy", [False, True])
def test_band_decay_against_exact_exponentials(noisy: bool) -> None:
    """A decay traced to 90 dB is complete and ends where its exact Schroeder curve is
    60 dB down (T60 and the build-up's 19 ms); one whose rays stop 40 or 25 dB down is
    continued from 10 dB above that by the line fitted to the 20 dB before, whose T60 is the
    decay's within 1 % (5 % under per-bin noise), and ends there too; one
    longer than the histogram is cut, with the level it reached (−44.4 dB for T60 = 2 s at
    1.5 s, its exact Schroeder curve) within 0.2 dB (1 dB under noise); a band without
    energy is empty."""
    rng = np.random.default_rng(1) if noisy else None
    tol = 0.05 if noisy else 0.01

    def sixty_db_s(t60_s: float) -> float:  # where its exact Schroeder curve is 60 dB down
        whole = np.cumsum(decay(t60_s, 20_000)[::-1])[::-1]
        return int(np.argmax(whole <= 1e-6 * whole[0])) * BIN_S

    end_s = sixty_db_s(1.0)  # 1.019 s: the 20 ms build-up
    full = band_decay(decay(1.0, 3000, 90.0, rng), BIN_S)
    assert full.status == "complete" and full.continued_from_bin is None
    assert full.end_bin * BIN_S == pytest.approx(end_s, rel=tol)
    for stop in (40.0, 25.0):
        cont = band_decay(decay(1.0, 3000, stop, rng), BIN_S)
        assert cont.status == "continued", stop
        assert -60.0 / cont.slope_db_per_s == pytest.approx(1.0, rel=tol)
        assert cont.continued_from_bin * BIN_S == pytest.approx((stop - 10.0) / 60.0, abs=0.03)
        assert cont.end_bin * BIN_S == pytest.approx(end_s, rel=tol)
        # The continuation is the exponential itself: its energy per bin where it starts
        # and 20 dB further down, against the exact envelope.
        exact = decay(1.0, 3000)
        for i in (cont.continued_from_bin + 10, cont.continued_from_bin + 333):
            assert 10 * math.log10(cont.energy[i] / exact[i]) == pytest.approx(0, abs=0.5 + 5 * tol)
        assert not cont.energy[cont.end_bin:].any()
    cut = band_decay(decay(2.0, 1500, None, rng), BIN_S)
    assert cut.status == "cut" and cut.end_bin == 1500
    whole = np.cumsum(decay(2.0, 20_000)[::-1])[::-1]  # its exact Schroeder curve
    reached = 10 * math.log10(whole[1500] / whole[0])  # -44.4 dB (the build-up: +0.6)
    assert cut.level_at_end_db == pytest.approx(reached, abs=1.0 if noisy else 0.2)
    assert band_decay(np.zeros(100), BIN_S).status == "empty"
    # A few bins of energy (nothing to fit) end with their data, not at the histogram's end.
    burst = np.zeros(2000)
    burst[50:53] = 1.0
    assert band_decay(burst, BIN_S).end_bin == 53


def test_a_silent_late_field_gives_a_short_rir() -> None:
    """No late energy in any band (a source the rays never reach): the envelope keeps one
    empty bin and the RIR is the early arrivals alone, not the cap's 10 s of zeros."""
    from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
    from sonicspec.acoustics.late.tails import shape_tail
    from sonicspec.acoustics.receivers.synthesis import synthesize_rir

    silent = EnergyHistogram(BIN_S, np.zeros((10_000, 2)), np.full((10_000, 3), np.nan),
                             np.full((10_000, 3), np.nan))
    late, report = shape_tail(silent, (250.0, 1000.0), "auto", 10.0, "max_rir_cap_s")
    assert late.n_bins == 1 and report.end_s == 0.0
    assert [d.status for d in report.decays] == ["empty", "empty"]
    assert report.to_dict()["decay_60db_s"] == [None, None]
    early = Arrivals(times_s=np.array([0.01]), amplitudes=np.ones((1, 2)),
                     directions=np.zeros((1, 3)), order=np.zeros(1, dtype=np.int64),
                     kind=np.zeros(1, dtype=np.int8), path_length_m=np.array([3.43]))
    rir = synthesize_rir(early, late, 8000, np.random.default_rng(0), max_length_s=10.0,
                         bands_hz=(250.0, 1000.0))
    assert 0 < len(rir) < 0.2 * 8000 and np.abs(rir).max() > 0


def live_settings(fs: int = 8000, **acoustics) -> engine.SimulationSettings:
    """The spec's defaults (``max_rir_length_s: auto``, 20,000 rays, roulette from 30 dB,
    horizontal guiding) with ``acoustics`` changed, at ``fs``."""
    return engine.SimulationSettings.from_spec(
        AcousticsSpec(**acoustics).model_dump(mode="json"), fs, 343.0)


LIVE_SIZE, LIVE_SRC, LIVE_MIC = (10.0, 7.0, 3.0), np.array([2.1, 3.3, 1.4]), np.array(
    [7.2, 4.9, 1.6])


def live_scene(n_bands: int):
    """The issue's live room: 10 × 7 × 3 m, α = 0.02, scattering 0.5 (T30 ≈ 7 s)."""
    return rooms.uniform_scene(*rooms.shoebox(*LIVE_SIZE), 0.02, 0.5, 0.0, n_bands)


def test_a_live_room_at_default_settings_decays_to_its_end() -> None:
    """The issue's check: with the spec's defaults the live room's RIR was cut at 2 s, T30
    −38 … −53 %. Now (8 kHz: the bands 125 Hz … 2 kHz) T30 per band is within 5 % of the
    exact particle walk (:func:`shoebox_decay_t60`, air included; measured +0.0 … +2.5 %
    at 16 kHz, 125 Hz … 4 kHz), the RIR ends where the last band's decay is 60 dB down,
    below the cap, and each band's energy decay curve is still falling at 0.8 T30: near
    −48 dB there (an exponential's), 6 dB down over the 0.1 T30 before it (±20 %) and more
    than 4 dB over the 0.1 T30 after it (the RIR's end, 60 dB down, steepens its last dB)."""
    settings = live_settings()
    assert settings.max_rir_length_s == "auto" and settings.rir_limit_s == 10.0
    bands = settings.bands_hz
    (result,) = engine.rir_results(live_scene(len(bands)), LIVE_MIC, LIVE_SRC[None], settings,
                                   np.random.default_rng(0), where="scene 'live'")
    exact = shoebox_decay_t60(LIVE_SIZE, LIVE_SRC, [0.02] * len(bands), 0.5,
                              air_m_per_m=settings.air(), n_paths=20_000)
    assert 6.5 < exact[0] < 7.2
    np.testing.assert_allclose(result.t30_s, exact, rtol=0.05)
    tail = result.tail
    assert tail.rule == "auto" and set(tail.level_at_limit_db) == {None}
    assert tail.decay_end_s == max(tail.decay_60db_s) < 10.0
    assert result.rir.shape[-1] / 8000 >= tail.decay_end_s
    # Each band's 60 dB point lies near its T60 (the build-up adds a little).
    np.testing.assert_allclose(tail.decay_60db_s, exact, rtol=0.1)
    fs = settings.sample_rate_hz
    for b, band in enumerate(OctaveFilterBank(fs, bands).split(result.rir[0].astype(float))):
        edc = edc_db(band**2)
        t = exact[b]
        at = [edc[round(f * t * fs)] for f in (0.7, 0.8, 0.9)]
        assert -52.0 < at[1] < -44.0, (bands[b], at)
        assert at[0] - at[1] == pytest.approx(6.0, rel=0.2), (bands[b], at)
        assert at[1] - at[2] > 4.0, (bands[b], at)


def test_the_cap_warns_naming_the_scene_and_the_band() -> None:
    """A cap below the decay cuts it and warns once, naming the scene, the field and each
    band with the level it reached; the facts say the same. A number of seconds is taken as
    asked: the same cut is in the facts, without a warning."""
    settings = live_settings(rays=2000, bands_hz=[250, 1000], max_rir_cap_s=2.0)
    scene = live_scene(2)
    with pytest.warns(SonicspecWarning) as caught:
        (result,) = engine.rir_results(scene, LIVE_MIC, LIVE_SRC[None], settings,
                                       np.random.default_rng(0), where="scene 'live'")
    assert len(caught) == 1
    message = str(caught[0].message)
    assert message.startswith("scene 'live': the RIR's late decay is cut at 2 s "
                              "(acoustics.max_rir_cap_s) before it is 60 dB below its early "
                              "level: the 250 Hz band at -"), message
    assert "the 1000 Hz band at -" in message and "raise acoustics.max_rir_cap_s" in message
    assert result.rir.shape[-1] == 2 * 8000
    tail = result.tail
    assert tail.decay_60db_s == (None, None)
    assert all(-25 < v < -12 for v in tail.level_at_limit_db), tail  # 2 s of a 7 s T60
    assert all(5.5 < v < 8.0 for v in tail.fitted_t60_s), tail
    fixed = live_settings(rays=2000, bands_hz=[250, 1000], max_rir_length_s=2.0)
    (quiet,) = engine.rir_results(scene, LIVE_MIC, LIVE_SRC[None], fixed,
                                  np.random.default_rng(0))  # filterwarnings: error
    assert quiet.tail.rule == "fixed" and quiet.tail.limit_field == "max_rir_length_s"
    assert quiet.tail.level_at_limit_db == tail.level_at_limit_db
    with pytest.raises(AcousticsError, match="max_rir_length_s: expected 'auto' or seconds"):
        engine.SimulationSettings(**{**settings.__dict__, "max_rir_length_s": "longest"})
    with pytest.raises(AcousticsError, match="max_rir_cap_s: expected seconds > 0"):
        engine.SimulationSettings(**{**settings.__dict__, "max_rir_cap_s": 0.0})


DOOR_MIC, DOOR_SRC = np.array([2.0, 1.0, 1.5]), np.array([8.5, 3.0, 1.2])
# The `sonicset` preset's acoustics (specs/sonicset.yaml) in two bands.
SONICSET = {"rays": 4000, "ray_splitting": 2.0, "free_air_ball_m": 4.0, "roulette_db": 20.0,
            "horizontal_guiding": 0.5, "image_source_order": 3, "bands_hz": [250, 1000]}


def test_the_sonicset_preset_no_longer_ends_early_in_a_door_room() -> None:
    """Two 5 × 4 × 3 m rooms joined by a 0.9 × 2.1 m door (α 0.1, scattering 0.3), source
    and microphone in different rooms. With the preset's 4,000 rays and roulette from 20 dB
    the rays run out 0.6–1.0 s in, before the decay is 60 dB down (the issue's seed ended
    at 0.95 s, its decay curve −85 dB at 0.8 T). Now the envelope goes on with the decay
    fitted to its last 20 dB: over 4 seeds each band is continued, its RIR reaches the
    60 dB point of a reference traced without roulette (20,000 rays followed to 100 dB)
    within 15 %, its T30 is within 10 % of the reference's, and its energy decay curve at
    0.8 T30 is between −56 and −38 dB (−48 for an exponential). Over 12 seeds: 60 dB point
    −10 … +12 %, T30 −5.5 … +5 %, the curve at 0.8 T30 −42 … −49 dB."""
    bands = SONICSET["bands_hz"]
    scene = rooms.uniform_scene(*rooms.door_rooms(), 0.1, 0.3, 0.0, len(bands))
    reference_settings = live_settings(**{**SONICSET, "rays": 20_000, "roulette_db": 0.0,
                                          "ray_splitting": 0.0, "energy_threshold_db": 100.0})
    (reference,) = engine.rir_results(scene, DOOR_MIC, DOOR_SRC[None], reference_settings,
                                      np.random.default_rng(99))
    assert reference.tail.continued_from_s == (None, None)
    ref_end = np.array(reference.tail.decay_60db_s)
    ref_t30 = reference.t30_s
    assert np.all((0.9 < ref_t30) & (ref_t30 < 1.2)), ref_t30
    settings = live_settings(**SONICSET)
    fs = settings.sample_rate_hz
    bank = OctaveFilterBank(fs, tuple(float(b) for b in bands))
    for seed in range(4):
        (result,) = engine.rir_results(scene, DOOR_MIC, DOOR_SRC[None], settings,
                                       np.random.default_rng(seed))
        tail = result.tail
        assert None not in tail.continued_from_s, (seed, tail)  # the rays ran out
        # ... 10 dB or more before the decay's end (a tenth of T60 or more)
        started = np.array(tail.continued_from_s)
        assert np.all(started < ref_end - 0.1), (seed, tail)
        np.testing.assert_allclose(tail.decay_60db_s, ref_end, rtol=0.15)
        assert result.rir.shape[-1] / fs >= max(tail.decay_60db_s)
        np.testing.assert_allclose(result.t30_s, ref_t30, rtol=0.10)
        for b, band in enumerate(bank.split(result.rir[0].astype(float))):
            at = edc_db(band**2)[round(0.8 * ref_t30[b] * fs)]
            assert -56.0 < at < -38.0, (seed, bands[b], at)


def test_figures_of_a_continued_rir_match_its_expected_energy() -> None:
    """The facts' expected figures (the energy the RIR was synthesised to have) include the
    continuation: T30 of the RIR and of its expected energy agree within 10 % per band; the
    JSON facts carry the tail and the length."""
    bands = SONICSET["bands_hz"]
    scene = rooms.uniform_scene(*rooms.door_rooms(), 0.1, 0.3, 0.0, len(bands))
    (result,) = engine.rir_results(scene, DOOR_MIC, DOOR_SRC[None], live_settings(**SONICSET),
                                   np.random.default_rng(1))
    assert None not in result.tail.continued_from_s
    np.testing.assert_allclose(result.expected["t30_s"], result.t30_s, rtol=0.10)
    facts = result.to_dict()
    assert facts["tail"] == result.tail.to_dict()
    assert facts["length_s"] == result.rir.shape[-1] / result.sample_rate_hz
