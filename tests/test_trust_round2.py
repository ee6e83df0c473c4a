"""Issue 28, second round of trust: the faults a hostile machine and a new user found (items 2,
3, 4, 5, 10 and 13). Each test reproduces its fault first; the builds are copies of the
cut-down demo built once per session (conftest's ``demo_reference``, through
``test_pipeline_trust``'s ``reference`` and ``copy``)."""

from __future__ import annotations

import errno
import io
import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from build_cases import ROOT, build_digest, write_spec
from test_pipeline_trust import cli, copy, reference  # noqa: F401  (fixtures)

from sonicspec.atomic import folder_problem, os_error_cause, write_text
from sonicspec.errors import GeometryError, StoreError
from sonicspec.stages.workflow import build
from sonicspec.store import ArtifactStore
from sonicspec.store.lock import StoreLock, StoreLockedError, group_members


def _flip_keeping_time(path: Path) -> None:
    """Bit rot: one byte changed, the file's size and modification time kept."""
    st = path.stat()
    data = bytearray(path.read_bytes())
    data[int(len(data) * 0.7)] ^= 0xFF
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.stat().st_size == st.st_size and path.stat().st_mtime_ns == st.st_mtime_ns


# --- item 2: what verify finds, the next build repairs ------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("target", ["flac", "store chunk"])
def test_damage_that_keeps_size_and_time_is_repaired_after_verify_names_it(copy, target) -> None:  # noqa: F811
    _folder, plan, expected = copy
    store, out = Path(plan.store_dir), Path(plan.output_dir)
    assert build(plan, cores=2, stream=io.StringIO()).jobs_run == 0  # the cache knows the copy
    if target == "flac":
        damaged = next(p for p in sorted(out.rglob("source1.flac")))
        named, verify_dir = damaged.relative_to(out).as_posix(), out
    else:
        job = next(j for j in plan.jobs if j.step == "render")
        art = ArtifactStore(store).path("render", job.key)
        damaged = next(p for p in sorted(art.rglob("*")) if p.is_file()
                       and p.name != "zarr.json" and p.stat().st_size > 100)
        named, verify_dir = f"render {job.key}", store
    _flip_keeping_time(damaged)
    # A build trusts what did not move (a no-op build reads no payload): the fault as reported.
    quiet = build(plan, cores=2, stream=io.StringIO())
    assert quiet.code == 0 and quiet.check.findings == []
    assert build_digest(plan) != expected
    found = cli("verify", str(verify_dir))
    assert found.returncode == 1 and named in found.stderr, found.stderr
    # What verify named is forgotten by the check cache: the next build re-reads and repairs it.
    stream = io.StringIO()
    result = build(plan, cores=2, stream=stream)
    assert result.code == 0, stream.getvalue()
    assert len(result.check.findings) == 1, stream.getvalue()
    assert build_digest(plan) == expected
    assert cli("verify", str(verify_dir)).returncode == 0


# --- item 3: the lock covers the whole build ------------------------------------------------------


def _own_group(*cmd: str) -> subprocess.Popen:
    return subprocess.Popen(list(cmd), start_new_session=True)


def _write_lock(store: Path, **fields) -> None:
    store.mkdir(parents=True, exist_ok=True)
    (store / "build.lock").write_text(json.dumps(
        {"host": socket.gethostname(), "since": "then", "purpose": "build", **fields}))


def test_a_lock_whose_head_died_but_whose_jobs_run_is_not_taken(tmp_path: Path) -> None:
    head = subprocess.Popen([sys.executable, "-c", "pass"])
    head.wait()
    jobs = _own_group("sleep", "60")
    try:
        _write_lock(tmp_path, pid=head.pid, pgid=jobs.pid)
        assert group_members(jobs.pid) == [jobs.pid]
        with pytest.raises(StoreLockedError, match=rf"died \(pid {head.pid}.*process group "
                                                   rf"{jobs.pid}\) are still running.*kill -- "
                                                   rf"-{jobs.pid}"):
            StoreLock(tmp_path).acquire()
    finally:
        jobs.kill()
        jobs.wait()
    assert group_members(jobs.pid) == []
    with StoreLock(tmp_path) as lock:  # the group is gone: stale, taken over
        assert json.loads(lock.path.read_text())["pid"] == os.getpid()


def test_a_dead_builds_own_jobs_are_stopped_and_the_lock_taken(tmp_path: Path) -> None:
    if not Path("/proc/self/stat").is_file():
        pytest.skip("a group's processes are recognised through /proc")
    store = tmp_path / "store"
    head = subprocess.Popen([sys.executable, "-c", "pass"])
    head.wait()
    # Stands for a job of the dead build: its command line names the store, as Snakemake's
    # --directory and the jobs' --plan do.
    job = _own_group(sys.executable, "-c", "import time; time.sleep(60)",
                     f"{store}/plans/p.json")
    other = _own_group("sleep", "60")  # not this store's: never touched
    try:
        _write_lock(store, pid=head.pid, pgid=job.pid)
        _wait_for(lambda: str(store) in Path(f"/proc/{job.pid}/cmdline").read_text())
        lock = StoreLock(store)
        with lock:
            assert lock.stopped.startswith(f"stopped 1 process(es) of a build of this store "
                                           f"that died (pid {head.pid}, process group {job.pid})")
            assert job.wait(timeout=15) is not None
        assert other.poll() is None
        _write_lock(tmp_path / "s2", pid=head.pid, pgid=other.pid)
        with pytest.raises(StoreLockedError, match=rf"kill -- -{other.pid}"):
            StoreLock(tmp_path / "s2").acquire()
    finally:
        for p in (job, other):
            p.kill()
            p.wait()


def test_a_zombie_head_counts_as_dead(tmp_path: Path) -> None:
    if not Path("/proc/self/stat").is_file():
        pytest.skip("zombies are told apart through /proc")
    head = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while Path(f"/proc/{head.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
        assert time.monotonic() < deadline
        time.sleep(0.02)
    try:
        _write_lock(tmp_path, pid=head.pid)  # not reaped yet: kill(pid, 0) still succeeds
        with StoreLock(tmp_path):
            pass
    finally:
        head.wait()


@pytest.mark.slow
def test_verify_refuses_while_a_build_holds_the_store(copy) -> None:  # noqa: F811
    _folder, plan, _ = copy
    with StoreLock(plan.store_dir):  # this process stands for a running build
        for folder in (plan.store_dir, plan.output_dir):
            found = cli("verify", folder)
            assert found.returncode == 1, found.stderr
            assert "not verified: another build of this store is running (pid " \
                   f"{os.getpid()}" in found.stderr
            assert "no artifact at" not in found.stderr
    assert cli("verify", plan.store_dir).returncode == 0
    assert not (Path(plan.store_dir) / "build.lock").exists()  # verify released its lock


@pytest.mark.slow
def test_an_empty_artifact_folder_left_by_a_killed_job_is_not_damage(copy) -> None:  # noqa: F811
    # Snakemake makes an output's folder before its job runs; a kill leaves it empty.
    _folder, plan, _ = copy
    (Path(plan.store_dir) / "mix" / "ab" / f"{'ab' * 32}.zarr").mkdir(parents=True)
    found = cli("verify", plan.store_dir)
    assert found.returncode == 0, found.stderr


def _wait_for(what, timeout_s: float = 120.0, step_s: float = 0.05):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = what()
        if value:
            return value
        time.sleep(step_s)
    raise AssertionError("timed out")


def _build_with_jobs_running(folder: Path, plan) -> tuple[subprocess.Popen, int]:
    """A CLI build of the copy with render jobs to do, once its first job is running: the
    head and the process group of its Snakemake and jobs."""
    store = ArtifactStore(plan.store_dir)
    for job in plan.jobs:
        if job.step in ("render", "mix", "export", "dataset"):
            shutil.rmtree(store.path(job.step, job.key))
    head = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", "build",
                             str(folder / "demo.yaml"), "--cores", "2"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    lock = StoreLock(plan.store_dir)
    pgid = _wait_for(lambda: (lock.holder() or {}).get("pgid"))
    _wait_for(lambda: len(group_members(pgid)) > 2)  # Snakemake and a job's shell and python
    return head, pgid


@pytest.mark.slow
def test_killing_only_the_head_never_lets_a_second_snakemake_in(copy) -> None:  # noqa: F811
    folder, plan, expected = copy
    head, pgid = _build_with_jobs_running(folder, plan)
    head.send_signal(signal.SIGKILL)
    head.wait()
    # The head is gone, its jobs are not: the lock is not stale. The next build stops that
    # Snakemake and its jobs before it runs its own (never two on one store), and resumes.
    assert group_members(pgid)
    second = cli("build", str(folder / "demo.yaml"), "--cores", "2")
    assert second.returncode == 0, second.stderr
    if "stopped " in second.stderr:
        assert re.search(rf"stopped \d+ process\(es\) of a build of this store that died "
                         rf"\(pid {head.pid}, process group {pgid}\)", second.stderr)
    assert group_members(pgid) == []
    assert build_digest(plan) == expected


@pytest.mark.slow
def test_a_terminated_build_stops_its_jobs_and_releases_the_lock(copy) -> None:  # noqa: F811
    folder, plan, _ = copy
    head, pgid = _build_with_jobs_running(folder, plan)
    head.send_signal(signal.SIGTERM)
    _, err = head.communicate(timeout=60)
    assert head.returncode == 130, err
    assert "sonicspec: interrupted" in err
    assert group_members(pgid) == []
    assert not (Path(plan.store_dir) / "build.lock").exists()


# --- item 4: output folders are checked where they really are ---------------------------------


@pytest.mark.parametrize("name", ["dir", "store_dir"])
def test_an_output_folder_that_is_a_symlink_out_of_the_spec_folder_is_refused(
        tmp_path: Path, name: str) -> None:
    (tmp_path / "spec").mkdir()
    spec = write_spec(tmp_path / "spec")
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (tmp_path / "spec" / "out").symlink_to(outside)  # out/demo and out/store lead outside
    before = sorted(outside.iterdir())
    flag = "--output-dir" if name == "dir" else "--store-dir"
    for command in ("validate", "build"):
        done = cli(command, str(spec))
        assert done.returncode == 2, (command, done.stderr)
        assert f"outputs.{name}: expected a folder inside the spec's folder" in done.stderr
        assert f"which is a symbolic link (or lies under one) to {outside}" in done.stderr
        assert flag in done.stderr
    assert sorted(outside.iterdir()) == before
    # A link that stays inside the folder is fine.
    (tmp_path / "spec" / "out").unlink()
    (tmp_path / "spec" / "real").mkdir()
    (tmp_path / "spec" / "out").symlink_to(tmp_path / "spec" / "real")
    assert cli("validate", str(spec)).returncode == 0


# --- item 5: files that lie about their size ------------------------------------------------------


def _lying_wav(path: Path, claimed_bytes: int, held: bytes) -> None:
    fmt = struct.pack("<IHHIIHH", 16, 1, 1, 16000, 32000, 2, 16)
    riff = struct.pack("<I", min(claimed_bytes + 36, 0xFFFFFFFF))
    path.write_bytes(b"RIFF" + riff + b"WAVE" + b"fmt " + fmt + b"data"
                     + struct.pack("<I", claimed_bytes) + held)


def test_a_wav_whose_header_claims_more_than_it_holds_is_skipped_with_the_reason(
        tmp_path: Path) -> None:
    import soundfile as sf

    from sonicspec.audio.corpora import index_folder, probe_audio

    root = tmp_path / "noise"
    root.mkdir()
    for k in range(4):
        sf.write(str(root / f"clip{k}.wav"), 0.1 * np.ones(16000), 16000)
    _lying_wav(root / "cut.wav", 2_000_000_000, b"\x01\x02" * 50)
    assert sf.info(str(root / "cut.wav")).frames == 50  # libsndfile reads it without a word
    assert probe_audio(root / "cut.wav").startswith(
        "truncated: its header's data chunk claims 2,000,000,000 bytes of audio but the file "
        "holds 100")
    index = index_folder(root, [".wav"], {"train": 1.0}, np.random.default_rng(0),
                         by_speaker=False)
    assert sorted(i.id for i in index.items) == [f"clip{k}" for k in range(4)]
    assert [(Path(p).name, r.split(":")[0]) for p, r in index.skipped] == [("cut.wav",
                                                                             "truncated")]
    # A streaming writer's "unknown length" is not a claim.
    _lying_wav(root / "stream.wav", 0xFFFFFFFF, b"\x01\x02" * 8000)
    assert probe_audio(root / "stream.wav") == (8000, 16000)


def test_a_mesh_file_beyond_the_size_bound_is_refused_before_it_is_read(
        tmp_path: Path, monkeypatch) -> None:
    from sonicspec.geometry.io import load_mesh

    big = tmp_path / "scan.obj"
    with open(big, "wb") as fh:  # 2 GiB, sparse: costs no disk
        fh.truncate(2 * 2**30)
    monkeypatch.delenv("SONICSPEC_MAX_MESH_MB", raising=False)
    with pytest.raises(GeometryError, match=rf"{big}: expected a scene file of at most 1,024 "
                                            r"MiB, got 2,048 MiB \(2,147,483,648 bytes\).*"
                                            r"SONICSPEC_MAX_MESH_MB=2049"):
        load_mesh(big)
    room = ROOT / "specs" / "meshes" / "room.obj"
    monkeypatch.setenv("SONICSPEC_MAX_MESH_MB", "0.0002")
    with pytest.raises(GeometryError, match=r"at most 0.0002 MiB, got 0.00048 MiB \(507 bytes"):
        load_mesh(room)
    monkeypatch.setenv("SONICSPEC_MAX_MESH_MB", "1")  # raised: read
    assert load_mesh(room).faces.shape[0] > 0
    monkeypatch.setenv("SONICSPEC_MAX_MESH_MB", "lots")
    with pytest.raises(GeometryError, match="SONICSPEC_MAX_MESH_MB: expected a positive number "
                                            "of MiB, got 'lots'"):
        load_mesh(room)


def test_a_spec_with_a_mesh_beyond_the_bound_is_refused_by_plan_and_validate(
        tmp_path: Path) -> None:
    spec = write_spec(tmp_path)
    spec.write_text(spec.read_text().replace(
        "  - kind: shoebox\n    id: living_room",
        "  - {kind: mesh, id: scan, path: scan.obj}\n  - kind: shoebox\n    id: living_room", 1))
    with open(tmp_path / "scan.obj", "wb") as fh:
        fh.truncate(2 * 2**30)
    for command in (("plan",), ("validate", "--check-files")):
        done = cli(*command[:1], str(spec), *command[1:])
        assert done.returncode == 2, (command, done.stderr)
        assert "scan.obj: expected a scene file of at most 1,024 MiB, got 2,048 MiB" \
            in done.stderr, done.stderr
    # Refused before the plan hashed it: no digest of it was cached.
    cached = tmp_path / "out" / "store" / "cache" / "file-digests.json"
    assert not cached.exists() or "scan.obj" not in cached.read_text()


# --- item 10: every I/O failure names the folder and the cause -----------------------------------


def test_io_errors_are_put_in_words() -> None:
    assert os_error_cause(OSError(errno.ENOSPC, "No space left on device")) == \
        "no space left: the disk is full"
    assert os_error_cause(OSError(errno.EROFS, "Read-only file system"), "/x") == \
        "the file system is read-only (/x)"
    assert os_error_cause(OSError(errno.EIO, "Input/output error")) == "Input/output error"


def test_a_write_that_hides_its_cause_is_diagnosed_from_the_folder(tmp_path: Path,
                                                                   monkeypatch) -> None:
    import sonicspec.atomic as atomic

    assert folder_problem(tmp_path) is None
    assert folder_problem(tmp_path / "not" / "yet") is None  # asks where it would be made
    monkeypatch.setattr(atomic, "folder_problem", lambda folder: f"no space left ({folder})")

    class HiddenCause(RuntimeError):  # libsndfile's "System error"
        pass

    with pytest.raises(StoreError, match=rf"cannot write {tmp_path}/a.flac: no space left "
                                         rf"\({tmp_path}\)"), atomic.atomic_path(
            tmp_path / "a.flac") as tmp:
        tmp.write_bytes(b"x")
        raise HiddenCause("System error")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(atomic, "folder_problem", lambda folder: None)
    with pytest.raises(HiddenCause), atomic.atomic_path(tmp_path / "b.flac"):
        raise HiddenCause("a real bug stays a bug")


def _mount(*args: str) -> bool:
    return subprocess.run(["mount", *args], capture_output=True).returncode == 0


@pytest.fixture
def mounts():
    """Mount points made by a test, unmounted after it; skips where mounting is not allowed."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("read-only and full folders are made with mount (root only)")
    made: list[Path] = []
    yield made
    for point in reversed(made):
        subprocess.run(["umount", "-l", str(point)], capture_output=True)


def _read_only(folder: Path, mounts: list[Path]) -> None:
    if not (_mount("--bind", str(folder), str(folder))
            and _mount("-o", "remount,bind,ro", str(folder))):
        pytest.skip("bind mounts are not allowed here")
    mounts.append(folder)


def _no_internal_error(text: str) -> None:
    assert "internal error" not in text and "please report" not in text, text
    assert "Traceback" not in text, text


@pytest.mark.slow
def test_a_read_only_store_is_named_as_such(copy, mounts) -> None:  # noqa: F811
    folder, plan, _ = copy
    _read_only(Path(plan.store_dir), mounts)
    done = cli("build", str(folder / "demo.yaml"), "--cores", "1")
    _no_internal_error(done.stderr)
    assert done.returncode == 1
    assert (f"cannot take the store's lock {plan.store_dir}/build.lock: the file system is "
            f"read-only ({plan.store_dir})") in done.stderr
    # Nothing builds in a read-only store: verify reads it without its lock.
    assert cli("verify", plan.store_dir).returncode == 0


@pytest.mark.slow
def test_a_read_only_dataset_folder_is_named_as_such(copy, mounts) -> None:  # noqa: F811
    folder, plan, _ = copy
    out = Path(plan.output_dir)
    next(iter(sorted(out.rglob("source1.flac")))).unlink()  # work for the build to do
    _read_only(out, mounts)
    done = cli("build", str(folder / "demo.yaml"), "--cores", "1")
    _no_internal_error(done.stderr)
    assert done.returncode == 1
    assert f"the file system is read-only ({out}" in done.stderr, done.stderr


@pytest.mark.slow
def test_a_full_dataset_folder_is_named_as_such_and_the_summary_says_what_failed(
        copy, mounts, tmp_path: Path) -> None:  # noqa: F811
    folder, _plan, _ = copy
    full = tmp_path / "full"
    full.mkdir()
    if not _mount("-t", "tmpfs", "-o", "size=64k", "tmpfs", str(full)):
        pytest.skip("tmpfs mounts are not allowed here")
    mounts.append(full)
    done = cli("build", str(folder / "demo.yaml"), "--cores", "2", "--output-dir",
               str(full / "demo"))
    _no_internal_error(done.stderr)
    assert done.returncode == 1
    assert f"no space left: the disk is full ({full}" in done.stderr, done.stderr
    summary = done.stderr[done.stderr.index("build FAILED"):]
    # item 13: a failed build's summary says what failed and what was not made
    assert "no warnings" not in summary and "dataset: 0 groups" not in summary
    assert "job failed (export " in summary or "jobs failed (export " in summary, summary
    assert "not made: " in summary and "dataset 1)" in summary
    assert f"dataset: NOT written: {full / 'demo'} is incomplete" in summary
    assert "dataset written to" not in done.stderr


def test_an_os_error_reaching_the_command_line_is_not_an_internal_error(
        tmp_path: Path, monkeypatch, capsys) -> None:
    import argparse

    import sonicspec.cli as cli_module

    def read_only(_args) -> int:
        raise PermissionError(errno.EROFS, "Read-only file system", str(tmp_path / "f"))

    class Parser:
        def parse_args(self, _argv):
            return argparse.Namespace(func=read_only)

    monkeypatch.setattr(cli_module, "build_parser", Parser)
    assert cli_module.main([]) == 1
    assert capsys.readouterr().err == (f"sonicspec: error: {tmp_path / 'f'}: the file system "
                                       f"is read-only ({tmp_path})\n")


# --- item 13: the demo is clean, and a failed build does not read as a success ----------------


@pytest.mark.slow
def test_the_demo_levels_leave_the_peak_guard_idle(copy) -> None:  # noqa: F811
    _folder, plan, _ = copy
    store = ArtifactStore(plan.store_dir)
    cuts, levels = [], []
    for job in plan.jobs:
        if job.step == "mix":
            for g in store.read_data("mix", job.key)["groups"]:
                cuts.append(g["group_gain_db"])
                levels += [(c["target_lufs"], c["output_lufs"]) for c in g["components"].values()]
    assert cuts and all(c == 0.0 for c in cuts), cuts
    assert all(abs(out - target) < 0.5 for target, out in levels), levels


def test_write_text_names_a_full_disk(tmp_path: Path, monkeypatch) -> None:
    def full(*_a, **_k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(StoreError, match=rf"cannot write {tmp_path}/x.json: no space left: the "
                                         rf"disk is full \({tmp_path}\)"):
        write_text(tmp_path / "x.json", "{}")
