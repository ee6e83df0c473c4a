"""Benchmark (issue 27): CPU per group of the render, mix and export steps, two code
revisions side by side on the same inputs, and whether their outputs are the same bytes.

The spec is (``--spec cheap``) ``bench_scale.py``'s cheap build (the demo at 100 rays,
image-source order 1, 0.2 s RIRs, 1 m RIR spacing, ``--seconds`` groups of 2 talkers + noise
+ music) cut to ``--groups`` groups (all but two in one train shard), or (``--spec demo``)
the tests' cut-down demo (``tests/build_cases.write_spec``). Its steps up to ``rir`` are built once
(by this checkout, in a child process); then each revision — ``--against`` (a git revision,
extracted with ``git archive``; default ``main``) and this checkout — runs in its own child
process (``PYTHONPATH`` = its tree) on a copy of that store: its numba kernels are compiled
first (``sonicspec.stages.warm``, not counted), then every remaining job runs in plan order
through ``sonicspec.stages.run_job`` and each job's CPU is its ``getrusage`` (user + system)
around the call. Printed: CPU s per group of the train shard's render, mix and export jobs
for both revisions, the ratio, and whether each render artifact's files and the dataset's
``checksums.sha256`` are byte-identical.

Run it ``nice`` on a shared machine: CPU seconds stay comparable while wall times do not.

Reproduce:
    nice -n 10 python bench/bench_render_job.py                    # main vs this checkout
    nice -n 10 python bench/bench_render_job.py --groups 8 --against b26bb05
    nice -n 10 python bench/bench_render_job.py --spec demo       # the tests' cut-down demo
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

MEASURED = ("render", "mix", "export")

CHILD = r'''
import hashlib, json, resource, sys
from pathlib import Path

spec, until, out = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
from sonicspec.plan.compile import compile_spec
from sonicspec.spec import load_spec
from sonicspec.stages import run_job

from sonicspec.plan.model import STEPS
from sonicspec.store import ArtifactStore

plan = compile_spec(load_spec(spec))
if until != "all":
    order = [s.name for s in STEPS]
    for job in plan.jobs:  # in dependency order
        if order.index(job.step) <= order.index(until):
            run_job(plan, job.key)
    raise SystemExit(0)

from sonicspec.stages.warm import warm

warm()  # compile this tree's kernels into numba's cache: not counted
measured = set(sys.argv[4].split(","))


def digest(folder: Path) -> str:
    h = hashlib.sha256()
    for f in sorted(folder.rglob("*")):
        if f.is_file():
            h.update(f.relative_to(folder).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()


rows = []
for job in plan.jobs:
    before = resource.getrusage(resource.RUSAGE_SELF)
    ran = run_job(plan, job.key)
    after = resource.getrusage(resource.RUSAGE_SELF)
    if not ran or job.step not in measured:
        continue
    data = ArtifactStore(plan.store_dir).read_data(job.step, job.key)
    groups = len(data["groups"]) if isinstance(data, dict) and "groups" in data else None
    art = Path(plan.store_dir) / job.step / job.key[:2] / f"{job.key}.zarr"
    rows.append({"step": job.step, "label": job.label, "key": job.key, "groups": groups,
                 "cpu_s": (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime),
                 "digest": digest(art) if art.is_dir() else None})
sums = Path(plan.output_dir) / "checksums.sha256"
checksums = sums.read_text() if sums.is_file() else None
out.write_text(json.dumps({"jobs": rows, "checksums": checksums}))
'''


def _tree(rev: str, into: Path) -> Path:
    """``rev`` of this repository extracted into ``into`` (``git archive``)."""
    shutil.rmtree(into, ignore_errors=True)
    into.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def _child(tree: Path, spec: Path, until: str, out: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run([sys.executable, "-c", CHILD, str(spec), until, str(out),
                           ",".join(MEASURED)], env=env, cwd=tree, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise SystemExit(f"{tree}: {until} failed\n{done.stderr[-4000:]}")


def _groups_of(plan_jobs: list[dict], label: str) -> int:
    return next(r["groups"] for r in plan_jobs if r["label"] == label)


def main() -> None:
    from bench_scale import cheap_spec

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--groups", type=int, default=8,
                        help="groups in all (2 held out: one val, one test; default 8)")
    parser.add_argument("--seconds", type=float, default=5.0, help="seconds per group")
    parser.add_argument("--against", default="main",
                        help="the git revision to compare with (default: main)")
    parser.add_argument("--spec", choices=("cheap", "demo"), default="cheap",
                        help="cheap: bench_scale.py's cheap build (default); demo: the tests' "
                             "cut-down demo (tests/build_cases.write_spec: 2 + 1 + 1 groups "
                             "of 10 s, 600 rays, image-source order 2, 0.4 s RIRs)")
    parser.add_argument("--keep", type=Path, help="work here (kept) instead of a temp folder")
    args = parser.parse_args()
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.against],
                         check=True, capture_output=True, text=True).stdout.strip()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                          check=True, capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "sonicspec"],
                           check=True, capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="bench-render-job-") as tmp:
        work = (args.keep or Path(tmp)).resolve()
        work.mkdir(parents=True, exist_ok=True)
        if args.spec == "demo":
            sys.path.insert(0, str(ROOT / "tests"))
            from build_cases import write_spec

            text = write_spec(work).read_text()
        else:
            text = cheap_spec(args.groups, args.seconds)
        base = work / "base"
        base.mkdir(exist_ok=True)
        (base / "cheap.yaml").write_text(text)
        _child(ROOT, base / "cheap.yaml", "rir", work / "base.json")
        results = {}
        trees = {f"{rev} (--against)": _tree(rev, work / "tree-old"),
                 f"{head}{'+' if dirty else ''} (this checkout)": ROOT}
        for n, (name, tree) in enumerate(trees.items()):
            folder = work / f"run{n}"
            shutil.rmtree(folder, ignore_errors=True)
            shutil.copytree(base, folder)  # the store and the generated corpora beside it
            _child(tree, folder / "cheap.yaml", "all", folder / "result.json")
            results[name] = json.loads((folder / "result.json").read_text())
    (old_name, old), (new_name, new) = results.items()
    train = next(r["label"] for r in new["jobs"] if r["step"] == "render"
                 and r["label"].startswith("render train"))
    shard = train.split(" ", 1)[1]
    groups = _groups_of(new["jobs"], train)
    what = (f"cheap build, {args.groups} groups of {args.seconds:g} s" if args.spec == "cheap"
            else "the tests' cut-down demo")
    print(f"{what}; the train shard "
          f"({shard}, {groups} groups); CPU s per group (getrusage of the job):")
    print(f"| step | {old_name} | {new_name} | ratio | same artifact bytes |")
    print("|---|---|---|---|---|")
    for step in MEASURED:
        label = f"{step} {shard}"
        a = next((r for r in old["jobs"] if r["label"] == label), None)
        b = next((r for r in new["jobs"] if r["label"] == label), None)
        if a is None or b is None:
            print(f"| {step} | {'—' if a is None else ''} | {'—' if b is None else ''} | | |")
            continue
        print(f"| {step} | {a['cpu_s'] / groups:.3f} | {b['cpu_s'] / groups:.3f} | "
              f"{a['cpu_s'] / b['cpu_s']:.2f}x | {a['digest'] == b['digest']} |")
    keyed_old = {r["label"]: r for r in old["jobs"]}
    same = all(keyed_old.get(r["label"], {}).get("digest") == r["digest"] for r in new["jobs"])
    print(f"every measured job's artifact the same bytes: {same}; dataset checksums.sha256 "
          f"the same: {old['checksums'] is not None and old['checksums'] == new['checksums']}")
    print(f"\ncommand: python bench/{Path(__file__).name} {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
