"""``sonicspec validate`` on bad ``augmentation:`` values (issue 30): every message names the
field, the value written and what is expected; the loader's check of the same block (plain
data, :func:`sonicspec.audio.augment.parse_chain`) names the same field and value."""

from __future__ import annotations

import re

import pytest
import yaml
from spec_cases import BASE

from sonicspec.audio import augment as A
from sonicspec.errors import AudioError
from sonicspec.spec import validate_text
from sonicspec.spec.load import format_path

E = "augmentation.effects[0]"
MP3_LIST = r"expected a list of MP3 bit rates in kbit/s \(8, 16, .* or 320\), one drawn per group"
# (id, effect, field path, what the message says; the value as written is checked separately)
CASES = [
    ("mp3-negative-scalar", "{kind: mp3, bitrate_kbps: -5}", f"{E}.bitrate_kbps", MP3_LIST),
    ("mp3-text", "{kind: mp3, bitrate_kbps: fast}", f"{E}.bitrate_kbps", MP3_LIST),
    ("mp3-empty", "{kind: mp3, bitrate_kbps: []}", f"{E}.bitrate_kbps",
     r"expected a non-empty list of MP3 bit rates"),
    ("mp3-odd", "{kind: mp3, bitrate_kbps: [65]}", f"{E}.bitrate_kbps[0]",
     r"expected 8, 16, .* or 320"),
    ("opus-negative-scalar", "{kind: opus, bitrate_kbps: -5}", f"{E}.bitrate_kbps",
     r"expected a range \[min, max\] with both ends >= 6 and <= 256; \[x, x\] fixes the value"),
    ("opus-zero", "{kind: opus, bitrate_kbps: 0}", f"{E}.bitrate_kbps",
     r"expected a range \[min, max\] with both ends >= 6 and <= 256"),
    ("opus-three", "{kind: opus, bitrate_kbps: [16, 24, 32]}", f"{E}.bitrate_kbps",
     r"expected 2 values \[min, max\] \(got 3: "),
    ("opus-reversed", "{kind: opus, bitrate_kbps: [32, 16]}", f"{E}.bitrate_kbps",
     r"expected \[min, max\] with min <= max"),
    ("snr-scalar", "{kind: self_noise, snr_db: 20}", f"{E}.snr_db",
     r"expected a range \[min, max\] with both ends >= -20 and <= 100"),
    ("snr-text", "{kind: self_noise, snr_db: loud}", f"{E}.snr_db",
     r"expected a range \[min, max\]"),
    ("snr-below", "{kind: self_noise, snr_db: [-30, 10]}", f"{E}.snr_db",
     r"both ends must be >= -20 and <= 100"),
    ("color-unknown", "{kind: self_noise, snr_db: [20, 30], color: brown}", f"{E}.color",
     r"expected 'white' or 'pink'"),
    ("gain-scalar", "{kind: gain, gain_db: 100}", f"{E}.gain_db",
     r"expected a range \[min, max\] with both ends >= -60 and <= 40"),
    ("clipping-positive", "{kind: clipping, threshold_dbfs: [-3, 3]}", f"{E}.threshold_dbfs",
     r"both ends must be >= -60 and <= 0"),
    ("clipping-scalar", "{kind: clipping, threshold_dbfs: -3}", f"{E}.threshold_dbfs",
     r"expected a range \[min, max\] with both ends >= -60 and <= 0"),
    ("resample-scalar", "{kind: resample, rate_hz: -5}", f"{E}.rate_hz",
     r"expected a list of sample rates in Hz \(1000-192000\), one drawn per group"),
    ("resample-zero", "{kind: resample, rate_hz: [0]}", f"{E}.rate_hz[0]",
     r"must be greater than or equal to 1000"),
    ("resample-empty", "{kind: resample, rate_hz: []}", f"{E}.rate_hz",
     r"expected a non-empty list of sample rates in Hz"),
    ("resample-fraction", "{kind: resample, rate_hz: [8000.5]}", f"{E}.rate_hz[0]",
     r"must be a valid integer"),
    ("probability-negative", "{kind: gsm, probability: -1}", f"{E}.probability",
     r"must be greater than or equal to 0"),
    ("probability-above-one", "{kind: gsm, probability: 2}", f"{E}.probability",
     r"must be less than or equal to 1"),
    ("probability-text", "{kind: gsm, probability: often}", f"{E}.probability",
     r"must be a valid number"),
    ("targets-number", "{kind: gsm, targets: 1}", f"{E}.targets", r"must be a valid boolean"),
    ("kind-unknown", "{kind: aac}", f"{E}.kind",
     r"unknown kind 'aac'; expected one of 'response', .*'one_of'"),
    ("field-of-another-kind", "{kind: gsm, bitrate_kbps: [13, 13]}", f"{E}.bitrate_kbps",
     r"unknown field 'bitrate_kbps' \(allowed: kind, probability, targets\)"),
    ("preset-unknown", "{kind: response, preset: [iphone]}", f"{E}.preset[0]",
     r"expected 'smartphone', 'laptop', 'headset' or 'telephone'"),
    ("preset-scalar", "{kind: response, preset: smartphone}", f"{E}.preset",
     r"expected a list of device-class presets \('smartphone', 'laptop', 'headset', "
     r"'telephone'\), one drawn per group, e\.g\. \[smartphone, laptop\]"),
    ("preset-empty", "{kind: response, preset: []}", f"{E}.preset",
     r"expected a non-empty list of device-class presets"),
    ("response-neither", "{kind: response}", E,
     r"expected either preset or points, one of the two \(got neither\)"),
    ("points-one", "{kind: response, points: [[100, 0]]}", f"{E}.points",
     r"expected at least 2 of \[frequency Hz, gain dB\] pairs"),
    ("points-triple", "{kind: response, points: [[100, 0, 1], [200, 1]]}", f"{E}.points[0]",
     r"expected a \[frequency Hz, gain dB\] pair"),
    ("points-out-of-range", "{kind: response, points: [[100, 0], [0.5, 3]]}", f"{E}.points",
     r"expected \[Hz, dB\] with 1 <= Hz <= 100000 and -60 <= dB <= 30 \(got \[0\.5, 3\] as "
     r"point 1\)"),
    ("points-decreasing", "{kind: response, points: [[200, 0], [100, 3]]}", f"{E}.points",
     r"expected points in increasing frequency \(got \[\[200, 0\], \[100, 3\]\]\)"),
    ("files-scalar", "{kind: impulse_response, files: ir.wav}", f"{E}.files",
     r"expected a list of impulse-response files \(relative to the spec\)"),
    ("files-empty", "{kind: impulse_response, files: []}", f"{E}.files",
     r"expected a non-empty list of impulse-response files"),
    ("one-of-empty", "{kind: one_of, effects: []}", f"{E}.effects",
     r"expected a non-empty list of effects to choose from"),
    ("one-of-weights-count", "{kind: one_of, effects: [{kind: gsm}], weights: [1, 2]}",
     f"{E}.weights", r"expected 1 weights >= 0 \(one per effect\) with a positive sum"),
    ("one-of-weights-zero", "{kind: one_of, effects: [{kind: gsm}, {kind: gsm}], "
     "weights: [0, 0]}", f"{E}.weights", r"with a positive sum"),
    ("one-of-nested", "{kind: one_of, effects: [{kind: one_of, effects: [{kind: gsm}]}]}",
     f"{E}.effects[0].kind", r"unknown kind 'one_of'; expected one of 'response', .*'gsm'$"),
    ("one-of-inner-bad", "{kind: one_of, effects: [{kind: opus, bitrate_kbps: 8}]}",
     f"{E}.effects[0].bitrate_kbps", r"expected a range \[min, max\]"),
]
# what each message must show of the value written (where it is not the effect's own text)
SHOWN = {"mp3-negative-scalar": "(got -5)", "mp3-text": "(got 'fast')", "mp3-empty": "(got [])",
         "mp3-odd": "got 65", "opus-negative-scalar": "(got -5)", "opus-zero": "(got 0)",
         "opus-three": "[16, 24, 32]", "opus-reversed": "(got [32, 16])",
         "snr-scalar": "(got 20)", "snr-text": "(got 'loud')", "snr-below": "(got [-30, 10])",
         "color-unknown": "got 'brown'", "gain-scalar": "(got 100)",
         "clipping-positive": "(got [-3, 3])", "clipping-scalar": "(got -3)",
         "resample-scalar": "(got -5)", "resample-zero": "(got 0)", "resample-empty": "(got [])",
         "resample-fraction": "(got 8000.5)", "probability-negative": "(got -1)",
         "probability-above-one": "(got 2)", "probability-text": "(got 'often')",
         "targets-number": "(got 1)", "kind-unknown": "'aac'",
         "field-of-another-kind": "'bitrate_kbps'", "preset-unknown": "got 'iphone'",
         "preset-scalar": "(got 'smartphone')", "preset-empty": "(got [])",
         "response-neither": "(got neither)", "points-one": "(got [[100, 0]])",
         "points-triple": "(got [100, 0, 1])", "points-out-of-range": "[0.5, 3]",
         "points-decreasing": "[[200, 0], [100, 3]]", "files-scalar": "(got 'ir.wav')",
         "files-empty": "(got [])", "one-of-empty": "(got [])",
         "one-of-weights-count": "(got [1, 2])", "one-of-weights-zero": "(got [0, 0])",
         "one-of-nested": "'one_of'", "one-of-inner-bad": "(got 8)"}


def _problems(effect: str) -> list:
    text = BASE + f"augmentation:\n  effects:\n    - {effect}\n"
    loaded, problems = validate_text(text, "bad.yaml")
    assert loaded is None, effect
    return [p for p in problems if p.severity == "error"]


def test_every_case_says_what_value_it_got() -> None:
    assert set(SHOWN) == {c[0] for c in CASES}


@pytest.mark.parametrize(("case", "effect", "path", "expected"), CASES,
                         ids=[c[0] for c in CASES])
def test_validate_names_the_field_the_value_and_what_is_expected(
        case: str, effect: str, path: str, expected: str) -> None:
    problems = _problems(effect)
    assert [format_path(p.path) for p in problems] == [path], case
    (problem,) = problems
    line = problem.format("bad.yaml")
    assert line.startswith(f"bad.yaml:{BASE.count(chr(10)) + 3}:"), line  # the effect's line
    assert re.search(expected, problem.message), line
    assert SHOWN[case] in problem.message, line
    # no pydantic wording, nothing said twice
    for phrase in ("valid list", "valid tuple", "after validation", "Tuple should",
                   "(got a mapping)"):
        assert phrase not in problem.message, line
    assert problem.message.count("got ") <= 1 or case == "resample-fraction", line


LIBRARY = {  # the loader's check of the same block: the same field, value and expectation
    "mp3-negative-scalar": r"expected a non-empty list of MP3 bit rates in kbit/s, one drawn "
                           r"per group, got -5",
    "opus-zero": r"expected a range \[min, max\] with both ends in \[6, 256\] \(\[x, x\] "
                 r"fixes the value\), got 0",
    "snr-scalar": r"expected a range \[min, max\] with both ends in \[-20, 100\]",
    "resample-scalar": r"expected a non-empty list of sample rates in Hz \(1000-192000\)",
    "preset-scalar": r"expected a non-empty list of presets \(headset, laptop, smartphone, "
                     r"telephone\), one drawn per group, got 'smartphone'",
    "files-empty": r"expected a non-empty list of impulse-response files",
}


@pytest.mark.parametrize("case", sorted(LIBRARY))
def test_the_loader_s_check_says_the_same(case: str) -> None:
    _, effect, path, _ = next(c for c in CASES if c[0] == case)
    block = {"effects": [yaml.safe_load(effect)]}
    with pytest.raises(AudioError, match=re.escape(path) + ": " + LIBRARY[case]):
        A.parse_chain(block)
