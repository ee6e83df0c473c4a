"""CPU of one RIR at the ``sonicset`` preset in the furnished 100 k-triangle apartment
(``bench_rlr.apartment_mesh``), for this checkout or another one given on the command line, so
two versions are compared side by side in one run (each in its own process).

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
print(json.dumps({"cpu_s": sorted(cpu), "order": facts.image_source_order}))
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
        print(f"  {tree}: {cpu} s (image-source order reached {r['order']}; "
              f"{time.perf_counter() - t0:.0f} s in all)")
    print("command: python bench/bench_preset_rir.py " + " ".join(sys.argv[1:]))


if __name__ == "__main__":
    main()
