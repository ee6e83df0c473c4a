"""Arrangement (whole utterances, inside the clip) and loudness/mixing (targets, peak guard)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonicspec.audio.arrange import (
    Clip,
    Segment,
    arrange_background,
    arrange_speech,
    assemble,
)
from sonicspec.audio.mix import (
    gain_to_loudness,
    integrated_loudness,
    peak_guard,
    task_mixtures,
)
from sonicspec.errors import AudioError

FS = 16000


@settings(max_examples=60, deadline=None)
@given(lengths=st.lists(st.integers(1000, 80000), min_size=1, max_size=8),
       clip=st.integers(20000, 200000), seed=st.integers(0, 2**32 - 1))
def test_speech_is_whole_utterances_inside_the_clip(lengths, clip, seed) -> None:
    utts = [Clip(f"u{i}", n, f"WORDS {i}") for i, n in enumerate(lengths)]
    try:
        segs = arrange_speech(utts, clip, (3, 5), (0.0, 1.0), FS, np.random.default_rng(seed))
    except AudioError as exc:
        assert "no utterance fits" in str(exc)
        assert min(lengths) > clip - FS  # only when a gap of up to 1 s leaves no room
        return
    by_id = {u.id: u for u in utts}
    assert 1 <= len(segs) <= 5 and len({s.id for s in segs}) == len(segs)
    prev_end = 0
    for s in segs:
        assert s.end - s.start == by_id[s.id].num_samples  # never cut
        assert prev_end <= s.start and s.end <= clip  # in order, never past the end
        assert s.start - prev_end <= FS  # gap within the drawn range
        assert s.text == by_id[s.id].text and s.offset == 0
        prev_end = s.end


def test_speech_is_deterministic_and_reports_when_nothing_fits() -> None:
    utts = [Clip(f"u{i}", 16000 * (i + 1), "W") for i in range(6)]
    a = arrange_speech(utts, 10 * FS, (3, 5), (0.0, 2.0), FS, np.random.default_rng(7))
    b = arrange_speech(utts, 10 * FS, (3, 5), (0.0, 2.0), FS, np.random.default_rng(7))
    assert a == b
    with pytest.raises(AudioError, match=r"speaker 19: no utterance fits in the 1 s clip "
                                         r"\(shortest 2.00 s"):
        arrange_speech([Clip("long", 2 * FS)], FS, (1, 1), (0.0, 0.0), FS,
                       np.random.default_rng(0), where="speaker 19")
    with pytest.raises(AudioError, match="expected at least one utterance"):
        arrange_speech([], FS, (1, 1), (0.0, 0.0), FS, np.random.default_rng(0))


def test_background_fills_with_gaps_and_cuts_the_last_clip() -> None:
    clips = [Clip(f"n{i}", 3 * FS) for i in range(3)]
    segs = arrange_background(clips, 10 * FS, (6, 8), (0.0, 0.5), FS, np.random.default_rng(1))
    assert segs[-1].end <= 10 * FS
    assert all(s.end - s.start <= 3 * FS for s in segs)
    assert all(b.start >= a.end for a, b in itertools.pairwise(segs))
    # More clips asked for than the corpus has: they repeat, each pass in a new order.
    assert len(segs) >= 3 and {s.id for s in segs} == {"n0", "n1", "n2"}
    assert arrange_background(clips, FS, (0, 0), (0, 1), FS, np.random.default_rng(1)) == []
    with pytest.raises(AudioError, match="music: expected at least one clip"):
        arrange_background([], FS, (1, 2), (0, 1), FS, np.random.default_rng(1), where="music")


def test_assemble_places_samples_exactly() -> None:
    audio = {"a": np.arange(1, 6, dtype=float), "b": np.full(4, -1.0)}
    segs = [Segment("a", 2, 7), Segment("b", 8, 10, offset=2)]
    out = assemble(segs, audio, 12)
    assert out.tolist() == [0, 0, 1, 2, 3, 4, 5, 0, -1, -1, 0, 0]
    assert [Segment.from_dict(s.to_dict()) for s in segs] == segs
    with pytest.raises(AudioError, match="segment 'b': needs 4 samples from offset 2"):
        assemble([Segment("b", 0, 4, offset=2)], audio, 12)
    with pytest.raises(AudioError, match="segment 'c': its audio was not given"):
        assemble([Segment("c", 0, 4)], audio, 12)


def _speechlike(seconds: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    envelope = 0.5 * (1 + np.sin(2 * np.pi * 3 * t)) * (rng.random(t.size) > 0.0)
    return 0.1 * envelope * rng.standard_normal(t.size)


@pytest.mark.parametrize("target", [-17.0, -21.0, -24.0, -29.0])
def test_normalised_loudness_is_within_a_tenth_of_a_lu(target: float) -> None:
    x = np.zeros(10 * FS)
    x[2 * FS:7 * FS] = _speechlike(5.0, 3)  # silence around it is gated out
    gain, measured = gain_to_loudness(x, FS, target)
    assert integrated_loudness(gain * x, FS) == pytest.approx(target, abs=0.1)
    assert measured == pytest.approx(integrated_loudness(x, FS))
    # Multichannel: measured on channel 0; binaural on both ears (BS.1770 stereo).
    arr = np.stack([x, 0.5 * x, 0.1 * x])
    g, _ = gain_to_loudness(arr, FS, target)
    assert integrated_loudness(g * arr[0], FS) == pytest.approx(target, abs=0.1)
    ears = np.stack([x, 0.5 * x])
    g, _ = gain_to_loudness(ears, FS, target, binaural=True)
    assert integrated_loudness(g * ears, FS, binaural=True) == pytest.approx(target, abs=0.1)
    # BS.1770 sums the ears' power: 1 + 0.25 is 0.97 dB louder than the left ear alone.
    assert g == pytest.approx(gain / np.sqrt(1.25), rel=1e-3)


def test_normalisation_corrects_for_the_gates_moving_with_the_gain() -> None:
    """A long quiet passage just above −70 LUFS drops under the absolute gate when the gain
    lowers it, which moves the relative gate: one gain step lands 0.1 LU off, the corrected
    gain lands on the target."""
    rng = np.random.default_rng(0)

    def part(seconds: float, db: float) -> np.ndarray:
        return 0.1 * 10 ** (db / 20) * rng.standard_normal(int(seconds * FS))

    x = np.concatenate([part(2, 0.0), part(2, -9.6), part(30, -50.5)])
    measured = integrated_loudness(x, FS)
    one_step = 10 ** ((-23.0 - measured) / 20)
    assert abs(integrated_loudness(one_step * x, FS) + 23.0) > 0.05  # the gates moved
    gain, _ = gain_to_loudness(x, FS, -23.0)
    assert integrated_loudness(gain * x, FS) == pytest.approx(-23.0, abs=0.01)


def test_silent_and_short_inputs_are_named() -> None:
    with pytest.raises(AudioError, match=r"source2: expected sound to normalise to -17 LUFS, "
                                         "got silence"):
        gain_to_loudness(np.zeros(FS), FS, -17.0, where="source2")
    with pytest.raises(AudioError, match=r"noise: expected at least 0.4 s to measure loudness, "
                                         r"got 0.200 s"):
        integrated_loudness(np.ones(FS // 5), FS, where="noise")
    with pytest.raises(AudioError, match="expected finite samples"):
        integrated_loudness(np.full(FS, np.nan), FS)


def test_task_mixtures_cover_every_combination() -> None:
    speakers = ["source1", "source2", "source3"]
    tasks = [{"kind": "separation", "speakers": 2, "background": "noise"},
             {"kind": "enhancement", "background": "both"}]
    mixes = task_mixtures(tasks, speakers, ["noise", "music"])
    names = [m.name for m in mixes]
    assert names == ["sep_s1s2_noise", "sep_s1s3_noise", "sep_s2s3_noise",
                     "enh_s1_both", "enh_s2_both", "enh_s3_both"]
    assert mixes[0].components == ("source1", "source2", "noise")
    assert mixes[3].components == ("source1", "noise", "music") and mixes[3].targets == (
        "source1",)
    with pytest.raises(AudioError, match=r"mixture.tasks\[1\]: background 'both' needs music"):
        task_mixtures(tasks, speakers, ["noise"], where="mixture.tasks")  # the caller's field
    with pytest.raises(AudioError, match="separation of 4 speakers, but a group has 3"):
        task_mixtures([{"kind": "separation", "speakers": 4, "background": "none"}], speakers,
                      [])
    with pytest.raises(AudioError, match=r"mixtures \['enh_s1_noise'\] are asked for twice"):
        task_mixtures([tasks[0] | {"kind": "enhancement"}] * 2, ["source1"], ["noise"])


def test_peak_guard_scales_the_whole_group_below_the_limit() -> None:
    a = np.array([[0.6, -0.2, 0.1]])
    b = np.array([[0.5, 0.1, -0.9]])
    mixes = task_mixtures([{"kind": "separation", "speakers": 2, "background": "none"}],
                          ["source1", "source2"], [])
    gain, peak = peak_guard({"source1": a, "source2": b}, {"source1": 1.0, "source2": 1.0},
                            mixes, -1.0)
    assert peak == pytest.approx(1.1)  # the mixture's first sample
    assert gain * peak == pytest.approx(10 ** (-1 / 20))
    gain, _ = peak_guard({"source1": a}, {"source1": 1.0}, [], -1.0)
    assert gain == 1.0  # 0.6 is under −1 dBFS: nothing to do
