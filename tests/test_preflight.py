"""`validate` finds what a build would find: split shares, missing packages and tools, meshes
and corpora that cannot be read (issue 16, part 3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from build_cases import readme_spec
from spec_cases import BASE
from test_cli_spec import run_cli

from sonicspec.audio.generated import espeak_available
from sonicspec.cli import main
from sonicspec.errors import CorpusError, SonicspecError
from sonicspec.shares import split_shares
from sonicspec.spec import validate_file, validate_text
from sonicspec.spec.load import format_path
from sonicspec.stages import preflight as preflight_module
from sonicspec.stages.corpus import corpus_shares
from sonicspec.stages.preflight import preflight

# --- split shares: one rule for validate and the corpus stage ----------------------------


def test_default_shares_follow_the_spec_splits() -> None:
    """Issue 16: the 7:2:1 default with only train and test splits failed 52 s into a build."""
    assert split_shares(None, ["train", "test"]) == pytest.approx({"train": 0.875, "test": 0.125})
    assert split_shares(None, ["train", "val", "test"]) == pytest.approx(
        {"train": 0.7, "val": 0.2, "test": 0.1})
    assert split_shares(None, ["train"]) == {"train": 1.0}


def test_default_shares_need_known_split_names() -> None:
    with pytest.raises(SonicspecError, match=r"expected split names with a default share "
                       r"\(train, val, test\), got 'dev'; give the shares, e.g. split_ratios: "
                       r"\{train: 0.5, dev: 0.5\}"):
        split_shares(None, ["train", "dev"])


def test_shares_of_other_splits_are_ignored_and_the_rest_must_sum_to_one() -> None:
    assert split_shares({"train": 0.8, "test": 0.2, "val": 0.5}, ["train", "test"]) == {
        "test": 0.2, "train": 0.8}
    with pytest.raises(SonicspecError, match=r"expected shares summing to 1 over the splits "
                       r"train, test, got 0.8; write split_ratios: \{train: 0.875, test: 0.125\}"
                       r", or leave split_ratios out"):
        split_shares({"train": 0.7, "val": 0.2, "test": 0.1}, ["train", "test"])
    with pytest.raises(SonicspecError, match=r"expected a share for every split \(train, "
                       r"test\), got none for 'test'"):
        split_shares({"train": 1.0}, ["train", "test"])
    with pytest.raises(SonicspecError, match=r"expected shares >= 0, got test: -0.5"):
        split_shares({"train": 1.5, "test": -0.5}, ["train", "test"])
    with pytest.raises(SonicspecError, match=r"expected at least one split"):
        split_shares({"train": 1.0}, [])


def test_suggested_shares_sum_to_one() -> None:
    with pytest.raises(SonicspecError, match=r"\{a: 0.3334, b: 0.3333, c: 0.3333\}") as exc:
        split_shares({"a": 0.2, "b": 0.2, "c": 0.2}, ["a", "b", "c"])
    written = str(exc.value).split("{")[1].split("}")[0]
    assert sum(float(x.split(": ")[1]) for x in written.split(", ")) == pytest.approx(1, abs=1e-9)


def test_corpus_stage_names_the_field() -> None:
    with pytest.raises(CorpusError, match=r"corpora.noise.split_ratios: expected shares summing "
                       r"to 1 over the splits train, test, got 0.8"):
        corpus_shares({"train": 0.7, "val": 0.2, "test": 0.1}, ["train", "test"], "noise")


NOISE = "  noise: {kind: fsd50k, root: data/fsd, split_ratios: {train: 0.8, test: 0.2}}"


def _errors(text: str) -> list[tuple[str, int | None, str, str]]:
    _, problems = validate_text(text, "s.yaml")
    return [(format_path(p.path), p.line, p.severity, p.message) for p in problems]


def test_validate_accepts_default_shares_with_train_and_test_only() -> None:
    assert NOISE in BASE
    loaded, problems = validate_text(BASE.replace(NOISE, "  noise: {kind: fsd50k, root: "
                                                         "data/fsd}"), "s.yaml")
    assert loaded is not None, problems


def test_validate_rejects_what_the_corpus_stage_rejects() -> None:
    """The user's 0.7/0.2/0.1 with train and test splits: validate said yes, the build no."""
    text = BASE.replace("{train: 0.8, test: 0.2}", "{train: 0.7, val: 0.2, test: 0.1}")
    found = _errors(text)
    assert ("corpora.noise.split_ratios", 35, "error",
            "expected shares summing to 1 over the splits train, test, got 0.8; write "
            "split_ratios: {train: 0.875, test: 0.125}, or leave split_ratios out for "
            "SonicSet's 7:2:1 over these splits") in found
    assert ("corpora.noise.split_ratios.val", 35, "warning",
            "expected shares of the spec's splits (train, test), got one for 'val', which is "
            "not used") in found


def test_unused_share_warns_with_did_you_mean() -> None:
    text = BASE.replace("{train: 0.8, test: 0.2}", "{train: 0.8, tset: 0.2}")
    found = _errors(text)
    assert ("corpora.noise.split_ratios", 35, "error",
            "expected a share for every split (train, test), got none for 'test'") in found
    assert any(f[0] == "corpora.noise.split_ratios.tset" and f[2] == "warning"
               and f[3].endswith("did you mean 'test'?") for f in found), found


# --- preflight: files, corpora, packages and programs ------------------------------------

SPEC = """\
sonicspec: 1
name: pre
seed: 1
sample_rate_hz: 16000
scenes:
  - {kind: shoebox, id: room, size_m: [6, 5, 3]}
  - {kind: shoebox, id: hall, size_m: [8, 6, 3]}
microphone: {kind: mono}
corpora:
  speech: {kind: folder, root: data/speech}
  noise: {kind: folder, root: data/noise}
mixture: {duration_s: 20, speakers: 2}
splits:
  train: {groups: 2, scenes: [room]}
  test: {groups: 1, scenes: [hall]}
"""


def _wav(path: Path, seconds: float = 1.0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(len(str(path)))
    sf.write(str(path), 0.1 * rng.standard_normal(int(16000 * seconds)), 16000)


def _corpora(tmp_path: Path) -> None:
    for s in range(4):
        for u in range(2):
            _wav(tmp_path / "data" / "speech" / f"spk{s}" / f"u{u}.wav")
    for n in range(4):
        _wav(tmp_path / "data" / "noise" / f"n{n}.wav")


def _spec(tmp_path: Path, text: str = SPEC, corpora: bool = True) -> Path:
    if corpora:
        _corpora(tmp_path)
    path = tmp_path / "s.yaml"
    path.write_text(text)
    return path


def _preflight(path: Path) -> list[str]:
    loaded, problems = validate_file(path)
    assert loaded is not None, [p.format(str(path)) for p in problems]
    return [p.format("s.yaml") for p in preflight(loaded)]


def test_tiny_spec_with_default_shares_passes_check_files(tmp_path: Path) -> None:
    """A folder noise corpus, train and test splits, no split_ratios: the issue's user spec."""
    path = _spec(tmp_path)
    assert _preflight(path) == []
    assert main(["validate", "--check-files", "-q", str(path)]) == 0


@pytest.mark.parametrize("ext,data", [
    (".obj", b"this is not a mesh\n\x00\x01"),
    (".ply", b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n"),
    (".glb", b"glTF\x02\x00\x00\x00garbage"),
])
def test_corrupt_mesh_is_a_located_error(tmp_path: Path, ext: str, data: bytes) -> None:
    (tmp_path / f"scan{ext}").write_bytes(data)
    text = SPEC.replace("  - {kind: shoebox, id: hall, size_m: [8, 6, 3]}",
                        f"  - {{kind: mesh, id: hall, path: scan{ext}}}")
    found = _preflight(_spec(tmp_path, text))
    assert len(found) == 1, found
    assert found[0].startswith(f"s.yaml:7:34: scenes[1].path: {tmp_path}/scan{ext}: expected a ")
    assert "mesh" in found[0]


def test_corrupt_mesh_of_a_glob_and_an_obstacle_are_named(tmp_path: Path) -> None:
    from sonicspec.testing.meshes import write_plain_meshes

    write_plain_meshes(tmp_path / "scans", "good")
    (tmp_path / "scans" / "zbad.obj").write_bytes(b"not a mesh")
    (tmp_path / "chair.ply").write_bytes(b"ply\ngarbage")
    text = SPEC.replace(
        "  - {kind: shoebox, id: hall, size_m: [8, 6, 3]}",
        "  - {kind: mesh, id: hall, path: 'scans/*.obj'}\n"
        "  - {kind: shoebox, id: den, size_m: [5, 4, 3], obstacles: [{kind: mesh, path: "
        "chair.ply, position_m: [2, 2, 0]}]}")
    found = _preflight(_spec(tmp_path, text))
    assert len(found) == 2, found
    assert found[0].startswith(f"s.yaml:7:34: scenes[1].path: {tmp_path}/scans/zbad.obj: "
                               "expected a mesh with triangles")
    assert found[1].startswith("s.yaml:8:80: scenes[2].obstacles[0].path: "
                               f"{tmp_path}/chair.ply: expected a readable ply mesh")


def test_good_meshes_pass(tmp_path: Path) -> None:
    from sonicspec.testing.meshes import write_plain_meshes

    write_plain_meshes(tmp_path / "scans", "good")
    text = SPEC.replace("  - {kind: shoebox, id: hall, size_m: [8, 6, 3]}",
                        "  - {kind: mesh, id: hall, path: 'scans/good.*'}")
    assert _preflight(_spec(tmp_path, text)) == []


def test_folder_of_corrupt_audio_is_an_error_naming_it(tmp_path: Path) -> None:
    path = _spec(tmp_path)
    for f in (tmp_path / "data" / "noise").iterdir():
        f.write_bytes(b"RIFF....not audio")
    found = _preflight(path)
    noise = tmp_path / "data" / "noise"
    assert found == [
        f"s.yaml:11:31: corpora.noise.root: expected readable audio files in '{noise}', got "
        f"none readable among the first 4, e.g. {noise}/n0.wav: unreadable audio "
        + found[0].split("unreadable audio ", 1)[1]]
    assert found[0].endswith("; the corpus stage would skip them all")


def test_folder_of_non_audio_files_is_an_error_naming_it(tmp_path: Path) -> None:
    path = _spec(tmp_path)
    for f in (tmp_path / "data" / "noise").iterdir():
        f.rename(f.with_suffix(".txt"))
    assert _preflight(path) == [
        f"s.yaml:11:31: corpora.noise.root: expected audio files ending in .flac, .wav in "
        f"'{tmp_path / 'data' / 'noise'}', got none"]


def test_one_corrupt_file_among_good_ones_is_left_to_the_build(tmp_path: Path) -> None:
    path = _spec(tmp_path)
    (tmp_path / "data" / "noise" / "n0.wav").write_bytes(b"broken")
    assert _preflight(path) == []


def test_missing_espeak_for_generated_speech(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(preflight_module, "program_available", lambda name: False)
    text = SPEC.replace("{kind: folder, root: data/speech}", "{kind: generated}")
    assert _preflight(_spec(tmp_path, text)) == [
        "s.yaml:10:18: corpora.speech.kind: expected espeak-ng on the PATH to generate "
        "speech, got none; apt-get install espeak-ng (or use a librispeech or folder corpus)"]


def test_missing_sofar_for_a_sofa_hrtf(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(preflight_module, "module_available", lambda name: name != "sofar")
    (tmp_path / "h.sofa").write_bytes(b"")
    text = SPEC.replace("{kind: mono}", "{kind: binaural, hrtf: {kind: sofa, path: h.sofa}}")
    assert _preflight(_spec(tmp_path, text)) == [
        "s.yaml:8:43: microphone.hrtf.kind: expected the sofar package to read a SOFA HRTF, "
        "got none installed; pip install 'sonicspec[sofa]'"]


def test_fma_without_mp3_support(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from sonicspec.testing.corpora import write_fsd50k

    monkeypatch.setattr(preflight_module, "mp3_readable", lambda: False)
    (tmp_path / "data" / "fma" / "fma_small").mkdir(parents=True)
    (tmp_path / "data" / "fma" / "fma_metadata").mkdir()
    (tmp_path / "data" / "fma" / "fma_metadata" / "tracks.csv").write_text("")
    write_fsd50k(tmp_path / "data" / "fsd", 2, 1, clip_duration_s=1.0)
    text = SPEC.replace("  noise: {kind: folder, root: data/noise}",
                        "  noise: {kind: fsd50k, root: data/fsd}\n"
                        "  music: {kind: fma, root: data/fma}")
    found = _preflight(_spec(tmp_path, text))
    assert len(found) == 1, found
    assert found[0].startswith("s.yaml:12:17: corpora.music.kind: expected a libsndfile that "
                               "reads MP3 (FMA's tracks are MP3), got libsndfile ")
    assert found[0].endswith("; pip install -U soundfile (its wheels bring libsndfile 1.1 or "
                             "later)")


def test_check_files_and_plan_exit_2_with_located_errors(tmp_path: Path) -> None:
    path = _spec(tmp_path)
    for f in (tmp_path / "data" / "noise").iterdir():
        f.write_bytes(b"junk")
    assert run_cli("validate", str(path)).returncode == 0
    done = run_cli("validate", "--check-files", str(path))
    assert done.returncode == 2
    assert f"{path}:11:31: corpora.noise.root: expected readable audio files in " in done.stderr
    assert f"{path}: invalid (1 error)" in done.stderr
    done = run_cli("plan", str(path))
    assert done.returncode == 2
    assert f"{path}:11:31: corpora.noise.root: expected readable audio" in done.stderr
    assert not (tmp_path / ".sonicspec-store").exists()


@pytest.mark.parametrize("command,extra", [
    (["scene", "inspect"], []),
    (["rir"], ["--source", "1", "1", "1", "--mic", "2", "2", "1"]),
])
def test_plot_without_matplotlib_exits_2_before_any_work(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
        command: list[str], extra: list[str]) -> None:
    monkeypatch.setattr(preflight_module, "module_available", lambda name: name != "matplotlib")
    # No spec file at all: the check comes before anything is read.
    code = main([*command, str(tmp_path / "none.yaml"), *extra,
                 "--plot", str(tmp_path / "p.png")])
    assert code == 2
    assert capsys.readouterr().err == ("sonicspec: error: --plot needs matplotlib: "
                                       "pip install 'sonicspec[plot]'\n")


# --- the README's one-screen spec -------------------------------------------------------


@pytest.mark.skipif(not espeak_available(), reason="the LibriSpeech fixture speaks with espeak-ng")
def test_readme_spec_validates_plans_and_indexes_its_corpora(tmp_path: Path) -> None:
    """Issue 16: the README's own spec (FSD50K noise, train and test splits only) passed
    validate and failed 52 s into the build on the 7:2:1 default shares."""
    from sonicspec.audio.generated import write_librispeech
    from sonicspec.plan.compile import compile_spec
    from sonicspec.plan.params import read_params
    from sonicspec.stages.corpus import build_index
    from sonicspec.testing import corpora as tc

    write_librispeech(tmp_path / "data" / "LibriSpeech",
                      {"train-clean-360": 3, "test-clean": 3}, 1, seed=1)
    tc.write_fsd50k(tmp_path / "data" / "FSD50K", 6, 2, clip_duration_s=1.0, seed=2)
    path = tmp_path / "readme.yaml"
    path.write_text(readme_spec())
    done = run_cli("validate", "--check-files", str(path))
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    done = run_cli("plan", str(path))
    assert done.returncode == 0, done.stderr
    # The corpus stage splits what validate accepted (no Snakemake: the stage's own function).
    loaded, _ = validate_file(path)
    plan = compile_spec(loaded, cache=False)
    for job in plan.by_step()["corpus"]:
        rng = np.random.default_rng(0)
        index = build_index(read_params("corpus", job.params), dict(job.paths), job.key, rng)
        assert index.splits == ["test", "train"], job.label
        if job.params["role"] == "noise":  # 0.875 : 0.125 of the clips without speech
            n = len(index.items)
            assert len(index.split("test")) == round(0.125 * n) >= 1


# --- skipped corpus files are counted (issue 7) -------------------------------------------


def test_index_records_skipped_files_with_reasons(tmp_path: Path) -> None:
    from sonicspec.audio.corpora import CorpusIndex, index_folder

    _corpora(tmp_path)
    root = tmp_path / "data" / "noise"
    (root / "n0.wav").write_bytes(b"broken")
    (root / "loose.wav").write_bytes(b"")
    index = index_folder(root, [".wav"], {"train": 1.0},
                         np.random.default_rng(0), by_speaker=False)
    assert [p for p, _ in index.skipped] == [str(root / "loose.wav"), str(root / "n0.wav")]
    assert all(r.startswith("unreadable audio (") for _, r in index.skipped)
    assert len(index.items) == 3
    # Kept through the index's JSON (the corpus cache).
    assert CorpusIndex.from_dict(index.to_dict()).skipped == index.skipped


def test_librispeech_chapter_without_transcript_is_recorded_file_by_file(tmp_path: Path) -> None:
    from sonicspec.audio.corpora import index_librispeech

    chapter = tmp_path / "ls" / "dev" / "11" / "22"
    _wav(chapter / "11-22-0000.flac")
    _wav(chapter / "11-22-0001.flac")
    ok = tmp_path / "ls" / "dev" / "12" / "23"
    _wav(ok / "12-23-0000.flac")
    (ok / "12-23.trans.txt").write_text("12-23-0000 HELLO\n")
    index = index_librispeech(tmp_path / "ls", {"train": ["dev"]})
    assert index.skipped == (
        (str(chapter / "11-22-0000.flac"), "transcript file 11-22.trans.txt missing"),
        (str(chapter / "11-22-0001.flac"), "transcript file 11-22.trans.txt missing"))
    assert len(index.problems) == 1  # the log keeps one line per chapter


def test_corpus_artifact_lists_skipped_files_and_skipped_files_reads_them(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from sonicspec.plan.compile import compile_spec
    from sonicspec.stages import run_job
    from sonicspec.stages.corpus import skipped_files
    from sonicspec.store import ArtifactStore

    path = _spec(tmp_path)
    (tmp_path / "data" / "noise" / "n0.wav").write_bytes(b"broken")
    (tmp_path / "data" / "speech" / "stray.wav").write_bytes(b"")
    loaded, _ = validate_file(path)
    plan = compile_spec(loaded, cache=False)
    store = ArtifactStore(plan.store_dir)
    assert skipped_files(plan, store) == {}
    with caplog.at_level("WARNING", logger="sonicspec.stages.corpus"):
        for job in plan.by_step()["corpus"]:
            run_job(plan, job.key)
    skipped = skipped_files(plan, store)
    assert list(skipped) == ["speech", "noise"]
    assert skipped["speech"] == [{"path": "stray.wav", "reason": "not inside a speaker folder"}]
    (noise,) = skipped["noise"]
    assert noise["path"] == "n0.wav" and noise["reason"].startswith("unreadable audio (")
    # The log warning stays.
    assert any("corpora.noise:" in r.getMessage() and "n0.wav: unreadable audio" in
               r.getMessage() for r in caplog.records)
