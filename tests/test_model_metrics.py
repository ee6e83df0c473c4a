"""Metrics with models the user holds: WER/CER (a transcriber) and DNSMOS (ONNX files)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.dataload.evaluate import evaluate, expand_metrics, summarise
from sonicspec.dataload.folder import DatasetError, Group

RATE = 16000


def _plain_set(root: Path, est_root: Path, n: int = 2, seconds: float = 2.0) -> list[np.ndarray]:
    """A plain enhancement set of ``n`` items (``test/item<k>``) and an estimates folder;
    the estimates, distinct noises, are returned."""
    rng = np.random.default_rng(1)
    estimates = []
    for k in range(n):
        item = root / "test" / f"item{k}"
        item.mkdir(parents=True)
        clean = 0.1 * rng.standard_normal(int(seconds * RATE))
        sf.write(item / "clean.wav", clean, RATE, subtype="FLOAT")
        sf.write(item / "mixture.wav", clean + 0.05 * rng.standard_normal(len(clean)), RATE,
                 subtype="FLOAT")
        est = clean + 0.01 * rng.standard_normal(len(clean))
        (est_root / "test" / f"item{k}").mkdir(parents=True)
        sf.write(est_root / "test" / f"item{k}" / "mixture.wav", est, RATE, subtype="FLOAT")
        estimates.append(est)
    return estimates


class _Stub:
    """A transcriber whose output is known: the text of the estimate the audio is."""

    kind = "stub"
    files: tuple = ()

    def __init__(self, signals: list[np.ndarray], texts: list[str]) -> None:
        self.signals, self.texts, self.calls = signals, texts, 0

    def __call__(self, audio: np.ndarray, rate: int) -> str:
        assert rate == RATE
        self.calls += 1
        corr = [abs(np.corrcoef(audio, s)[0, 1]) for s in self.signals]
        return self.texts[int(np.argmax(corr))]


def test_metric_names_expand_to_columns() -> None:
    assert expand_metrics(["si_snr,sdr,pesq,stoi,wer,dnsmos"]) == [
        "si_snr", "sdr", "pesq_nb", "pesq_wb", "stoi", "wer", "cer", "dnsmos_sig",
        "dnsmos_bak", "dnsmos_ovrl", "dnsmos_p808"]
    assert expand_metrics(["wer", "cer", "wer"]) == ["wer", "cer"]
    with pytest.raises(DatasetError, match="got 'mos'"):
        expand_metrics(["si_snr,mos"])


def test_error_counts_on_known_strings_match_jiwer_after_the_normaliser() -> None:
    jiwer = pytest.importorskip("jiwer", reason="jiwer is not installed (sonicspec[asr])")
    english = pytest.importorskip("whisper_normalizer.english",
                                  reason="whisper-normalizer is not installed (sonicspec[asr])")
    from sonicspec.dataload.asr import error_counts

    # By hand: one word substituted of six; "the" -> "a" is 3 character edits of 22.
    c = error_counts("The cat sat on the mat.", "the cat sat on a mat")
    assert (c["word_errors"], c["ref_words"], c["wer"]) == (1, 6, 1 / 6)
    assert (c["char_errors"], c["ref_chars"], c["cer"]) == (3, 22, 3 / 22)
    # The normaliser: British spellings, numbers, contractions, punctuation and case.
    ref, hyp = "Mr. Smith's colour costs twenty-five dollars!", "mister smith's color costs $25"
    c = error_counts(ref, hyp)
    assert c["wer"] == 0.0 and c["cer"] == 0.0, c
    norm = english.EnglishTextNormalizer()
    ref, hyp = "I've got 3 apples, and she's GOT none.", "I have got three apple and she got"
    c = error_counts(ref, hyp)
    assert c["wer"] == jiwer.wer(norm(ref), norm(hyp))
    assert c["cer"] == jiwer.cer(norm(ref), norm(hyp))
    assert c["wer"] != jiwer.wer(ref, hyp)  # the normaliser made a difference
    with pytest.raises(DatasetError, match="no words after Whisper's normaliser"):
        error_counts("Uh, um!", "hello")  # fillers and punctuation only


def test_wer_through_evaluate_with_a_stub_transcriber(tmp_path: Path) -> None:
    pytest.importorskip("jiwer", reason="jiwer is not installed (sonicspec[asr])")
    pytest.importorskip("whisper_normalizer", reason="whisper-normalizer is not installed")
    root, est = tmp_path / "set", tmp_path / "est"
    signals = _plain_set(root, est)
    refs = {"test/item0/source1": "The cat sat on the mat.",
            "test/item1": "It is twenty five degrees"}
    stub = _Stub(signals, ["the cat sat on a mat", "it's 25 degrees"])
    rows = evaluate(root, "test", "enhancement", estimates=est, metrics=["si_snr", "wer", "cer"],
                    transcriber=stub, transcripts=refs)
    assert stub.calls == 2
    got = {r["group"]: r for r in rows}
    assert got["test/item0"]["wer"] == 1 / 6 and got["test/item0"]["cer"] == 3 / 22
    assert got["test/item1"]["wer"] == 0.0
    assert got["test/item1"]["transcript"] == "it is 25 degrees"
    summary = summarise(rows, ["si_snr", "wer", "cer"])
    # Pooled: 1 error over 6 + 4 words (the mean of the rows would be 1/12).
    assert summary["per_method"]["estimates"]["wer"] == 1 / 10
    assert summary["per_method"]["estimates"]["si_snr"] > 10
    # A silent estimate says nothing: every word deleted, the transcriber not asked.
    sf.write(est / "test" / "item1" / "mixture.wav", np.zeros(len(signals[1])), RATE)
    rows = evaluate(root, "test", "enhancement", estimates=est, metrics=["wer"],
                    transcriber=stub, transcripts=refs)
    assert stub.calls == 3 and rows[1]["wer"] == 1.0 and rows[1]["word_errors"] == 4


def test_references_come_from_metadata_words_or_the_transcripts_file(tmp_path: Path) -> None:
    from sonicspec.dataload.asr import read_transcripts, reference_text

    group = Group(tmp_path, "test/000001", {"source1": {"words": ["hello there", "again"]},
                                            "source2": {}})
    assert reference_text(group, "source1", 2, None) == "hello there again"
    assert reference_text(group, "source1", 2, {"test/000001/source1": "x"}) == "x"
    with pytest.raises(DatasetError, match=r"group test/000001: no transcript for source2"):
        reference_text(group, "source2", 2, {"test/000001": "not for two targets"})
    f = tmp_path / "t.tsv"
    f.write_text("test/1/source1\thello world\n\ntest/2\tbye\n", encoding="utf-8")
    assert read_transcripts(f) == {"test/1/source1": "hello world", "test/2": "bye"}
    f.write_text("test/1/source1 hello world\n", encoding="utf-8")
    with pytest.raises(DatasetError, match=r"t.tsv:1: expected '<group id>/<target><TAB>"):
        read_transcripts(f)
    f.write_text("a\tx\na\ty\n", encoding="utf-8")
    with pytest.raises(DatasetError, match=r"t.tsv:2: 'a' is given twice"):
        read_transcripts(f)
    with pytest.raises(DatasetError, match="no such file"):
        read_transcripts(tmp_path / "none.tsv")


# ---- DNSMOS: the pipeline on tiny ONNX models that mimic the real ones' shapes ----

def _tiny_dnsmos(folder: Path) -> None:
    """``sig_bak_ovr.onnx``: [N, 144160] -> [N, 3] = (mean, max, min) of the segment;
    ``model_v8.onnx``: [N, 900, 120] -> [N, 1, 1] = the mean of the features."""
    onnx = pytest.importorskip("onnx", reason="the onnx package is not installed (builds "
                               "the test's tiny models)")
    from onnx import TensorProto, helper

    folder.mkdir(parents=True, exist_ok=True)
    x = helper.make_tensor_value_info("input_1", TensorProto.FLOAT, ["N", 144160])
    y = helper.make_tensor_value_info("out", TensorProto.FLOAT, ["N", 3])
    nodes = [helper.make_node("ReduceMean", ["input_1"], ["a"], axes=[1], keepdims=1),
             helper.make_node("ReduceMax", ["input_1"], ["b"], axes=[1], keepdims=1),
             helper.make_node("ReduceMin", ["input_1"], ["c"], axes=[1], keepdims=1),
             helper.make_node("Concat", ["a", "b", "c"], ["out"], axis=1)]
    graph = helper.make_graph(nodes, "p835", [x], [y])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(folder / "sig_bak_ovr.onnx"))
    x = helper.make_tensor_value_info("input_1", TensorProto.FLOAT, ["N", 900, 120])
    y = helper.make_tensor_value_info("out", TensorProto.FLOAT, ["N", 1, 1])
    nodes = [helper.make_node("ReduceMean", ["input_1"], ["out"], axes=[1, 2], keepdims=1)]
    graph = helper.make_graph(nodes, "p808", [x], [y])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(folder / "model_v8.onnx"))


@pytest.mark.parametrize(("seconds", "starts"), [
    # int(20 - 9.01) + 1 = 11 segments, one a second, but the reference's floating-point cut
    # leaves those from 7 s on one sample short, and skips them.
    (20.5, [float(s) for s in range(7)]),
    (3.0, [0.0, 1.0, 2.0]),  # repeated to 6 s, then 12 s: three segments
])
def test_dnsmos_pipeline_segments_maps_and_averages(tmp_path: Path, seconds: float,
                                                    starts: list[float]) -> None:
    pytest.importorskip("onnxruntime", reason="onnxruntime is not installed (sonicspec[mos])")
    from sonicspec.dataload.mos import P835_POLY, log_mel, open_mos, segments

    _tiny_dnsmos(tmp_path / "m")
    model = open_mos("dnsmos", tmp_path / "m")
    n = int(seconds * RATE)
    ramp = np.arange(n) / RATE  # each sample is its time: a segment's mean tells its start
    clip = np.tile(ramp, 4) if n < 144160 else ramp
    segs = [clip[round(s * RATE):round(s * RATE) + 144160] for s in starts]
    assert len(segments(ramp)) == len(starts)
    for got, want in zip(segments(ramp), segs, strict=True):
        np.testing.assert_array_equal(got, want.astype(np.float32))
    raw = np.array([[s.mean(), s.max(), s.min()] for s in segs])
    want = {f"dnsmos_{k}": np.mean(np.polyval(P835_POLY[k], raw[:, i]))
            for i, k in enumerate(("sig", "bak", "ovrl"))}
    want["dnsmos_p808"] = np.mean([log_mel(s[:-160].astype(np.float32)).mean() for s in segs])
    got = model(ramp, RATE)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-4), k
    # The mean of the mapped segments, not the mapped mean (the fits are not linear).
    mapped_mean = np.polyval(P835_POLY["sig"], raw[:, 0].mean())
    if np.ptp(raw[:, 0]) > 1.0:  # segments that differ (the repeated clip's do not)
        assert abs(got["dnsmos_sig"] - mapped_mean) > 1e-3
    assert [f["path"] for f in model.files] == [str((tmp_path / "m" / n).resolve()) for n in
                                                ("sig_bak_ovr.onnx", "model_v8.onnx")]
    assert all(len(f["sha256"]) == 64 for f in model.files)


def test_segments_skip_those_the_reference_cuts_short() -> None:
    from sonicspec.dataload.mos import segments

    ramp = np.arange(130 * RATE) / RATE
    starts = [round(float(s[0]), 6) for s in segments(ramp)]
    # int(130 - 9.01) + 1 = 121 segments at 0…120 s; the reference skips 7…23, 119, 120.
    assert starts == [float(s) for s in (*range(7), *range(24, 119))]


def test_log_mel_matches_librosa_with_the_references_padding() -> None:
    librosa = pytest.importorskip("librosa", reason="librosa is not installed (the check of "
                                  "the mel front end against it)")
    from sonicspec.dataload.mos import log_mel

    x = np.random.default_rng(0).standard_normal(144000) * 0.1
    mel = librosa.feature.melspectrogram(y=x, sr=16000, n_fft=321, hop_length=160, n_mels=120,
                                         pad_mode="reflect")
    want = ((librosa.power_to_db(mel, ref=np.max) + 40) / 40).T
    got = log_mel(x)
    assert got.shape == (900, 120)
    np.testing.assert_allclose(got, want, atol=1e-6)


def _dnsmos_dir() -> Path:
    given = os.environ.get("SONICSPEC_DNSMOS_DIR")
    if given:
        return Path(given)
    import importlib.util

    spec = importlib.util.find_spec("speechmos")
    if spec is None:
        pytest.skip("no DNSMOS ONNX files: set SONICSPEC_DNSMOS_DIR to a folder holding "
                    "sig_bak_ovr.onnx and model_v8.onnx, or pip install speechmos (it ships them)")
    return Path(next(iter(spec.submodule_search_locations))) / "dnsmos_models"


def _espeak(text: str, tmp: Path) -> np.ndarray:
    exe = shutil.which("espeak-ng")
    if exe is None:
        pytest.skip("espeak-ng is not installed (the test's speech)")
    wav = tmp / "speech.wav"
    subprocess.run([exe, "-w", str(wav), text], check=True, capture_output=True)
    x, rate = sf.read(wav)
    from scipy.signal import resample_poly

    return resample_poly(x, 16000 // 50, rate // 50) if rate != RATE else x


def test_real_dnsmos_rates_clean_speech_above_speech_in_noise(tmp_path: Path) -> None:
    pytest.importorskip("onnxruntime", reason="onnxruntime is not installed (sonicspec[mos])")
    from sonicspec.dataload.mos import open_mos

    model = open_mos("dnsmos", _dnsmos_dir())
    speech = _espeak("The quick brown fox jumps over the lazy dog, and then it runs away "
                     "into the forest before the sun goes down.", tmp_path)
    speech = 0.3 * speech / np.max(np.abs(speech))
    noise = np.random.default_rng(0).standard_normal(len(speech))
    noise *= np.sqrt(np.mean(speech ** 2) / np.mean(noise ** 2))  # 0 dB SNR
    clean, noisy = model(speech, RATE), model(speech + noise, RATE)
    for k in ("dnsmos_sig", "dnsmos_bak", "dnsmos_ovrl", "dnsmos_p808"):
        assert 1.0 <= noisy[k] < clean[k] <= 5.0, (k, clean, noisy)


def test_real_whisper_run_when_a_model_is_held(tmp_path: Path) -> None:
    path = os.environ.get("SONICSPEC_ASR_MODEL")
    if not path:
        pytest.skip("no Whisper model on this machine: set SONICSPEC_ASR_MODEL to a "
                    "faster-whisper model folder or an openai-whisper .pt file (nothing is "
                    "downloaded)")
    from sonicspec.dataload.asr import error_counts, open_transcriber

    model = open_transcriber(path)
    text = "The birch canoe slid on the smooth planks."
    speech = _espeak(text, tmp_path)
    counts = error_counts(text, model(speech, RATE))
    assert counts["wer"] <= 0.5, counts


# ---- the CLI: every missing or invalid model path is named ----

def _cli(argv: list[str], capsys) -> tuple[int, str]:
    from sonicspec.cli import main

    code = main(argv)
    return code, capsys.readouterr().err


@pytest.mark.parametrize(("extra", "message"), [
    (["--metrics", "wer"], "--metrics wer: give the speech recogniser with --asr-model"),
    (["--metrics", "dnsmos"], "--metrics dnsmos: give the DNSMOS model files with --dnsmos-dir"),
    (["--metrics", "si_snr", "--asr-model", "X"], "--asr-model: given without wer"),
    (["--metrics", "si_snr", "--dnsmos-dir", "X"], "--dnsmos-dir: given without dnsmos"),
    (["--metrics", "si_snr,loudness"], "got 'loudness'"),
    (["--metrics", "wer", "--asr-model", "{tmp}/nowhere"],
     "--asr-model {tmp}/nowhere: no such file or folder"),
    (["--metrics", "wer", "--asr-model", "{tmp}/empty"],
     "--asr-model {tmp}/empty: missing model.bin, config.json"),
    (["--metrics", "wer", "--asr-model", "{tmp}/model.txt"],
     "--asr-model {tmp}/model.txt: expected a faster-whisper model folder or an "
     "openai-whisper checkpoint (.pt), got a .txt file"),
    (["--metrics", "dnsmos", "--dnsmos-dir", "{tmp}/nowhere"],
     "--dnsmos-dir {tmp}/nowhere: no such folder"),
    (["--metrics", "dnsmos", "--dnsmos-dir", "{tmp}/empty"],
     "--dnsmos-dir {tmp}/empty: missing sig_bak_ovr.onnx, model_v8.onnx"),
    (["--metrics", "dnsmos", "--dnsmos-dir", "{tmp}/zero"],
     "--dnsmos-dir {tmp}/zero: model_v8.onnx is empty"),
    (["--metrics", "dnsmos", "--dnsmos-dir", "{tmp}/junk"],
     "{tmp}/junk/sig_bak_ovr.onnx: not a loadable ONNX model"),
])
def test_cli_names_missing_and_invalid_models(tmp_path: Path, capsys, extra: list[str],
                                              message: str) -> None:
    root, est = tmp_path / "set", tmp_path / "est"
    _plain_set(root, est, n=1)
    (tmp_path / "empty").mkdir()
    (tmp_path / "model.txt").write_text("not a model")
    (tmp_path / "zero").mkdir()
    (tmp_path / "zero" / "sig_bak_ovr.onnx").write_bytes(b"x")
    (tmp_path / "zero" / "model_v8.onnx").write_bytes(b"")
    (tmp_path / "junk").mkdir()
    for name in ("sig_bak_ovr.onnx", "model_v8.onnx"):
        (tmp_path / "junk" / name).write_bytes(b"not an onnx file at all")
    if "junk" in message:
        pytest.importorskip("onnxruntime", reason="onnxruntime is not installed")
    argv = ["evaluate", str(root), "--split", "test", "--task", "enhancement", "--estimates",
            str(est), "-o", str(tmp_path / "out"),
            *(a.replace("{tmp}", str(tmp_path)) for a in extra)]
    code, err = _cli(argv, capsys)
    assert code != 0
    assert message.replace("{tmp}", str(tmp_path)) in err, err


def test_cli_names_a_model_folder_the_transcriber_cannot_load(tmp_path: Path, capsys) -> None:
    import importlib.util

    root, est = tmp_path / "set", tmp_path / "est"
    _plain_set(root, est, n=1)
    model = tmp_path / "fw"
    model.mkdir()
    (model / "model.bin").write_bytes(b"junk")
    (model / "config.json").write_text("{}")
    code, err = _cli(["evaluate", str(root), "--split", "test", "--task", "enhancement",
                      "--estimates", str(est), "--metrics", "wer", "--asr-model", str(model),
                      "-o", str(tmp_path / "out")], capsys)
    assert code != 0
    if importlib.util.find_spec("faster_whisper") is None:
        assert (f"the faster_whisper package is needed for --asr-model {model} (a "
                "faster-whisper model folder); pip install 'sonicspec[asr]'") in err, err
    else:
        assert f"--asr-model {model}: faster-whisper cannot load it" in err, err


def test_cli_dnsmos_summary_states_the_model_files_and_checksums(tmp_path: Path,
                                                                  capsys) -> None:
    pytest.importorskip("onnxruntime", reason="onnxruntime is not installed (sonicspec[mos])")
    from sonicspec.hashing import file_sha256

    root, est = tmp_path / "set", tmp_path / "est"
    _plain_set(root, est, n=2)
    _tiny_dnsmos(tmp_path / "m")
    code, err = _cli(["evaluate", str(root), "--split", "test", "--task", "enhancement",
                      "--estimates", str(est), "--metrics", "si_snr,dnsmos", "--dnsmos-dir",
                      str(tmp_path / "m"), "-o", str(tmp_path / "out")], capsys)
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    files = summary["settings"]["model_files"]["dnsmos"]["files"]
    assert [f["sha256"] for f in files] == [file_sha256(tmp_path / "m" / n) for n in
                                            ("sig_bak_ovr.onnx", "model_v8.onnx")]
    assert summary["settings"]["metrics"] == ["si_snr", "dnsmos_sig", "dnsmos_bak",
                                              "dnsmos_ovrl", "dnsmos_p808"]
    means = summary["per_method"]["estimates"]
    assert all(isinstance(means[k], float) for k in summary["settings"]["metrics"])
    header = (tmp_path / "out" / "scores.csv").read_text().splitlines()[0]
    assert "dnsmos_p808" in header


def test_cli_model_metrics_in_a_cross_set_table(tmp_path: Path, capsys) -> None:
    pytest.importorskip("onnxruntime", reason="onnxruntime is not installed (sonicspec[mos])")
    sets, models = tmp_path / "sets", tmp_path / "models"
    for name in ("a", "b"):
        _plain_set(sets / name, models / "m1" / name, n=1)
    _tiny_dnsmos(tmp_path / "m")
    code, err = _cli(["evaluate", "--estimates-root", str(models), "--sets",
                      f"a={sets / 'a'},b={sets / 'b'}", "--split", "test", "--task",
                      "enhancement", "--metrics", "si_snr", "dnsmos", "--dnsmos-dir",
                      str(tmp_path / "m"), "-o", str(tmp_path / "out")], capsys)
    assert code == 0, err
    table = json.loads((tmp_path / "out" / "table.json").read_text())
    assert table["settings"]["model_files"]["dnsmos"]["files"][0]["path"].endswith(
        "sig_bak_ovr.onnx")
    head = (tmp_path / "out" / "table.md").read_text()
    assert "a OVRL" in head and "b P808" in head, head


def test_transcriber_hears_16_khz_float32() -> None:
    from sonicspec.dataload.asr import Transcriber

    heard = []
    t = Transcriber("probe", lambda x: heard.append(x) or "ok")
    t_8k = np.sin(2 * np.pi * 440 * np.arange(8000) / 8000)
    assert t(t_8k, 8000) == "ok"
    x = heard[0]
    assert x.dtype == np.float32 and len(x) == 16000
    spectrum = np.abs(np.fft.rfft(x))
    assert abs(int(np.argmax(spectrum)) - 440) <= 1  # 1 Hz bins: still a 440 Hz tone


def test_the_table_bolds_the_lowest_wer() -> None:
    from sonicspec.dataload.tables import markdown

    cells = {"A": {"s": {"wer": 0.30, "si_snr": 9.0}}, "B": {"s": {"wer": 0.10, "si_snr": 8.0}}}
    table = {"settings": {"models": ["A", "B"], "metrics": ["si_snr", "wer"], "task":
                          "enhancement", "sets": [{"name": "s"}]},
             "rows": ["A", "B"], "cells": cells, "missing": []}
    lines = markdown(table).splitlines()
    assert lines[2].startswith("| A | **9.00** | 0.300 |"), lines
    assert lines[3].startswith("| B | 8.00 | **0.100** |"), lines
