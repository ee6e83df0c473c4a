"""Builds a user can trust, tried as a user works: edits, kills, damage, deletions, two builds at
once, and bad output folders (issue 16's fault table; ``bench/bench_trust.py`` prints it).

Every case builds the cut-down demo of ``test_pipeline_build`` through Snakemake. A reference
build is made once per session (conftest's ``demo_reference``); each test works on a copy of it
(spec, store and dataset folder).
"""

from __future__ import annotations

import io
import json
import random
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from build_cases import EDITS, ROOT, build_digest, plan_for, readme_spec, write_spec

from sonicspec.export.checksums import CHECKSUMS_NAME, DATASET_MARKER
from sonicspec.plan.compile import plan_changes
from sonicspec.plan.model import STEPS, Plan
from sonicspec.stages.workflow import build
from sonicspec.store import ArtifactStore

pytestmark = pytest.mark.slow


def cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sonicspec.cli", *args], capture_output=True,
                          text=True, cwd=cwd)


@pytest.fixture(scope="module")
def reference(demo_reference) -> tuple[Path, dict[str, str]]:
    """A finished build (its folder: spec, store, dataset) and its digests: conftest's, made
    once per session; read-only (each test works on a ``copy``)."""
    return demo_reference


@pytest.fixture
def copy(reference, tmp_path: Path) -> tuple[Path, Plan, dict[str, str]]:
    """A copy of the reference build, ready to damage."""
    folder = tmp_path / "b"
    shutil.copytree(reference[0], folder, symlinks=True)
    return folder, plan_for(folder / "demo.yaml"), reference[1]


def ran_by_step(result) -> dict[str, int]:
    return {s: n for s, n in result.ran.items() if n}


# --- 1. an edit runs exactly the jobs whose keys are new ---------------------------------



def test_each_edit_runs_exactly_the_jobs_the_plan_says_are_new(copy) -> None:
    folder, plan, _ = copy
    spec = folder / "demo.yaml"
    seen = []
    for section, old, new in EDITS:
        text = spec.read_text()
        assert old in text, (section, old)
        spec.write_text(text.replace(old, new, 1))
        new_plan = plan_for(spec)
        store = ArtifactStore(new_plan.store_dir)
        predicted = {s: c["added"] for s, c in plan_changes(plan, new_plan).items() if c["added"]}
        absent = {}
        for j in new_plan.jobs:
            if not store.exists(j.step, j.key):
                absent[j.step] = absent.get(j.step, 0) + 1
        assert absent == predicted, section  # the plan's prediction is what the store lacks
        result = build(new_plan, cores=2, stream=io.StringIO())
        assert result.code == 0, section
        assert ran_by_step(result) == predicted, section
        assert result.reused == len(new_plan.jobs) - sum(predicted.values())
        seen.append((section, sum(predicted.values())))
        plan = new_plan
    # Each edit touched something, and none reran the whole plan.
    assert all(0 < n < len(plan.jobs) for _, n in seen), seen


# --- 2. damage is found by verify and repaired by build ------------------------------------


def _first_file(root: Path, pattern: str) -> Path:
    return next(p for p in sorted(root.rglob(pattern)) if p.is_file())


def _flip_byte(path: Path, at: float = 0.5) -> None:
    data = bytearray(path.read_bytes())
    i = int(len(data) * at)
    data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def _edit_first_text(node) -> bool:
    """Change the first transcript (``text``) found in an artifact's data, in place."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "text" and isinstance(v, str):
                node[k] = v + " EDITED"
                return True
            if _edit_first_text(v):
                return True
    elif isinstance(node, list):
        return any(_edit_first_text(v) for v in node)
    return False


@pytest.mark.parametrize("target", ["store chunk", "store data", "flac", "metadata",
                                    "manifest"])
def test_damage_is_named_by_verify_and_repaired_by_build(copy, target: str) -> None:
    _folder, plan, expected = copy
    store, out = Path(plan.store_dir), Path(plan.output_dir)
    if target == "store chunk":
        job = next(j for j in plan.jobs if j.step == "render")
        art = ArtifactStore(store).path("render", job.key)
        damaged = next(p for p in sorted(art.rglob("*")) if p.is_file()
                       and p.name != "zarr.json" and p.stat().st_size > 100)
        _flip_byte(damaged)
        found = cli("verify", str(store))
        assert found.returncode == 1
        assert f"render {job.key}" in found.stderr
    elif target == "store data":  # issue 28 item 1: a transcript edited in arrange's data
        job = next(j for j in plan.jobs if j.step == "arrange")
        meta = ArtifactStore(store).path("arrange", job.key) / "zarr.json"
        doc = json.loads(meta.read_text())
        assert _edit_first_text(doc["attributes"]["data"])
        meta.write_text(json.dumps(doc))
        found = cli("verify", str(store))
        assert found.returncode == 1
        assert re.search(rf"arrange {job.key}: data .* does not match", found.stderr), \
            found.stderr
    else:
        damaged = {"flac": lambda: _first_file(out / "train", "source1.flac"),
                   "metadata": lambda: _first_file(out / "val", "metadata.json"),
                   "manifest": lambda: _first_file(out / "manifests", "*.jsonl")}[target]()
        if target == "flac":
            _flip_byte(damaged, 0.7)
        else:
            damaged.write_text(damaged.read_text().replace("1", "2", 1))
        found = cli("verify", str(out))
        assert found.returncode == 1, found.stderr
        rel = damaged.relative_to(out).as_posix()
        assert re.search(rf"{re.escape(rel)}: contents differ", found.stderr), found.stderr
    stream = io.StringIO()
    result = build(plan, cores=2, stream=stream)
    assert result.code == 0
    assert len(result.check.findings) == 1, stream.getvalue()
    assert "repairing: " in stream.getvalue()
    assert build_digest(plan) == expected
    assert cli("verify", str(out)).returncode == 0
    assert cli("verify", str(store)).returncode == 0


def test_a_deleted_dataset_folder_is_rebuilt_from_the_store(copy) -> None:
    _folder, plan, expected = copy
    shutil.rmtree(plan.output_dir)
    result = build(plan, cores=2, stream=io.StringIO())
    assert result.code == 0
    # Only the jobs that write the folder ran; nothing upstream.
    assert set(ran_by_step(result)) == {"export", "dataset"}
    assert build_digest(plan) == expected


def test_a_deleted_store_artifact_is_remade_with_what_follows(copy) -> None:
    _folder, plan, expected = copy
    store = ArtifactStore(plan.store_dir)
    mix = next(j for j in plan.jobs if j.step == "mix")
    shutil.rmtree(store.path("mix", mix.key))
    result = build(plan, cores=2, stream=io.StringIO())
    assert result.code == 0
    assert ran_by_step(result) == {"mix": 1, "export": 1, "dataset": 1}
    assert build_digest(plan) == expected


def test_build_says_dataset_written_only_when_it_is(copy) -> None:
    folder, _, _ = copy
    done = cli("build", str(folder / "demo.yaml"), "--cores", "2")
    assert done.returncode == 0 and "dataset written to" in done.stderr
    assert "0 jobs run" in done.stderr and "0 repaired" in done.stderr
    shutil.rmtree(folder / "out" / "demo" / "test")
    again = cli("build", str(folder / "demo.yaml"), "--cores", "2")
    assert again.returncode == 0, again.stderr
    assert "repairing: export test/hall#0" in again.stderr
    assert "1 repaired" in again.stderr and "dataset written to" in again.stderr


# --- 3. kills at random points resume to the same bytes -----------------------------------


def test_killed_five_times_at_random_points_then_resumed_to_the_same_bytes(
        reference, tmp_path: Path) -> None:
    expected = reference[1]
    plan = plan_for(write_spec(tmp_path))
    store = ArtifactStore(plan.store_dir)
    rng = random.Random(16)
    kills = 0
    for _ in range(12):
        done = sum(store.exists(j.step, j.key) for j in plan.jobs)
        if done == len(plan.jobs) or kills == 5:
            break
        # Kill when a random number of further jobs has finished (at least one).
        target = min(len(plan.jobs) - 1, done + rng.randint(1, 6))
        procs: list[subprocess.Popen] = []

        def killer(target: int = target, procs: list = procs) -> None:
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                if procs and sum(store.exists(j.step, j.key) for j in plan.jobs) >= target:
                    time.sleep(rng.random() * 0.5)  # somewhere inside the next jobs
                    procs[0].send_signal(signal.SIGKILL)
                    subprocess.run(["pkill", "-9", "-f", f"sonicspec job --plan {plan.store_dir}"],
                                   check=False)
                    return
                time.sleep(0.02)

        thread = threading.Thread(target=killer)
        thread.start()
        result = build(plan, cores=2, poll_s=0.1, on_start=procs.append, stream=io.StringIO())
        thread.join()
        if result.code != 0:
            kills += 1
    assert kills == 5
    assert build(plan, cores=2, stream=io.StringIO()).code == 0
    assert build_digest(plan) == expected
    assert store.temp_folders() == []
    assert [p for p in Path(plan.output_dir).rglob("*.tmp-*")] == []


# --- 4. one build at a time ------------------------------------------------------------------


def test_a_second_build_of_the_same_store_gets_the_lock_error(copy) -> None:
    folder, plan, expected = copy
    shutil.rmtree(plan.output_dir)  # the first build has work to do
    first = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", "build",
                              str(folder / "demo.yaml"), "--cores", "1"],
                             stderr=subprocess.PIPE, text=True)
    lock = Path(plan.store_dir) / "build.lock"
    deadline = time.monotonic() + 60
    while not lock.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    second = cli("build", str(folder / "demo.yaml"), "--cores", "1")
    _, first_err = first.communicate(timeout=300)
    assert first.returncode == 0, first_err
    assert second.returncode == 1
    assert "another build of this store is running (pid" in second.stderr
    assert f"pid {first.pid}" in second.stderr or "pid" in second.stderr
    assert not lock.exists()
    assert build_digest(plan) == expected


def test_a_lock_left_by_a_dead_build_is_taken_over(copy) -> None:
    _folder, plan, _ = copy
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    import socket

    (Path(plan.store_dir) / "build.lock").write_text(json.dumps(
        {"pid": dead.pid, "host": socket.gethostname(), "since": "then", "purpose": "build"}))
    assert build(plan, cores=1, stream=io.StringIO()).code == 0


# --- 5. progress counts only up ---------------------------------------------------------------


def test_progress_never_goes_backwards_on_a_repairing_build(copy) -> None:
    _folder, plan, _ = copy
    store = ArtifactStore(plan.store_dir)
    rir = next(j for j in plan.jobs if j.step == "rir")
    shutil.rmtree(store.path("rir", rir.key))
    stream = io.StringIO()
    assert build(plan, cores=1, poll_s=0.05, stream=stream).code == 0
    counts = [int(m.group(1)) for m in re.finditer(r"\] (\d+)/\d+ jobs", stream.getvalue())]
    assert len(counts) >= 3
    assert counts == sorted(counts), counts


# --- 6. verify knows what it is pointed at -----------------------------------------------------


def test_verify_refuses_a_folder_that_is_neither_store_nor_dataset(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("x")
    for folder in ("empty", "other"):
        found = cli("verify", str(tmp_path / folder))
        assert found.returncode == 2, found.stderr
        assert "not a sonicspec store or dataset" in found.stderr


def test_verify_reports_missing_and_stray_dataset_files(copy) -> None:
    _folder, plan, _ = copy
    out = Path(plan.output_dir)
    (out / "dataset.json").unlink()
    (out / "train" / "notes.txt").write_text("mine")
    found = cli("verify", str(out))
    assert found.returncode == 1
    assert "dataset.json: missing" in found.stderr
    assert "train/notes.txt: not written by the build" in found.stderr
    assert (out / DATASET_MARKER).is_file() and (out / CHECKSUMS_NAME).is_file()


def test_the_checksum_file_works_with_coreutils(copy) -> None:
    _folder, plan, _ = copy
    if shutil.which("sha256sum") is None:
        pytest.skip("no sha256sum")
    done = subprocess.run(["sha256sum", "--quiet", "-c", CHECKSUMS_NAME], cwd=plan.output_dir,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_step_has_a_rule_and_nothing_else_reruns(copy) -> None:
    """A second build of an unchanged spec runs nothing and re-reads nothing."""
    _folder, plan, _ = copy
    first = build(plan, cores=2, stream=io.StringIO())
    assert first.jobs_run == 0 and first.reused == len(plan.jobs)
    second = build(plan, cores=2, stream=io.StringIO())
    assert second.jobs_run == 0
    assert second.check.artifacts_verified == 0 and second.check.files_hashed == 0
    assert {s.name for s in STEPS} >= set(first.ran)


# --- 7. a spec chooses where it writes only inside its own folder ------------------------------


@pytest.mark.parametrize("where", ["/etc", "../../x", "out/../../x"])
def test_outputs_outside_the_spec_folder_are_refused(tmp_path: Path, where: str) -> None:
    spec = write_spec(tmp_path)
    spec.write_text(spec.read_text().replace("dir: out/demo", f"dir: {where}"))
    before = sorted(Path("/etc").iterdir())
    for command in ("validate", "plan", "build"):
        done = cli(command, str(spec))
        assert done.returncode == 2, (command, done.stderr)
        assert "outputs.dir: expected a folder inside the spec's folder" in done.stderr
        assert "--output-dir" in done.stderr
    assert sorted(Path("/etc").iterdir()) == before
    spec.write_text(spec.read_text().replace("  audio_format", "  allow_outside_spec_folder: "
                                                               "true\n  audio_format"))
    assert cli("validate", str(spec)).returncode == 0


def test_output_dir_on_the_command_line_moves_the_dataset_and_keeps_the_keys(copy) -> None:
    folder, _plan, expected = copy
    spec = folder / "demo.yaml"
    elsewhere = folder.parent / "elsewhere"
    spec.write_text(spec.read_text().replace("dir: out/demo", "dir: ../elsewhere"))
    assert cli("build", str(spec)).returncode == 2
    done = cli("build", str(spec), "--output-dir", str(elsewhere), "--cores", "2")
    assert done.returncode == 0, done.stderr
    # Same keys: only the jobs that write the (new) dataset folder ran.
    assert re.search(r"\d+ jobs run \(export \d+, dataset 1\)", done.stderr), done.stderr
    moved = {k.replace("out/", "", 1): v for k, v in expected.items() if k.startswith("out/")}
    got = {p.relative_to(elsewhere).as_posix() for p in elsewhere.rglob("*") if p.is_file()}
    assert got == set(moved)


def test_a_non_empty_folder_that_is_not_a_dataset_is_never_written(tmp_path: Path) -> None:
    spec = write_spec(tmp_path)
    mine = tmp_path / "out" / "demo"
    mine.mkdir(parents=True)
    (mine / "notes.txt").write_text("my thesis")
    done = cli("build", str(spec), "--cores", "1")
    assert done.returncode == 2, done.stderr
    assert f"outputs.dir: {mine} is not empty and is not a sonicspec dataset" in done.stderr
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
    assert (mine / "notes.txt").read_text() == "my thesis"
    # The same for a store, and a store and a dataset folder cannot swap roles.
    assert not (tmp_path / "out" / "store").exists()  # nothing was written before refusing
    spec.write_text(spec.read_text().replace("dir: out/demo", "dir: out/fresh"))
    (tmp_path / "out" / "store").mkdir()
    (tmp_path / "out" / "store" / "data.csv").write_text("1,2")
    done = cli("build", str(spec), "--cores", "1")
    assert done.returncode == 2 and "outputs.store_dir:" in done.stderr
    assert "is not empty and is not a sonicspec store" in done.stderr


def test_the_store_and_the_dataset_folder_cannot_nest(tmp_path: Path) -> None:
    spec = write_spec(tmp_path)
    spec.write_text(spec.read_text().replace("store_dir: out/store", "store_dir: out/demo/st"))
    done = cli("validate", str(spec))
    assert done.returncode == 2
    assert "must not lie inside one another" in done.stderr


# --- 8. nothing is skipped silently -------------------------------------------------------------


def test_skipped_corpus_files_are_counted_in_the_summary_and_dataset_json(tmp_path: Path) -> None:
    import numpy as np
    import soundfile as sf

    spec = write_spec(tmp_path)
    noise = tmp_path / "noise"
    noise.mkdir()
    rng = np.random.default_rng(3)
    for k in range(12):
        sf.write(str(noise / f"clip{k:02d}.wav"), 0.1 * rng.standard_normal(16000 * 3), 16000)
    (noise / "broken.wav").write_bytes(b"RIFF....WAVEjunk" * 10)
    text = spec.read_text()
    old = "noise: {kind: generated, clips_per_split: 4, clip_duration_s: 3.0}"
    assert old in text
    spec.write_text(text.replace(old, "noise: {kind: folder, root: noise}"))
    done = cli("build", str(spec), "--cores", "2")
    assert done.returncode == 0, done.stderr
    assert re.search(r"corpus files skipped .*: noise 1 \(first: broken\.wav, ", done.stderr)
    # The corpus job's warning is in the summary too, with the job's label.
    assert re.search(r"\d+ warnings? in the jobs' logs:\n(  .*\n)*  corpus noise: .*WARNING"
                     r".*broken\.wav", done.stderr), done.stderr
    summary = json.loads((tmp_path / "out" / "demo" / "dataset.json").read_text())
    skipped = summary["corpus_files_skipped"]
    assert skipped["noise"]["count"] == 1 and skipped["noise"]["files"][0]["path"] == "broken.wav"
    assert skipped["speech"]["count"] == 0


def test_files_left_from_a_bigger_build_are_reported(copy) -> None:
    folder, _plan, _ = copy
    spec = folder / "demo.yaml"
    spec.write_text(spec.read_text().replace("train: {groups: 2,", "train: {groups: 1,"))
    done = cli("build", str(spec), "--cores", "2")
    assert done.returncode == 0, done.stderr
    assert re.search(r"\d+ file\(s\) in the dataset folder are not part of this dataset "
                     r"\(first: train/000001/", done.stderr), done.stderr
    assert (folder / "out" / "demo" / "train" / "000001").is_dir()  # reported, not deleted


# --- 9. the README's own spec builds -------------------------------------------------------------


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="the LibriSpeech fixture speaks")
def test_the_readme_spec_builds(tmp_path: Path) -> None:
    """As written, but for its group counts (1 per split instead of 100 and 10), on tiny
    corpora in the real LibriSpeech and FSD50K layouts. It failed 52 s into the build on the
    corpus shares, then on a noise clip repeated in its track."""
    from sonicspec.audio.generated import write_librispeech
    from sonicspec.testing import corpora as tc

    text = readme_spec()
    for old, new in (("train: {groups: 100,", "train: {groups: 1,"),
                     ("test: {groups: 10,", "test: {groups: 1,")):
        assert old in text
        text = text.replace(old, new)
    write_librispeech(tmp_path / "data" / "LibriSpeech",
                      {"train-clean-360": 3, "test-clean": 3}, 5, seed=1)
    tc.write_fsd50k(tmp_path / "data" / "FSD50K", 10, 4, clip_duration_s=8.0, seed=2)
    spec = tmp_path / "readme.yaml"
    spec.write_text(text)
    done = cli("build", str(spec), "--cores", "2")
    assert done.returncode == 0, done.stderr
    assert "dataset written to" in done.stderr
    assert cli("verify", str(tmp_path / "out")).returncode == 0


def test_a_running_job_shows_how_far_it_is_on_the_progress_line(tmp_path: Path) -> None:
    from sonicspec.stages.context import JobContext, progress_path
    from sonicspec.stages.workflow import _job_progress

    plan = plan_for(write_spec(tmp_path))
    rir = plan.by_step()["rir"][0]
    ctx = JobContext(rir, plan, ArtifactStore(plan.store_dir))
    ctx.progress("group 1/2: 15 points, 8,192/600 rays")
    ctx.progress("never shown: within a second of the last")
    line = _job_progress(plan, [rir])
    assert line == f" | {rir.label}: group 1/2: 15 points, 8,192/600 rays"
    progress_path(plan.store_dir, rir.key).unlink()
    assert _job_progress(plan, [rir]) == ""


def test_a_killed_jobs_progress_is_not_shown_by_the_next_build(tmp_path: Path) -> None:
    """A job killed with its build leaves its progress file; the next build's line showed it as
    running (seen in the 1,000-group bench: 'group 33/50' for a job dead since the last run)."""
    from sonicspec.export.checksums import claim_folder
    from sonicspec.stages.context import JobContext, progress_path
    from sonicspec.stages.workflow import build

    plan = plan_for(write_spec(tmp_path))
    claim_folder(Path(plan.store_dir), "store", "outputs.store_dir", {})  # as the killed build did
    rir = plan.by_step()["rir"][0]
    JobContext(rir, plan, ArtifactStore(plan.store_dir)).progress("group 1/2")
    assert progress_path(plan.store_dir, rir.key).is_file()
    assert build(plan, dry_run=True, stream=io.StringIO()).code == 0
    assert not progress_path(plan.store_dir, rir.key).exists()


def test_planning_a_mesh_scene_does_not_block_claiming_its_fresh_store(tmp_path: Path) -> None:
    # Planning reads mesh files and caches their digests in <store>/cache before a build
    # claims the store: the claim must accept that cache (a fresh store of a spec with mesh
    # scenes was refused as "not empty"), and nothing else.
    from sonicspec.export.checksums import UnsafeOutputError, claim_folder

    shutil.copy(ROOT / "specs" / "meshes" / "room.obj", tmp_path / "room.obj")
    spec = write_spec(tmp_path)
    spec.write_text(spec.read_text().replace(
        "  - kind: shoebox\n    id: living_room",
        "  - {kind: mesh, id: scan, path: room.obj, repair: {leak_test_rays: 0}}\n"
        "  - kind: shoebox\n    id: living_room", 1))
    plan = plan_for(spec)
    store = Path(plan.store_dir)
    assert sorted(p.name for p in store.iterdir()) == ["cache"]  # the digests, before a build
    claim_folder(store, "store", "outputs.store_dir")
    assert (store / "sonicspec-store.json").is_file()
    other = tmp_path / "other"
    (other / "cache").mkdir(parents=True)
    (other / "cache" / "file-digests.json").write_text("{}")
    (other / "cache" / "notes.txt").write_text("mine")
    with pytest.raises(UnsafeOutputError, match="is not empty and is not a sonicspec store"):
        claim_folder(other, "store", "outputs.store_dir")
