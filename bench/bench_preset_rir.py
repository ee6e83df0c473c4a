"""CPU of one RIR (and of the 7 RIR points of a 1.5 m walk, which share one image-source
search, as a rir job's source does) at the ``sonicset`` preset in the furnished 100 k-triangle
apartment (``bench_rlr.apartment_mesh``), for this checkout or another one given on the command
line, so two versions are compared side by side in one run (each in its own process).

Reproduce (the second tree an older checkout, e.g. ``git worktree add /tmp/base 346f31f``):
    python bench/bench_preset_rir.py . /tmp/base
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = """
import json, sys, time
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
cpu = []
for seed in range(4):
    c0 = time.process_time()
    _, facts = b.sonicspec_rir(scene, regions, s, seed, 1)
    cpu.append(time.process_time() - c0)
walk = b.SOURCE_M[None] + np.linspace(0, 1.5, 7)[:, None] * np.array([1.0, 0.3, 0.0])
c0 = time.process_time()
with b.warnings.catch_warnings():
    b.warnings.simplefilter("ignore")
    b.simulate_rirs(scene, b.MIC_M, walk, s, np.random.default_rng(0), regions=regions,
                    n_threads=1)
print(json.dumps({"cpu_s": sorted(cpu), "order": facts.image_source_order,
                  "walk_cpu_s": time.process_time() - c0}))
"""


def measure(tree: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PYTHONPATH": str(tree)}
        out = subprocess.run([sys.executable, "-c", CHILD, str(tree), tmp], env=env,
                             capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    trees = [Path(p).resolve() for p in (sys.argv[1:] or ["."])]
    print("CPU of one RIR, sonicset preset, furnished 100k-triangle apartment (4 seeds, 1 core)")
    for tree in trees:
        t0 = time.perf_counter()
        r = measure(tree)
        cpu = ", ".join(f"{c:.3f}" for c in r["cpu_s"])
        walk = (f"; 7 RIR points of a 1.5 m walk (one search): {r['walk_cpu_s']:.2f} s, "
                f"{r['walk_cpu_s'] / 7:.3f} s per point" if "walk_cpu_s" in r else "")
        print(f"  {tree}: {cpu} s (image-source order reached {r['order']}; "
              f"{time.perf_counter() - t0:.0f} s in all){walk}")
    print("command: python bench/bench_preset_rir.py " + " ".join(sys.argv[1:]))


if __name__ == "__main__":
    main()
