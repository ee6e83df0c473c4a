"""Benchmark (issue 27, item 6): the image-source search with pruning by beams and at the
last order, against the unpruned search with its count cap.

Each row runs in a fresh process (peak RSS from ``getrusage``; CPU is the search alone, after a
warm-up call that compiles the kernels and builds the per-scene tables):

* small rooms where the unpruned search is feasible to order 3 — the tests' 6 x 5 x 3 m
  shoebox cut into 160 triangles, clean and jittered by ±2 mm (every triangle its own mirror),
  and a furnished L-room (two boxes) subdivided twice: candidates per order, CPU, RSS, and
  whether the arrivals (times, amplitudes, directions, orders) are the same bytes (the
  unpruned search with a cap of 10^7, so that it too reaches order 3);
* the furnished apartment (``bench_rlr.apartment_mesh``, ~81k triangles, simplified at the
  ``sonicset`` preset's 1 mm), clean and with every vertex jittered by ±2 mm, at the preset's
  settings (order 3): the unpruned search (the old cap of 2,000,000 candidates), the pruned one
  with exact mirrors, and with ``mirror_tolerance_m: 0.01`` (the presets' value) — the order
  reached, candidates per order, CPU, RSS; and how far the jittered room's arrivals are from
  the clean room's (merged mirrors are an approximation of the order of the noise).

Reproduce:
    python bench/bench_ism_pruning.py
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, resource, sys, time, warnings
sys.path[:0] = [sys.argv[1] + "/bench", sys.argv[1], sys.argv[1] + "/tests"]
import numpy as np
from sonicspec.acoustics.paths.image_sources import image_sources, planar_regions
from sonicspec.acoustics.room.scene import AcousticScene
case, beams, tol, cap = sys.argv[2], sys.argv[3] == "1", float(sys.argv[4]), int(sys.argv[5])
if case.startswith("apartment"):
    import bench_rlr as b
    from bench_navigation import apartment, subdivide
    from sonicspec.acoustics.engine import SimulationSettings, acoustic_scene
    from sonicspec.geometry.materials import load_library
    jitter = 0.002 if case.endswith("jittered") else 0.0
    mesh = subdivide(apartment(np.random.default_rng(0)), 81000, jitter,
                     np.random.default_rng(0)).with_materials(
                         load_library("sonicset").material_for_label)
    s = SimulationSettings.from_spec(b.preset_acoustics(), b.SAMPLE_RATE_HZ,
                                     b.SPEED_OF_SOUND_M_S)
    scene = acoustic_scene(mesh, load_library("sonicset"), s)
    src, rcv = b.MIC_M, b.SOURCE_M[None]
    air, c, limit = s.air(), s.speed_of_sound_m_s, s.speed_of_sound_m_s * s.rir_limit_s
else:
    import trimesh
    from sonicspec.geometry.procedural import add_obstacles, box_obstacle, l_shape, shoebox
    if case.startswith("shoebox"):
        room = shoebox([6.0, 5.0, 3.0])
        v, f = trimesh.remesh.subdivide_to_size(room.vertices, room.faces, max_edge=2.0)
        if case.endswith("jittered"):
            v = v + np.random.default_rng(0).uniform(-0.002, 0.002, v.shape)
        src, rcv = np.array([4.2, 3.1, 1.6]), np.array([[1.5, 1.2, 1.4], [3.0, 1.0, 1.2]])
    else:
        room = l_shape([6.0, 5.0, 2.7], [2.5, 2.0])
        room = add_obstacles(room, [box_obstacle([1.5, 1.5, 0.4], [1.0, 0.6, 0.8]),
                                    box_obstacle([3.0, 3.5, 0.5], [0.8, 0.8, 1.0],
                                                 yaw_deg=30.0)])
        v, f = room.vertices, room.faces
        for _ in range(2):
            v, f = trimesh.remesh.subdivide(v, f)
        src, rcv = np.array([0.8, 0.6, 1.5]), np.array([[2.8, 2.4, 1.2], [0.5, 2.2, 1.6]])
    n = len(f)
    scene = AcousticScene(v, f, np.full((n, 6), 0.1), np.full((n, 6), 0.05), np.zeros((n, 6)))
    air, c, limit = None, 343.0, 343.0 * 0.5
regions = (planar_regions(scene) if tol <= 1e-4 else
           planar_regions(scene, angle_tol_rad=0.5, distance_tol_m=tol))
def run():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return image_sources(scene, src, rcv, 3, air, c, regions, max_path_length_m=limit,
                             beams=beams, max_candidates=cap)
run()  # compile, per-scene tables
c0 = time.process_time()
res = run()
cpu = time.process_time() - c0
a = res.arrivals[0]
key = np.lexsort((np.round(a.times_s, 12), a.order))
print(json.dumps({"order": res.max_order, "stopped": res.stopped,
                  "candidates": list(res.candidates), "cpu_s": cpu, "faces": scene.n_faces,
                  "mirrors": regions.n_regions, "arrivals": len(a),
                  "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "times": a.times_s[key].tolist(), "amps": a.amplitudes[key].tolist(),
                  "orders": a.order[key].tolist(),
                  "bytes": [x.tobytes().hex() for x in (a.times_s, a.amplitudes,
                                                        a.directions, a.order)]}))
"""


def measure(case: str, beams: bool, tol: float = 1e-4, cap: int = 2_000_000) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), case, str(int(beams)),
                          str(tol), str(cap)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def row(label: str, r: dict) -> str:
    counts = " / ".join(f"{n:,}" for n in r["candidates"])
    why = f" ({r['stopped']})" if r["stopped"] else ""
    return (f"| {label} | {r['faces']:,} / {r['mirrors']:,} | {r['order']}{why} | {counts} | "
            f"{r['arrivals']} | {r['cpu_s']:.2f} | {r['rss_mb']:.0f} |")


def main() -> None:
    head = ["| search | triangles / mirrors | order reached (of 3) | candidates per order | "
            "arrivals (first receiver) | CPU s | peak RSS MB |", "|---|---|---|---|---|---|---|"]
    print("## Small rooms: pruned against unpruned (order 3)\n")
    print("\n".join(head))
    same = []
    for case in ("shoebox-160", "shoebox-160-jittered", "furnished-l-room"):
        # the jittered room's unpruned order 3 needs 3.4 M candidates: a cap of 10^7 for it
        old, new = measure(case, False, cap=10**7), measure(case, True)
        print(row(f"{case}, unpruned (cap 10^7)", old))
        print(row(f"{case}, pruned", new), flush=True)
        same.append((case, old["bytes"] == new["bytes"], old["order"], new["order"]))
    for case, equal, o, n in same:
        print(f"{case}: arrivals the same bytes: {equal} (orders {o} / {n})")
    print("\n## The furnished apartment at the sonicset preset's settings (order 3)\n")
    print("\n".join(head))
    runs = {}
    for case in ("apartment", "apartment-jittered"):
        for label, beams, tol in (("unpruned (the old cap)", False, 1e-4),
                                  ("pruned, exact mirrors", True, 1e-4),
                                  ("pruned, mirror_tolerance_m 0.01", True, 0.01)):
            if case == "apartment-jittered" and label == "pruned, exact mirrors":
                continue  # 66,504 mirrors: order 2 tests 4.4 billion pairs (minutes); merge
            r = measure(case, beams, tol)
            runs[(case, label)] = r
            print(row(f"{case}, {label}", r), flush=True)
    clean = runs[("apartment", "pruned, exact mirrors")]
    for case, label in (("apartment", "pruned, mirror_tolerance_m 0.01"),
                        ("apartment-jittered", "pruned, mirror_tolerance_m 0.01")):
        r = runs[(case, label)]
        import numpy as np

        e_clean = float(np.sum(np.square(clean["amps"])))
        e = float(np.sum(np.square(r["amps"])))
        by_order = {k: (sum(1 for o in clean["orders"] if o == k),
                        sum(1 for o in r["orders"] if o == k)) for k in (1, 2, 3)}
        print(f"{case}, {label}: {r['arrivals']} arrivals against the clean room's "
              f"{clean['arrivals']} (per order 1/2/3: {by_order}); their summed energy "
              f"{10 * np.log10(e / e_clean):+.2f} dB from the clean room's")
    print("\ncommand: python bench/bench_ism_pruning.py")


if __name__ == "__main__":
    main()
