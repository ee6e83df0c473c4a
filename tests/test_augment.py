"""Device and channel effects (issue 30): each effect's measured effect, the draws, and the
spec block's checks (the spec model and the library's parser name the same field)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import yaml
from scipy.signal import correlate, welch
from spec_cases import BASE

from sonicspec.audio import augment as A
from sonicspec.errors import AudioError
from sonicspec.spec import validate_text
from sonicspec.spec.augmentation import AugmentationSpec
from sonicspec.spec.load import format_path

RATE = 16000


def _noise(seconds: float = 8.0, channels: int = 1, seed: int = 0) -> np.ndarray:
    return 0.05 * np.random.default_rng(seed).standard_normal((channels, int(seconds * RATE)))


def _draw(effect: dict, seed: int = 0) -> list[dict]:
    return A.draw_chain(A.parse_chain({"effects": [effect]}), np.random.default_rng(seed))


def _third_octave_levels(x: np.ndarray, y: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Output over input power per third-octave band, dB (Welch PSDs summed in the band)."""
    f, px = welch(x, RATE, nperseg=8192)
    _, py = welch(y, RATE, nperseg=8192)
    out = []
    for c in centres:
        band = (f >= c * 2 ** (-1 / 6)) & (f < c * 2 ** (1 / 6))
        out.append(10 * math.log10(py[band].sum() / px[band].sum()))
    return np.array(out)


def _asked_levels(points, centres: np.ndarray) -> np.ndarray:
    """The asked response's power averaged over each band of a flat input, dB."""
    out = []
    for c in centres:
        f = np.linspace(c * 2 ** (-1 / 6), c * 2 ** (1 / 6), 200)
        out.append(10 * math.log10(np.mean(10 ** (A.response_db(points, f) / 10))))
    return np.array(out)


CENTRES = 1000.0 * 2.0 ** (np.arange(-10, 9) / 3)  # 100 Hz ... 6.3 kHz third octaves


@pytest.mark.parametrize("preset", sorted(A.RESPONSE_PRESETS))
def test_a_response_preset_is_met_within_half_a_db_in_every_band(preset: str) -> None:
    x = _noise()
    y, _ = A.apply_chain(_draw({"kind": "response", "preset": [preset]}), x, RATE)
    points = A.RESPONSE_PRESETS[preset]["points"]
    asked = _asked_levels(points, CENTRES)
    measured = _third_octave_levels(x[0], y[0], CENTRES)
    keep = asked > -25  # far down the skirts the input's own band leakage dominates
    assert np.max(np.abs(measured - asked)[keep]) < 0.5, (measured - asked).round(2)
    assert A.RESPONSE_PRESETS[preset]["source"]


def test_a_response_of_ones_own_points_is_met_and_keeps_the_signal_aligned() -> None:
    points = [[100, -6.0], [1000, 0.0], [3000, 6.0], [6000, -3.0]]
    x = _noise()
    y, _ = A.apply_chain(_draw({"kind": "response", "points": points}), x, RATE)
    measured = _third_octave_levels(x[0], y[0], CENTRES)
    assert np.max(np.abs(measured - _asked_levels(points, CENTRES))) < 0.5
    # minimum phase: the energy comes first, so the mixture stays on its targets' time
    lag = np.argmax(correlate(y[0], x[0], mode="full", method="fft")) - (x.shape[1] - 1)
    assert lag == 0


@pytest.mark.parametrize("color", ["white", "pink"])
@pytest.mark.parametrize("snr", [0.0, 17.3, 40.0])
def test_self_noise_is_at_the_asked_snr_within_0_2_db(color: str, snr: float) -> None:
    x = _noise(channels=2)
    x[1] *= 0.5  # channels of different levels: the SNR is on the mean power
    draw = _draw({"kind": "self_noise", "snr_db": [snr, snr], "color": color})
    y, measured = A.apply_chain(draw, x, RATE)
    noise = y - x
    got = 10 * math.log10(np.mean(x ** 2) / np.mean(noise ** 2))
    assert abs(got - snr) < 0.2
    assert measured[0]["noise_rms_db"] == pytest.approx(10 * math.log10(np.mean(noise ** 2)))
    # each capsule's own noise: the channels' noises are uncorrelated
    # (pink noise's power sits in few low-frequency bins: compare its differences, ~white)
    white = noise if color == "white" else np.diff(noise, axis=1)
    assert abs(np.corrcoef(white)[0, 1]) < 0.05
    if color == "pink":  # 1/f: 3 dB less per octave
        f, p = welch(noise[0], RATE, nperseg=4096)
        slope = np.polyfit(np.log2(f[(f > 200) & (f < 6000)]),
                           10 * np.log10(p[(f > 200) & (f < 6000)]), 1)[0]
        assert slope == pytest.approx(-3.0, abs=0.3)


def test_gain_and_clipping_are_exact() -> None:
    x = _noise()
    y, _ = A.apply_chain(_draw({"kind": "gain", "gain_db": [6.0, 6.0]}), x, RATE)
    np.testing.assert_allclose(y, x * 10 ** (6 / 20))
    level = 10 ** (-30 / 20)
    y, measured = A.apply_chain(_draw({"kind": "clipping", "threshold_dbfs": [-30, -30]}), x,
                                RATE)
    assert np.max(np.abs(y)) == pytest.approx(level)
    assert measured[0]["clipped_share"] == pytest.approx(np.mean(np.abs(x) > level))
    inside = np.abs(x) <= level
    np.testing.assert_array_equal(y[inside], x[inside])


def test_resampling_to_8_khz_and_back_keeps_the_band_and_removes_the_rest() -> None:
    t = np.arange(4 * RATE) / RATE
    for f0, kept in ((1000.0, True), (3500.0, True), (5000.0, False), (7000.0, False)):
        x = 0.5 * np.sin(2 * np.pi * f0 * t)[None]
        y, _ = A.apply_chain(_draw({"kind": "resample", "rate_hz": [8000]}), x, RATE)
        core = slice(RATE, 3 * RATE)  # away from the ends
        gain_db = 10 * math.log10(np.mean(y[0, core] ** 2) / np.mean(x[0, core] ** 2))
        if kept:  # 3.5 kHz < 0.9 × 4 kHz: the pass band
            assert abs(gain_db) < 0.01, (f0, gain_db)
        else:
            assert gain_db < -80, (f0, gain_db)
    # a rate at or above the signal's does nothing, and says so
    x = _noise()
    y, measured = A.apply_chain(_draw({"kind": "resample", "rate_hz": [16000]}), x, RATE)
    np.testing.assert_array_equal(y, x)
    assert "not below" in measured[0]["skipped"]


def _lag(x: np.ndarray, y: np.ndarray) -> int:
    return int(np.argmax(correlate(y, x, mode="full", method="fft")) - (x.size - 1))


@pytest.mark.parametrize(("rate", "bitrate"), [(16000, 32), (16000, 64), (48000, 128),
                                               (8000, 16)])
def test_mp3_is_coded_at_the_asked_constant_bitrate_and_stays_aligned(rate: int,
                                                                     bitrate: int) -> None:
    x = 0.05 * np.random.default_rng(1).standard_normal((1, 5 * rate))
    y, measured = A.encode_decode(x, rate, "mp3", bitrate)
    # encoded bytes × 8 / duration: the asked rate, plus the frames' padding and headers
    assert measured["bitrate_kbps"] == pytest.approx(bitrate, rel=0.05)
    assert y.shape == x.shape
    assert _lag(x[0], y[0]) == 0


def test_opus_is_coded_near_the_asked_bitrate_per_channel() -> None:
    # Opus through libsndfile is variable bit rate: on white noise the rate comes within 15 %
    # of the asked one (libopus spends less than asked at the lowest rates); per channel.
    x = _noise(seconds=10, channels=2)
    x[1] = _noise(seconds=10, seed=3)[0]
    for asked in (12.0, 24.0, 64.0):
        y, measured = A.encode_decode(x, RATE, "opus", asked)
        assert measured["bitrate_kbps"] == pytest.approx(asked, rel=0.15), asked
        assert y.shape == x.shape
        assert _lag(x[0], y[0]) == 0


def test_gsm_full_rate_is_13_kbps_at_8_khz_and_narrow_band() -> None:
    x = _noise(seconds=6)
    y, measured = A.encode_decode(x, RATE, "gsm")
    # GSM 06.10: 33-byte frames of 160 samples (13.2 kbit/s as stored by libsndfile's WAV
    # GSM610, 65-byte pairs of frames per 320 samples), plus the header
    assert 13.0 <= measured["bitrate_kbps"] <= 13.3
    assert measured["codec_rate_hz"] == 8000
    f, p = welch(y[0], RATE, nperseg=2048)
    assert 10 * math.log10(p[f > 4500].mean() / p[(f > 500) & (f < 3000)].mean()) < -60
    assert _lag(x[0], y[0]) == 0


def test_an_impulse_response_colours_without_delay_or_level_change() -> None:
    h = np.zeros(64)
    h[5], h[6], h[9] = 1.0, -0.4, 0.2
    x = _noise()
    draw = _draw({"kind": "impulse_response", "files": ["phone.wav"]})
    y, _ = A.apply_chain(draw, x, RATE, impulse_responses={"phone.wav": h})
    expected = np.convolve(x[0], h / np.linalg.norm(h))[5:5 + x.shape[1]]
    np.testing.assert_allclose(y[0], expected, atol=1e-12)
    assert np.mean(y ** 2) == pytest.approx(np.mean(x ** 2), rel=0.02)
    with pytest.raises(AudioError, match=r"'phone\.wav' was not read"):
        A.apply_chain(draw, x, RATE)


CHAIN = {"effects": [
    {"kind": "response", "preset": ["smartphone", "laptop", "headset"], "probability": 0.7},
    {"kind": "self_noise", "snr_db": [10, 30], "targets": True},
    {"kind": "gain", "gain_db": [-6, 6], "probability": 0.4},
    {"kind": "clipping", "threshold_dbfs": [-12, -1], "probability": 0.3},
    {"kind": "resample", "rate_hz": [8000, 11025]},
    {"kind": "one_of", "weights": [2, 1, 1],
     "effects": [{"kind": "mp3", "bitrate_kbps": [32, 64]},
                 {"kind": "opus", "bitrate_kbps": [8, 24]}, {"kind": "gsm"}]},
]}


def test_draws_are_deterministic_and_follow_probabilities_and_ranges() -> None:
    chain = A.parse_chain(CHAIN)
    assert A.draw_chain(chain, np.random.default_rng(5)) == \
        A.draw_chain(chain, np.random.default_rng(5))
    draws = [A.draw_chain(chain, np.random.default_rng(s)) for s in range(3000)]
    for i, p in enumerate((0.7, 1.0, 0.4, 0.3, 1.0, 1.0)):
        share = np.mean([d[i]["applied"] for d in draws])
        assert abs(share - p) < 4 * math.sqrt(p * (1 - p) / len(draws)) + 1e-9, (i, share)
    snr = np.array([d[1]["snr_db"] for d in draws])
    assert snr.min() >= 10 and snr.max() <= 30 and abs(snr.mean() - 20) < 0.5
    assert {d[0]["preset"] for d in draws} == {"smartphone", "laptop", "headset"}
    choice = np.bincount([d[5]["choice"] for d in draws], minlength=3) / len(draws)
    np.testing.assert_allclose(choice, [0.5, 0.25, 0.25], atol=0.04)
    assert {d[5]["effect"]["bitrate_kbps"] for d in draws if d[5]["choice"] == 0} == {32, 64}
    assert all(d[5]["effect"]["kind"] == "gsm" for d in draws if d[5]["choice"] == 2)
    # every effect is drawn whether applied or not: its parameters are in every draw
    assert all("gain_db" in d[2] for d in draws)


def test_the_same_draw_gives_the_same_bytes_and_targets_take_only_their_effects() -> None:
    chain = A.parse_chain(CHAIN)
    draw = A.draw_chain(chain, np.random.default_rng(11))
    x = _noise(seconds=3)
    a, _ = A.apply_chain(draw, x, RATE)
    b, _ = A.apply_chain(draw, x, RATE)
    assert a.tobytes() == b.tobytes()
    other, _ = A.apply_chain(A.draw_chain(chain, np.random.default_rng(12)), x, RATE)
    assert other.tobytes() != a.tobytes()
    # a target takes only the effects marked targets (here the self-noise)
    t, measured = A.apply_chain(draw, x, RATE, target=True)
    assert [i for i, m in enumerate(measured) if m is not None] == [1]
    got = 10 * math.log10(np.mean(x ** 2) / np.mean((t - x) ** 2))
    assert abs(got - draw[1]["snr_db"]) < 0.2
    # and a 1-D signal comes back 1-D
    assert A.apply_chain(draw, x[0], RATE)[0].shape == x[0].shape


# --- the spec block: the model and the library's parser name the same field ----------------

BAD_BLOCKS = [
    # (case, effect, the field named)
    ("probability-above-one", {"kind": "gain", "gain_db": [0, 1], "probability": 1.5},
     "augmentation.effects[0].probability"),
    ("snr-range-reversed", {"kind": "self_noise", "snr_db": [30, 10]},
     "augmentation.effects[0].snr_db"),
    ("gain-missing", {"kind": "gain"}, "augmentation.effects[0].gain_db"),
    ("clipping-above-full-scale", {"kind": "clipping", "threshold_dbfs": [-3, 3]},
     "augmentation.effects[0].threshold_dbfs"),
    ("unknown-preset", {"kind": "response", "preset": ["walkie_talkie"]},
     "augmentation.effects[0].preset[0]"),
    ("unknown-kind", {"kind": "reverb"}, "augmentation.effects[0].kind"),
    ("mp3-odd-bitrate", {"kind": "mp3", "bitrate_kbps": [33]},
     "augmentation.effects[0].bitrate_kbps[0]"),
    ("opus-too-slow", {"kind": "opus", "bitrate_kbps": [2, 8]},
     "augmentation.effects[0].bitrate_kbps"),
    ("resample-too-low", {"kind": "resample", "rate_hz": [500]},
     "augmentation.effects[0].rate_hz[0]"),
    ("gsm-with-bitrate", {"kind": "gsm", "bitrate_kbps": [13, 13]},
     "augmentation.effects[0].bitrate_kbps"),
    ("nested-one-of", {"kind": "one_of", "effects": [{"kind": "one_of", "effects": []}]},
     "augmentation.effects[0].effects[0].kind"),
    ("targets-not-bool", {"kind": "gain", "gain_db": [0, 1], "targets": "yes"},
     "augmentation.effects[0].targets"),
    ("files-empty", {"kind": "impulse_response", "files": []},
     "augmentation.effects[0].files"),
]


@pytest.mark.parametrize(("case", "effect", "field"), BAD_BLOCKS, ids=[c[0] for c in BAD_BLOCKS])
def test_a_bad_value_is_refused_naming_its_field_by_the_spec_and_the_library(
        case: str, effect: dict, field: str) -> None:
    block = {"augmentation": {"effects": [effect]}}
    loaded, problems = validate_text(BASE + yaml.safe_dump(block), "bad.yaml")
    assert loaded is None, case
    paths = [format_path(p.path) for p in problems if p.severity == "error"]
    assert paths == [field], case
    with pytest.raises(AudioError, match=re.escape(field) + ":"):
        A.parse_chain(block["augmentation"])


def test_response_needs_exactly_one_of_preset_and_points() -> None:
    for effect in ({"kind": "response"},
                   {"kind": "response", "preset": ["laptop"], "points": [[100, 0], [200, 1]]}):
        with pytest.raises(AudioError, match="either preset or points"):
            A.parse_chain({"effects": [effect]})
        with pytest.raises(ValueError, match="either preset or points"):
            AugmentationSpec.model_validate({"effects": [effect]})
    with pytest.raises(AudioError, match=r"points: expected points in increasing frequency"):
        A.parse_chain({"effects": [{"kind": "response", "points": [[200, 0], [100, 0]]}]})


def test_a_valid_block_reads_the_same_in_the_spec_and_the_library() -> None:
    spec = AugmentationSpec.model_validate(CHAIN)
    assert A.parse_chain(spec) == A.parse_chain(CHAIN)
    # every preset the spec offers is one the library has, and no other
    from typing import get_args

    from sonicspec.spec.augmentation import ResponsePreset

    assert set(get_args(ResponsePreset)) == set(A.RESPONSE_PRESETS)
    # and every kind
    from sonicspec.spec.augmentation import EffectSpec

    def models(tp) -> list:
        args = get_args(tp)
        return [m for a in args for m in models(a)] if args else [tp]

    kinds = {m.model_fields["kind"].annotation.__args__[0] for m in models(EffectSpec)
             if hasattr(m, "model_fields")}
    assert kinds == set(A.KINDS)


def test_mp3_at_a_rate_without_that_bitrate_is_an_error_naming_it() -> None:
    with pytest.raises(AudioError, match=r"mp3 bitrate_kbps: 320 kbit/s is not an MP3 bit "
                       r"rate at 16000 Hz"):
        A.encode_decode(_noise(seconds=1), RATE, "mp3", 320)


@pytest.mark.parametrize("rate", [8000, 11025, 16000, 22050, 32000, 44100, 48000, 96000])
def test_the_spec_knows_the_mp3_bit_rates_the_library_codes_at(rate: int) -> None:
    from sonicspec.spec.augmentation import mp3_bitrates_at

    allowed = mp3_bitrates_at(rate)
    x = 0.05 * np.random.default_rng(0).standard_normal((1, rate))
    for bitrate in (allowed[0], allowed[-1]):  # the library codes at both ends
        y, _ = A.encode_decode(x, rate, "mp3", bitrate)
        assert y.shape == x.shape
    rate_used = A._codec_rate(rate, A.MP3_RATES_HZ)
    table = A.MP3_BITRATES_KBPS["mpeg1" if rate_used >= 32000 else "mpeg2"]
    assert allowed == tuple(b for b in table if rate_used >= 16000 or b <= 64)


def test_validate_refuses_an_mp3_bit_rate_the_sample_rate_cannot_take() -> None:
    block = {"augmentation": {"effects": [
        {"kind": "one_of", "effects": [{"kind": "mp3", "bitrate_kbps": [64, 320]}]},
        {"kind": "resample", "rate_hz": [16000]}]}}
    loaded, problems = validate_text(BASE + yaml.safe_dump(block), "bad.yaml")
    assert loaded is None
    found = {format_path(p.path): (p.severity, p.message) for p in problems}
    assert found["augmentation.effects[0].effects[0].bitrate_kbps[1]"][0] == "error"
    assert "sample_rate_hz 16000" in found["augmentation.effects[0].effects[0].bitrate_kbps[1]"][1]
    assert found["augmentation.effects[1].rate_hz[0]"] == (
        "warning", "16000 Hz is not below sample_rate_hz (16000): resampling through it does "
        "nothing")


def test_an_impulse_response_file_is_read_resampled_and_refused_when_unusable(tmp_path) -> None:
    import soundfile as sf

    h = np.zeros(96)
    h[4] = 1.0
    sf.write(tmp_path / "ir48k.wav", np.stack([h, -h], 1), 48000, subtype="FLOAT")
    got = A.read_impulse_response(tmp_path / "ir48k.wav", 16000)
    assert got.shape == (32,)  # the first channel, at 16 kHz
    sf.write(tmp_path / "silent.wav", np.zeros(64), 16000, subtype="FLOAT")
    with pytest.raises(AudioError, match=r"ir 'silent': expected a finite, non-silent "
                       r"response in .*silent\.wav"):
        A.read_impulse_response(tmp_path / "silent.wav", 16000, where="ir 'silent'")
    with pytest.raises(AudioError, match=r"ir 'gone': cannot read .*gone\.wav"):
        A.read_impulse_response(tmp_path / "gone.wav", 16000, where="ir 'gone'")


def test_codecs_without_mp3_or_opus_in_libsndfile_say_how_to_get_them(monkeypatch) -> None:
    import soundfile

    monkeypatch.setattr(soundfile, "available_formats", lambda: {"WAV": "WAV", "OGG": "OGG"})
    with pytest.raises(AudioError, match=r"need libsndfile >= 1\.1 with MP3 and Opus .*"
                       r"pip install 'sonicspec\[augment\]'"):
        A.encode_decode(_noise(seconds=0.5), RATE, "gsm")
