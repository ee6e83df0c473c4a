"""Benchmark (issue 27): each rule's peak memory at the ``sonicset`` preset, for its ``mem_mb``.

Lays out SonicSet's inputs (``sonicspec.testing.sonicset``: the one-room Matterport
fixture scan under three ids, LibriSpeech-layout speakers, small FSD50K and FMA), copies
``specs/sonicset.yaml`` beside them with only the splits made small (``--groups`` train
groups in one scene, one val and one test group in a scene each; everything else — 60 s
groups, 3 talkers of 3–5 utterances, noise and music, 4,000 rays with splitting, image-source
order 3, ``max_rir_length_s: auto``, 24-bit FLAC, 16 groups per shard — is the preset's), and
builds it twice through ``sonicspec build``:

1. one Snakemake job per step and shard: each ``sonicspec job`` process records its exact
   ``getrusage`` at exit (a ``sitecustomize`` on ``PYTHONPATH``, as ``bench_pipeline.py``):
   peak RSS and CPU per step, against the step's ``mem_mb`` in ``sonicspec.plan.model.STEPS``;
2. batched (``--shards-per-batch`` = every shard in one batch, a fresh store): the ``sonicspec
   batch`` process's peak RSS, which runs every shard job one after another: whether memory
   accumulates across a batch's jobs. The two builds' dataset checksums are compared.

3. ``--apartment``: one RIR at the preset in the furnished 100k-triangle apartment
   (``bench_rlr.apartment_mesh``, as ``bench_preset_rir.py``): the peak RSS of that process,
   the memory a real scan's mesh, BVH and image-source search add over the fixture room.

A job's memory depends on its shard (groups per shard, the group's length, talkers, RIR
length), not on how many groups the plan has (the dataset step's is bench_scale.py's
``dataset`` section, flat from 10^2 to 10^4 groups), so these are the figures of a
SonicSet-size plan's jobs.

Reproduce:
    python bench/bench_rule_memory.py               # ~15-30 min on a loaded 2-core machine
    python bench/bench_rule_memory.py --groups 16 --skip-batched
    python bench/bench_rule_memory.py --apartment        # the apartment RIR only
"""

from __future__ import annotations

import argparse
import io
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SITECUSTOMIZE = '''
import os, sys
_dir = os.environ.get("SONICSPEC_BENCH_RUSAGE_DIR")
if _dir and len(sys.argv) > 2 and sys.argv[1] in ("job", "batch"):
    import atexit, json, resource

    def _write_rusage(key=sys.argv[-1], what=sys.argv[1]):
        s = resource.getrusage(resource.RUSAGE_SELF)
        c = resource.getrusage(resource.RUSAGE_CHILDREN)
        data = {"what": what, "cpu_s": s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime,
                "maxrss_mb": s.ru_maxrss / 1024, "children_maxrss_mb": c.ru_maxrss / 1024}
        with open(os.path.join(_dir, key + ".json"), "w") as fh:
            json.dump(data, fh)

    atexit.register(_write_rusage)
'''


APARTMENT = """
import json, resource, sys, time
from pathlib import Path
import numpy as np
tree, tmp = Path(sys.argv[1]), Path(sys.argv[2])
sys.path[:0] = [str(tree / "bench"), str(tree)]
import bench_rlr as b
mesh = b.apartment_mesh(100_000)
np.savez(tmp / "mesh.npz", vertices=mesh.vertices, faces=mesh.faces,
         face_material=mesh.face_material)
(tmp / "materials.json").write_text(json.dumps(list(mesh.materials)))
s = b.SimulationSettings.from_spec(b.preset_acoustics(), b.SAMPLE_RATE_HZ, b.SPEED_OF_SOUND_M_S)
scene, regions, _, _ = b.prepared_scene(tmp, s)
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
_, facts = b.sonicspec_rir(scene, regions, s, 0, 1)
r = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"scene_mb": r0, "peak_mb": r.ru_maxrss / 1024, "cpu_s": r.ru_utime + r.ru_stime,
                  "order": facts["image_source_order"], "faces": len(mesh.faces)}))
"""


def apartment() -> None:
    import subprocess

    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-c", APARTMENT, str(ROOT), tmp],
                             capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"one RIR, sonicset preset, furnished apartment ({r['faces']:,} triangles): peak RSS "
          f"{r['peak_mb']:.0f} MB (scene prepared: {r['scene_mb']:.0f} MB), CPU {r['cpu_s']:.0f} "
          f"s, image-source order reached {r['order']}")


def write_spec(folder: Path, groups: int) -> Path:
    from sonicspec.testing.sonicset import write_sonicset_inputs

    write_sonicset_inputs(folder / "data", ["fixture0", "fixture1", "fixture2"],
                          {"train-clean-360": 6, "dev-clean": 3, "test-clean": 3})
    text = (ROOT / "specs" / "sonicset.yaml").read_text()
    start = text.index("\nsplits:\n")
    end = text.index("\noutputs:\n")
    splits = ("\nsplits:\n"
              f"  train: {{groups: {groups}, scenes: [\"mp3d/*\"], scene_count: 1}}\n"
              "  val: {groups: 1, scenes: [\"mp3d/*\"], scene_count: 1}\n"
              "  test: {groups: 1, scenes: [\"mp3d/*\"], scene_count: 1}\n")
    path = folder / "sonicset.yaml"
    path.write_text(text[:start] + splits + text[end:])
    return path


def run(spec: Path, rusage: Path, shards_per_batch: int) -> tuple[object, float, float]:
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages.workflow import build

    plan = compile_spec(load_spec(spec))
    rusage.mkdir(parents=True, exist_ok=True)
    os.environ["SONICSPEC_BENCH_RUSAGE_DIR"] = str(rusage)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    stream = io.StringIO()
    result = build(plan, cores=2, shards_per_batch=shards_per_batch, stream=stream)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.code != 0:
        raise SystemExit(f"build failed:\n{stream.getvalue()[-4000:]}")
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return plan, wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--groups", type=int, default=16,
                        help="train groups (16 per shard at the preset)")
    parser.add_argument("--skip-batched", action="store_true")
    parser.add_argument("--keep", type=Path, help="build here (kept) instead of a temp folder")
    parser.add_argument("--apartment", action="store_true",
                        help="only the one-RIR apartment measurement (item 3 above)")
    args = parser.parse_args()
    if args.apartment:
        apartment()
        print(f"\ncommand: python bench/{Path(__file__).name} {' '.join(sys.argv[1:])}")
        return
    from sonicspec.plan.model import STEP_BY_NAME

    with tempfile.TemporaryDirectory(prefix="bench-mem-") as tmp:
        folder = (args.keep or Path(tmp)).resolve()
        folder.mkdir(parents=True, exist_ok=True)
        site = folder / "site"
        site.mkdir(exist_ok=True)
        (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
        os.environ["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(site), os.environ.get("PYTHONPATH", "")) if p)
        unbatched = folder / "jobs"
        unbatched.mkdir(exist_ok=True)
        plan, wall, cpu = run(write_spec(unbatched, args.groups), folder / "rusage-jobs", 0)
        jobs = plan.by_key()
        per_step: dict[str, list[dict]] = {}
        for path in (folder / "rusage-jobs").glob("*.json"):
            if path.stem in jobs:
                per_step.setdefault(jobs[path.stem].step, []).append(json.loads(path.read_text()))
        print(f"one Snakemake job per step and shard: {len(plan.jobs)} jobs, wall {wall:.0f} s, "
              f"CPU {cpu:.0f} s (the build's processes)")
        print("| step | jobs | CPU s (max per job) | peak RSS MB (max over jobs) | mem_mb now |")
        print("|---|---|---|---|---|")
        for step in STEP_BY_NAME:
            rows = per_step.get(step, [])
            if not rows:
                continue
            peak = max(max(r["maxrss_mb"], r["children_maxrss_mb"]) for r in rows)
            print(f"| {step} | {len(rows)} | {max(r['cpu_s'] for r in rows):.1f} | {peak:.0f} | "
                  f"{STEP_BY_NAME[step].mem_mb} |", flush=True)
        if args.skip_batched:
            return
        batched = folder / "batched"
        batched.mkdir(exist_ok=True)
        shards = len(plan.by_step()["export"])
        plan_b, wall, cpu = run(write_spec(batched, args.groups), folder / "rusage-batch",
                                shards)
        rows = [json.loads(p.read_text()) for p in (folder / "rusage-batch").glob("*.json")]
        batch = [r for r in rows if r["what"] == "batch"]
        member_peak = max(max(r["maxrss_mb"], r["children_maxrss_mb"])
                          for step, rs in per_step.items()
                          if step in ("placement", "arrange", "rir", "render", "mix", "export")
                          for r in rs)
        print(f"\nbatched, {shards} shards in one batch ({len(batch)} batch process): wall "
              f"{wall:.0f} s, CPU {cpu:.0f} s")
        for r in batch:
            print(f"| batch of {shards} shards ({shards * 6} jobs) | CPU {r['cpu_s']:.1f} s | "
                  f"peak RSS: batch process {r['maxrss_mb']:.0f} MB, its jobs (forked) "
                  f"{r['children_maxrss_mb']:.0f} MB | largest shard job alone "
                  f"{member_peak:.0f} MB |")
        same = ((Path(plan.output_dir) / "checksums.sha256").read_text()
                == (Path(plan_b.output_dir) / "checksums.sha256").read_text())
        print(f"dataset checksums the same both ways: {same}")
    print(f"\ncommand: python bench/{Path(__file__).name} {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
