"""Benchmark (issue 6): end-to-end throughput of the demo, cost per step, SonicSet projection.

Copies ``specs/demo.yaml`` into a fresh temporary folder (nothing cached), builds it through
Snakemake with ``run_build(plan, cores=N)`` and reads every job's Snakemake ``benchmark:`` file
(``<store>/benchmarks/<step>/<pre>/<key>.tsv``: wall ``s``, ``cpu_time``, ``max_rss``). Then:

- a second build with the corpora cache warm (``.sonicspec-cache`` kept) but an empty store and
  output folder (``--skip-warm`` leaves it out);
- a build of a spec closer to SonicSet (60 s groups, 3 speakers of 3–5 utterances, 20 000 rays,
  1 s RIRs, 2 train groups; ``--skip-sonicset-like`` leaves it out), whose per-group cost gives
  the second projection.

Snakemake samples a job's process tree every 0.5 s (every 30 s after its first 30 samples), so
its ``cpu_time`` misses up to one interval at the end of a job and ``max_rss`` is a sampled
peak. Each job process therefore also records its exact ``getrusage`` (self + children; peak
RSS of the Python process) through a ``sitecustomize`` put on ``PYTHONPATH`` for the build only;
the table shows both, and the whole build's CPU (Snakemake included) comes from the bench's own
``RUSAGE_CHILDREN``.

Definitions:
- group-clip hours: sum over groups of the clip (mixture) duration;
- written audio hours: every audio file of the dataset folder (sources, targets, noise, music,
  mixtures, RIRs), counted separately;
- throughput: group-clip hours per CPU core-hour (CPU time of all jobs), and per wall
  core-hour (build wall time × cores);
- projection to SonicSet (960 h of group clips, 90 scenes) on 100 cores: per-group steps
  (placement, arrange, rir, render, mix, export, and dataset, which grows with the groups) are
  scaled by the group count, mesh and navigation by the scene count, corpus counted once;
  wall hours = reserved core-hours (threads × wall per job) / 100, i.e. perfect packing.
  Each job is a fresh Python process; the CPU it spends importing (measured apart, per step)
  is paid once per shard, so "start-up amortised" subtracts it from the per-group cost: the
  limit of large shards.

Reproduce:
    python bench/bench_pipeline.py                          # three builds, 8-16 min on 2 cores
    python bench/bench_pipeline.py --skip-warm --skip-sonicset-like
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import platform
import resource
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

STEP_NAMES = ("corpus", "mesh", "navigation", "placement", "arrange", "rir", "render", "mix",
              "export", "dataset")
PER_GROUP = ("placement", "arrange", "rir", "render", "mix", "export", "dataset")
PER_SCENE = ("mesh", "navigation")
SONICSET_HOURS = 960.0
SONICSET_SCENES = 90
CLUSTER_CORES = 100
SONICSIM_RAYS = 50_000

# Edits of specs/demo.yaml for the SonicSet-like build (the corpus gets 6 utterances per
# speaker so that 3-5 utterances per track can be drawn).
SONICSET_LIKE = (
    ("duration_s: 10.0", "duration_s: 60.0"),
    ("  speakers: 2\n", "  speakers: 3\n"),
    ("utterances_per_speaker: [1, 2]", "utterances_per_speaker: [3, 5]"),
    ("rays: 4000", "rays: 20000"),
    ("max_rir_length_s: 1.0", "max_rir_length_s: 1.0"),
    ("train: {groups: 4,", "train: {groups: 2,"),
    ("speakers_per_split: 3, utterances_per_speaker: 4",
     "speakers_per_split: 3, utterances_per_speaker: 6"),
)

# Imported by every Python process of the build (PYTHONPATH); only `sonicspec job ... KEY`
# writes its exact resource usage, at exit, to $SONICSPEC_BENCH_RUSAGE_DIR/KEY.json.
SITECUSTOMIZE = '''
import os, sys
_dir = os.environ.get("SONICSPEC_BENCH_RUSAGE_DIR")
if _dir and len(sys.argv) > 2 and sys.argv[1] == "job":
    import atexit, json, resource

    def _write_rusage(key=sys.argv[-1]):
        s = resource.getrusage(resource.RUSAGE_SELF)
        c = resource.getrusage(resource.RUSAGE_CHILDREN)
        data = {"cpu_s": s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime,
                "maxrss_mb": s.ru_maxrss / 1024, "children_maxrss_mb": c.ru_maxrss / 1024}
        with open(os.path.join(_dir, key + ".json"), "w") as fh:
            json.dump(data, fh)

    atexit.register(_write_rusage)
'''


@dataclass
class JobCost:
    step: str
    threads: int
    wall_s: float
    cpu_s: float  # Snakemake benchmark cpu_time
    max_rss_mb: float  # Snakemake benchmark max_rss (process tree, sampled)
    exact_cpu_s: float | None = None  # getrusage of the job process and its children
    exact_rss_mb: float | None = None  # ru_maxrss of the job's Python process


@dataclass
class BuildResult:
    label: str
    wall_s: float
    cores: int
    total_cpu_s: float  # every process of the build, Snakemake included
    jobs: list[JobCost]
    n_groups: int
    n_scenes: int
    group_hours: float
    audio_hours: dict[str, float]
    load: tuple[float, float]
    rays: int
    groups: dict[str, int] = field(default_factory=dict)

    def steps(self) -> dict[str, list[JobCost]]:
        return {s: [j for j in self.jobs if j.step == s] for s in STEP_NAMES}

    def cpu(self, job: JobCost, exact: bool) -> float:
        return job.exact_cpu_s if exact and job.exact_cpu_s is not None else job.cpu_s


def read_benchmark(path: Path) -> dict[str, float]:
    with open(path) as fh:
        row = next(csv.DictReader(fh, delimiter="\t"))
    return {k: float(row[k]) if row[k] not in ("NA", "") else 0.0
            for k in ("s", "cpu_time", "max_rss")}


def audio_hours(output_dir: Path) -> tuple[dict[str, float], int, float]:
    """Hours of written audio by kind; number of groups and their summed clip hours."""
    import soundfile

    hours = {"sources and targets": 0.0, "noise and music": 0.0, "mixtures": 0.0, "rirs": 0.0}
    group_seconds: dict[Path, float] = {}
    for path in sorted(output_dir.rglob("*")):
        if path.suffix not in (".flac", ".wav") or not path.is_file():
            continue
        info = soundfile.info(str(path))
        seconds = info.frames / info.samplerate
        rel = path.relative_to(output_dir).parts
        if "rirs" in rel:
            kind = "rirs"
        elif "mixtures" in rel:
            kind = "mixtures"
        elif path.stem in ("noise", "music"):
            kind = "noise and music"
        else:
            kind = "sources and targets"
        hours[kind] += seconds / 3600
        group = output_dir / rel[0] / rel[1]
        if kind != "rirs" and (group / "metadata.json").is_file():
            group_seconds[group] = max(group_seconds.get(group, 0.0), seconds)
    return hours, len(group_seconds), sum(group_seconds.values()) / 3600


def build(spec_path: Path, label: str, cores: int, rusage_dir: Path, verbose: bool
          ) -> BuildResult:
    from sonicspec.plan.compile import compile_spec
    from sonicspec.plan.model import STEP_BY_NAME
    from sonicspec.spec import load_spec
    from sonicspec.stages.workflow import run_build

    for old in rusage_dir.glob("*.json"):
        old.unlink()
    plan = compile_spec(load_spec(spec_path))
    load0 = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    stream = sys.stderr if verbose else io.StringIO()
    t0 = time.perf_counter()
    code = run_build(plan, cores=cores, stream=stream)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if code != 0:
        sys.stderr.write(stream.getvalue() if isinstance(stream, io.StringIO) else "")
        raise SystemExit(f"{label}: build failed (exit {code})")
    total_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)

    store = Path(plan.store_dir)
    jobs = []
    for job in plan.jobs:
        bench = read_benchmark(store / "benchmarks" / job.step / job.key[:2] / f"{job.key}.tsv")
        cost = JobCost(job.step, STEP_BY_NAME[job.step].threads, bench["s"],
                       bench["cpu_time"], bench["max_rss"])
        exact = rusage_dir / f"{job.key}.json"
        if exact.is_file():
            data = json.loads(exact.read_text())
            cost.exact_cpu_s = data["cpu_s"]
            cost.exact_rss_mb = max(data["maxrss_mb"], data["children_maxrss_mb"])
        jobs.append(cost)
    hours, n_groups, group_hours = audio_hours(Path(plan.output_dir))
    spec_groups = {s: int(n) for s, n in
                   next(j for j in plan.jobs if j.step == "dataset").params["splits"].items()}
    if n_groups != sum(spec_groups.values()):
        raise SystemExit(f"{label}: found {n_groups} group folders, plan has {spec_groups}")
    n_scenes = sum(1 for j in plan.jobs if j.step == "mesh")
    rays = next(j for j in plan.jobs if j.step == "rir").params["acoustics"]["rays"]
    return BuildResult(label, wall, cores, total_cpu, jobs, n_groups, n_scenes, group_hours,
                       hours, (load0, os.getloadavg()[0]), rays, spec_groups)


def startup_cpu_s(step: str, repeats: int = 3) -> float:
    """CPU seconds a ``sonicspec job`` process of ``step`` spends importing (median of runs):
    the per-job floor that bigger shards amortise over more groups."""
    import subprocess

    times = []
    code = f"import sonicspec.cli, sonicspec.stages, zarr, sonicspec.stages.{step}"
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-c", code], check=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return sorted(times)[len(times) // 2]


def print_build(r: BuildResult, startup: dict[str, float]) -> None:
    steps = r.steps()
    cpu = sum(j.cpu_s for j in r.jobs)
    exact = sum(r.cpu(j, True) for j in r.jobs)
    print(f"\n### {r.label}: {r.n_groups} groups ({r.group_hours * 3600:.0f} s of group clips), "
          f"{r.n_scenes} scenes, {len(r.jobs)} jobs; load average {r.load[0]:.1f} -> "
          f"{r.load[1]:.1f}")
    print(f"wall {r.wall_s:.1f} s on {r.cores} cores; CPU of all jobs {cpu:.1f} s (Snakemake "
          f"benchmarks), {exact:.1f} s (exact getrusage); whole build incl. Snakemake "
          f"{r.total_cpu_s:.1f} s")
    print()
    print("| step | jobs | wall s (sum) | CPU s (benchmark) | CPU s (exact) | share | "
          "start-up CPU s / job | peak RSS MB (benchmark / exact) |")
    print("|---|---|---|---|---|---|---|---|")
    for step, jobs in steps.items():
        if not jobs:
            continue
        c = sum(j.cpu_s for j in jobs)
        e = sum(r.cpu(j, True) for j in jobs)
        rss = max(j.max_rss_mb for j in jobs)
        rss_e = max((j.exact_rss_mb or 0.0) for j in jobs)
        print(f"| {step} | {len(jobs)} | {sum(j.wall_s for j in jobs):.1f} | {c:.1f} | {e:.1f} "
              f"| {100 * e / exact:.1f} % | {startup[step]:.2f} | {rss:.0f} / {rss_e:.0f} |")
    boot = sum(startup[j.step] for j in r.jobs)
    print(f"| **all jobs** | {len(r.jobs)} | {sum(j.wall_s for j in r.jobs):.1f} | {cpu:.1f} | "
          f"{exact:.1f} | 100 % | {boot:.1f} in all | {max(j.max_rss_mb for j in r.jobs):.0f} / "
          f"{max((j.exact_rss_mb or 0.0) for j in r.jobs):.0f} |")
    audio = sum(r.audio_hours.values())
    print()
    print(f"group-clip hours {r.group_hours:.5f} h; written audio {audio:.5f} h (" +
          ", ".join(f"{k} {v * 3600:.0f} s" for k, v in r.audio_hours.items()) + ")")
    wall_core_h = r.wall_s * r.cores / 3600
    print(f"throughput: {r.group_hours / (exact / 3600):.3f} group-clip h per CPU core-hour "
          f"(jobs' exact CPU), {r.group_hours / (r.total_cpu_s / 3600):.3f} with Snakemake's "
          f"own CPU, {r.group_hours / wall_core_h:.3f} per wall core-hour (wall x {r.cores}); "
          f"written audio {audio / (exact / 3600):.3f} h per CPU core-hour")


def cpu_of(r: BuildResult, jobs: list[JobCost], exact: bool) -> float:
    return sum(r.cpu(j, exact) for j in jobs)


def per_unit(r: BuildResult, startup: dict[str, float], exact: bool) -> dict[str, float]:
    """Core-seconds per group, per scene and for the corpora; CPU and reserved."""
    steps = r.steps()
    boot = sum(startup[s] * len(steps[s]) for s in PER_GROUP) / r.n_groups
    tracing = (cpu_of(r, steps["rir"], exact) - startup["rir"] * len(steps["rir"])) / r.n_groups

    def cpu(names):
        return sum(r.cpu(j, exact) for s in names for j in steps[s])

    def reserved(names):
        return sum(j.threads * j.wall_s for s in names for j in steps[s])

    return {
        "cpu_group": cpu(PER_GROUP) / r.n_groups,
        "boot_group": boot,
        "rir_group": tracing,
        "cpu_scene": cpu(PER_SCENE) / r.n_scenes,
        "cpu_corpus": cpu(("corpus",)),
        "res_group": reserved(PER_GROUP) / r.n_groups,
        "res_scene": reserved(PER_SCENE) / r.n_scenes,
        "res_corpus": reserved(("corpus",)),
        "group_s": r.group_hours * 3600 / r.n_groups,
    }


def projection(r: BuildResult, startup: dict[str, float], exact: bool = True
               ) -> dict[str, float]:
    u = per_unit(r, startup, exact)
    groups = SONICSET_HOURS * 3600 / u["group_s"]
    cpu_h = (groups * u["cpu_group"] + SONICSET_SCENES * u["cpu_scene"] + u["cpu_corpus"]) / 3600
    lean_h = cpu_h - groups * u["boot_group"] / 3600
    res_h = (groups * u["res_group"] + SONICSET_SCENES * u["res_scene"] + u["res_corpus"]) / 3600
    return {**u, "groups": groups, "cpu_h": cpu_h, "lean_h": lean_h, "reserved_h": res_h,
            "wall_h": res_h / CLUSTER_CORES, "wall_h_cpu": cpu_h / CLUSTER_CORES}


def print_projection(results: list[BuildResult], startup: dict[str, float]) -> None:
    print(f"\n### Projection to SonicSet scale ({SONICSET_HOURS:.0f} h of group clips, "
          f"{SONICSET_SCENES} scenes) on {CLUSTER_CORES} cores")
    print()
    print("| from build | group length | groups | CPU core-s / group (start-up) | reserved "
          "core-s / group | CPU core-hours (start-up amortised) | reserved core-hours | "
          "wall h at 100 cores (reserved / CPU) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        p = projection(r, startup)
        print(f"| {r.label} | {p['group_s']:.0f} s | {p['groups']:,.0f} | {p['cpu_group']:.2f} "
              f"({p['boot_group']:.2f}) | {p['res_group']:.2f} | {p['cpu_h']:,.0f} "
              f"({p['lean_h']:,.0f}) | {p['reserved_h']:,.0f} | "
              f"{p['wall_h']:.1f} / {p['wall_h_cpu']:.1f} |")
    print()
    for r in results:
        p = projection(r, startup)
        extra = p["groups"] * p["rir_group"] * (SONICSIM_RAYS / r.rays - 1) / 3600
        print(f"{r.label}: tracing {p['rir_group']:.1f} core-s / group at {r.rays:,} rays; "
              f"scaled linearly to {SONICSIM_RAYS:,} rays (not measured): "
              f"{p['cpu_h'] + extra:,.0f} CPU core-hours, "
              f"{(p['cpu_h'] + extra) / CLUSTER_CORES:.1f} h at {CLUSTER_CORES} cores")
    for r in results:
        p = projection(r, startup)
        print(f"{r.label}: per scene {p['cpu_scene']:.1f} core-s CPU (x {SONICSET_SCENES} = "
              f"{SONICSET_SCENES * p['cpu_scene'] / 3600:.2f} core-h), corpora "
              f"{p['cpu_corpus']:.1f} core-s once")


def sonicset_like_spec(text: str) -> str:
    for old, new in SONICSET_LIKE:
        if old not in text:
            raise SystemExit(f"specs/demo.yaml changed: {old!r} not found; update SONICSET_LIKE")
        text = text.replace(old, new)
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--skip-warm", action="store_true",
                        help="leave out the build with a warm corpora cache")
    parser.add_argument("--skip-sonicset-like", action="store_true",
                        help="leave out the 60 s / 3 speakers / 20 000 rays build")
    parser.add_argument("--keep", help="build in this folder (kept) instead of a temporary one")
    parser.add_argument("--verbose", action="store_true", help="show the builds' progress")
    args = parser.parse_args()

    demo_text = (ROOT / "specs" / "demo.yaml").read_text()
    with tempfile.TemporaryDirectory(prefix="bench-pipeline-") as tmp_name:
        tmp = Path(args.keep).resolve() if args.keep else Path(tmp_name)
        site = tmp / "site"
        rusage_dir = tmp / "rusage"
        site.mkdir(parents=True, exist_ok=True)
        rusage_dir.mkdir(exist_ok=True)
        (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
        os.environ["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(site), os.environ.get("PYTHONPATH", "")) if p)
        os.environ["SONICSPEC_BENCH_RUSAGE_DIR"] = str(rusage_dir)

        print(f"python {platform.python_version()}, {os.cpu_count()} cpus, "
              f"{args.cores} cores for the builds; folder {tmp}", flush=True)
        startup = {s: startup_cpu_s(s) for s in STEP_NAMES}
        results = []
        demo = tmp / "demo"
        if demo.exists():
            shutil.rmtree(demo)
        demo.mkdir()
        (demo / "demo.yaml").write_text(demo_text)
        results.append(build(demo / "demo.yaml", "demo, cold", args.cores, rusage_dir,
                             args.verbose))
        print_build(results[-1], startup)
        if not args.skip_warm:
            for name in ("out",):  # the store and the dataset; .sonicspec-cache stays
                shutil.rmtree(demo / name)
            warm = build(demo / "demo.yaml", "demo, corpora cache warm, empty store",
                         args.cores, rusage_dir, args.verbose)
            print_build(warm, startup)
        if not args.skip_sonicset_like:
            like = tmp / "sonicset-like"
            if like.exists():
                shutil.rmtree(like)
            like.mkdir()
            (like / "demo.yaml").write_text(sonicset_like_spec(demo_text))
            results.append(build(like / "demo.yaml", "SonicSet-like, cold", args.cores,
                                 rusage_dir, args.verbose))
            print_build(results[-1], startup)
        print_projection(results, startup)
        print("\nDemo settings: 10 s groups, 2 speakers of 1-2 utterances, 4000 rays, 1 s RIRs, "
              "shoebox/L/polygon rooms. SonicSet: 60 s groups, 3 speakers, 50 000 rays "
              "(SonicSim), Matterport scans; the SonicSet-like build uses 20 000 rays.")


if __name__ == "__main__":
    main()
