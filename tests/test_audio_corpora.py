"""Corpus readers on tiny corpora in the real layouts, resampling and loading.

The corpora are written by sonicspec.audio.generated and sonicspec.testing.corpora (espeak-ng
speech, synthesised noise and music) into temporary folders; the tests then break them the way
real corpora break.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.audio import generated as gen
from sonicspec.audio.corpora import (
    CorpusIndex,
    CorpusItem,
    _ratio_counts,
    cached_index,
    index_fma,
    index_folder,
    index_fsd50k,
    index_librispeech,
    index_split_folders,
    load_audio,
    resample,
)
from sonicspec.errors import AudioError, CorpusError
from sonicspec.testing import corpora as tc

RATIOS = {"train": 0.7, "val": 0.2, "test": 0.1}
LS_SUBSETS = {"train": ["train-clean-360"], "val": ["dev-clean"], "test": ["test-clean"]}
NO_SPEECH = ["Speech", "Human_voice", "Singing", "Music"]

needs_espeak = pytest.mark.skipif(not gen.espeak_available(), reason="espeak-ng not installed")
needs_mp3 = pytest.mark.skipif(not tc.mp3_writable(), reason="libsndfile cannot write MP3")


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    (dst / gen.MARKER).unlink(missing_ok=True)
    return dst


@pytest.fixture(scope="module")
def librispeech(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not gen.espeak_available():
        pytest.skip("espeak-ng not installed")
    root = tmp_path_factory.mktemp("corpora") / "LibriSpeech"
    return gen.write_librispeech(root, {"train-clean-360": 3, "dev-clean": 2, "test-clean": 2},
                                3, seed=0)


@pytest.fixture(scope="module")
def fsd50k(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("corpora") / "FSD50K"
    return tc.write_fsd50k(root, dev_clips=60, eval_clips=20, clip_duration_s=0.3, seed=0)


@pytest.fixture(scope="module")
def fma(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not tc.mp3_writable():
        pytest.skip("libsndfile cannot write MP3")
    root = tmp_path_factory.mktemp("corpora") / "fma"
    return tc.write_fma(root, 16, clip_duration_s=1.0, seed=0)


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("corpora") / "folder"
    return tc.write_folder(root, speakers=10, files_per_speaker=2, seed=0)


def split_sizes(index: CorpusIndex) -> dict[str, int]:
    return {name: len(index.split(name)) for name in ("train", "val", "test")}


# --------------------------------------------------------------------------------------------
# LibriSpeech


@needs_espeak
def test_librispeech_index_reads_layout_and_transcripts(librispeech: Path) -> None:
    index = index_librispeech(librispeech, LS_SUBSETS)
    assert index.kind == "librispeech" and index.problems == ()
    assert split_sizes(index) == {"train": 9, "val": 6, "test": 6}
    assert [len(index.speakers(s)) for s in ("train", "val", "test")] == [3, 2, 2]
    sentences = {gen.transcript_words(s) for s in gen.SENTENCES}
    for item in index.items:
        path = Path(item.path)
        assert path.is_absolute() and path.is_file()
        assert re.fullmatch(rf"{item.speaker}-\d+-\d{{4}}", item.id)
        assert path.parts[-3:] == (item.speaker, item.id.split("-")[1], item.id + ".flac")
        assert item.text in sentences and item.text == item.text.upper()
        info = sf.info(item.path)
        assert (item.num_samples, item.sample_rate_hz) == (info.frames, 16000)
        assert 1.0 < item.duration_s < 6.0
        trans = path.parent / f"{item.speaker}-{path.parent.name}.trans.txt"
        assert f"{item.id} {item.text}\n" in trans.read_text()
    assert list(index.items) == sorted(index.items, key=lambda it: (it.split, it.id))
    speakers = [set(index.speakers(s)) for s in ("train", "val", "test")]
    assert not (speakers[0] & speakers[1] or speakers[0] & speakers[2]
                or speakers[1] & speakers[2])


@needs_espeak
def test_librispeech_speech_is_audible_and_voices_differ(librispeech: Path) -> None:
    index = index_librispeech(librispeech, LS_SUBSETS)
    pitches = []
    for items in index.speakers("train").values():
        x = load_audio(items[0], 16000)
        assert 0.25 < np.max(np.abs(x)) < 0.75  # the per-speaker level, no clipping
        spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size)))
        f = np.fft.rfftfreq(x.size, 1 / 16000)
        band = (f > 60) & (f < 400)
        pitches.append(f[band][np.argmax(spectrum[band])])
    assert len(set(np.round(pitches))) == len(pitches)


@needs_espeak
def test_librispeech_corrupt_file_and_missing_transcripts_are_reported(
        librispeech: Path, tmp_path: Path) -> None:
    root = copy(librispeech, tmp_path / "ls")
    chapters = sorted(p for p in (root / "train-clean-360").glob("*/*") if p.is_dir())
    corrupt = sorted(chapters[0].glob("*.flac"))[0]
    corrupt.write_bytes(b"fLaC" + bytes(range(256)) * 8)
    missing_trans = next(chapters[1].glob("*.trans.txt"))
    missing_trans.unlink()
    trans = next(chapters[2].glob("*.trans.txt"))
    lines = trans.read_text().splitlines(keepends=True)
    trans.write_text("".join(lines[1:]))
    dropped_line = lines[0].split()[0]
    extra = chapters[2] / "gone.flac"  # listed in no transcript and not audio at all
    assert not extra.exists()
    index = index_librispeech(root, LS_SUBSETS)
    assert split_sizes(index) == {"train": 9 - 1 - 3 - 1, "val": 6, "test": 6}
    ids = {item.id for item in index.items}
    assert corrupt.stem not in ids and dropped_line not in ids
    assert not any(Path(item.path).parent == chapters[1] for item in index.items)
    text = "\n".join(index.problems)
    assert f"{corrupt}: unreadable audio" in text
    assert f"{missing_trans}: transcript file missing; skipped the 3 utterances" in text
    assert f"{chapters[2] / (dropped_line + '.flac')}: utterance {dropped_line} missing from " \
           f"its transcript {trans}" in text
    assert len(index.problems) == 3


@needs_espeak
def test_librispeech_transcript_line_without_audio_is_reported(librispeech: Path,
                                                               tmp_path: Path) -> None:
    root = copy(librispeech, tmp_path / "ls")
    flac = sorted((root / "dev-clean").glob("*/*/*.flac"))[0]
    flac.unlink()
    index = index_librispeech(root, LS_SUBSETS)
    assert len(index.split("val")) == 5
    assert any(f"lists {flac.stem} but {flac} does not exist" in p for p in index.problems)


@needs_espeak
def test_librispeech_errors(librispeech: Path, tmp_path: Path) -> None:
    with pytest.raises(CorpusError, match=r"LibriSpeech root: expected a folder at .*nowhere"):
        index_librispeech(tmp_path / "nowhere", LS_SUBSETS)
    with pytest.raises(CorpusError, match=r"subset 'test-other': expected a folder at"):
        index_librispeech(librispeech, {"train": ["train-clean-360"], "test": ["test-other"]})
    with pytest.raises(CorpusError, match=r"subset 'dev-clean': expected in one split, got in "
                                          r"'val' and 'test'"):
        index_librispeech(librispeech, {"val": ["dev-clean"], "test": ["dev-clean"]})
    with pytest.raises(CorpusError, match=r"split 'val': expected at least one subset"):
        index_librispeech(librispeech, {"train": ["train-clean-360"], "val": []})
    # A speaker present in the subsets of two splits.
    root = copy(librispeech, tmp_path / "ls")
    speaker = sorted((root / "train-clean-360").iterdir())[0]
    shutil.copytree(speaker, root / "dev-clean" / speaker.name)
    with pytest.raises(CorpusError, match=rf"speaker {speaker.name} .*: expected in the subsets "
                                          r"of one split, got in 'val' and 'train'"):
        index_librispeech(root, LS_SUBSETS)
    # A split whose every chapter lost its transcript.
    root = copy(librispeech, tmp_path / "ls2")
    for trans in (root / "test-clean").glob("*/*/*.trans.txt"):
        trans.unlink()
    with pytest.raises(CorpusError, match=r"LibriSpeech: split 'test' has no usable files; "
                                          r"skipped files: .*transcript file missing"):
        index_librispeech(root, LS_SUBSETS)


@needs_espeak
def test_require_speakers_and_items(librispeech: Path) -> None:
    index = index_librispeech(librispeech, LS_SUBSETS)
    index.require_speakers("val", 2, "mixture.speakers")
    with pytest.raises(CorpusError, match=r"^mixture.speakers: split 'val' has 2 speakers, the "
                                          r"mixture needs 3; add speakers"):
        index.require_speakers("val", 3, "mixture.speakers")
    with pytest.raises(CorpusError, match=r"split 'dev' has 0 speakers, the mixture needs 1"):
        index.require_speakers("dev", 1, "mixture.speakers")
    index.require_items("test", 6, "corpora.speech")
    with pytest.raises(CorpusError, match=r"^corpora.speech: split 'test' has 6 usable files, "
                                          r"7 are needed"):
        index.require_items("test", 7, "corpora.speech")


def test_require_hint_names_a_skipped_file() -> None:
    index = CorpusIndex("folder", (), ("/data/a.wav: unreadable audio (bad); skipped",))
    with pytest.raises(CorpusError, match=r"has 0 usable files, 1 are needed; .*\(1 files were "
                                          r"skipped, e.g. /data/a.wav: unreadable"):
        index.require_items("train", 1, "corpora.noise")


# --------------------------------------------------------------------------------------------
# FSD50K


def test_fsd50k_index_filters_labels_and_splits_7_2_1(fsd50k: Path) -> None:
    index = index_fsd50k(fsd50k, RATIOS, NO_SPEECH, rng(0))
    assert index.kind == "fsd50k" and index.problems == ()
    listed = {}
    for part in ("dev", "eval"):
        lines = (fsd50k / "FSD50K.ground_truth" / f"{part}.csv").read_text().splitlines()[1:]
        for line in lines:
            fname, labels = re.match(r'(\d+),("[^"]*"|[^,]*)', line).groups()
            listed[fname] = (part, tuple(labels.strip('"').split(",")))
    kept = {f for f, (_, labels) in listed.items() if not set(labels) & set(NO_SPEECH)}
    assert 0 < len(kept) < len(listed)  # the fixture holds speech and music clips to drop
    assert {item.id for item in index.items} == kept
    assert {listed[i.id][0] for i in index.items} == {"dev", "eval"}
    for item in index.items:
        assert item.labels == listed[item.id][1] and item.speaker == ""
        folder = "FSD50K.dev_audio" if listed[item.id][0] == "dev" else "FSD50K.eval_audio"
        assert item.path == str((fsd50k / folder / f"{item.id}.wav").resolve())
        assert (item.num_samples, item.sample_rate_hz) == (round(0.3 * 44100), 44100)
    n = len(index.items)
    sizes = split_sizes(index)
    assert sizes == _ratio_counts(n, RATIOS)
    for name, share in RATIOS.items():
        assert abs(sizes[name] - share * n) <= 1


def test_fsd50k_split_is_deterministic_for_the_seed(fsd50k: Path) -> None:
    a = index_fsd50k(fsd50k, RATIOS, NO_SPEECH, rng(7))
    b = index_fsd50k(fsd50k, dict(reversed(RATIOS.items())), NO_SPEECH, rng(7))
    c = index_fsd50k(fsd50k, RATIOS, NO_SPEECH, rng(8))
    assert a == b
    assert {i.id: i.split for i in a.items} != {i.id: i.split for i in c.items}
    assert split_sizes(a) == split_sizes(c)


def test_fsd50k_broken_and_missing_clips_are_reported(fsd50k: Path, tmp_path: Path) -> None:
    root = copy(fsd50k, tmp_path / "fsd")
    clean = index_fsd50k(root, RATIOS, NO_SPEECH, rng(0))
    broken, gone = clean.items[0], clean.items[1]
    Path(broken.path.replace(str(fsd50k.resolve()), str(root.resolve()))).write_bytes(
        b"RIFF" + bytes(100))
    Path(gone.path.replace(str(fsd50k.resolve()), str(root.resolve()))).unlink()
    index = index_fsd50k(root, RATIOS, NO_SPEECH, rng(0))
    assert {i.id for i in index.items} == {i.id for i in clean.items} - {broken.id, gone.id}
    # The split is drawn before files are opened: a broken file moves no other clip.
    before = {i.id: i.split for i in clean.items}
    assert all(before[i.id] == i.split for i in index.items)
    text = "\n".join(index.problems)
    assert f"{broken.id}.wav: unreadable audio" in text
    assert f"{gone.id}.wav: listed in the ground truth but missing; skipped" in text


def test_fsd50k_errors(fsd50k: Path, tmp_path: Path) -> None:
    with pytest.raises(CorpusError, match=r"FSD50K root: expected a folder at"):
        index_fsd50k(tmp_path / "none", RATIOS, NO_SPEECH, rng())
    with pytest.raises(CorpusError, match=r"FSD50K split_ratios: expected shares summing to 1, "
                                          r"got 0.9"):
        index_fsd50k(fsd50k, {"train": 0.7, "val": 0.2}, NO_SPEECH, rng())
    with pytest.raises(CorpusError, match=r"expected shares >= 0, got val: -0.1"):
        index_fsd50k(fsd50k, {"train": 1.1, "val": -0.1}, NO_SPEECH, rng())
    root = copy(fsd50k, tmp_path / "fsd")
    gt = root / "FSD50K.ground_truth" / "eval.csv"
    gt.unlink()
    with pytest.raises(CorpusError, match=rf"FSD50K eval ground truth: expected the file "
                                          rf"{re.escape(str(gt))}, got nothing there"):
        index_fsd50k(root, RATIOS, NO_SPEECH, rng())
    gt.write_text("name,tags\n1,Rain\n")
    with pytest.raises(CorpusError, match=r"eval.csv: expected columns fname, labels, got "
                                          r"name, tags"):
        index_fsd50k(root, RATIOS, NO_SPEECH, rng())
    gt.write_text("fname,labels,mids\n")
    for wav in (root / "FSD50K.dev_audio").glob("*.wav"):
        wav.write_bytes(b"not audio")
    with pytest.raises(CorpusError, match=r"FSD50K: split '\w+' has no usable files; skipped "
                                          r"files: .*unreadable audio"):
        index_fsd50k(root, RATIOS, NO_SPEECH, rng())


# --------------------------------------------------------------------------------------------
# FMA


@needs_mp3
def test_fma_index_reads_multilevel_header_and_keeps_instrumental(fma: Path) -> None:
    every = index_fma(fma, "small", RATIOS, False, rng(0))
    assert every.kind == "fma" and every.problems == ()
    mp3s = sorted((fma / "fma_small").glob("*/*.mp3"))
    assert len(every.items) == len(mp3s) == 16
    assert {i.id for i in every.items} == {p.stem for p in mp3s}
    index = index_fma(fma, "small", RATIOS, True, rng(0))
    assert 0 < len(index.items) < 16
    for item in index.items:
        assert "Instrumental" in item.labels
        assert re.fullmatch(r"\d{6}", item.id)
        assert Path(item.path).parent.name == f"{int(item.id) // 1000:03d}"
        assert (item.num_samples, item.sample_rate_hz) == (44100, 44100)
    # genre_top empty, Instrumental only in genres_all (FMA's tracks of several top genres)
    assert ("Instrumental", "Electronic") in {i.labels for i in index.items}
    assert ("Rock",) in {i.labels for i in every.items} - {i.labels for i in index.items}
    assert sum(split_sizes(index).values()) == len(index.items)
    assert all(n > 0 for n in split_sizes(index).values())


@needs_mp3
def test_fma_problems_and_errors(fma: Path, tmp_path: Path) -> None:
    root = copy(fma, tmp_path / "fma")
    clean = index_fma(root, "small", RATIOS, False, rng(0))
    broken = Path(clean.items[0].path)
    broken.write_bytes(bytes(range(256)) * 4)
    stray = root / "fma_small" / "099" / "099999.mp3"
    stray.parent.mkdir(exist_ok=True)
    shutil.copy(clean.items[1].path, stray)
    odd = root / "fma_small" / "099" / "cover.mp3"
    shutil.copy(clean.items[1].path, odd)
    index = index_fma(root, "small", RATIOS, False, rng(0))
    assert len(index.items) == 15
    text = "\n".join(index.problems)
    assert f"{broken}: unreadable audio" in text
    assert f"{stray}: track 99999 is not in {root / 'fma_metadata' / 'tracks.csv'}" in text
    assert f"{odd}: expected an FMA file name <track id>.mp3; skipped" in text
    with pytest.raises(CorpusError, match=r"FMA size: expected one of small, medium, large, "
                                          r"full, got 'tiny'"):
        index_fma(root, "tiny", RATIOS, True, rng())
    with pytest.raises(CorpusError, match=r"FMA audio \(fma_medium\): expected a folder at"):
        index_fma(root, "medium", RATIOS, True, rng())
    tracks = root / "fma_metadata" / "tracks.csv"
    text = tracks.read_text()
    tracks.write_text("\n".join(text.splitlines()[1:]))  # one header row short
    with pytest.raises(CorpusError, match=r"tracks.csv: expected FMA's three header rows"):
        index_fma(root, "small", RATIOS, True, rng())
    tracks.write_text(text.replace("genres_all", "genres_every"))
    with pytest.raises(CorpusError, match=r"tracks.csv: expected the columns track/genre_top "
                                          r"and track/genres_all"):
        index_fma(root, "small", RATIOS, True, rng())
    tracks.unlink()
    with pytest.raises(CorpusError, match=rf"FMA track metadata: expected the file "
                                          rf"{re.escape(str(tracks))}"):
        index_fma(root, "small", RATIOS, True, rng())


@needs_mp3
def test_load_audio_mp3_stereo_is_averaged_and_resampled(fma: Path) -> None:
    item = index_fma(fma, "small", RATIOS, False, rng(0)).items[0]
    stereo, rate = sf.read(item.path, always_2d=True)
    assert stereo.shape[1] == 2 and rate == 44100
    x = load_audio(item, 16000)
    assert x.dtype == np.float64 and x.ndim == 1 and x.size == 16000
    np.testing.assert_allclose(x, resample(stereo.mean(axis=1), 44100, 16000), atol=1e-12)


# --------------------------------------------------------------------------------------------
# Plain folders


def test_folder_by_speaker_keeps_speakers_in_one_split(folder: Path) -> None:
    index = index_folder(folder, [".wav", "FLAC"], RATIOS, rng(3), by_speaker=True)
    assert index.kind == "folder" and index.problems == ()
    assert len(index.items) == 20
    assert {i.id for i in index.items} == {
        p.relative_to(folder).with_suffix("").as_posix() for p in folder.glob("spk*/*")}
    assert {len(index.speakers(s)) for s in ("train", "val", "test")} <= {7, 2, 1}
    assert [len(index.speakers(s)) for s in ("train", "val", "test")] == [7, 2, 1]
    split_of: dict[str, str] = {}
    for item in index.items:
        assert split_of.setdefault(item.speaker, item.split) == item.split
        assert item.id.startswith(item.speaker + "/")
    assert {i.sample_rate_hz for i in index.items} == {16000, 22050, 48000}
    assert index == index_folder(folder, [".flac", ".wav"], RATIOS, rng(3), by_speaker=True)
    only_wav = index_folder(folder, [".wav"], {"train": 1.0}, rng(3), by_speaker=True)
    assert {Path(i.path).suffix for i in only_wav.items} == {".wav"}


def test_folder_without_speakers_splits_files(folder: Path, tmp_path: Path) -> None:
    index = index_folder(folder, [".wav", ".flac"], RATIOS, rng(0), by_speaker=False)
    assert split_sizes(index) == {"train": 14, "val": 4, "test": 2}
    assert {i.speaker for i in index.items} == {""}
    root = copy(folder, tmp_path / "f")
    shutil.copy(next(root.glob("spk01/*.wav")), root / "loose.wav")
    (root / ".hidden.tmp.wav").write_bytes(b"half a file")
    with_speakers = index_folder(root, [".wav", ".flac"], RATIOS, rng(0), by_speaker=True)
    assert with_speakers.problems == (f"{root / 'loose.wav'}: not inside a speaker folder; "
                                      "skipped",)
    flat = index_folder(root, [".wav", ".flac"], RATIOS, rng(0), by_speaker=False)
    assert "loose" in {i.id for i in flat.items} and len(flat.items) == 21
    with pytest.raises(CorpusError, match=r"folder corpus extensions: expected at least one"):
        index_folder(root, [], RATIOS, rng(), by_speaker=True)
    with pytest.raises(CorpusError, match=r"folder corpus .*: split '\w+' has no usable files"):
        index_folder(root, [".ogg"], RATIOS, rng(), by_speaker=False)


def test_ratio_counts_round_by_largest_remainder() -> None:
    assert _ratio_counts(1000, RATIOS) == {"train": 700, "val": 200, "test": 100}
    assert _ratio_counts(15, RATIOS) == {"train": 11, "val": 3, "test": 1}  # 10.5, 3, 1.5
    assert _ratio_counts(3, RATIOS) == {"train": 1, "val": 1, "test": 1}
    assert _ratio_counts(5, RATIOS) == {"train": 3, "val": 1, "test": 1}
    assert _ratio_counts(2, RATIOS) == {"train": 1, "val": 1, "test": 0}
    assert _ratio_counts(0, RATIOS) == {"train": 0, "val": 0, "test": 0}
    for n in range(1, 60):
        assert sum(_ratio_counts(n, RATIOS).values()) == n


# --------------------------------------------------------------------------------------------
# Index objects and the cache


def item(uid: str, split: str = "train", **kw: object) -> CorpusItem:
    return CorpusItem(id=uid, path=f"/c/{uid}.flac", split=split, speaker=kw.pop("speaker", "s"),
                      num_samples=32000, sample_rate_hz=16000, **kw)


def test_index_sorts_round_trips_and_rejects_duplicate_ids() -> None:
    index = CorpusIndex("librispeech", (item("b", "val"), item("c", text="HI"),
                                        item("a", "val", labels=("x", "y"))), ["p"])
    assert [(i.split, i.id) for i in index.items] == [("train", "c"), ("val", "a"),
                                                      ("val", "b")]
    assert index.problems == ("p",) and index.splits == ["train", "val"]
    assert index.items[0].duration_s == 2.0
    assert CorpusIndex.from_dict(json.loads(json.dumps(index.to_dict()))) == index
    assert CorpusItem.from_dict(index.items[1].to_dict()).labels == ("x", "y")
    with pytest.raises(CorpusError, match=r"fma corpus: expected unique item ids, got 'a' more"):
        CorpusIndex("fma", (item("a"), item("a", "val")))
    with pytest.raises(CorpusError, match=r"corpus index: expected format 2, got 0"):
        CorpusIndex.from_dict({**index.to_dict(), "format": 0})


def test_cached_index_builds_once_and_rebuilds_a_corrupt_cache(tmp_path: Path) -> None:
    calls: list[int] = []
    index = CorpusIndex("folder", (item("a"), item("b", "test")), ("skipped x",))

    def build() -> CorpusIndex:
        calls.append(1)
        return index

    cache = tmp_path / "cache" / "speech-index.json"
    assert cached_index(cache, build) == index and len(calls) == 1
    assert cached_index(cache, build) == index and len(calls) == 1
    cache.write_text('{"format": 1, "kind": "folder", "items": [{"id": ')  # torn write
    assert cached_index(cache, build) == index and len(calls) == 2
    assert CorpusIndex.from_dict(json.loads(cache.read_text())) == index
    cache.write_text(json.dumps({**index.to_dict(), "format": 99}))
    assert cached_index(cache, build) == index and len(calls) == 3
    assert os.listdir(cache.parent) == ["speech-index.json"]  # no temporaries left

    def failing() -> CorpusIndex:
        raise CorpusError("corpus gone")

    cache.unlink()
    with pytest.raises(CorpusError, match="corpus gone"):
        cached_index(cache, failing)
    assert not cache.exists()


# --------------------------------------------------------------------------------------------
# Resampling and loading


def tone(freq: float, rate: int, seconds: float = 1.0) -> np.ndarray:
    return np.sin(2 * np.pi * freq * np.arange(round(seconds * rate)) / rate)


def fit_tone(x: np.ndarray, freq: float, rate: int) -> tuple[float, float]:
    """(amplitude of the best-fitting sinusoid at ``freq``, RMS of what is left), in the
    middle of ``x`` (away from the filter's edge transients)."""
    t = np.arange(x.size) / rate
    mid = slice(x.size // 5, -x.size // 5)
    basis = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t)], axis=1)[mid]
    coef, *_ = np.linalg.lstsq(basis, x[mid], rcond=None)
    residual = x[mid] - basis @ coef
    return float(np.hypot(*coef)), float(np.sqrt(np.mean(residual**2)))


def test_resample_keeps_a_1khz_tone_and_suppresses_aliasing() -> None:
    y = resample(tone(1000, 44100), 44100, 16000)
    assert y.size == 16000
    amplitude, residual = fit_tone(y, 1000, 16000)
    assert abs(20 * np.log10(amplitude)) < 0.1
    assert residual < 1e-3  # the frequency is kept: nothing but the 1 kHz tone remains
    # 10 kHz lies above the new Nyquist (8 kHz) and would alias to 6 kHz.
    alias = resample(tone(10000, 44100), 44100, 16000)
    mid = alias[alias.size // 5: -alias.size // 5]
    assert 20 * np.log10(np.sqrt(2 * np.mean(mid**2))) < -60
    # 7 kHz (inside the 0.9 × Nyquist passband) passes.
    amplitude, _ = fit_tone(resample(tone(7000, 44100), 44100, 16000), 7000, 16000)
    assert abs(20 * np.log10(amplitude)) < 0.1


def test_resample_up_and_along_the_last_axis() -> None:
    x = np.stack([tone(440, 16000), 0.5 * tone(2000, 16000)])
    y = resample(x, 16000, 44100)
    assert y.shape == (2, 44100)
    np.testing.assert_allclose(y[1], resample(x[1], 16000, 44100), atol=1e-12)
    amplitude, residual = fit_tone(y[0], 440, 44100)
    assert abs(20 * np.log10(amplitude)) < 0.1 and residual < 1e-3
    same = resample(x, 16000, 16000)
    assert same is not x and np.array_equal(same, x)
    assert resample(np.zeros(7), 48000, 16000).shape == (3,)
    with pytest.raises(AudioError, match=r"resample to_hz: expected a positive whole number "
                                         r"of Hz, got 0"):
        resample(x, 16000, 0)
    with pytest.raises(AudioError, match=r"resample from_hz: .* got 22050.5"):
        resample(x, 22050.5, 16000)


def test_load_audio_averages_channels_and_resamples(tmp_path: Path) -> None:
    left = 0.5 * tone(500, 48000)
    right = -0.25 * tone(500, 48000)
    path = tmp_path / "stereo.wav"
    sf.write(path, np.stack([left, right], axis=1), 48000, subtype="FLOAT")
    x = load_audio(path, 16000)
    assert x.shape == (16000,)
    amplitude, residual = fit_tone(x, 500, 16000)
    assert abs(amplitude - 0.125) < 1e-4 and residual < 1e-4
    np.testing.assert_allclose(load_audio(str(path), 48000), (left + right) / 2, atol=1e-7)
    bad = tmp_path / "bad.flac"
    bad.write_bytes(b"fLaC" + bytes(64))
    with pytest.raises(CorpusError, match=rf"{re.escape(str(bad))}: expected a readable audio "
                                          r"file"):
        load_audio(bad, 16000)
    with pytest.raises(CorpusError, match=r"/c/missing.flac: expected a readable audio file"):
        load_audio(item("missing"), 16000)


# --------------------------------------------------------------------------------------------
# The writers


def file_bytes(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != gen.MARKER}


def test_writers_are_deterministic_and_atomic(tmp_path: Path) -> None:
    a = tc.write_fsd50k(tmp_path / "a", 4, 2, clip_duration_s=0.2, seed=5)
    b = tc.write_fsd50k(tmp_path / "b", 4, 2, clip_duration_s=0.2, seed=5)
    c = tc.write_fsd50k(tmp_path / "c", 4, 2, clip_duration_s=0.2, seed=6)
    assert file_bytes(a) == file_bytes(b) != file_bytes(c)
    assert not [p for p in a.rglob(".*") if p.name != gen.MARKER]  # no temporaries left
    marker = json.loads((a / gen.MARKER).read_text())
    assert sorted(marker["files"]) == sorted(file_bytes(a))
    # A finished root is not written again ...
    wav = next((a / "FSD50K.dev_audio").glob("*.wav"))
    wav.write_bytes(b"edited")
    tc.write_fsd50k(a, 4, 2, clip_duration_s=0.2, seed=5)
    assert wav.read_bytes() == b"edited"
    # ... an unfinished one (no marker: interrupted) is, with the same bytes ...
    (a / gen.MARKER).unlink()
    tc.write_fsd50k(a, 4, 2, clip_duration_s=0.2, seed=5)
    assert file_bytes(a) == file_bytes(b)
    # ... and other parameters replace the files the old run wrote.
    tc.write_fsd50k(a, 2, 1, clip_duration_s=0.2, seed=6)
    assert len(list((a / "FSD50K.dev_audio").glob("*.wav"))) == 2
    assert len(list((a / "FSD50K.eval_audio").glob("*.wav"))) == 1


def test_interrupted_generation_leaves_no_half_file_and_no_marker(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real_write = sf.write
    calls: list[str] = []

    def write_then_die(path: str, *args: object, **kw: object) -> None:
        calls.append(path)
        real_write(path, *args, **kw)
        if len(calls) == 3:
            raise KeyboardInterrupt  # killed after writing the third file's temporary

    monkeypatch.setattr(tc.sf, "write", write_then_die)
    root = tmp_path / "fsd"
    with pytest.raises(KeyboardInterrupt):
        tc.write_fsd50k(root, 4, 2, clip_duration_s=0.2, seed=5)
    monkeypatch.undo()
    assert not (root / gen.MARKER).exists()
    assert not [p for p in root.rglob(".*")]  # the temporary was removed
    assert len(list(root.rglob("*.wav"))) == 2  # two finished files, the third never renamed
    for wav in root.rglob("*.wav"):
        assert sf.info(wav).frames == round(0.2 * 44100)
    tc.write_fsd50k(root, 4, 2, clip_duration_s=0.2, seed=5)
    fresh = tc.write_fsd50k(tmp_path / "fresh", 4, 2, clip_duration_s=0.2, seed=5)
    assert file_bytes(root) == file_bytes(fresh)


@needs_espeak
def test_speech_and_music_writers_are_deterministic(tmp_path: Path) -> None:
    for name in ("a", "b"):
        gen.write_librispeech(tmp_path / name / "ls", {"dev-clean": 1}, 2, seed=3)
        if tc.mp3_writable():
            tc.write_fma(tmp_path / name / "fma", 2, clip_duration_s=0.5, seed=3)
    assert file_bytes(tmp_path / "a") == file_bytes(tmp_path / "b")


def test_writer_argument_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(CorpusError, match=r"dev_clips, eval_clips: expected >= 0 and not both"):
        tc.write_fsd50k(tmp_path, 0, 0)
    with pytest.raises(CorpusError, match=r"clip_duration_s: expected > 0, got 0"):
        tc.write_fsd50k(tmp_path, 1, 1, clip_duration_s=0)
    with pytest.raises(CorpusError, match=r"tracks: expected >= 1, got 0"):
        tc.write_fma(tmp_path, 0)
    with pytest.raises(CorpusError, match=r"role: expected noise or music, got 'speech'"):
        gen.generate_background_corpus(tmp_path, "speech", ["train"], 1, 1.0, seed=0)
    with pytest.raises(CorpusError, match=r"splits: expected distinct non-empty names"):
        gen.generate_background_corpus(tmp_path, "noise", ["train", "train"], 1, 1.0, seed=0)
    with pytest.raises(CorpusError, match=r"subsets: expected subset names with >= 1 speaker"):
        gen.write_librispeech(tmp_path, {"dev-clean": 0}, 2)
    monkeypatch.setattr(gen, "espeak_available", lambda: False)
    with pytest.raises(CorpusError, match=r"^espeak-ng not found; install it with apt-get "
                                          r"install espeak-ng$"):
        gen.generate_speech_corpus(tmp_path / "gen", ["train"], 1, 1, seed=0)
    assert not (tmp_path / "gen").exists()


@needs_espeak
def test_generated_speech_corpus_feeds_index_librispeech(tmp_path: Path) -> None:
    subsets = gen.generate_speech_corpus(tmp_path, ["train", "val", "test"], 2, 2, seed=4)
    assert subsets == {s: [f"generated-{s}"] for s in ("train", "val", "test")}
    index = index_librispeech(tmp_path, subsets)
    assert [len(index.speakers(s)) for s in ("train", "val", "test")] == [2, 2, 2]
    assert len(index.items) == 12 and index.problems == ()
    assert len({i.speaker for i in index.items}) == 6


def test_generated_background_corpus_feeds_index_split_folders(tmp_path: Path) -> None:
    splits = ["train", "val", "test"]
    for role in ("noise", "music"):
        ids = gen.generate_background_corpus(tmp_path / role, role, splits, 3, 0.5, seed=2)
        assert ids["val"] == ["val/" + role + f"-{i:04d}" for i in range(3)]
        index = index_split_folders(tmp_path / role, splits)
        assert {s: [i.id for i in index.split(s)] for s in splits} == ids
        for entry in index.items:
            assert (entry.num_samples, entry.sample_rate_hz) == (8000, 16000)
            x = load_audio(entry, 16000)
            assert 0.29 < np.max(np.abs(x)) < 0.81
    with pytest.raises(CorpusError, match=r"split 'dev': expected a folder at"):
        index_split_folders(tmp_path / "noise", ["train", "dev"])
