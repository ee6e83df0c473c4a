"""Benchmark (issue 27): the mesh step's peak memory on a ~1 M-triangle scan, two code
revisions side by side, against the step's ``mem_mb`` request.

The scan is ``bench_scene.py``'s damaged furnished apartment (``--triangles``, default
1,000,000: ±5 mm vertex noise, T-junctions, 5 % of faces flipped, 2 % split, a wall panel
missing) written as PLY, declared as a ``kind: mesh`` scene (repair on, holes up to 2 m
closed, the default 20,000-ray leak test). Each revision — ``--against`` (a git revision,
extracted with ``git archive``; default ``main``) and this checkout — runs the plan's one
``mesh`` job through ``sonicspec.stages.run_job`` in a fresh child process (``PYTHONPATH`` =
its tree, its own store): its peak RSS (``VmHWM``: ``ru_maxrss`` would carry the spawning
process's peak over ``exec``, here the scan generator's) and CPU (``getrusage``). The two mesh
artifacts are compared file by file.

Reproduce:
    nice -n 10 python bench/bench_mesh_memory.py                 # main vs this checkout
    nice -n 10 python bench/bench_mesh_memory.py --triangles 250000 --against b26bb05
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

SPEC = """\
sonicspec: 1
name: meshmem
seed: 3
scenes:
  - kind: mesh
    id: apartment
    path: {ply}
    up_axis: z
    repair: {{max_hole_size_m: 2.0, on_leak: warn}}
microphone: {{kind: mono}}
trajectory: {{kind: shortest_path, rir_spacing_m: 0.5}}
acoustics: {{rays: 100, image_source_order: 1, max_rir_length_s: 0.2}}
mixture: {{speakers: 1, tasks: []}}
corpora: {{speech: {{kind: generated}}}}
splits: {{train: {{groups: 1, scenes: [apartment]}}}}
"""

CHILD = r'''
import hashlib, json, resource, sys
from pathlib import Path

from sonicspec.plan.compile import compile_spec
from sonicspec.spec import load_spec
from sonicspec.stages import run_job

plan = compile_spec(load_spec(Path(sys.argv[1])))
job = next(j for j in plan.jobs if j.step == "mesh")
run_job(plan, job.key)
r = resource.getrusage(resource.RUSAGE_SELF)
# VmHWM, not ru_maxrss: Linux carries ru_maxrss over exec from the parent that spawned us
with open("/proc/self/status") as status:
    hwm = next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
art = Path(plan.store_dir) / "mesh" / job.key[:2] / f"{job.key}.zarr"
h = hashlib.sha256()
for f in sorted(art.rglob("*")):
    if f.is_file():
        h.update(f.relative_to(art).as_posix().encode())
        h.update(f.read_bytes())
print(json.dumps({"peak_mb": hwm / 1024, "cpu_s": r.ru_utime + r.ru_stime,
                  "digest": h.hexdigest(), "key": job.key}))
'''


def main() -> None:
    from bench_scene import damaged_ply

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--triangles", type=int, default=1_000_000)
    parser.add_argument("--ply", type=Path,
                        help="measure this PLY instead of generating the apartment")
    parser.add_argument("--against", default="main",
                        help="the git revision to compare with (default: main)")
    args = parser.parse_args()
    from sonicspec.plan.model import STEP_BY_NAME

    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.against],
                         check=True, capture_output=True, text=True).stdout.strip()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                          check=True, capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="bench-mesh-memory-") as tmp:
        work = Path(tmp)
        if args.ply:
            import trimesh

            ply = args.ply.resolve()
            scan = trimesh.load(ply, process=False)
            n_faces, n_vertices = len(scan.faces), len(scan.vertices)
            del scan
        else:
            ply = work / "apartment.ply"
            n_faces, n_vertices = damaged_ply(ply, args.triangles)
        old = work / "tree-old"
        old.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive, check=True)
        results = {}
        for name, tree in ((f"{rev} (--against)", old), (f"{head} (this checkout)", ROOT)):
            folder = work / name.split()[0]
            folder.mkdir()
            (folder / "spec.yaml").write_text(SPEC.format(ply=ply))
            done = subprocess.run([sys.executable, "-c", CHILD, str(folder / "spec.yaml")],
                                  env=dict(os.environ, PYTHONPATH=str(tree)), cwd=tree,
                                  capture_output=True, text=True)
            if done.returncode != 0:
                raise SystemExit(f"{name}: the mesh job failed\n{done.stderr[-4000:]}")
            results[name] = json.loads(done.stdout.strip().splitlines()[-1])
    request = STEP_BY_NAME["mesh"].mem_mb
    print(f"mesh step, damaged apartment of {n_faces:,} triangles ({n_vertices:,} vertices); "
          f"mem_mb requested now: {request}")
    print("| revision | peak RSS MB | CPU s | request / peak |")
    print("|---|---|---|---|")
    for name, r in results.items():
        print(f"| {name} | {r['peak_mb']:.0f} | {r['cpu_s']:.1f} | "
              f"{request / r['peak_mb']:.2f}x |")
    (a, b) = results.values()
    print(f"same content key: {a['key'] == b['key']}; same artifact bytes: "
          f"{a['digest'] == b['digest']}")
    print(f"\ncommand: python bench/{Path(__file__).name} {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
