"""The real-recording kit (issue 31): the playback sheet, recordings the test makes from it
(integer + fractional delay, ±50 ppm clock drift, a room's RIR per loudspeaker, noise at
20 dB SNR), their alignment to within 1 ms, the cut into the ``plain`` layout and
``evaluate`` on it; the errors; the same through the CLI."""

from __future__ import annotations

import json
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from scipy.signal import butter, fftconvolve, resample_poly, sosfiltfilt

from sonicspec.cli import main
from sonicspec.dataload.evaluate import evaluate
from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.recording import (
    Chirp,
    align,
    align_take,
    find_chirps,
    matched_filter,
    read_sheet,
    resample_at,
    write_sheet,
)

RATE = 16000
GROUPS = {"test/000000": 2.0, "test/000001": 1.5}  # group -> talkers' length, seconds


def write_dataset(root: Path, rate: int = RATE) -> Path:
    """A dataset folder as `sonicspec build` writes it (dataset.json, metadata.json per
    group, the dry stems ``source<k>_dry.wav`` beside the tracks), with speech-like talkers:
    noise bursts in the speech band (80 Hz – 7 kHz) shaped by a syllable-rate envelope."""
    rng = np.random.default_rng(7)
    speech_band = butter(8, (80, min(7000, 0.45 * rate)), "bandpass", fs=rate, output="sos")
    groups = []
    for gid, seconds in GROUPS.items():
        n = int(seconds * rate)
        meta = {"sample_rate_hz": rate, "num_samples": n}
        t = np.arange(n) / rate
        for k in (1, 2):
            env = np.maximum(0.0, np.sin(2 * np.pi * (3 + k) * t + k)) ** 2
            x = 0.3 * env * sosfiltfilt(speech_band, rng.standard_normal(n))
            (root / gid).mkdir(parents=True, exist_ok=True)
            sf.write(root / gid / f"source{k}_dry.wav", x, rate, subtype="FLOAT")
            sf.write(root / gid / f"source{k}.wav", 0.5 * x, rate, subtype="FLOAT")
            meta[f"source{k}"] = {"file": f"{gid}/source{k}.wav"}
        (root / gid / "metadata.json").write_text(json.dumps(meta))
        groups.append({"group": gid, "split": "test",
                       "metadata": {"path": f"{gid}/metadata.json"}})
    (root / "dataset.json").write_text(json.dumps({"splits": {"test": {}}, "groups": groups}))
    return root


def room_rir(rng: np.random.Generator, direct: int, rt60_s: float = 0.3) -> np.ndarray:
    """A synthetic room: a direct path at ``direct`` samples, then an exponentially decaying
    noise tail (``rt60_s``) from 2 ms after it, twice the direct sound's energy (a
    direct-to-reverberant ratio of -3 dB: a talker a few metres away in a living room)."""
    n = direct + int(rt60_s * RATE)
    h = np.zeros(n)
    h[direct] = 1.0
    start = direct + int(0.002 * RATE)
    m = n - start
    decay = np.exp(-6.9 * np.arange(m) / (rt60_s * RATE))
    tail = rng.standard_normal(m) * decay
    h[start:] = tail * np.sqrt(2.0 / np.sum(tail ** 2))
    return h


def fractional_delay(x: np.ndarray, delay: float) -> np.ndarray:
    """``x`` delayed by ``delay`` samples (exact for a band-limited signal: a phase ramp in
    the frequency domain, with room to spare at the end)."""
    pad = int(np.ceil(delay)) + 1024
    n = len(x) + pad
    spec = np.fft.rfft(x, n)
    f = np.fft.rfftfreq(n)
    return np.fft.irfft(spec * np.exp(-2j * np.pi * f * delay), n)


def record(sheet: Path, take: dict, rng: np.random.Generator, delay: float, ppm: float,
           snr_db: float = 20.0) -> tuple[np.ndarray, dict]:
    """What a recorder would hold: every loudspeaker through its own RIR, summed, played on
    a clock ``ppm`` fast (the recorder takes ``1 + ppm/1e6`` samples per played one), after
    ``delay`` recorder samples of silence, with white noise ``snr_db`` below the talkers."""
    played = [sf.read(sheet / ls["file"])[0] for ls in take["loudspeakers"]]
    directs = [int(rng.integers(20, 60)) for _ in played]
    rirs = [room_rir(rng, d) for d in directs]
    room = np.zeros(len(played[0]) + max(len(h) for h in rirs) - 1)
    for p, h in zip(played, rirs, strict=True):
        wet = fftconvolve(p, h)
        room[:len(wet)] += wet
    ratio = Fraction(1_000_000 + int(ppm), 1_000_000)
    drifted = resample_poly(room, ratio.numerator, ratio.denominator)
    y = fractional_delay(drifted, delay)
    noise = rng.standard_normal(len(y))
    lay = take["layout_samples"]
    talkers = room[lay["lead"] + lay["chirp"] + lay["gap"]:][:lay["content"]]
    noise *= np.sqrt(np.mean(talkers ** 2) / np.mean(noise ** 2)) * 10 ** (-snr_db / 20)
    truth = {"ratio": float(ratio), "delay": delay, "direct": directs[0], "room": room}
    return y + noise, truth


@pytest.fixture(scope="module")
def kit(tmp_path_factory) -> dict:
    tmp = tmp_path_factory.mktemp("kit")
    data = write_dataset(tmp / "data")
    manifest = write_sheet(data, tmp / "sheet", "test")
    rng = np.random.default_rng(2026)
    truths = {}
    for take, delay, ppm in zip(manifest["takes"], (1234.37, 4321.81), (50, -50), strict=True):
        y, truth = record(tmp / "sheet", take, rng, delay, ppm)
        (tmp / "rec" / "test").mkdir(parents=True, exist_ok=True)
        sf.write(tmp / "rec" / take["recording"], y, RATE, subtype="FLOAT")
        truths[take["group"]] = truth
    result = align(tmp / "rec", tmp / "sheet", tmp / "cut")
    return {"tmp": tmp, "data": data, "manifest": manifest, "truths": truths, "result": result}


def test_the_sheet_plays_the_dry_talkers_between_two_chirps(kit: dict) -> None:
    tmp, manifest = kit["tmp"], kit["manifest"]
    assert manifest == read_sheet(tmp / "sheet")
    sweep = Chirp(**manifest["chirp"]).samples(RATE)
    for take in manifest["takes"]:
        lay = take["layout_samples"]
        start = lay["lead"] + lay["chirp"] + lay["gap"]
        for ls in take["loudspeakers"]:
            x, rate = sf.read(tmp / "sheet" / ls["file"])
            dry, _ = sf.read(kit["data"] / take["group"] / f"{ls['talker']}_dry.wav")
            assert rate == RATE and len(x) == start + lay["content"] + lay["gap"] + \
                lay["chirp"] + lay["tail"]
            # The talker as the dataset holds it, at the take's gain (24-bit PCM).
            np.testing.assert_allclose(x[start:start + len(dry)], take["gain"] * dry,
                                       atol=2 ** -22)
            chirp_at = [lay["lead"], start + lay["content"] + lay["gap"]]
            for at in chirp_at:
                seg = x[at:at + lay["chirp"]]
                expect = sweep if ls["loudspeaker"] == 1 else np.zeros_like(sweep)
                np.testing.assert_allclose(seg, expect, atol=2 ** -22)
    rows = (tmp / "sheet" / "schedule.csv").read_text().splitlines()
    assert rows[0].startswith("take,loudspeaker,file,start_s") and len(rows) == 1 + 4


def test_alignment_is_within_1_ms_and_the_drift_is_measured(kit: dict) -> None:
    for a in kit["result"]:
        truth = kit["truths"][a.group]
        lead = kit["manifest"]["takes"][0]["layout_samples"]["lead"]
        expected = (lead + truth["direct"]) * truth["ratio"] + truth["delay"]
        assert abs(a.start_chirp - expected) < 0.001 * RATE, (a, expected)
        assert a.drift_ppm == pytest.approx((truth["ratio"] - 1) * 1e6, abs=2.0)
        assert a.correlation > 0.3


def test_the_cut_mixture_is_the_room_on_the_playback_clock(kit: dict) -> None:
    tmp = kit["tmp"]
    for take in kit["manifest"]["takes"]:
        truth = kit["truths"][take["group"]]
        lay = take["layout_samples"]
        item = tmp / "cut" / "test" / take["item"]
        mix, rate = sf.read(item / "mixture.wav")
        assert rate == RATE and len(mix) == lay["content"]
        for ls in take["loudspeakers"]:
            ref, _ = sf.read(item / f"s{ls['loudspeaker']}.wav")
            played, _ = sf.read(tmp / "sheet" / ls["file"])
            start = lay["lead"] + lay["chirp"] + lay["gap"]
            assert len(ref) == lay["content"]
            np.testing.assert_allclose(ref, played[start:start + lay["content"]], atol=2 ** -22)
        # The room's sound of the talkers, from the sync loudspeaker's arrival on.
        at = lay["lead"] + lay["chirp"] + lay["gap"] + truth["direct"]
        clean = truth["room"][at:at + lay["content"]]
        r = np.correlate(mix, clean, mode="full")[len(clean) - 1 - 40:len(clean) + 40]
        assert abs(int(np.argmax(r)) - 40) <= 0.001 * RATE
        rho = float(np.dot(mix, clean) / np.linalg.norm(mix) / np.linalg.norm(clean))
        assert rho > 0.98  # 20 dB SNR bounds it near 0.995


def test_evaluate_scores_the_cut_set_like_any_split(kit: dict) -> None:
    rows = evaluate(kit["tmp"] / "cut", "test", "separation", oracle=True, format="plain",
                    metrics=["si_snr", "si_snri"])
    mix = [r for r in rows if r["method"] == "oracle_mixture"]
    top = [r for r in rows if r["method"] == "oracle_targets"]
    assert len(mix) == len(top) == 2 * len(GROUPS)
    assert all(r["si_snri"] == pytest.approx(0.0, abs=1e-9) for r in mix)
    assert all(r["si_snr"] >= 100.0 for r in top)


@pytest.mark.parametrize("hz", [1234.5, 6000.0])
def test_resample_at_matches_a_sinusoid_at_a_drifted_clock(hz: float) -> None:
    """The exact reference: a sinusoid evaluated at the drifted instants (the kernel's
    pass-band ripple, about -86 dB with the Kaiser window, bounds the error)."""
    n = 4000
    f = hz / RATE
    x = np.sin(2 * np.pi * f * np.arange(n))
    y = resample_at(x, 100.25, 1.00005, 3000)[0]
    t = 100.25 + np.arange(3000) * 1.00005
    err = y[50:-50] - np.sin(2 * np.pi * f * t[50:-50])
    assert np.max(np.abs(err)) < 1e-4


def test_matched_filter_normalised_peak_is_one_on_the_chirp() -> None:
    sweep = Chirp().samples(RATE)
    x = np.concatenate([np.zeros(500), sweep, np.zeros(300)])
    _, rho = matched_filter(x, sweep)
    assert int(np.argmax(rho)) == 500 and rho[500] == pytest.approx(1.0, abs=1e-9)


def test_a_multichannel_reversed_polarity_recording_aligns_the_same(kit: dict) -> None:
    take = kit["manifest"]["takes"][0]
    y, _ = sf.read(kit["tmp"] / "rec" / take["recording"])
    before = next(a for a in kit["result"] if a.group == take["group"])
    a, cut = align_take(np.stack([-y, -0.5 * y]), RATE, take, Chirp(), "two channels")
    assert abs(a.start_chirp - before.start_chirp) < 0.01
    assert a.drift_ppm == pytest.approx(before.drift_ppm, abs=0.01)
    assert cut.shape == (2, take["layout_samples"]["content"])


def test_the_direct_sound_is_found_before_a_stronger_reflection() -> None:
    """A reflection 3 ms after the direct sound and stronger than it (a loudspeaker facing a
    wall): the arrival is the direct sound's, not the correlation's maximum."""
    sweep = Chirp().samples(RATE)
    x = np.zeros(60000)
    x[1000:1000 + len(sweep)] += sweep
    x[40000:40000 + len(sweep)] += sweep
    h = np.zeros(200)
    h[100], h[148] = 0.6, 1.0
    t0, t1, corr = find_chirps(np.convolve(x, h), sweep, 39000, RATE, "wall")
    assert t0 == pytest.approx(1100, abs=0.1) and t1 == pytest.approx(40100, abs=0.1)
    assert corr > 0.5


def _one_take(kit: dict, tmp: Path, y: np.ndarray) -> Path:
    rec = tmp / "rec"
    for take in kit["manifest"]["takes"]:
        (rec / take["recording"]).parent.mkdir(parents=True, exist_ok=True)
        sf.write(rec / take["recording"], y, RATE, subtype="FLOAT")
    return rec


def test_errors_name_the_file_and_the_value(kit: dict, tmp_path: Path) -> None:
    sheet = kit["tmp"] / "sheet"
    rng = np.random.default_rng(1)
    noise = 0.1 * rng.standard_normal(8 * RATE)
    with pytest.raises(DatasetError, match=r"000000\.wav: sync chirp not found: the best "
                       r"normalised correlation with it is 0\.0\d\d"):
        align(_one_take(kit, tmp_path / "a", noise), sheet, tmp_path / "out")
    take = kit["manifest"]["takes"][0]
    played = sf.read(sheet / take["loudspeakers"][0]["file"])[0]
    # 1500 ppm fast: the chirps lie too far apart.
    fast = resample_poly(played, 2003, 2000)
    with pytest.raises(DatasetError, match=r"000000\.wav: the chirps are \d+ samples apart.*"
                       r"\+1500 ppm, beyond the plausible ±1000 ppm"):
        align(_one_take(kit, tmp_path / "b", fast), sheet, tmp_path / "out")
    # Stopped in the talkers: shorter than the schedule.
    lay = take["layout_samples"]
    rec = _one_take(kit, tmp_path / "c", played[:lay["lead"] + lay["chirp"] + lay["gap"]
                                               + lay["content"] // 2])
    with pytest.raises(DatasetError, match=r"000000\.wav: \d+ samples \([\d.]+ s\), shorter "
                       r"than the schedule: the take plays \d+ samples"):
        align(rec, sheet, tmp_path / "out")
    with pytest.raises(DatasetError, match=r"manifest\.json: missing"):
        align(rec, tmp_path / "nosheet", tmp_path / "out")
    with pytest.raises(DatasetError, match=r"no recording of 2 take\(s\), first test/000000"):
        align(tmp_path, sheet, tmp_path / "out")


def test_playback_needs_the_dry_stems_and_the_split(kit: dict, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    data = write_dataset(tmp_path / "data")
    with pytest.raises(DatasetError, match=r"split 'val' not in the dataset; it has \['test'\]"):
        write_sheet(data, tmp_path / "sheet", "val")
    # At 8 kHz (LibriMix wav8k) the sweep stops at 3.2 kHz, below the Nyquist frequency.
    with pytest.raises(DatasetError, match=r"chirp: 100.0–6000.0 Hz does not fit below the "
                       r"Nyquist frequency of 8000 Hz"):
        Chirp().samples(8000)
    low = write_sheet(write_dataset(tmp_path / "data8k", rate=8000), tmp_path / "s8k")
    assert low["chirp"]["f_stop_hz"] == 3200.0
    (data / "test/000001/source2_dry.wav").unlink()
    assert main(["playback", str(data), "--out", str(tmp_path / "sheet")]) == 2
    assert re.search(r"test/000001: no source2_dry file; the dataset was built without "
                     r"mixture.targets: \[dry\]", capsys.readouterr().err)


def test_the_cli_plays_aligns_and_evaluates(kit: dict, tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    assert main(["playback", str(kit["data"]), "--out", str(tmp_path / "sheet"),
                 "--split", "test"]) == 0
    assert "2 take(s)" in capsys.readouterr().out
    assert (tmp_path / "sheet" / "manifest.json").read_bytes() != b""
    assert main(["align", str(kit["tmp"] / "rec"), "--sheet", str(tmp_path / "sheet"),
                 "--out", str(tmp_path / "cut")]) == 0
    out = capsys.readouterr().out
    assert "test/000000" in out and "ppm" in out
    assert main(["evaluate", str(tmp_path / "cut"), "--split", "test", "--task",
                 "separation", "--format", "plain", "--oracle", "--metrics", "si_snri",
                 "-o", str(tmp_path / "ev")]) == 0
    summary = json.loads((tmp_path / "ev" / "summary.json").read_text())
    assert summary["per_method"]["oracle_mixture"]["si_snri"] == pytest.approx(0.0, abs=1e-9)
    assert main(["align", str(tmp_path), "--sheet", str(tmp_path / "sheet"),
                 "--out", str(tmp_path / "cut2")]) == 2
    assert "no recording of 2 take(s)" in capsys.readouterr().err
