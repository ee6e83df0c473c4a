"""Benchmark (issue 16): planning 10^6 groups, time and peak memory.

Writes ``specs/demo.yaml`` with 1,000,000 groups (train 999,998, val 1, test 1: the most the
spec allows in all splits together) and the default ``groups_per_shard`` (4, so 250,002 shards
and 1,500,022 jobs) into a fresh temporary folder, in two variants: the demo's one procedural
room for train, and train spread over eight procedural rooms. For each it measures, each in
its own child process:

- ``compile_spec``: loading the spec and compiling the plan (wall time inside the child);
- ``Plan.write``: the plan file ``sonicspec build`` hands Snakemake (peak RSS: the same
  process, compile included);
- ``sonicspec plan SPEC``: the whole command (summary, compile, what changed since the last
  build, what the store holds), wall time around the child.

Peak memory is the child's maximum resident set size as the kernel reports it to its parent
(``os.wait4``), so each row is one process and nothing else. The last column is a SHA-256 over
every job key in plan order: it must not change between commits (``--tree`` runs an older
checkout, e.g. a ``git archive`` of it, to compare).

``--limits`` measures instead what the spec's bounds protect: the walkable-area grid of square
shoeboxes (memory grows with the floor area, hence ``MAX_FLOOR_AREA_M2``), the tracer at 10^5
and 10^6 rays (time grows with the rays, memory does not: rays go in batches of 8,192), and
``sonicspec validate`` on an alias bomb and on a 64 MiB (sparse) file.

Reproduce:
    python bench/bench_plan.py                     # about 2 min on 2 cores
    python bench/bench_plan.py --tree /tmp/old     # the same against another source tree
    python bench/bench_plan.py --groups 100000     # smaller
    python bench/bench_plan.py --limits            # the bounds' reasons, about 1 min
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

COMPILE = """
import hashlib, json, resource, sys, time
from pathlib import Path
t0 = time.perf_counter()
from sonicspec.plan.compile import compile_spec
from sonicspec.spec import load_spec
loaded = load_spec(sys.argv[1])
t1 = time.perf_counter()
plan = compile_spec(loaded, cache=False)
t2 = time.perf_counter()
rss_compile = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
plan.write(Path(sys.argv[2]))
t3 = time.perf_counter()
digest = hashlib.sha256("\\n".join(j.key for j in plan.jobs).encode()).hexdigest()
print(json.dumps({"jobs": len(plan.jobs), "load_s": t1 - t0, "compile_s": t2 - t1,
                  "write_s": t3 - t2, "rss_compile": rss_compile,
                  "plan_bytes": Path(sys.argv[2]).stat().st_size, "digest": digest}))
"""

# --limits: what the spec's bounds protect, each in its own child (peak RSS of that child).
NAVIGATION = """
import sys, time
from sonicspec.geometry.navigation import build_navigation
from sonicspec.geometry.procedural import shoebox
side = float(sys.argv[1])
t0 = time.perf_counter()
build_navigation(shoebox([side, side, 3.0]))
print(time.perf_counter() - t0)
"""
TRACER = """
import sys, time
import numpy as np
from sonicspec.acoustics.late.raytrace import RayTraceSettings, trace_rays
from sonicspec.testing.rooms import shoebox, uniform_scene
scene = uniform_scene(*shoebox(6.0, 4.8, 3.0), alpha=0.2)
def run(n):
    t0 = time.perf_counter()
    trace_rays(scene, np.array([1.0, 1.0, 1.5]), np.array([[2.0, 2.0, 1.5], [3.0, 1.5, 1.5]]),
               np.random.default_rng(1), RayTraceSettings(n_rays=n, max_time_s=1.0))
    return time.perf_counter() - t0
run(1000)  # compile the kernels first
print(run(int(sys.argv[1])))
"""
EXTRA_ROOMS = 7  # the second variant's train split uses the living room and 7 more


def write_spec(folder: Path, groups: int, rooms: int) -> Path:
    """The demo spec with ``groups`` groups in all, train over ``rooms`` procedural rooms."""
    text = (ROOT / "specs" / "demo.yaml").read_text()
    text = text.replace("  groups_per_shard: 2\n", "")  # the default, 4
    scenes = "living_room" + (", 'extra*'" if rooms > 1 else "")
    text = text.replace("train: {groups: 4, scenes: [living_room]}",
                        f"train: {{groups: {groups - 2}, scenes: [{scenes}]}}")
    extra = "".join(
        f"  - {{kind: shoebox, id: extra{k}, size_m: [{5 + k}, 4, 3]}}\n"
        for k in range(rooms - 1)
    )
    text = text.replace("\nmicrophone:", f"{extra}\nmicrophone:", 1)
    path = folder / f"plan-{groups}-{rooms}rooms.yaml"
    path.write_text(text)
    return path


def run_child(cmd: list[str], env: dict[str, str], cwd: str, expect: int = 0
              ) -> tuple[float, int, str]:
    """(wall s, peak RSS in bytes, stdout) of one child process.

    ``cwd`` must not hold a ``sonicspec`` package: ``-c`` and ``-m`` put it first on the path.
    """
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=err, cwd=cwd)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != expect:
            err.seek(0)
            raise SystemExit(f"{cmd[-2]} {cmd[-1]}: exit {proc.returncode}\n{err.read()}")
        out.seek(0)
        return wall, usage.ru_maxrss * 1024, out.read()


def billion_laughs() -> str:
    lines = ["sonicspec: 1", "a0: &a0 [" + ", ".join(["lol"] * 9) + "]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    return "\n".join([*lines, "name: *a9", ""])


def limits(env: dict[str, str]) -> None:
    """The bounds' reasons, measured: walkable grid vs floor size, tracer vs rays, inputs."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-limits-") as tmp:
        for side in (25, 50, 100):
            _, rss, out = run_child([sys.executable, "-c", NAVIGATION, str(side)], env, tmp)
            rows.append((f"walkable grid of a {side} m x {side} m x 3 m shoebox", float(out), rss))
        for n in (100_000, 1_000_000):
            _, rss, out = run_child([sys.executable, "-c", TRACER, str(n)], env, tmp)
            rows.append((f"trace {n:,} rays, 6 m room (kernels compiled)", float(out), rss))
        bomb = Path(tmp) / "bomb.yaml"
        bomb.write_text(billion_laughs())
        big = Path(tmp) / "big.yaml"
        with big.open("wb") as fh:
            fh.truncate(64 << 20)
        for path, what in ((bomb, "billion laughs (9 x 9 aliases)"), (big, "a 64 MiB file")):
            cmd = [sys.executable, "-m", "sonicspec.cli", "validate", str(path)]
            wall, rss, out = run_child(cmd, env, tmp, expect=2)
            rows.append((f"sonicspec validate: {what} (exit 2)", wall, rss))
    print("| measured | wall s | peak RSS MB |")
    print("|---|---|---|")
    for what, wall, rss in rows:
        print(f"| {what} | {wall:.1f} | {rss / 1e6:,.0f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", type=int, default=1_000_000)
    ap.add_argument("--tree", default=str(ROOT), help="source tree to import sonicspec from")
    ap.add_argument("--limits", action="store_true",
                    help="measure what the spec's bounds protect instead of planning")
    args = ap.parse_args(argv)
    env = {**os.environ, "PYTHONPATH": os.path.abspath(args.tree)}
    if args.limits:
        limits(env)
        print("\nreproduce: python bench/bench_plan.py --limits")
        return 0
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-plan-") as tmp:
        for rooms in (1, 1 + EXTRA_ROOMS):
            spec = write_spec(Path(tmp), args.groups, rooms)
            plan_file = Path(tmp) / "plan.json"
            _, rss, out = run_child([sys.executable, "-c", COMPILE, str(spec), str(plan_file)],
                                    env, tmp)
            info = json.loads(out)
            rows.append((rooms, "compile_spec (load + compile)", info["jobs"],
                         info["load_s"] + info["compile_s"], info["rss_compile"],
                         info["digest"][:16]))
            rows.append((rooms, f"then Plan.write ({info['plan_bytes'] / 1e6:,.0f} MB file)",
                         info["jobs"], info["write_s"], rss, ""))
            plan_file.unlink()
            wall, rss, _ = run_child([sys.executable, "-m", "sonicspec.cli", "plan", str(spec)],
                                     env, tmp)
            rows.append((rooms, "sonicspec plan SPEC", info["jobs"], wall, rss, ""))
    print(f"{args.groups:,} groups, groups_per_shard 4; tree {args.tree}; "
          f"Python {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f} at the end")
    print()
    print("| rooms in train | measured | jobs | wall s | peak RSS MB | keys digest |")
    print("|---|---|---|---|---|---|")
    for rooms, what, jobs, wall, rss, digest in rows:
        print(f"| {rooms} | {what} | {jobs:,} | {wall:.1f} | {rss / 1e6:,.0f} | {digest} |")
    print()
    print(f"reproduce: python bench/bench_plan.py --groups {args.groups}"
          + (f" --tree {args.tree}" if Path(args.tree).resolve() != ROOT else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
