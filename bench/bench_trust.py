"""Benchmark (issue 16): the fault table — edits, damage, kills, two builds at once, bad inputs.

Everything runs through the command line, as a user works, on the cut-down demo that the
pipeline tests build (``tests/build_cases.py``: 4 groups, 600 rays) in a fresh temporary
folder. Each row names the case, what a trustworthy tool must do, what happened (exit code,
the jobs the build ran against what ``plan`` predicted, the first line of the message), the
wall time and the peak RSS of the command's process tree (``wait4``'s ``ru_maxrss``: the
largest of the process and the children it waited for).

Rows:
- a fresh build; a rebuild with nothing changed;
- one edit in each section of the spec, applied one after another: jobs run per step against
  ``sonicspec plan --json``'s prediction of new jobs;
- damage: a byte flipped in a store chunk, in an exported FLAC, in a metadata.json; a deleted
  dataset folder; a deleted store artifact. ``verify`` must name it, ``build`` must repair it
  and end with the reference bytes;
- five kills at random points, then a resume to the reference bytes;
- two builds of one store at once;
- bad inputs: a YAML alias bomb, a 50 MB spec, 10^6 groups, a 1e9 m room, 10^7 rays,
  outputs in /etc and ../: each must exit 2 with a message, in bounded memory;
- issue 28: truncated RIRs in the build summary; ``report`` on a deleted FLAC and an empty
  metadata.json (exit 1, named); ``validate`` of a clip no utterance fits; ``plan --summary``
  of the SonicSet preset without data; ``evaluate`` of a NaN and of an all-zero estimate; the
  internal ``job`` command out of ``--help``.

Issue 28 (second round) adds:
- bit rot: a byte flipped in an exported FLAC and in a store chunk with the file's size and
  time kept: a build alone trusts them (it stats, never re-reads, unchanged files); ``verify``
  names them and the next build repairs them;
- only the build's head killed (``kill -9`` of the main pid) while jobs run: the next build
  must not run a second Snakemake beside the orphaned jobs (it stops the dead build's process
  group first) and resumes to the reference bytes; ``verify`` during a build says a build is
  running;
- an output folder that is a symbolic link out of the spec's folder; a noise WAV whose header
  claims 2 GB but holds 100 bytes (skipped, named in the summary); a 2 GiB OBJ (refused
  before it is read, in bounded time and memory);
- (root, where ``mount`` works) a read-only store, a read-only dataset folder and a full one:
  an error naming the folder and the cause, never "internal error"; a failed build's summary
  says what was not made.

Reproduce:
    python bench/bench_trust.py            # ~15 min on 2 cores
    python bench/bench_trust.py --quick    # no kills, edits, head kill, clip build (~5 min)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from build_cases import EDITS, write_spec  # noqa: E402  (the tests' cut-down demo)


@dataclass
class Run:
    code: int
    out: str
    err: str
    seconds: float
    max_rss_mb: float


def sonicspec(*args: str, timeout_s: float = 900) -> Run:
    """Run the command line; its exit code, output, wall time and peak RSS."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", *args], stdout=out,
                                stderr=err, text=True, start_new_session=True)
        deadline = start + timeout_s
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() > deadline:
                os.killpg(proc.pid, signal.SIGKILL)
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
        seconds = time.monotonic() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        return Run(proc.returncode, out.read(), err.read(), seconds, usage.ru_maxrss / 1024)


def digest(folder: Path) -> dict[str, str]:
    """SHA-256 of the artifacts and dataset files (logs, plans, caches, Snakemake state out)."""
    skip = {"logs", "benchmarks", "plans", ".snakemake", "cache", "build.lock"}
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*"))
            if p.is_file() and not skip & set(p.relative_to(folder).parts)}


def ran(err: str) -> str:
    m = re.search(r"(\d+) jobs? run \(([^)]*)\)", err)
    return f"{m.group(1)} ({m.group(2)})" if m else "?"


def first_line(text: str) -> str:
    """The first line of a message that is not progress or a spec warning."""
    lines = [x for x in text.splitlines()
             if x.strip() and not x.startswith("[") and ": warning: " not in x]
    return lines[0][:110] if lines else ""


class Table:
    def __init__(self) -> None:
        self.rows: list[tuple[str, ...]] = []

    def add(self, case: str, expected: str, result: str, ok: bool, run: Run | None) -> None:
        row = (case, expected, result, "yes" if ok else "NO",
               f"{run.seconds:.1f}" if run else "", f"{run.max_rss_mb:.0f}" if run else "")
        self.rows.append(row)
        print(" | ".join(row), flush=True)

    def markdown(self) -> str:
        head = ("case", "a trustworthy tool", "what happened", "ok", "s", "peak MB")
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        lines += ["| " + " | ".join(c.replace("|", "/") for c in r) + " |" for r in self.rows]
        return "\n".join(lines)


def flip(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def damage_rows(table: Table, work: Path, spec: Path, reference: dict[str, str]) -> None:
    store, out = work / "out" / "store", work / "out" / "demo"

    def repaired(case: str, named_as: str, verify_dir: Path) -> None:
        check = sonicspec("verify", str(verify_dir))
        named = named_as in check.err
        b = sonicspec("build", str(spec), "--cores", "2")
        same = digest(work / "out") == reference
        fixed = re.search(r"(\d+) repaired", b.err)
        table.add(case, "verify names it (exit 1); build repairs it, same bytes",
                  f"verify exit {check.code}{' names it' if named else ''}; build exit {b.code},"
                  f" {fixed.group(1) if fixed else '?'} repaired, {ran(b.err)} jobs run, "
                  f"{'same bytes' if same else 'DIFFERENT bytes'}",
                  check.code == 1 and named and b.code == 0 and same, b)

    chunk = next(p for p in sorted((store / "render").rglob("*")) if p.is_file()
                 and p.name != "zarr.json" and p.stat().st_size > 100)
    flip(chunk)
    key = next(p for p in chunk.parents if p.suffix == ".zarr").stem
    repaired("byte flipped in a store chunk", f"render {key}", store)
    flac = next(iter(sorted(out.rglob("source1.flac"))))
    flip(flac)
    repaired("byte flipped in an exported FLAC", flac.relative_to(out).as_posix(), out)
    meta = next(iter(sorted(out.rglob("metadata.json"))))
    meta.write_text(meta.read_text().replace("1", "2", 1))
    repaired("metadata.json edited", meta.relative_to(out).as_posix(), out)
    for case, folder in (("dataset folder deleted", out),
                         ("a store artifact (rir) deleted",
                          next(p for p in sorted((store / "rir").glob("*/*.zarr"))))):
        shutil.rmtree(folder)
        b = sonicspec("build", str(spec), "--cores", "2")
        same = digest(work / "out") == reference
        table.add(case, "remade (with what follows), same bytes",
                  f"exit {b.code}, {ran(b.err)} jobs run, {'same' if same else 'DIFFERENT'} "
                  "bytes", b.code == 0 and same, b)
    empty = work / "empty"
    empty.mkdir()
    v = sonicspec("verify", str(empty))
    table.add("verify on an empty folder", "exit 2: not a store or dataset",
              f"exit {v.code}: {first_line(v.err)}", v.code == 2, v)


def flip_keeping_time(path: Path) -> None:
    st = path.stat()
    flip(path)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


def bitrot_rows(table: Table, work: Path, spec: Path, reference: dict[str, str]) -> None:
    store, out = work / "out" / "store", work / "out" / "demo"
    flac = next(iter(sorted(out.rglob("source2.flac"))))
    chunk = next(p for p in sorted((store / "mix").rglob("*")) if p.is_file()
                 and p.name != "zarr.json")
    key = next(p for p in chunk.parents if p.suffix == ".zarr").stem
    for case, path, named_as, verify_dir in (
            ("FLAC byte flipped, size and time kept", flac, flac.relative_to(out).as_posix(),
             out),
            ("store chunk byte flipped, size and time kept", chunk, f"mix {key}", store)):
        flip_keeping_time(path)
        alone = sonicspec("build", str(spec), "--cores", "2")
        check = sonicspec("verify", str(verify_dir))
        b = sonicspec("build", str(spec), "--cores", "2")
        fixed = re.search(r"(\d+) repaired", b.err)
        first = re.search(r"(\d+) repaired", alone.err)
        same = digest(work / "out") == reference
        table.add(case, "verify names it; the build after verify repairs it, same bytes",
                  f"build alone: {first.group(1) if first else '?'} repaired; "
                  f"verify exit {check.code}{' names it' if named_as in check.err else ''}; "
                  f"then build: {fixed.group(1) if fixed else '?'} repaired, "
                  f"{'same bytes' if same else 'DIFFERENT bytes'}",
                  check.code == 1 and named_as in check.err and b.code == 0 and same, b)


def _pgid_of(lock: Path) -> int | None:
    try:
        return json.loads(lock.read_text()).get("pgid")
    except (OSError, ValueError):
        return None


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def head_kill_rows(table: Table, work: Path, spec: Path, reference: dict[str, str]) -> None:
    """Only the head killed while jobs run; verify during a build."""
    store = work / "out" / "store"
    for step in ("render", "mix", "export", "dataset"):
        shutil.rmtree(store / step, ignore_errors=True)
    head = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", "build", str(spec),
                             "--cores", "2"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    lock = store / "build.lock"
    deadline = time.monotonic() + 300
    while _pgid_of(lock) is None and time.monotonic() < deadline:
        time.sleep(0.05)
    pgid = _pgid_of(lock)
    while not list(store.glob("render/*/*.zarr")) and time.monotonic() < deadline:
        time.sleep(0.05)  # Snakemake made a render job's folder: jobs are running
    v = sonicspec("verify", str(store))
    table.add("verify during a build", "exit 1: says a build is running (no false damage)",
              f"exit {v.code}: {first_line(v.err)[:90]}",
              v.code == 1 and "build of this store is running" in v.err
              and "no artifact at" not in v.err, v)
    head.send_signal(signal.SIGKILL)
    head.wait()
    alive = pgid is not None and _group_alive(pgid)
    second = sonicspec("build", str(spec), "--cores", "2")
    start = time.monotonic()
    while pgid is not None and _group_alive(pgid) and time.monotonic() - start < 300:
        time.sleep(0.2)
    ended = time.monotonic() - start
    b = sonicspec("build", str(spec), "--cores", "2")
    same = digest(work / "out") == reference
    stopped = second.code == 0 and "stopped " in second.err and f"group {pgid})" in second.err
    table.add("head killed (kill -9 main pid) while jobs run",
              "no second Snakemake beside the orphaned jobs; resumes, same bytes",
              f"jobs {'alive' if alive else 'gone'} after the kill; next build exit "
              f"{second.code}{' (stopped the dead group first)' if stopped else ''}"
              f"; group gone {ended:.0f} s after it; again: exit {b.code}, "
              f"{'same' if same else 'DIFFERENT'} bytes",
              (stopped or not alive) and second.code == 0 and b.code == 0 and same, second)


def input_fault_rows(table: Table, base: Path) -> None:
    """Folders and files that are not what they seem."""
    folder = base / "inputs"
    folder.mkdir()
    spec = write_spec(folder)
    outside = base / "outside"
    outside.mkdir()
    (folder / "out").symlink_to(outside)
    r = sonicspec("build", str(spec))
    table.add("output folder a symlink out of the spec's folder", "exit 2, nothing written",
              f"exit {r.code}: {first_line(r.err)[:90]}",
              r.code == 2 and "symbolic link" in r.err and not any(outside.iterdir()), r)
    (folder / "out").unlink()
    big = folder / "scan.obj"
    with open(big, "wb") as fh:
        fh.truncate(2 * 2**30)  # sparse: no disk used
    text = spec.read_text()
    mesh = text.replace("  - kind: shoebox\n    id: living_room",
                        "  - {kind: mesh, id: scan, path: scan.obj}\n"
                        "  - kind: shoebox\n    id: living_room", 1)
    path = folder / "big_mesh.yaml"
    path.write_text(mesh)
    r = sonicspec("validate", str(path), "--check-files")
    table.add("a 2 GiB OBJ scene", "refused before it is read, bounded time and memory",
              f"exit {r.code}: {first_line(r.err)[:90]}",
              r.code == 2 and "SONICSPEC_MAX_MESH_MB" in r.err and r.seconds < 30, r)


def truncated_clip_row(table: Table, base: Path) -> None:
    import numpy as np
    import soundfile as sf

    folder = base / "truncated"
    folder.mkdir()
    spec = write_spec(folder)
    noise = folder / "noise"
    noise.mkdir()
    rng = np.random.default_rng(3)
    for k in range(12):
        sf.write(str(noise / f"clip{k:02d}.wav"), 0.1 * rng.standard_normal(16000 * 3), 16000)
    fmt = struct.pack("<IHHIIHH", 16, 1, 1, 16000, 32000, 2, 16)
    (noise / "cut.wav").write_bytes(b"RIFF" + struct.pack("<I", 2_000_000_036) + b"WAVE"
                                    + b"fmt " + fmt + b"data"
                                    + struct.pack("<I", 2_000_000_000) + b"\x01\x02" * 50)
    old = "noise: {kind: generated, clips_per_split: 4, clip_duration_s: 3.0}"
    spec.write_text(spec.read_text().replace(old, "noise: {kind: folder, root: noise}"))
    b = sonicspec("build", str(spec), "--cores", "2")
    said = re.search(r"noise 1 \(first: cut\.wav, truncated[^)]*\)", b.err)
    table.add("noise WAV claiming 2 GB, holding 100 bytes", "skipped, named with the reason",
              f"exit {b.code}; {said.group(0)[:80] if said else 'NOT named'}",
              b.code == 0 and said is not None, b)


def _mount(*args: str) -> bool:
    return subprocess.run(["mount", *args], capture_output=True).returncode == 0


def io_rows(table: Table, base: Path) -> None:
    """Read-only and full folders (root only: made with mount)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        table.add("read-only / full folders", "(needs root for mount)", "skipped", True, None)
        return
    work = base / "io"
    shutil.copytree(base / "main", work, symlinks=True)
    spec = work / "demo.yaml"
    mounted: list[Path] = []

    def read_only(folder: Path) -> bool:
        ok = (_mount("--bind", str(folder), str(folder))
              and _mount("-o", "remount,bind,ro", str(folder)))
        mounted.append(folder)
        return ok

    def clear(r: Run, words: str) -> bool:
        return r.code == 1 and words in r.err and "internal error" not in r.err

    def cause(r: Run, words: str) -> str:
        line = next((x.strip() for x in r.err.splitlines() if words in x), "NOT named")
        return line[:110]

    try:
        store, out = work / "out" / "store", work / "out" / "demo"
        if read_only(store):
            r = sonicspec("build", str(spec), "--cores", "1")
            table.add("read-only store", "error naming the folder and the cause",
                      f"exit {r.code}: {cause(r, 'read-only')}",
                      clear(r, "the file system is read-only"), r)
        subprocess.run(["umount", "-l", str(store)], capture_output=True)
        mounted.remove(store)
        next(iter(sorted(out.rglob("source1.flac")))).unlink()
        if read_only(out):
            r = sonicspec("build", str(spec), "--cores", "1")
            table.add("read-only dataset folder", "error naming the folder and the cause",
                      f"exit {r.code}: {cause(r, 'read-only')}",
                      clear(r, "the file system is read-only"), r)
        full = base / "full"
        full.mkdir()
        if _mount("-t", "tmpfs", "-o", "size=64k", "tmpfs", str(full)):
            mounted.append(full)
            r = sonicspec("build", str(spec), "--cores", "2", "--output-dir",
                          str(full / "demo"))
            failed = r.err[r.err.find("build FAILED"):]
            table.add("full dataset folder", "error naming folder and cause; the summary "
                      "says what was not made",
                      f"exit {r.code}: {cause(r, 'the disk is full')}; summary: "
                      f"{'dataset NOT written' if 'NOT written' in failed else 'NOT said'}",
                      clear(r, "the disk is full") and "NOT written" in failed
                      and "no warnings" not in failed, r)
    finally:
        for point in reversed(mounted):
            subprocess.run(["umount", "-l", str(point)], capture_output=True)


def kill_rows(table: Table, base: Path, reference: dict[str, str]) -> None:
    work = base / "kills"
    work.mkdir()
    spec = write_spec(work)
    rng = random.Random(16)
    kills = 0
    start = time.monotonic()
    for _ in range(12):
        if kills == 5:
            break
        proc = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", "build", str(spec),
                                 "--cores", "2"], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
        time.sleep(2 + rng.random() * 6)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            subprocess.run(["pkill", "-9", "-f", f"sonicspec job --plan {work}"], check=False)
            kills += 1
        proc.wait()
    b = sonicspec("build", str(spec), "--cores", "2")
    same = digest(work / "out") == reference
    table.add(f"killed {kills}x at random points, then resumed",
              "the resumed build gives the same bytes",
              f"exit {b.code}, {'same' if same else 'DIFFERENT'} bytes "
              f"({time.monotonic() - start:.0f} s in all)", b.code == 0 and same and kills == 5, b)


def concurrent_row(table: Table, base: Path) -> None:
    work = base / "concurrent"
    work.mkdir()
    spec = write_spec(work)
    first = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", "build", str(spec),
                              "--cores", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True)
    lock = work / "out" / "store" / "build.lock"
    while not lock.exists() and first.poll() is None:
        time.sleep(0.05)
    second = sonicspec("build", str(spec), "--cores", "1")
    first.communicate()
    table.add("two builds of one store at once", "one runs; the other gets the lock error",
              f"first exit {first.returncode}; second exit {second.code}: "
              f"{first_line(second.err)[:70]}",
              first.returncode == 0 and second.code == 1 and "another build" in second.err,
              second)


def bad_input_rows(table: Table, base: Path) -> None:
    folder = base / "bad"
    folder.mkdir()
    spec = write_spec(folder)
    text = spec.read_text()

    def row(case: str, content: str, command: str = "validate") -> None:
        path = folder / f"{re.sub(r'[^a-z0-9]+', '_', case.split()[0])}.yaml"
        path.write_text(content)
        r = sonicspec(command, str(path))
        table.add(case, "exit 2 with a message, bounded memory",
                  f"exit {r.code}: {first_line(r.err)}", r.code == 2, r)

    floor = sonicspec("--version")
    table.add("sonicspec --version", "(the floor of the memory column: the bench's own pages "
              "at fork count too)", f"exit {floor.code}", floor.code == 0, floor)
    bomb = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    for k in range(1, 10):
        refs = ", ".join([f"*a{k - 1}"] * 9)
        bomb.append(f"a{k}: &a{k} [{refs}]")
    row("alias-bomb (9 levels x 9)", "sonicspec: 1\n" + "\n".join(bomb) + "\n")
    filler = "# " + "x" * 98 + "\n"
    row("50MB spec (comments)", text + filler * (50 * 2**20 // len(filler)))
    path = folder / "groups_1e6.yaml"  # 999,998 + 1 + 1: the most the spec allows
    path.write_text(text.replace("train: {groups: 2,", "train: {groups: 999998,")
                    .replace("groups_per_shard: 2", "groups_per_shard: 4"))  # the default
    r = sonicspec("plan", str(path))
    table.add("10^6 groups: sonicspec plan", "plans in <= 60 s and <= 2 GB",
              f"exit {r.code}: {r.seconds:.0f} s, {r.max_rss_mb / 1024:.2f} GB",
              r.code == 0 and r.seconds <= 60 and r.max_rss_mb <= 2048, r)
    path.write_text(text.replace("train: {groups: 2,", "train: {groups: 1000000,"))
    row("groups-above-1e6", path.read_text())
    row("size-1e9 m room", text.replace("size_m: [6.0, 4.5, 2.7]", "size_m: [1e9, 1e9, 1e9]"))
    row("rays-1e7", text.replace("rays: 600", "rays: 10000000"))
    row("outputs-/etc", text.replace("dir: out/demo", "dir: /etc"), command="build")
    row("outputs-../../x", text.replace("dir: out/demo", "dir: ../../x"), command="build")


def issue28_rows(table: Table, base: Path, work: Path, fresh: Run) -> None:
    """Issue 28's faults of this helper's part (items 6, 8, 9, 11, 12, 14), on the built
    cut-down demo and the presets."""
    import numpy as np
    import soundfile as sf

    cut = "while still decaying" in fresh.err
    table.add("RIRs cut at 0.4 s in a decaying room", "the build summary says so",
              "summary names them" if cut else "not in the summary", cut, None)
    built = work / "out" / "demo"
    folder = base / "i28"
    shutil.copytree(built, folder / "ds")
    ds = folder / "ds"
    flac = sorted(ds.glob("test/*/source1.flac"))[0]
    flac.unlink()
    r = sonicspec("report", str(ds), "-o", str(folder / "r1.html"))
    table.add("report: a FLAC deleted", "exit 1 naming the file",
              f"exit {r.code}: {first_line(r.err)}",
              r.code == 1 and flac.relative_to(ds).as_posix() in r.err, r)
    shutil.copy(built / flac.relative_to(ds), flac)
    meta = sorted(ds.glob("train/*/metadata.json"))[0]
    meta.write_text("{}")
    r = sonicspec("report", str(ds), "-o", str(folder / "r2.html"))
    table.add("report: an empty metadata.json", "exit 1 naming the file",
              f"exit {r.code}: {first_line(r.err)}", r.code == 1 and "(empty)" in r.err, r)
    spec = write_spec(folder)
    short = folder / "short.yaml"
    short.write_text(spec.read_text().replace("duration_s: 10.0", "duration_s: 6.0")
                     .replace("utterance_gap_s: [0.0, 2.0]", "utterance_gap_s: [0.0, 8.0]"))
    r = sonicspec("validate", str(short))
    table.add("validate: a clip no utterance fits after the longest gap", "exit 2 (the build "
              "failed 39 s in)", f"exit {r.code}: {first_line(r.out + r.err)}",
              r.code == 2 and "utterance_gap_s" in r.out + r.err, r)
    empty = base / "nodata"
    empty.mkdir()
    shutil.copy(ROOT / "specs" / "sonicset.yaml", empty / "sonicset.yaml")
    r = sonicspec("plan", str(empty / "sonicset.yaml"), "--summary")
    table.add("plan --summary of the SonicSet preset, no data", "exit 0, '?', what to get",
              f"exit {r.code}; {'says what to download' if 'to build it, get:' in r.out else '-'}",
              r.code == 0 and "to build it, get:" in r.out, r)
    group = sorted(ds.glob("test/*/metadata.json"))[0].parent
    m = json.loads((group / "metadata.json").read_text())
    mixes = [x for x in m["mixtures"] if x["task"] == "enhancement"]
    n, rate = m["num_samples"], m["sample_rate_hz"]
    for name, fill in (("nan", np.nan), ("zeros", 0.0)):
        est = folder / f"est_{name}" / group.relative_to(ds)
        est.mkdir(parents=True)
        for x in mixes:
            data = np.zeros(n) if fill == 0.0 else np.full(n, 0.01)
            if name == "nan":
                data[n // 2] = fill
            sf.write(str(est / f"{x['name']}.wav"), data, rate, subtype="FLOAT")
        r = sonicspec("evaluate", str(ds), "--split", "test", "--task", "enhancement",
                      "--estimates", str(folder / f"est_{name}"), "--metrics", "si_snr", "sdr",
                      "pesq_wb", "-o", str(folder / f"scores_{name}"))
        if name == "nan":
            table.add("evaluate: an estimate with a NaN", "exit 2 naming the file",
                      f"exit {r.code}: {first_line(r.err)}",
                      r.code == 2 and "not finite" in r.err, r)
        else:
            warned = next((x for x in r.err.splitlines() if "are silent" in x), "")
            table.add("evaluate: all-zero estimates", "scored as undefined, counted, exit 0",
                      f"exit {r.code}: {warned[:110]}", r.code == 0 and bool(warned), r)
    r = sonicspec("--help")
    table.add("sonicspec --help", "no internal `job` command listed",
              "job listed" if re.search(r"^\s+job\b", r.out, re.M) else "not listed",
              not re.search(r"^\s+job\b", r.out, re.M), r)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="no kills, no edits table")
    args = parser.parse_args()
    table = Table()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        work = base / "main"
        work.mkdir()
        spec = write_spec(work)
        b = sonicspec("build", str(spec), "--cores", "2")
        table.add("fresh build", "every job runs", f"exit {b.code}, {ran(b.err)} jobs run",
                  b.code == 0, b)
        fresh = b
        reference = digest(work / "out")
        b = sonicspec("build", str(spec), "--cores", "2")
        checked = re.search(r"checked [^\n]*", b.err)
        table.add("rebuild, nothing changed", "no job runs, nothing re-read",
                  f"exit {b.code}, {ran(b.err)} jobs run; {checked.group(0) if checked else '?'}",
                  b.code == 0 and " 0 jobs run" in b.err and "0 re-read" in b.err, b)
        damage_rows(table, work, spec, reference)
        bitrot_rows(table, work, spec, reference)
        input_fault_rows(table, base)
        io_rows(table, base)
        if not args.quick:
            truncated_clip_row(table, base)
            head_kill_rows(table, work, spec, reference)
            edits = base / "edits"
            shutil.copytree(work, edits)
            espec = edits / "demo.yaml"
            for section, old, new in EDITS:
                espec.write_text(espec.read_text().replace(old, new, 1))
                predicted = json.loads(sonicspec("plan", str(espec), "--json").out)["steps"]
                want = {s: c["added"] for s, c in predicted.items() if c["added"]}
                b = sonicspec("build", str(espec), "--cores", "2")
                got = {s: int(n) for s, n in re.findall(r"(\w+) (\d+)", ran(b.err).split("(")[-1])}
                table.add(f"edit: {section}", "runs exactly the jobs plan predicts",
                          f"plan {sum(want.values())} new, build ran {ran(b.err)}",
                          b.code == 0 and got == want, b)
            kill_rows(table, base, reference)
        concurrent_row(table, base)
        bad_input_rows(table, base)
        issue28_rows(table, base, work, fresh)
    print()
    print(table.markdown())
    print(f"\n$ python bench/bench_trust.py{' --quick' if args.quick else ''}   "
          f"# {os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}")


if __name__ == "__main__":
    main()
