"""The SonicSet presets reproduce the paper's table and levels (issue 20).

The inputs are laid out as the presets read them (:mod:`sonicspec.testing.sonicset`): 90
Matterport scans under data/mp3d, LibriSpeech with 921 / 40 / 40 speakers, FSD50K and FMA. The
scans carry the released scripts' building ids, so both presets plan over the same folder.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.audio.mix import integrated_loudness
from sonicspec.dataload.folder import Group
from sonicspec.errors import CompileError, CorpusError
from sonicspec.plan.compile import compile_spec
from sonicspec.plan.model import Plan
from sonicspec.plan.params import ArrangeParams, read_params
from sonicspec.spec import load_spec, validate_text
from sonicspec.stages import run_job
from sonicspec.stages.arrange import scene_speakers
from sonicspec.testing.sonicset import PAPER_SPEAKERS, write_sonicset_inputs, write_speaker_folders

ROOT = Path(__file__).resolve().parents[1]
PAPER = (ROOT / "specs" / "sonicset.yaml").read_text()
RELEASE = (ROOT / "specs" / "sonicset_release.yaml").read_text()
SUBSET = {"train": "train-clean-360", "val": "dev-clean", "test": "test-clean"}


def released_scene_lists() -> dict[str, list[str]]:
    """The scene ids the release preset pins, per split."""
    folder = Path(__file__).parent
    loaded, problems = validate_text(RELEASE, str(folder / "sonicset_release.yaml"), folder)
    assert loaded is not None, problems
    return {name: list(s.scenes) for name, s in loaded.spec.splits.items()}


@pytest.fixture(scope="module")
def paper_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sonicset")
    ids = [sid.split("/")[1] for ids in released_scene_lists().values() for sid in ids]
    assert len(ids) == len(set(ids)) == 90
    write_sonicset_inputs(folder / "data", ids, PAPER_SPEAKERS)
    (folder / "sonicset.yaml").write_text(PAPER)
    (folder / "sonicset_release.yaml").write_text(RELEASE)
    return folder


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sonicspec.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=120)


def table(stdout: str) -> dict[str, list[str]]:
    """The rows of `plan --summary`'s table by split: scenes, speakers, groups, tracks,
    hours, track hours (numbers as printed)."""
    rows = {}
    for line in stdout.splitlines():
        cells = line.split()
        if cells and cells[0] in ("train", "val", "test", "total") and len(cells) >= 7:
            rows[cells[0]] = cells[1:7]
    return rows


def test_plan_summary_prints_the_papers_table(paper_data: Path) -> None:
    done = cli("plan", "--summary", "sonicset.yaml", cwd=paper_data)
    assert done.returncode == 0, done.stderr
    rows = table(done.stdout)
    # scenes, speakers, groups, speech tracks (trajectories), hours of mixtures, of tracks
    assert rows["train"] == ["62", "921", "19,034", "57,102", "317.23", "951.70"]
    assert rows["val"] == ["19", "40", "247", "741", "4.12", "12.35"]
    assert rows["test"] == ["9", "40", "247", "741", "4.12", "12.35"]
    assert rows["total"][:2] == ["90", "1,001"]
    page = (ROOT / "docs" / "guide" / "sonicset.md").read_text(encoding="utf-8")
    start = done.stdout.index("split ")
    end = done.stdout.index("\nimage-source order")  # then per scene (estimates of fixtures)
    assert done.stdout[start:end].strip() in page  # the docs show this very table
    assert "  87 more scenes not built yet, not estimated" in done.stdout
    # The paper's 57,102 / 247 / 247 and ~952 / 4 / 4 h: training counted per trajectory,
    # validation and test per group (247 is no multiple of three).
    summary = json.loads(cli("plan", "--summary", "--json", "sonicset.yaml",
                             cwd=paper_data).stdout)
    by = {s["name"]: s for s in summary["splits"]}
    assert (by["train"]["speech_tracks"], by["val"]["groups"], by["test"]["groups"]) == (
        57_102, 247, 247)
    assert [round(by["train"]["track_hours"]), round(by["val"]["audio_hours"]),
            round(by["test"]["audio_hours"])] == [952, 4, 4]


def test_the_release_preset_pins_the_scripts_scene_lists(paper_data: Path) -> None:
    done = cli("plan", "--summary", "sonicset_release.yaml", cwd=paper_data)
    assert done.returncode == 0, done.stderr
    rows = table(done.stdout)
    assert rows["train"][:4] == ["62", "921", "19,034", "57,102"]
    assert rows["val"][:4] == ["19", "40", "247", "741"]
    assert rows["test"][:4] == ["9", "40", "117", "351"]
    plan = compile_spec(load_spec(paper_data / "sonicset_release.yaml"), cache=False)
    used: dict[str, set[str]] = {}
    for job in plan.by_step()["placement"]:
        used.setdefault(job.params["split"], set()).add(job.params["scene_id"])
    assert {k: sorted(v) for k, v in used.items()} == {
        k: sorted(v) for k, v in released_scene_lists().items()}


@pytest.fixture(scope="module")
def paper_plan(paper_data: Path) -> Plan:
    return compile_spec(load_spec(paper_data / "sonicset.yaml"), cache=False)


def test_each_speaker_once_per_scene(paper_data: Path, paper_plan: Plan) -> None:
    speakers = {split: sorted(p.name for p in (paper_data / "data" / "LibriSpeech" / sub)
                              .iterdir()) for split, sub in SUBSET.items()}
    per_scene: dict[tuple[str, str], list[str]] = {}
    groups: dict[str, list[str]] = {}
    for job in paper_plan.by_step()["arrange"]:
        params: ArrangeParams = read_params("arrange", job.params, job.label)
        groups.setdefault(params.split, []).extend(params.groups)
        if params.composition is None:
            continue
        chosen = scene_speakers(speakers[params.split], params, paper_plan.seed)
        assert all(len(c) == 3 for c in chosen)
        per_scene.setdefault((params.split, params.composition.scene_id), []).extend(
            s for c in chosen for s in c)
    assert {s: len(g) for s, g in groups.items()} == {"train": 19_034, "val": 247, "test": 247}
    assert sorted(groups["train"]) == [f"train/{i:06d}" for i in range(19_034)]
    scenes = Counter(split for split, _ in per_scene)
    assert scenes == {"train": 62, "val": 19}  # test: 247 groups drawn per group
    left_out = set()
    for (split, _), used in per_scene.items():
        counts = Counter(used)
        assert max(counts.values()) == 1  # nobody twice in a scene
        assert len(used) == 3 * (len(speakers[split]) // 3)  # 921 all; 39 of 40
        if split == "val":
            left_out |= set(speakers["val"]) - set(used)
    assert len(left_out) > 1  # the speaker who sits a scene out changes with the scene


def test_the_composition_is_seeded_and_survives_replanning(paper_data: Path,
                                                           paper_plan: Plan) -> None:
    again = compile_spec(load_spec(paper_data / "sonicset.yaml"), cache=False)
    assert [j.key for j in again] == [j.key for j in paper_plan]
    first = next(j for j in paper_plan.by_step()["arrange"] if j.params["split"] == "val")
    names = sorted(p.name for p in (paper_data / "data" / "LibriSpeech" / "dev-clean").iterdir())
    params = read_params("arrange", first.params, first.label)
    assert scene_speakers(names, params, 0) == scene_speakers(names, params, 0)
    assert scene_speakers(names, params, 0) != scene_speakers(names, params, 1)


def test_a_speaker_missing_from_the_index_is_an_error_naming_the_split(paper_plan: Plan
                                                                       ) -> None:
    job = next(j for j in paper_plan.by_step()["arrange"] if j.params["split"] == "val")
    params = read_params("arrange", job.params, job.label)
    with pytest.raises(CorpusError, match=r"split 'val' has 39 usable speakers in the corpus "
                                          r"index but the plan counted 40"):
        scene_speakers([str(i) for i in range(39)], params, 0)


def test_too_few_speakers_for_a_group_is_a_compile_error(tmp_path: Path) -> None:
    shutil.copy(ROOT / "specs" / "meshes" / "room.obj", tmp_path / "room.obj")
    write_speaker_folders(tmp_path / "ls", {"train-clean-360": 2}, utterances=1,
                          utterance_s=1.0)
    text = (
        "sonicspec: 1\nname: few\nseed: 0\nscenes:\n"
        "  - {kind: mesh, id: scan, path: room.obj, repair: {leak_test_rays: 0}}\n"
        "corpora:\n  speech: {kind: librispeech, root: ls, subsets: {train: "
        "[train-clean-360]}}\n"
        "mixture: {speakers: 3, noise_clips: [0, 0], music_clips: [0, 0],\n"
        "          tasks: [{kind: separation, speakers: 2, background: none}]}\n"
        "splits:\n  train: {groups: each_speaker_per_scene, scenes: [scan]}\n"
        "outputs: {dir: out, store_dir: store}\n")
    loaded, problems = validate_text(text, str(tmp_path / "few.yaml"), tmp_path)
    assert loaded is not None, [p.format("few.yaml") for p in problems]
    with pytest.raises(CompileError, match=r"splits.train.groups: each_speaker_per_scene needs "
                                           r"at least 3 speakers .* gives split 'train' 2"):
        compile_spec(loaded, cache=False)


def _release_with(old: str, new: str) -> str:
    assert old in RELEASE
    return RELEASE.replace(old, new, 1)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("mp3d/pa4otMbVnkk,", "mp3d/pa4otMbVnkk, mp3d/pa4otMbVnkk,",
         r"splits.val.scenes\[\d+\]: 'mp3d/pa4otMbVnkk' is listed twice \(also scenes\[16\]\)"),
        ("mp3d/82sE5b5pLXE,", "mp3d/82sE5b5pLXE, mp3d/D7G3Y4RVNrH,",
         r"splits.test.scenes\[5\]: scene 'mp3d/D7G3Y4RVNrH' is also listed by split 'train'"),
    ],
)
def test_pinned_scene_lists_refuse_duplicates_and_overlaps(tmp_path: Path, old: str, new: str,
                                                          message: str) -> None:
    loaded, problems = validate_text(_release_with(old, new), str(tmp_path / "s.yaml"), tmp_path)
    assert loaded is None
    assert any(re.search(message, p.format("s.yaml")) for p in problems), [
        p.format("s.yaml") for p in problems]


def test_a_pinned_scene_the_data_lacks_is_named(paper_data: Path) -> None:
    text = _release_with("mp3d/sT4fr6TAbpF]", "mp3d/sT4fr6TAbpf]")
    _, problems = validate_text(text, str(paper_data / "s.yaml"), paper_data, files=True)
    assert any("splits.test.scenes[8]: no scene 'mp3d/sT4fr6TAbpf': glob of scene 'mp3d' "
               "gives no such file; did you mean 'mp3d/sT4fr6TAbpF'?" in p.format("s.yaml")
               for p in problems), [p.format("s.yaml") for p in problems]
    loaded, _ = validate_text(text, str(paper_data / "s.yaml"), paper_data)
    with pytest.raises(CompileError, match=r"splits.test.scenes\[8\]: 'mp3d/sT4fr6TAbpf' "
                                           "matches no scene"):
        compile_spec(loaded, cache=False)


def test_a_one_group_per_split_cut_builds_and_keeps_the_papers_levels(tmp_path: Path) -> None:
    """The paper preset with three scans and 3 / 4 / 3 speakers (one group per scene and
    split; dev-clean's fourth speaker sits out) and, to keep the test fast, fewer rays and
    image sources: every component lands at the paper's level (-17 / -21 / -24 LUFS), no
    group is scaled, and mixtures louder than 0 dBFS are kept (by each file's scale)."""
    write_sonicset_inputs(tmp_path / "data", ["s0", "s1", "s2"],
                          {"train-clean-360": 3, "dev-clean": 4, "test-clean": 3})
    text = PAPER
    for old, new in (("scene_count: 62", "scene_count: 1"), ("scene_count: 19", "scene_count: 1"),
                     ("scene_count: 9", "scene_count: 1"), ("test: {groups: 247,",
                                                            "test: {groups: 1,"),
                     ("rays: 4000", "rays: 500"), ("image_source_order: 3",
                                                   "image_source_order: 1")):
        assert old in text
        text = text.replace(old, new)
    (tmp_path / "sonicset.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp_path / "sonicset.yaml"))
    assert len(plan.by_step()["export"]) == 3
    for job in plan.jobs:
        run_job(plan, job.key)
    out = Path(plan.output_dir)
    ls = tmp_path / "data" / "LibriSpeech"
    loudest = 0.0
    for split in ("train", "val", "test"):
        group = out / split / "000000"
        meta = json.loads((group / "metadata.json").read_text())
        assert meta["group_gain_db"] == 0.0
        speakers = [meta[f"source{k}"]["speaker"] for k in (1, 2, 3)]
        assert len(set(speakers)) == 3
        assert set(speakers) <= {p.name for p in (ls / SUBSET[split]).iterdir()}
        # 18 bits in 24-bit FLAC, each file scaled to just under full scale (issue 27)
        g = Group(out, f"{split}/000000", meta)
        for name, lufs in (("source1", -17), ("source2", -17), ("source3", -17),
                           ("noise", -21), ("music", -24)):
            info = sf.info(str(group / f"{name}.flac"))
            assert (info.format, info.subtype) == ("FLAC", "PCM_24")
            x = g.read(name).astype(np.float64)[0]
            assert integrated_loudness(x, g.sample_rate_hz) == pytest.approx(lufs, abs=0.1), (
                split, name)
        for mixture in (group / "mixtures").iterdir():
            raw = float(np.max(np.abs(sf.read(str(mixture))[0])))
            assert raw < 1.0  # a plain reader gets valid audio, at the gain 1 / scale
            loudest = max(loudest, float(np.max(np.abs(g.read(f"{split}/000000/mixtures/"
                                                              f"{mixture.name}")))))
    assert loudest > 1.0  # kept, not clipped nor limited: the scale holds it


def test_speakers_counted_from_folder_names_are_the_indexs(tmp_path: Path) -> None:
    """The plan counts speakers from folder names; the corpus job's index must agree."""
    from sonicspec.audio.corpora import (
        folder_speakers,
        index_folder,
        index_librispeech,
        librispeech_speakers,
    )
    from sonicspec.testing.corpora import write_folder

    root = write_folder(tmp_path / "folder", 7, 1, seed=0)
    ratios = {"train": 0.6, "val": 0.2, "test": 0.2}
    found = folder_speakers(root, [".flac", ".wav"], ratios, np.random.default_rng(3))
    index = index_folder(root, [".flac", ".wav"], ratios, np.random.default_rng(3),
                         by_speaker=True)
    assert found == {s: sorted(index.speakers(s)) for s in ratios}
    assert sum(len(v) for v in found.values()) == 7
    subsets = {"train": ["train-clean-360"], "test": ["test-clean"]}
    write_speaker_folders(tmp_path / "ls", {"train-clean-360": 4, "test-clean": 2},
                          utterances=1, utterance_s=0.5)
    index = index_librispeech(tmp_path / "ls", subsets)
    assert librispeech_speakers(tmp_path / "ls", subsets) == {
        s: sorted(index.speakers(s)) for s in subsets}


def test_the_realistic_preset_plans_the_papers_table(paper_data: Path) -> None:
    """sonicset_realistic adds realism, not data: on the same inputs `plan --summary` gives
    the paper preset's table (scenes, speakers, groups, tracks, hours)."""
    text = (ROOT / "specs" / "sonicset_realistic.yaml").read_text()
    (paper_data / "sonicset_realistic.yaml").write_text(text)
    done = cli("plan", "--summary", "sonicset_realistic.yaml", cwd=paper_data)
    assert done.returncode == 0, done.stderr
    paper = cli("plan", "--summary", "sonicset.yaml", cwd=paper_data)
    assert table(done.stdout) == table(paper.stdout)
    assert table(done.stdout)["train"][:4] == ["62", "921", "19,034", "57,102"]
