"""Benchmark (issue 27): what a build costs per group, and whether it stays flat as groups grow.

One function per measurement; ``--only NAME`` runs one (others may add sections: each takes
the parsed arguments and returns the lines it printed, for RESULTS.md).

* ``dataset`` — the dataset step on synthetic store contents of 10^2, 10^3 and 10^4 groups
  (:mod:`sonicspec.testing.scale`: export records of SonicSet-preset groups, 60 s, 3 talkers,
  3 mixtures, no audio rendered): the peak RSS of the ``sonicspec job`` process
  (``getrusage`` in a fresh subprocess, plan excerpt read as a job reads it), the RSS once the
  plan is read, wall and CPU per group, and the bytes of the outputs.
* ``bytes`` — a real build of the tests' cut-down demo (``tests/build_cases.py``: 4 train,
  1 val, 1 test group, ``--duration`` seconds each) and its bytes per group by file kind in
  the dataset folder and by step in the store, per group-second against the issue's
  non-audio target (20 kB per group-second); and the position tracks of one group encoded
  as they were (JSON lists in metadata.json, indented) against float32 ``.npy`` and the
  int32 ``tracks.npz`` written now.
* ``tracks`` — a SonicSet-like 60 s group's tracks (three talkers walking the whole clip)
  in candidate encodings: JSON (as before), float32 and int32 ``.npz``, raw and deflated, and
  frame differences.
* ``build`` — a real build of ``--groups`` groups (default 1,000; ``--build-seconds`` each,
  default 5 s) of the demo spec at cheap acoustic settings (100 rays, image-source order 1,
  0.2 s RIRs, 1 m RIR spacing, shards of 50 groups) through Snakemake on this machine:
  per step the jobs, CPU (exact ``getrusage`` of each ``sonicspec job`` process, via the
  ``sitecustomize`` of ``bench_pipeline.py``, and Snakemake's per-job benchmark), peak RSS and
  summed wall; the dataset folder's bytes per group by file kind and the store's by step.
  Then the projection to the whole of SonicSet (19,528 groups of 60 s) from per-group costs
  measured at the ``sonicset`` preset's settings (see ``bench_projection``).
* ``projection`` — a real build of the ``sonicset`` preset cut to 16 train groups (one shard,
  as the full plan's) + 1 val + 1 test group on its inputs in their real layouts (fixture scan,
  synthetic corpora), and the projection to the whole of SonicSet from its per-group CPU by
  step, RIR points per group (rir also scaled by the furnished apartment's CPU per RIR) and
  bytes per group.
* ``compare`` (with ``--against CHECKOUT``) — the pipeline tests' one-group spec built by an
  older checkout and by this one, file by file: what the format changes touched, and that
  everything else (audio, supervisions, the recordings apart from ``custom``, the track
  numbers) is the same.

Reproduce:
    python bench/bench_scale.py                      # both (~10 min on 2 cores)
    python bench/bench_scale.py --only dataset --sizes 100 1000 10000
    python bench/bench_scale.py --only bytes --duration 60
    python bench/bench_scale.py --only tracks
    nice -n 10 python bench/bench_scale.py --only build --groups 1000 --build-seconds 5
    nice -n 10 python bench/bench_scale.py --only projection --preset-groups 16
    python bench/bench_scale.py --only compare --against /path/to/checkout/at/346f31f
"""

from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import sys
import tempfile
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "bench"))

from build_cases import plan_for, write_spec  # noqa: E402  (the tests' cut-down demo)

from sonicspec.export.tracks import TrackFile, read_track  # noqa: E402
from sonicspec.testing.scale import measure_dataset_job, write_dataset_inputs  # noqa: E402


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _tree_bytes(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def bench_dataset(args: argparse.Namespace) -> list[str]:
    """Peak RSS, wall and CPU of the dataset job at each size (see the module docstring)."""
    lines = ["| groups | write inputs s | peak RSS MB | RSS after plan MB | wall s | CPU s | "
             "CPU ms/group | outputs MB |", "|---|---|---|---|---|---|---|---|"]
    print(lines[0])
    print(lines[1])
    for n in args.sizes:
        with tempfile.TemporaryDirectory(prefix="bench-scale-") as tmp:
            t0 = time.perf_counter()
            plan_file, key = write_dataset_inputs(Path(tmp), n)
            made = time.perf_counter() - t0
            m = measure_dataset_job(plan_file, key, env=_env())
            out_mb = _tree_bytes(Path(tmp) / "out") / 2**20
        line = (f"| {n} | {made:.1f} | {m['peak_rss_mb']:.0f} | {m['plan_rss_mb']:.0f} | "
                f"{m['wall_s']:.2f} | {m['cpu_s']:.2f} | {1000 * m['cpu_s'] / n:.2f} | "
                f"{out_mb:.1f} |")
        print(line, flush=True)
        lines.append(line)
    return lines


def _kind(rel: str) -> str:
    name = rel.rsplit("/", 1)[-1]
    if "/rirs/" in rel:
        return "RIR wav"
    if "/mixtures/" in rel:
        return "mixture audio"
    if name in ("metadata.json", "tracks.npz"):
        return name
    stem = name.rsplit(".", 1)[0]
    if stem.endswith(("_dry", "_direct", "_early")):
        return "target audio"
    return "track audio"


def _old_json_tracks(out: Path, meta: dict) -> bytes:
    """The tracks as metadata.json held them before (lists, indented like the file)."""
    tracks = {}
    for name in [k for k in meta if k.startswith("source") or k in ("noise", "music")]:
        t = read_track(out, meta[name]["track"])
        tracks[name] = {"hop_s": t["hop_s"], **{q: v.tolist() for q, v in t.items()
                                                if q != "hop_s"}}
    mic = read_track(out, meta["microphone_track"])
    tracks["microphone_track"] = {q: (v if q == "hop_s" else v.tolist()) for q, v in mic.items()}
    return json.dumps(tracks, indent=2, sort_keys=True).encode()


def _float32_npz(out: Path, meta: dict, compressed: bool) -> int:
    """Bytes of the same tracks as a float32 ``.npz`` (in metres and degrees)."""
    with np.load(out / meta["microphone_track"]["file"]) as z:
        arrays = {n: (z[n] / (10_000 if n.endswith("_m") else 100)).astype(np.float32)
                  for n in z.files}
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **arrays)
    return len(buf.getvalue())


def bench_bytes(args: argparse.Namespace) -> list[str]:
    """Bytes per group by kind of a real cut-down demo build (see the module docstring)."""
    from sonicspec.stages.workflow import run_build

    with tempfile.TemporaryDirectory(prefix="bench-bytes-") as tmp:
        folder = Path(tmp)
        spec = write_spec(folder)
        text = spec.read_text().replace("duration_s: 10.0", f"duration_s: {args.duration}")
        spec.write_text(text)
        plan = plan_for(spec)
        t0 = time.perf_counter()
        code = run_build(plan, cores=2)
        built_s = time.perf_counter() - t0
        if code != 0:
            raise SystemExit(f"the demo build failed (exit {code})")
        out, store = Path(plan.output_dir), Path(plan.store_dir)
        groups = sorted(p.parent for p in out.glob("*/*/metadata.json"))
        seconds = args.duration
        by_kind: dict[str, int] = {}
        for g in groups:
            for p in g.rglob("*"):
                if p.is_file():
                    k = _kind(p.relative_to(out).as_posix())
                    by_kind[k] = by_kind.get(k, 0) + p.stat().st_size
        n = len(groups)
        lines = [f"cut-down demo, {n} groups of {seconds:g} s, built in {built_s:.0f} s",
                 "", "| dataset file kind | bytes per group | bytes per group-second |",
                 "|---|---|---|"]
        for k, b in sorted(by_kind.items()):
            lines.append(f"| {k} | {b / n:,.0f} | {b / n / seconds:,.0f} |")
        non_audio = sum(b for k, b in by_kind.items() if k in ("metadata.json", "tracks.npz"))
        shared = _tree_bytes(out / "manifests") + sum(
            (out / f).stat().st_size for f in ("dataset.json", "checksums.sha256"))
        lines.append(f"| (dataset.json, manifests, checksums: shared) | {shared / n:,.0f} | "
                     f"{shared / n / seconds:,.0f} |")
        lines.append(f"\nnon-audio per group-second (metadata.json + tracks.npz + the group's "
                     f"share of the shared files): {(non_audio + shared) / n / seconds:,.0f} B "
                     "(target <= 20,000 B)")
        lines += ["", "| store step | bytes per group | files per group |", "|---|---|---|"]
        for step_dir in sorted(p for p in store.iterdir() if p.is_dir()):
            if step_dir.name in ("logs", "benchmarks", "plans", "cache", ".snakemake"):
                continue
            files = [p for p in step_dir.rglob("*") if p.is_file()]
            lines.append(f"| {step_dir.name} | {sum(p.stat().st_size for p in files) / n:,.0f} "
                         f"| {len(files) / n:.1f} |")
        meta_path = groups[0] / "metadata.json"
        meta = json.loads(meta_path.read_text())
        old = _old_json_tracks(out, meta)
        npz = (groups[0] / "tracks.npz").stat().st_size
        f32, f32z = _float32_npz(out, meta, False), _float32_npz(out, meta, True)
        with zipfile.ZipFile(groups[0] / "tracks.npz") as zf:
            raw = sum(i.file_size for i in zf.infolist())
        compact = len(json.dumps(json.loads(old), separators=(",", ":")))
        lines += ["", f"tracks of one {seconds:g} s group ({groups[0].relative_to(out)}):",
                  "", "| encoding | bytes | vs int32 tracks.npz |", "|---|---|---|",
                  f"| JSON lists in metadata.json (before, indented) | {len(old):,} | "
                  f"{len(old) / npz:.1f}x |",
                  f"| JSON lists, compact | {compact:,} | {compact / npz:.1f}x |",
                  f"| float32 .npz, uncompressed | {f32:,} | {f32 / npz:.1f}x |",
                  f"| float32 .npz, deflate | {f32z:,} | {f32z / npz:.1f}x |",
                  f"| int32 .npz, uncompressed | {raw:,} | {raw / npz:.1f}x |",
                  f"| int32 .npz, deflate (tracks.npz, now) | {npz:,} | 1.0x |",
                  f"\nmetadata.json of that group now: {meta_path.stat().st_size:,} B"]
        for line in lines:
            print(line)
        if args.keep:
            shutil.copytree(folder, args.keep, dirs_exist_ok=True)
        return lines


def _walking_group_tracks(folder: Path, seconds: float) -> TrackFile:
    """A SonicSet-like group's tracks: 3 talkers walking two legs over the whole clip
    (``span: clip``), static noise, music and microphone."""
    rng = np.random.default_rng(0)
    n = round(seconds / 0.01)
    files = TrackFile(folder, folder)
    mic = np.array([4.0, 3.0, 1.5])

    def labels(pos: np.ndarray) -> dict[str, np.ndarray]:
        rel = pos - mic
        dist = np.linalg.norm(rel, axis=1)
        return {"positions_m": pos, "azimuth_deg": np.degrees(np.arctan2(rel[:, 1], rel[:, 0])),
                "elevation_deg": np.degrees(np.arcsin(rel[:, 2] / dist)), "distance_m": dist}

    t = np.linspace(0.0, 1.0, n)[:, None]
    for k in range(3):
        a, b, c = (np.array([*rng.uniform(0, 10, 2), 1.7]) for _ in range(3))
        walk = np.where(t < 0.5, a + (b - a) * 2 * t, b + (c - b) * (2 * t - 1))
        files.add(f"source{k + 1}", 0.01, labels(walk))
    for name in ("noise", "music"):
        files.add(name, 0.01, labels(np.repeat([[*rng.uniform(0, 10, 2), 1.6]], n, axis=0)))
    files.add("microphone", 0.01, {"positions_m": np.repeat([mic], n, axis=0)})
    files.write()
    return files


def bench_tracks(args: argparse.Namespace) -> list[str]:
    """Encodings of a SonicSet-like 60 s group's tracks (walking over the whole clip), to
    choose the stored form with numbers."""
    def npz(arrays: dict[str, np.ndarray], compressed: bool) -> int:
        buf = io.BytesIO()
        (np.savez_compressed if compressed else np.savez)(buf, **arrays)
        return len(buf.getvalue())

    with tempfile.TemporaryDirectory(prefix="bench-tracks-") as tmp:
        files = _walking_group_tracks(Path(tmp), args.track_seconds)
        now = files.path.stat().st_size
        stored = files.arrays
        values = {k: v / (10_000 if k.endswith("_m") else 100) for k, v in stored.items()}
        rows = [
            ("JSON lists, indented (metadata.json before; 3 copies were kept)",
             len(json.dumps({k: v.tolist() for k, v in values.items()}, indent=2))),
            ("JSON lists, compact",
             len(json.dumps({k: v.tolist() for k, v in values.items()},
                            separators=(",", ":")))),
            ("float32 .npz", npz({k: v.astype(np.float32) for k, v in values.items()}, False)),
            ("float32 .npz, deflate",
             npz({k: v.astype(np.float32) for k, v in values.items()}, True)),
            ("int32 .npz", npz(stored, False)),
            ("int32 .npz, deflate (tracks.npz, now)", now),
            ("int32 frame-to-frame differences, deflate (needs a cumsum to read)",
             npz({k: np.diff(v, axis=0, prepend=0) for k, v in stored.items()}, True)),
        ]
    lines = [f"tracks of a {args.track_seconds:g} s group, 3 talkers walking the whole clip:",
             "", "| encoding | bytes | bytes per group-second | vs tracks.npz |",
             "|---|---|---|---|"]
    lines += [f"| {name} | {b:,} | {b / args.track_seconds:,.0f} | {b / now:.2f}x |"
              for name, b in rows]
    for line in lines:
        print(line)
    return lines


def cheap_spec(groups: int, seconds: float) -> str:
    """specs/demo.yaml cut to cheap acoustics and ``groups`` short groups: 2 % each to val
    (office) and test (hall), the rest train (living room); shards of 50 groups."""
    import re

    held = max(1, groups // 50)
    text = (ROOT / "specs" / "demo.yaml").read_text()
    edits = (("rays: 4000", "rays: 100"), ("image_source_order: 2", "image_source_order: 1"),
             ("duration_s: 10.0", f"duration_s: {seconds:g}"),
             ("utterances_per_speaker: [1, 2]", "utterances_per_speaker: [1, 1]"),
             ("utterance_gap_s: [0.0, 2.0]", "utterance_gap_s: [0.0, 0.5]"),
             ("noise_clips: [1, 2]", "noise_clips: [1, 1]"),
             ("music_clips: [1, 2]", "music_clips: [1, 1]"),
             ("rir_spacing_m: 0.25", "rir_spacing_m: 1.0"),
             ("source_travel_distance_m: [1.0, 3.0]", "source_travel_distance_m: [0.5, 1.0]"),
             ("train: {groups: 4,", f"train: {{groups: {groups - 2 * held},"),
             ("val: {groups: 1,", f"val: {{groups: {held},"),
             ("test: {groups: 1,", f"test: {{groups: {held},"),
             ("groups_per_shard: 2", "groups_per_shard: 50"))
    for old, new in edits:
        if old not in text:
            raise SystemExit(f"specs/demo.yaml changed: {old!r} not found")
        text = text.replace(old, new)
    text, n = re.subn(r"max_rir_length_s: auto[^\n]*", "max_rir_length_s: 0.2", text)
    if n != 1:
        raise SystemExit("specs/demo.yaml changed: max_rir_length_s: auto not found")
    return text


def _step_table(plan, store: Path, rusage_dir: Path) -> tuple[list[str], dict[str, dict]]:
    """Per step: jobs, summed wall, CPU (exact getrusage and Snakemake's benchmark), peak RSS."""
    from bench_pipeline import STEP_NAMES, read_benchmark

    steps: dict[str, dict] = {}
    for job in plan.jobs:
        bench_file = store / "benchmarks" / job.step / job.key[:2] / f"{job.key}.tsv"
        if not bench_file.is_file():  # not run (yet): a partial build's report
            continue
        b = read_benchmark(bench_file)
        exact = rusage_dir / f"{job.key}.json"
        data = json.loads(exact.read_text()) if exact.is_file() else None
        row = steps.setdefault(job.step, {"jobs": 0, "wall": 0.0, "cpu": 0.0, "bcpu": 0.0,
                                          "rss": 0.0, "brss": 0.0, "missing": 0})
        row["jobs"] += 1
        row["wall"] += b["s"]
        row["bcpu"] += b["cpu_time"]
        row["brss"] = max(row["brss"], b["max_rss"])
        if data is None:
            row["missing"] += 1
            row["cpu"] += b["cpu_time"]
        else:
            row["cpu"] += data["cpu_s"]
            row["rss"] = max(row["rss"], data["maxrss_mb"], data["children_maxrss_mb"])
    total = sum(r["cpu"] for r in steps.values())
    lines = ["| step | jobs | wall s (sum) | CPU s (exact) | CPU s (benchmark) | share | "
             "peak RSS MB (exact / benchmark) |", "|---|---|---|---|---|---|---|"]
    for name in STEP_NAMES:
        if name in steps:
            r = steps[name]
            lines.append(f"| {name} | {r['jobs']} | {r['wall']:.1f} | {r['cpu']:.1f} | "
                         f"{r['bcpu']:.1f} | {100 * r['cpu'] / total:.1f} % | "
                         f"{r['rss']:.0f} / {r['brss']:.0f} |")
    lines.append(f"| **all jobs** | {sum(r['jobs'] for r in steps.values())} | "
                 f"{sum(r['wall'] for r in steps.values()):.1f} | {total:.1f} | "
                 f"{sum(r['bcpu'] for r in steps.values()):.1f} | 100 % | "
                 f"{max(r['rss'] for r in steps.values()):.0f} / "
                 f"{max(r['brss'] for r in steps.values()):.0f} |")
    return lines, steps


def _bytes_tables(out: Path, store: Path, n: int, seconds: float) -> list[str]:
    """The dataset folder's bytes per group by file kind, the store's by step."""
    by_kind: dict[str, list[int]] = {}
    for p in out.rglob("*"):
        if not p.is_file():
            continue
        rel = p.relative_to(out).as_posix()
        kind = ("manifests, dataset.json, checksums (shared)" if "/" not in rel
                or rel.startswith("manifests/") else _kind(rel))
        got = by_kind.setdefault(kind, [0, 0])
        got[0] += p.stat().st_size
        got[1] += 1
    lines = ["| dataset file kind | bytes per group | bytes per group-second | files per group |",
             "|---|---|---|---|"]
    for k, (b, f) in sorted(by_kind.items()):
        lines.append(f"| {k} | {b / n:,.0f} | {b / n / seconds:,.0f} | {f / n:.2f} |")
    total = sum(b for b, _ in by_kind.values())
    lines.append(f"| **dataset folder** | {total / n:,.0f} | {total / n / seconds:,.0f} | "
                 f"{sum(f for _, f in by_kind.values()) / n:.2f} |")
    lines += ["", "| store step | bytes per group | files per group |", "|---|---|---|"]
    all_b = all_f = 0
    for step_dir in sorted(p for p in store.iterdir() if p.is_dir()):
        files = [p for p in step_dir.rglob("*") if p.is_file()]
        b = sum(p.stat().st_size for p in files)
        all_b, all_f = all_b + b, all_f + len(files)
        lines.append(f"| {step_dir.name} | {b / n:,.0f} | {len(files) / n:.2f} |")
    lines.append(f"| **store** | {all_b / n:,.0f} | {all_f / n:.2f} |")
    return lines


def bench_build(args: argparse.Namespace) -> list[str]:
    """A real build of ``--groups`` short groups at cheap acoustic settings (module docstring)."""
    import platform
    import resource

    from bench_pipeline import SITECUSTOMIZE

    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages.workflow import run_build

    keep = args.keep.resolve() if args.keep else None
    with tempfile.TemporaryDirectory(prefix="bench-build-") as tmp_name:
        tmp = keep or Path(tmp_name)
        tmp.mkdir(parents=True, exist_ok=True)
        site, rusage_dir = tmp / "site", tmp / "rusage"
        site.mkdir(exist_ok=True)
        rusage_dir.mkdir(exist_ok=True)
        (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
        os.environ["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(site), str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
        os.environ["SONICSPEC_BENCH_RUSAGE_DIR"] = str(rusage_dir)
        spec = tmp / "cheap.yaml"
        if not args.report:
            spec.write_text(cheap_spec(args.groups, args.build_seconds))
        t0 = time.perf_counter()
        plan = compile_spec(load_spec(spec))
        plan_s = time.perf_counter() - t0
        load0 = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        log = tmp / "build.log"
        code = 0
        if not args.report:
            with open(log, "w") as stream:
                code = run_build(plan, cores=args.cores, stream=stream)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if code != 0:
            raise SystemExit(f"the build failed (exit {code}); see {log}")
        all_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        out, store = Path(plan.output_dir), Path(plan.store_dir)
        n = len(list(out.glob("*/*/metadata.json")))
        if n != args.groups and not args.report:
            raise SystemExit(f"{n} group folders written, {args.groups} asked")
        if args.report:  # what a build stopped part-way made: per group of the plan
            n = args.groups
        table, steps = _step_table(plan, store, rusage_dir)
        jobs_cpu = sum(r["cpu"] for r in steps.values())
        lines = [f"python {platform.python_version()}, {os.cpu_count()} cpus, {args.cores} cores "
                 f"for the build, load average {load0:.1f} -> {os.getloadavg()[0]:.1f}",
                 f"{n} groups of {args.build_seconds:g} s (demo rooms; 100 rays, image-source "
                 "order 1, 0.2 s RIRs, 1 m RIR spacing, 1 utterance per talker, shards of "
                 f"50), {len(plan.jobs)} jobs; plan {plan_s:.2f} s",
                 f"wall {wall:.0f} s; CPU of all jobs {jobs_cpu:.0f} s (exact), whole build "
                 f"with Snakemake's head {all_cpu:.0f} s; {1000 * jobs_cpu / n:.0f} CPU ms "
                 f"per group in jobs, {1000 * all_cpu / n:.0f} with the head", ""]
        lines += table
        lines.append("")
        lines += _bytes_tables(out, store, n, args.build_seconds)
        for line in lines:
            print(line, flush=True)
        return lines


SONICSET_GROUPS = 19_528
SONICSET_TRACKS = 58_584  # 57,102 + 741 + 741 talker tracks of 60 s: 976 track-hours in all
SONICSET_SCENES = 90
APARTMENT_RIR_CPU_S = 0.30
"""CPU per RIR point at the preset (order 3 reached) in the furnished 100k-triangle apartment,
the 7 points of a 1.5 m walk sharing one image-source search as a rir job's source does
(``python bench/bench_preset_rir.py .``: 2.1 CPU s; one lone RIR costs 0.71 s)."""


def preset_spec(groups: int) -> str:
    """specs/sonicset.yaml with ``groups`` train groups in one scene (one shard of 16 when
    ``groups`` is 16, as in the full plan) and one val and one test group."""
    text = (ROOT / "specs" / "sonicset.yaml").read_text()
    for old, new in (
            ('train: {groups: each_speaker_per_scene, scenes: ["mp3d/*"], scene_count: 62}',
             f'train: {{groups: {groups}, scenes: ["mp3d/*"], scene_count: 1}}'),
            ('val: {groups: each_speaker_per_scene, scenes: ["mp3d/*"], scene_count: 19}',
             'val: {groups: 1, scenes: ["mp3d/*"], scene_count: 1}'),
            ('test: {groups: 247, scenes: ["mp3d/*"], scene_count: 9}',
             'test: {groups: 1, scenes: ["mp3d/*"], scene_count: 1}')):
        if old not in text:
            raise SystemExit(f"specs/sonicset.yaml changed: {old!r} not found")
        text = text.replace(old, new)
    return text


def bench_projection(args: argparse.Namespace) -> list[str]:
    """A real build of the ``sonicset`` preset cut to ``--preset-groups`` train groups (one
    shard) on its inputs in their real layouts (``sonicspec.testing.sonicset``: the one-room
    Matterport fixture under three scan ids, synthetic LibriSpeech/FSD50K/FMA), its per-group
    CPU by step, RIR points and bytes, and the projection to the whole of SonicSet."""
    import platform
    import resource

    from bench_pipeline import SITECUSTOMIZE

    from sonicspec.artifacts import decode
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages.workflow import run_build
    from sonicspec.store import ArtifactStore
    from sonicspec.testing.sonicset import write_sonicset_inputs

    keep = args.keep.resolve() if args.keep else None
    with tempfile.TemporaryDirectory(prefix="bench-preset-") as tmp_name:
        tmp = keep or Path(tmp_name)
        tmp.mkdir(parents=True, exist_ok=True)
        site, rusage_dir = tmp / "site", tmp / "rusage"
        site.mkdir(exist_ok=True)
        rusage_dir.mkdir(exist_ok=True)
        (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
        os.environ["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(site), str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
        os.environ["SONICSPEC_BENCH_RUSAGE_DIR"] = str(rusage_dir)
        if not (tmp / "data").is_dir():
            write_sonicset_inputs(tmp / "data", ["17DRP5sb8fy", "1LXtFkjw3qL", "1pXnuDYAj8r"],
                                  {"train-clean-360": 8, "dev-clean": 4, "test-clean": 4})
        spec = tmp / "sonicset.yaml"
        spec.write_text(preset_spec(args.preset_groups))
        plan = compile_spec(load_spec(spec))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        with open(tmp / "build.log", "w") as stream:
            code = run_build(plan, cores=args.cores, stream=stream)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if code != 0:
            raise SystemExit(f"the preset build failed (exit {code}); see {tmp / 'build.log'}")
        all_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        store, out = Path(plan.store_dir), Path(plan.output_dir)
        table, _ = _step_table(plan, store, rusage_dir)
        train = [j for j in plan.jobs if j.params.get("split") == "train"]
        n = args.preset_groups
        per_group: dict[str, float] = {}
        for job in train:
            data = json.loads((rusage_dir / f"{job.key}.json").read_text())
            per_group[job.step] = per_group.get(job.step, 0.0) + data["cpu_s"] / n
        scene_cpu: dict[str, float] = {}
        for job in plan.jobs:
            if job.step in ("mesh", "navigation"):
                data = json.loads((rusage_dir / f"{job.key}.json").read_text())
                scene_cpu.setdefault(job.step, []).append(data["cpu_s"])
        points = 0
        st = ArtifactStore(store)
        for job in train:
            if job.step == "rir":
                for g in decode("rir", st.read_data("rir", job.key)).groups:
                    points += sum(s.points for s in g.sources)
        points_per_group = points / n
        groups_all = len(list(out.glob("*/*/metadata.json")))
        lines = [f"python {platform.python_version()}, {os.cpu_count()} cpus; the sonicset "
                 f"preset, {n} train groups (one shard) + 1 val + 1 test of 60 s on the "
                 f"one-room Matterport fixture; wall {wall:.0f} s, CPU of all processes "
                 f"{all_cpu:.0f} s", "", *table, ""]
        lines += _bytes_tables(out, store, groups_all, 60.0)
        dataset_b = _tree_bytes(out) / groups_all
        store_b = _tree_bytes(store) / groups_all
        lines += ["", f"RIR points per train group: {points_per_group:.1f}", "",
                  "Projection to SonicSet (19,528 groups of 60 s, 58,584 talker tracks: "
                  f"{SONICSET_TRACKS / 60:,.0f} track-hours, 952 of them train; "
                  "90 scenes), per-group CPU of the train shard (its job start-up amortised "
                  "over 16 groups, as in the full plan):", "",
                  "| step | CPU core-s per group | SonicSet core-hours |", "|---|---|---|"]
        total = 0.0
        for step in ("placement", "arrange", "rir", "render", "mix", "export"):
            c = per_group.get(step, 0.0)
            total += c * SONICSET_GROUPS / 3600
            lines.append(f"| {step} | {c:.2f} | {c * SONICSET_GROUPS / 3600:,.1f} |")
        for step, cpus in scene_cpu.items():
            h = float(np.mean(cpus)) * SONICSET_SCENES / 3600
            total += h
            lines.append(f"| {step} (per scene, fixture scan) | {np.mean(cpus):.2f} / scene | "
                         f"{h:,.2f} |")
        ds = 0.86e-3 * SONICSET_GROUPS / 3600  # the dataset step: 0.86 CPU ms per group at 10^4
        total += ds
        lines.append(f"| dataset (0.86 CPU ms per group, --only dataset) | 0.0009 | {ds:.3f} |")
        rir_apartment = points_per_group * APARTMENT_RIR_CPU_S
        alt = total + (rir_apartment - per_group.get("rir", 0.0)) * SONICSET_GROUPS / 3600
        lines += [f"| **all** | | **{total:,.1f}** |", "",
                  f"In furnished scans the rir step costs more per point: {points_per_group:.1f} "
                  f"points x {APARTMENT_RIR_CPU_S} CPU s per RIR in the 100k-triangle apartment "
                  f"(bench_preset_rir.py, a walk's points) = {rir_apartment:.1f} core-s per "
                  "group, "
                  f"{rir_apartment * SONICSET_GROUPS / 3600:,.1f} core-hours for the rir step "
                  f"and {alt:,.1f} in all.",
                  f"Sizes: dataset folder {dataset_b / 1e6:.2f} MB per group -> "
                  f"{dataset_b * SONICSET_GROUPS / 1e12:.2f} TB; store "
                  f"{store_b / 1e6:.2f} MB per group -> {store_b * SONICSET_GROUPS / 1e12:.2f} TB "
                  "(the fixture's audio is synthetic: see the audiofmt section for real audio)."]
        for line in lines:
            print(line, flush=True)
        return lines


_BUILD_TINY = """
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[2] + "/tests")
from test_pipeline_stages import build
build(Path(sys.argv[1]))
"""


def bench_compare(args: argparse.Namespace) -> list[str]:
    """The outputs of the pipeline tests' one-group spec built by this checkout and by
    ``--against`` (an older checkout), compared file by file: what changed, and that the rest
    is the same."""
    import hashlib
    import subprocess

    if args.against is None:
        raise SystemExit("--only compare needs --against /path/to/an/older/checkout")
    with tempfile.TemporaryDirectory(prefix="bench-compare-") as tmp:
        outs = {}
        for name, checkout in (("old", args.against.resolve()), ("new", ROOT)):
            folder = Path(tmp) / name
            folder.mkdir()
            env = dict(os.environ, PYTHONPATH=str(checkout))
            subprocess.run([sys.executable, "-c", _BUILD_TINY, str(folder), str(checkout)],
                           check=True, env=env, capture_output=True, cwd=checkout)
            outs[name] = folder / "out"
        old, new = outs["old"], outs["new"]

        def digests(root: Path) -> dict[str, str]:
            return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
                    for p in root.rglob("*") if p.is_file()}

        a, b = digests(old), digests(new)
        same = sorted(k for k in a if b.get(k) == a[k])
        lines = [f"files the same: {len(same)} ({sum(k.endswith(('.flac', '.wav')) for k in same)}"
                 " audio)", f"only in the new: {sorted(set(b) - set(a))}",
                 f"only in the old: {sorted(set(a) - set(b))}",
                 f"differ: {sorted(k for k in a if k in b and a[k] != b[k])}"]
        ra = [json.loads(x) for x in (old / "manifests/train_recordings.jsonl").open()]
        rb = [json.loads(x) for x in (new / "manifests/train_recordings.jsonl").open()]
        same_numbers = all(
            np.array_equal(np.asarray(x["custom"]["track"][q]),
                           read_track(new, y["custom"]["track"])[q])
            for x, y in zip(ra, rb, strict=True) if "custom" in x
            for q in x["custom"]["track"])
        strip = [{k: v for k, v in r.items() if k != "custom"} for r in ra] == [
            {k: v for k, v in r.items() if k != "custom"} for r in rb]
        lines.append(f"recordings: the same apart from custom.track: {strip}; the tracks' "
                     f"numbers read from tracks.npz equal the old lists: {same_numbers}")
        meta_old = (old / "train/000000/metadata.json").stat().st_size
        meta_new = (new / "train/000000/metadata.json").stat().st_size
        tracks = (new / "train/000000/tracks.npz").stat().st_size
        lines.append(f"metadata.json {meta_old:,} B -> {meta_new:,} B + tracks.npz {tracks:,} B")
    for line in lines:
        print(line)
    return lines


BENCHES: dict[str, Callable[[argparse.Namespace], list[str]]] = {
    "dataset": bench_dataset,
    "bytes": bench_bytes,
    "compare": bench_compare,
    "tracks": bench_tracks,
    "build": bench_build,
    "projection": bench_projection,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", choices=sorted(BENCHES), action="append",
                        help="run only this measurement (repeatable)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000],
                        help="groups for the dataset step (default: 100 1000 10000)")
    parser.add_argument("--duration", type=float, default=10.0,
                        help="seconds per group of the demo build for 'bytes' (default: 10)")
    parser.add_argument("--track-seconds", type=float, default=60.0,
                        help="group length for 'tracks' (default: 60)")
    parser.add_argument("--keep", type=Path,
                        help="copy the demo build here ('bytes'); build in this folder, kept "
                             "('build')")
    parser.add_argument("--groups", type=int, default=1000,
                        help="groups of the real build ('build'; default 1000)")
    parser.add_argument("--build-seconds", type=float, default=5.0,
                        help="seconds per group of the real build ('build'; default 5)")
    parser.add_argument("--report", action="store_true",
                        help="'build' with --keep: report what the kept build made, no build")
    parser.add_argument("--preset-groups", type=int, default=16,
                        help="train groups of the preset build ('projection'; default 16)")
    parser.add_argument("--cores", type=int, default=2,
                        help="cores for the real build ('build'; default 2)")
    parser.add_argument("--against", type=Path,
                        help="an older checkout to compare outputs with ('compare')")
    args = parser.parse_args()
    argv = " ".join(sys.argv[1:])
    print(f"# python bench/bench_scale.py {argv}".rstrip())
    for name in args.only or [n for n in BENCHES if n not in ("compare", "build", "projection")
                                   or (n == "compare" and args.against)]:
        print(f"\n## {name}")
        BENCHES[name](args)


if __name__ == "__main__":
    main()
