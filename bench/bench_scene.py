"""Benchmark (issue 3): import + repair + walkable area of a ~1 M-triangle scanned apartment.

The scene is generated (no download): the furnished six-room apartment of
``bench_navigation.py``, subdivided to about ``--triangles`` triangles (welded, so the surface
is connected as a scanner's is; the weld also joins partitions and walls where they touch)
with ±5 mm vertex noise, then damaged like a scan: T-junctions on 1 % of faces (one edge
bisected on that face's side only, the midpoint within 0.2 mm of the edge; not in slivers),
5 % of faces flipped, every vertex of 2 % of faces split (duplicated), a wall panel removed;
and written as a binary PLY. A fresh process, pinned to one core, then times the three steps
a build runs on it and reads its peak memory, and runs a leak test on the repaired mesh (not
timed).

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
    vertices, faces = t_junctions(vertices, faces, 0.01, rng)
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


def t_junctions(vertices, faces, fraction: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """Bisect one edge of a ``fraction`` of faces on that face's side only.

    The face (a, b, c) becomes (a, m, c), (m, b, c) while its neighbour keeps the whole edge
    a-b: a T-junction, as where scan tiles or levels of detail of different resolution meet.
    m is the edge's midpoint moved by up to 0.2 mm. Edges picked from both sides are skipped,
    and so are edges of slivers (a face on either side less than 1 cm high over its longest
    edge): subdividing the 12 cm partitions leaves slivers only millimetres wide, which the
    ±5 mm noise folds over, and a T-junction inside such a fold is not a scan's.
    """
    n = len(vertices)
    corners = vertices[faces]
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    doubled_area = np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    height = doubled_area / sides.max(axis=1)
    edge_keys = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=2), axis=2)
    edge_keys = edge_keys[..., 0] * n + edge_keys[..., 1]  # (F, 3): edge corner k → k+1
    unique, inverse = np.unique(edge_keys.ravel(), return_inverse=True)
    lowest = np.full(len(unique), np.inf)
    np.minimum.at(lowest, inverse, np.repeat(height, 3))
    chosen = np.flatnonzero(rng.random(len(faces)) < fraction)
    corner = rng.integers(0, 3, len(chosen))
    sound = lowest[inverse.reshape(-1, 3)[chosen, corner]] >= 0.01
    chosen, corner = chosen[sound], corner[sound]
    a = faces[chosen, corner]
    b = faces[chosen, (corner + 1) % 3]
    c = faces[chosen, (corner + 2) % 3]
    key = edge_keys[chosen, corner]
    _, key_inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    once = counts[key_inverse] == 1
    chosen, a, b, c = chosen[once], a[once], b[once], c[once]
    m = n + np.arange(len(chosen))
    middle = 0.5 * (vertices[a] + vertices[b]) + rng.uniform(-2e-4, 2e-4, (len(chosen), 3))
    keep = np.ones(len(faces), bool)
    keep[chosen] = False
    faces = np.concatenate([faces[keep], np.column_stack([a, m, c]), np.column_stack([m, b, c])])
    return np.concatenate([vertices, middle]), faces


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
    total = t_load + t_repair + t_nav
    rss = peak_rss_mb()
    t0 = time.perf_counter()
    leak = leak_test(repaired, np.random.default_rng(0), 20_000)
    t_leak = time.perf_counter() - t0
    after = report.after
    print(f"import   {t_load:6.2f} s  ({mesh.n_faces:,} faces)")
    print(f"repair   {t_repair:6.2f} s  (merged {report.merged_vertices:,} vertices, stitched "
          f"{report.t_junctions_stitched:,} T-junctions, split {report.touching_vertices_split} "
          f"touching vertices, dropped {report.non_manifold_faces_removed} non-manifold faces, "
          f"flipped {report.faces_flipped_coherent:,} faces, closed {report.holes_closed} of "
          f"{report.holes_found} holes)")
    print(f"         after: {after.boundary_edges} open, {after.non_manifold_edges} non-manifold, "
          f"{after.inconsistent_edges} inconsistent edges, {after.components} pieces, "
          f"watertight {report.watertight}")
    print(f"walkable {t_nav:6.2f} s  ({sum(g.area_m2 for g in nav.grids):.1f} m² on "
          f"{len(nav.grids)} floor(s), 5 cm cells)")
    print(f"total    {total:6.2f} s, peak RSS {rss:.0f} MB (start {rss0:.0f} MB)")
    print(f"leak     {t_leak:6.2f} s  {leak.leak_fraction:.5f} of {leak.rays} rays ({leak.escaped} "
          f"escaped, {leak.backface} first hit a back face); peak RSS {peak_rss_mb():.0f} MB")


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
