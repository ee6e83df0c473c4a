"""Benchmark (issue 3): import + repair + walkable area of a ~1 M-triangle scanned apartment.

The scene is generated (no download): the furnished six-room apartment of
``bench_navigation.py``, subdivided to about ``--triangles`` triangles (welded, so the surface
is connected as a scanner's is) with ±5 mm vertex noise, then damaged like a scan: 5 % of faces
flipped, every vertex of 2 % of faces split (duplicated), a wall panel removed; and written as
a binary PLY. A fresh process, pinned to
one core, then times the three steps a build runs on it and reads its peak memory.

Target: under 60 s and under 4 GB on one core.

Reproduce:
    python bench/bench_scene.py                     # 1 M triangles
    python bench/bench_scene.py --triangles 250000
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_navigation import apartment, peak_rss_mb

from sonicspec.geometry.io import load_mesh
from sonicspec.geometry.navigation import NavigationSettings, build_navigation
from sonicspec.geometry.repair import RepairSettings, leak_test, repair_mesh


def damaged_ply(path: Path, triangles: int) -> tuple[int, int]:
    """Write the damaged apartment; returns (triangles, vertices)."""
    import trimesh
    import trimesh.remesh

    rng = np.random.default_rng(0)
    room = apartment(rng)
    # Subdivide, then weld the copies subdivision makes of shared edge points *before* adding
    # scan noise, so the surface stays connected as a scanner's mesh is (noise added to each
    # copy independently would tear it along every edge).
    area = float(room.face_areas.sum())
    max_edge = np.sqrt(2.0 * area / triangles)
    for _ in range(4):
        v, f = trimesh.remesh.subdivide_to_size(room.vertices, room.faces, max_edge=max_edge,
                                                max_iter=30)
        if abs(len(f) / triangles - 1) < 0.1:
            break
        max_edge *= np.sqrt(len(f) / triangles)
    welded = trimesh.Trimesh(v, f, process=False)
    welded.merge_vertices()
    vertices = np.array(welded.vertices) + rng.uniform(-0.005, 0.005, welded.vertices.shape)
    faces = np.array(welded.faces)
    flip = rng.random(len(faces)) < 0.05
    faces[flip] = faces[flip][:, ::-1]
    split = np.flatnonzero(rng.random(len(faces)) < 0.02)
    fresh = np.arange(len(vertices), len(vertices) + 3 * len(split)).reshape(-1, 3)
    vertices = np.concatenate([vertices, vertices[faces[split]].reshape(-1, 3)])
    faces[split] = fresh
    # A 1 x 1 m wall panel gone: faces of the x = 0 wall between y 3..4, z 1..2.
    c = vertices[faces].mean(axis=1)
    hole = (c[:, 0] < 0.01) & (c[:, 1] > 3) & (c[:, 1] < 4) & (c[:, 2] > 1) & (c[:, 2] < 2)
    faces = faces[~hole]
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    return len(faces), len(vertices)


def measure(path: Path) -> None:
    rss0 = peak_rss_mb()
    t0 = time.perf_counter()
    mesh = load_mesh(path)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    repaired, report = repair_mesh(mesh, RepairSettings(max_hole_size_m=2.0))
    t_repair = time.perf_counter() - t0
    t0 = time.perf_counter()
    nav = build_navigation(repaired, NavigationSettings(cell_m=0.05))
    t_nav = time.perf_counter() - t0
    leak = leak_test(repaired, np.random.default_rng(0), 20_000)
    total = t_load + t_repair + t_nav
    print(f"import   {t_load:6.2f} s  ({mesh.n_faces:,} faces)")
    print(f"repair   {t_repair:6.2f} s  (merged {report.merged_vertices:,} vertices, flipped "
          f"{report.faces_flipped_coherent:,} faces, closed {report.holes_closed} holes, "
          f"watertight {report.watertight})")
    print(f"walkable {t_nav:6.2f} s  ({sum(g.area_m2 for g in nav.grids):.1f} m² on "
          f"{len(nav.grids)} floor(s), 5 cm cells)")
    print(f"total    {total:6.2f} s, peak RSS {peak_rss_mb():.0f} MB (start {rss0:.0f} MB); "
          f"leak fraction after repair {leak.leak_fraction:.5f} of {leak.rays} rays")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=1_000_000)
    parser.add_argument("--ply", help=argparse.SUPPRESS)  # internal: the measuring child
    args = parser.parse_args()
    if args.ply:
        measure(Path(args.ply))
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "apartment.ply"
        n_faces, n_vertices = damaged_ply(path, args.triangles)
        print(f"python {platform.python_version()}, {os.cpu_count()} cpus; mesh {n_faces:,} "
              f"triangles, {n_vertices:,} vertices; measured on one core (taskset -c 0)",
              flush=True)
        pin = ["taskset", "-c", "0"] if sys.platform.startswith("linux") else []
        subprocess.run([*pin, sys.executable, __file__, "--ply", str(path)], check=True,
                       env=dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1"))


if __name__ == "__main__":
    main()
