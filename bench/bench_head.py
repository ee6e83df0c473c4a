"""Benchmark (issue 27, items 3 and 4): what a build's head costs on a big store.

- ``noop``: a synthetic store laid out like a built plan (per shard of 16 groups a placement,
  rir, render, mix and export artifact, one dataset artifact; 8 dataset files per group; each
  export artifact's JSON carries ``--payload-kb`` of per-group tracks, as the real metadata
  does), at 10^3 and 10^4 groups. Measures a no-op rebuild's check
  (``check_existing`` + ``present_keys`` + the check cache's load and save, what
  ``sonicspec build`` does before it would start Snakemake) in a child process: the first
  check (cold cache: every artifact verified, every file hashed) and the second (nothing
  changed), wall and CPU seconds, and how many artifact records it read.
- ``head``: the build head's progress loop while ``--waiting`` jobs wait (Snakemake replaced
  by a process that sleeps, two jobs writing progress): the head's CPU seconds per second of
  polling (``poll_s`` 0.1 s, scaled to the default 1 s poll).

- ``dag``: Snakemake's DAG for a synthetic plan of ``--groups`` (the ``noop`` layout, nothing
  built): ``snakemake --dry-run`` as ``sonicspec build --dry-run`` runs it, wall and CPU
  seconds and peak RSS of the Snakemake process (it reads the plan, builds the DAG, checks
  every output), in each of ``--layouts``: ``jobs`` (one Snakemake job per plan job, the
  layout of plans up to 20,000 jobs), ``grouped`` (the same with the SLURM profile's
  ``--groups``/``--group-components``) and ``batched`` (``sonicspec.plan.batches``: shards in
  batches, Snakemake reading the layout file; the head's cost of writing it is shown).

- ``warm``: what compiling the kernels once saves a job. Builds the tests' cut-down demo
  (``tests/build_cases.py``) up to ``render``, then reruns one rir and one render job
  (``sonicspec job``, its artifact removed first) with numba's cache (a) empty, (b) warmed by
  ``sonicspec.stages.warm.warm`` only, (c) warm from a real job: wall seconds of each job.

``--code DIR`` runs the measured child processes with another source tree first on the path
(e.g. ``/work/main``) for a before/after figure.

Reproduce:
    python bench/bench_head.py noop --groups 1000 10000
    python bench/bench_head.py head --waiting 1000
    python bench/bench_head.py noop --groups 1000 --code /work/main   # before
    python bench/bench_head.py dag --groups 100000 1000000 --layouts jobs grouped batched
    python bench/bench_head.py warm
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PER_SHARD = 16
FILES_PER_GROUP = 8

CHECK = """
import json, resource, sys, time
from pathlib import Path
t0 = time.perf_counter(); r0 = resource.getrusage(resource.RUSAGE_SELF)
from sonicspec.plan.model import Plan
from sonicspec.stages.checked import CheckCache
from sonicspec.stages.repair import check_existing, present_keys
from sonicspec.store import ArtifactStore
plan = Plan.read(Path(sys.argv[1]))
t1 = time.perf_counter(); r1 = resource.getrusage(resource.RUSAGE_SELF)
store = ArtifactStore(plan.store_dir)
cache = CheckCache.of_store(plan.store_dir)
report = check_existing(plan, store, cache)
cache.save()
present = present_keys(plan, store)
t2 = time.perf_counter(); r2 = resource.getrusage(resource.RUSAGE_SELF)
cpu = lambda a, b: b.ru_utime + b.ru_stime - a.ru_utime - a.ru_stime
print(json.dumps({"wall": t2 - t1, "cpu": cpu(r1, r2), "read_plan": t1 - t0,
                  "present": len(present), "findings": len(report.findings),
                  "verified": report.artifacts_verified, "hashed": report.files_hashed,
                  "records_read": getattr(report, "records_read", None),
                  "rss_mb": r2.ru_maxrss / 1024}))
"""

HEAD = """
import io, json, resource, sys, time
from pathlib import Path
import sonicspec.stages.workflow as wf
from sonicspec.plan.model import Plan
from sonicspec.store import ArtifactStore
plan = Plan.read(Path(sys.argv[1]))
seconds = float(sys.argv[2])
wf.snakemake_command = lambda *a, **k: [sys.executable, "-c",
                                        f"import time; time.sleep({seconds})"]
polls = [0]
sleep = time.sleep
def counted(s):
    polls[0] += 1
    sleep(s)
wf.time.sleep = counted
store = ArtifactStore(plan.store_dir)
from sonicspec.stages.repair import present_keys
present = present_keys(plan, store)
stream = io.StringIO()
r0 = resource.getrusage(resource.RUSAGE_SELF); t0 = time.perf_counter()
wf._run_snakemake(plan, store, present, cores=1, profile=None, dry_run=False, stream=stream,
                  poll_s=0.1, on_start=None, snakemake_args=None, start=time.monotonic())
r1 = resource.getrusage(resource.RUSAGE_SELF); t1 = time.perf_counter()
cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
lines = [x for x in stream.getvalue().splitlines() if x.startswith("[")]
print(json.dumps({"wall": t1 - t0, "cpu": cpu, "polls": polls[0],
                  "last_line": lines[-2] if len(lines) > 1 else ""}))
"""


def _child(code: Path, script: str, *args: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(code)}
    # cwd: ``python -c`` puts the working folder first on the path
    done = subprocess.run([sys.executable, "-c", script, *args], env=env, cwd=code,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"child failed: {done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def synthetic_plan(folder: Path, groups: int, waiting: int = 0, per_shard: int = PER_SHARD):
    """A plan shaped like a built one (see the module docstring); ``waiting`` extra rir jobs
    that are not built."""
    from sonicspec.plan.model import Job, Plan

    jobs = []
    exports = []
    for n, first in enumerate(range(0, groups, per_shard)):
        ids = [f"train/{g}" for g in range(first, min(first + per_shard, groups))]
        placement = Job("placement", {"groups": ids, "shard": n}, (), f"placement {n}")
        rir = Job("rir", {"shard": n}, (placement.key,), f"rir train/{n}")
        render = Job("render", {"shard": n}, (rir.key,), f"render train/{n}")
        mix = Job("mix", {"shard": n}, (render.key,), f"mix train/{n}")
        export = Job("export", {"groups": ids, "shard": n}, (mix.key,), f"export train/{n}")
        jobs += [placement, rir, render, mix, export]
        exports.append(export)
    dataset = Job("dataset", {"name": "bench"}, tuple(e.key for e in exports), "dataset")
    jobs.append(dataset)
    first_placement = jobs[0]
    extra = [Job("rir", {"waiting": w}, (first_placement.key,), f"rir waiting/{w}")
             for w in range(waiting)]
    jobs[1:1] = extra
    return Plan("bench", 1, str(folder / "store"), str(folder / "out"), "0" * 64,
                tuple(jobs)), set(j.key for j in extra)


def write_store(folder: Path, groups: int, payload_kb: int, waiting: int = 0) -> Path:
    """Build the synthetic store and dataset folder; returns the plan's path."""
    sys.path.insert(0, str(ROOT))
    from sonicspec.store import ArtifactStore

    plan, unbuilt = synthetic_plan(folder, groups, waiting)
    store = ArtifactStore(plan.store_dir)
    out = Path(plan.output_dir)
    rng = np.random.default_rng(1)
    arrays = {
        "placement": {"mic": rng.random((PER_SHARD, 3))},
        "rir": {"rirs": rng.random((PER_SHARD, 4, 2000), dtype=np.float32),
                "points": rng.random((PER_SHARD, 4, 3)), "index": np.arange(PER_SHARD)},
        "render": {"tracks": rng.random((PER_SHARD, 5, 4000), dtype=np.float32),
                   "gains": rng.random(PER_SHARD)},
        "mix": {"mixtures": rng.random((PER_SHARD, 3, 4000), dtype=np.float32),
                "levels": rng.random(PER_SHARD)},
        "export": {"peaks": rng.random(PER_SHARD)},
        "dataset": {"count": np.arange(1)},
    }
    floats = max(1, payload_kb * 1024 // 20)
    track = [round(float(x), 15) for x in rng.random(floats)]
    manifests = []
    for job in plan.jobs:
        if job.key in unbuilt:
            continue
        data: dict = {}
        if job.step == "export":
            data["groups"] = []
            for gid in job.params["groups"]:
                files = []
                for f in range(FILES_PER_GROUP):
                    rel = f"{gid}/file{f}.bin"
                    body = rng.bytes(512)
                    path = out / rel
                    path.parent.mkdir(parents=True, exist_ok=True)
                    path.write_bytes(body)
                    files.append({"path": rel, "bytes": len(body),
                                  "sha256": hashlib.sha256(body).hexdigest()})
                data["groups"].append({"id": gid, "files": files, "tracks": track})
        if job.step == "dataset":
            body = b"manifest\n" * 100
            for name in ("dataset.json", "train.jsonl"):
                (out / name).write_bytes(body)
                manifests.append({"path": name, "bytes": len(body),
                                  "sha256": hashlib.sha256(body).hexdigest()})
            data["files"] = manifests
        store.write(job.step, job.key, arrays[job.step], data=data, params=job.params,
                    input_keys=job.inputs)
    return plan.write(folder / "plan.json")


def _du_gb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 1e9


def noop(groups: list[int], payload_kb: int, code: Path) -> None:
    print(f"| groups | jobs | store GB | check | wall s | CPU s | artifacts verified | files "
          f"hashed | export records read | peak RSS MB |  (code: {code})")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in groups:
        with tempfile.TemporaryDirectory(prefix="bench-head-") as tmp:
            t = time.perf_counter()
            plan_path = write_store(Path(tmp), n, payload_kb)
            made = time.perf_counter() - t
            jobs = sum(1 for line in plan_path.read_text().splitlines() if '"key": ' in line)
            size = _du_gb(Path(tmp) / "store")
            for what in ("first (cold cache)", "no-op (warm cache)", "no-op again"):
                r = _child(code, CHECK, str(plan_path))
                print(f"| {n:,} | {jobs:,} | {size:.2f} | {what} | {r['wall']:.2f} | "
                      f"{r['cpu']:.2f} | {r['verified']} | {r['hashed']} | "
                      f"{r['records_read']} | {r['rss_mb']:.0f} |", flush=True)
            print(f"(store written in {made:.0f} s)", file=sys.stderr)


def head(waiting: int, groups: int, seconds: float, code: Path) -> None:
    with tempfile.TemporaryDirectory(prefix="bench-head-") as tmp:
        plan_path = write_store(Path(tmp), groups, 1, waiting=waiting)
        sys.path.insert(0, str(ROOT))
        from sonicspec.plan.model import Plan
        from sonicspec.stages.context import progress_path

        plan = Plan.read(plan_path)
        running = [j for j in plan.jobs if j.label.startswith("rir waiting/")][:2]
        for job in running:
            path = progress_path(plan.store_dir, job.key)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("group 1/16: 15 points, 8,192/600 rays")
        r = _child(code, HEAD, str(plan_path), str(seconds))
        per_poll = r["cpu"] / r["polls"]
        print(f"| {waiting:,} waiting, {groups:,} groups built | {r['polls']} polls in "
              f"{r['wall']:.1f} s | head CPU {r['cpu']:.2f} s | {per_poll * 1000:.2f} ms per "
              f"poll = {per_poll:.4f} CPU-s per second at poll_s 1 |  (code: {code})")
        print(f"last progress line: {r['last_line']}")


GROUPED = ["--groups", "placement=prep", "arrange=prep", "rir=rir", "render=shard", "mix=shard",
           "export=shard", "--group-components", "prep=16", "rir=8", "shard=8"]
"""The SLURM profile's job grouping, passed on the command line (``grouped`` layout)."""

LAYOUT = """
import json, resource, sys, time
from pathlib import Path
from sonicspec.plan.batches import auto_shards_per_batch, batch_plan
from sonicspec.plan.model import Plan
from sonicspec.stages.batch import write_layout
path = Path(sys.argv[1])
n = None if sys.argv[2] == "auto" else int(sys.argv[2])
plan = Plan.read(path)
t0 = time.perf_counter(); r0 = resource.getrusage(resource.RUSAGE_SELF)
n = auto_shards_per_batch(plan) if n is None else n
batches = batch_plan(plan, n)
write_layout(plan, path, batches, Path(sys.argv[3]))
t1 = time.perf_counter(); r1 = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"wall": t1 - t0, "cpu": r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime,
                  "batches": len(batches), "shards_per_batch": n}))
"""


def _dry_run(cmd: list[str], cwd: str, env: dict) -> tuple[float, float, float]:
    """Wall s, CPU s and peak RSS MB of one Snakemake dry run (a child of a fresh child, so
    its RSS is not mixed with an earlier run's)."""
    script = ("import json, resource, subprocess, sys, time\n"
              "t = time.perf_counter()\n"
              "done = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
              "wall = time.perf_counter() - t\n"
              "r = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
              "if done.returncode:\n"
              "    sys.exit(done.stdout[-2000:] + done.stderr[-2000:])\n"
              "print(json.dumps([wall, r.ru_utime + r.ru_stime, r.ru_maxrss / 1024]))\n")
    done = subprocess.run([sys.executable, "-c", script, *cmd], cwd=cwd, env=env,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"snakemake failed: {done.stderr[-4000:]}")
    return tuple(json.loads(done.stdout.strip().splitlines()[-1]))


def dag(groups: list[int], code: Path, per_shard: int, layouts: list[str],
        shards_per_batch: str) -> None:
    """Snakemake's dry run of each plan size in each layout, one after another."""
    sys.path.insert(0, str(ROOT))
    from sonicspec.stages.workflow import snakemake_command

    print(f"| groups | groups per shard | plan jobs | layout | Snakemake jobs | head: layout "
          f"written s (CPU s) | dry run wall s | dry run CPU s | peak RSS MB |  (code: {code})")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in groups:
        with tempfile.TemporaryDirectory(prefix="bench-head-") as tmp:
            plan, _ = synthetic_plan(Path(tmp), n, per_shard=per_shard)
            Path(plan.store_dir).mkdir(parents=True)
            path = plan.write(Path(tmp) / "plan.json")
            env = {**os.environ, "PYTHONPATH": str(code)}
            for layout in layouts:
                extra, layout_path, head, seen = [], None, "—", len(plan.jobs)
                if layout == "grouped":
                    extra = GROUPED
                elif layout == "batched":
                    layout_path = Path(tmp) / "layout.json"
                    r = _child(code, LAYOUT, str(path), shards_per_batch, str(layout_path))
                    head = f"{r['wall']:.1f} ({r['cpu']:.1f})"
                    seen = r["batches"] + 1
                    layout = f"batched, {r['shards_per_batch']} shards per batch"
                cmd = snakemake_command(path, plan, cores=1, profile=None, dry_run=True,
                                        extra=extra, layout=layout_path)
                wall, cpu, rss = _dry_run(cmd, plan.store_dir, env)
                print(f"| {n:,} | {per_shard} | {len(plan.jobs):,} | {layout} | {seen:,} | "
                      f"{head} | {wall:.1f} | {cpu:.1f} | {rss:.0f} |", flush=True)


def warm_saving(code: Path) -> None:
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "tests"))
    import shutil

    from build_cases import plan_for, write_spec

    from sonicspec.stages.workflow import build
    from sonicspec.store import ArtifactStore

    with tempfile.TemporaryDirectory(prefix="bench-head-") as tmp:
        folder = Path(tmp)
        plan = plan_for(write_spec(folder)).until("render")
        result = build(plan, cores=2, stream=io.StringIO())
        if result.code != 0:
            raise SystemExit("the demo build failed")
        plan_path = plan.write(folder / "plan.json")
        store = ArtifactStore(plan.store_dir)
        env = {**os.environ, "PYTHONPATH": str(code)}
        print(f"| job | empty cache s | cache warmed by stages.warm s | warm from a job s |  "
              f"(code: {code})")
        print("|---|---|---|---|")
        for step in ("rir", "render"):
            job = plan.by_step()[step][0]
            times = []
            for case in ("empty", "warmed", "job"):
                cache = folder / f"numba-{step}-{case if case != 'job' else 'warmed'}"
                if case == "empty":
                    shutil.rmtree(cache, ignore_errors=True)
                if case == "warmed":
                    shutil.rmtree(cache, ignore_errors=True)
                    subprocess.run([sys.executable, "-c",
                                    "from sonicspec.stages.warm import warm; warm()"],
                                   env={**env, "SONICSPEC_NUMBA_CACHE_DIR": str(cache)},
                                   cwd=code, check=True, capture_output=True)
                store.remove(step, job.key)
                t = time.perf_counter()
                subprocess.run([sys.executable, "-m", "sonicspec.cli", "job", "--plan",
                                str(plan_path), job.key],
                               env={**env, "SONICSPEC_NUMBA_CACHE_DIR": str(cache)}, cwd=code,
                               check=True, capture_output=True)
                times.append(time.perf_counter() - t)
            print(f"| {job.label} | {times[0]:.1f} | {times[1]:.1f} | {times[2]:.1f} |",
                  flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=["noop", "head", "dag", "warm"])
    parser.add_argument("--groups", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--payload-kb", type=int, default=100,
                        help="JSON of per-group tracks in each export artifact (real: MBs)")
    parser.add_argument("--waiting", type=int, default=1000)
    parser.add_argument("--per-shard", type=int, default=PER_SHARD,
                        help="groups per shard of the dag section's plan")
    parser.add_argument("--layouts", nargs="+", default=["jobs", "batched"],
                        choices=["jobs", "grouped", "batched"],
                        help="dag: one Snakemake job per plan job (today's default), the same "
                             "with the SLURM profile's grouping, or batched shards")
    parser.add_argument("--shards-per-batch", default="auto",
                        help="dag, batched layout: shards per batch (auto: as a build picks)")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--code", type=Path, default=ROOT)
    args = parser.parse_args()
    if args.what == "noop":
        noop(args.groups, args.payload_kb, args.code.resolve())
    elif args.what == "warm":
        warm_saving(args.code.resolve())
    elif args.what == "dag":
        dag(args.groups, args.code.resolve(), args.per_shard, args.layouts,
            args.shards_per_batch)
    else:
        head(args.waiting, args.groups[0], args.seconds, args.code.resolve())
    print(f"\ncommand: python bench/{Path(__file__).name} {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
