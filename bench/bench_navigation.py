"""Benchmark: floors + walkable area of a ~1 M-triangle apartment, path queries, placement.

The scene is generated (no download): a 20 × 14 m apartment, 2.7 m high, split into six rooms
by partition walls with door gaps, furnished with 30 boxes and columns; every face is then
subdivided until the mesh has about ``--triangles`` triangles (walls, floors and furniture
finely tessellated, as in a scan), and the vertices get ±``--noise-m`` of uniform jitter.

Reproduce:
    python bench/bench_navigation.py                      # 1 M triangles, 5 cm cells
    python bench/bench_navigation.py --triangles 250000 --cell-m 0.1

Prints the mesh size, the time and peak memory of ``build_navigation`` (floors + walkable
grid), the time of the first path query (which builds the grid graph) and of later ones, and
the time per placement group (3 moving speech sources, noise, music).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.navigation import (
    NavigationSettings,
    build_navigation,
    sample_walkable_points,
    shortest_path,
)
from sonicspec.geometry.placement import PlacementSettings, sample_placement
from sonicspec.geometry.procedural import add_obstacles, box_obstacle, cylinder_obstacle, shoebox


def apartment(rng: np.random.Generator) -> SceneMesh:
    """Six rooms: partitions (label "wall") with 1 m door gaps, plus furniture."""
    length, width, height = 20.0, 14.0, 2.7
    t = 0.12  # partition thickness

    def wall_x(x, y0, y1):  # a partition along y at x
        return box_obstacle([x, 0.5 * (y0 + y1), height / 2], [t, y1 - y0, height], label="wall")

    def wall_y(y, x0, x1):
        return box_obstacle([0.5 * (x0 + x1), y, height / 2], [x1 - x0, t, height], label="wall")

    parts = [
        wall_y(7.0, 0.0, 3.0),
        wall_y(7.0, 4.0, 10.0),
        wall_y(7.0, 11.0, 16.0),
        wall_y(7.0, 17.0, 20.0),
        wall_x(7.0, 0.0, 3.0),
        wall_x(7.0, 4.0, 7.0),
        wall_x(13.0, 0.0, 5.0),
        wall_x(13.0, 6.0, 7.0),
        wall_x(10.0, 7.0, 10.0),
        wall_x(10.0, 11.0, 14.0),
    ]
    for _ in range(24):  # tables, beds, cabinets
        sx, sy = rng.uniform(0.4, 1.6, 2)
        cx = rng.uniform(0.5 + sx / 2, length - 0.5 - sx / 2)
        cy = rng.uniform(0.5 + sy / 2, width - 0.5 - sy / 2)
        h = rng.uniform(0.4, 2.0)
        parts.append(box_obstacle([cx, cy, h / 2], [sx, sy, h], rng.uniform(0, 90)))
    for _ in range(6):  # columns, plants
        parts.append(
            cylinder_obstacle(rng.uniform(1, [length - 1, width - 1]), rng.uniform(0.1, 0.3), 1.5)
        )
    return add_obstacles(shoebox([length, width, height]), parts)


def subdivide(mesh: SceneMesh, target: int, noise_m: float, rng) -> SceneMesh:
    """Split faces (longest first, trimesh) to about ``target`` triangles; jitter vertices."""
    import trimesh.remesh

    area = float(mesh.face_areas.sum())
    # Right triangles with legs e have area e²/2; subdivision overshoots, so calibrate the
    # edge length on the result a few times.
    max_edge = np.sqrt(2.0 * area / target)
    for _ in range(4):
        vertices, faces, index = trimesh.remesh.subdivide_to_size(
            mesh.vertices, mesh.faces, max_edge=max_edge, max_iter=30, return_index=True
        )
        if abs(len(faces) / target - 1) < 0.1:
            break
        max_edge *= np.sqrt(len(faces) / target)
    vertices = vertices + rng.uniform(-noise_m, noise_m, vertices.shape)
    return SceneMesh(
        vertices=vertices,
        faces=faces,
        face_material=mesh.face_material[index],
        materials=mesh.materials,
        face_label=mesh.face_label[index],
        labels=mesh.labels,
        face_object=mesh.face_object[index],
    )


def peak_rss_mb() -> float:
    """This process's peak resident memory, MB.

    Linux: VmHWM of /proc/self/status (``ru_maxrss`` survives exec, so a child would report
    its parent's peak); elsewhere ``ru_maxrss``.
    """
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    scale = 1 / 1024 if sys.platform != "darwin" else 1 / 1024**2
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=1_000_000)
    parser.add_argument("--cell-m", type=float, default=0.05)
    parser.add_argument("--noise-m", type=float, default=0.005)
    parser.add_argument("--queries", type=int, default=20)
    parser.add_argument("--groups", type=int, default=20)
    parser.add_argument("--mesh-npz", help=argparse.SUPPRESS)  # internal: the measuring child
    args = parser.parse_args()
    if args.mesh_npz is None:
        # Generate the mesh here, measure in a fresh process: its peak RSS is then the
        # navigation's (plus the loaded mesh), not the mesh generator's.
        rng = np.random.default_rng(0)
        t0 = time.perf_counter()
        mesh = subdivide(apartment(rng), args.triangles, args.noise_m, rng)
        t_gen = time.perf_counter() - t0
        print(f"python {platform.python_version()}, {os.cpu_count()} cpus, {platform.machine()}")
        print(
            f"mesh: {mesh.n_faces:,} triangles, {mesh.vertices.shape[0]:,} vertices "
            f"(generated in {t_gen:.1f} s); cell {args.cell_m} m",
            flush=True,
        )
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "mesh.npz")
            np.savez(
                path,
                vertices=mesh.vertices,
                faces=mesh.faces,
                face_material=mesh.face_material,
                face_label=mesh.face_label,
                face_object=mesh.face_object,
                materials=np.array(mesh.materials),
                labels=np.array(mesh.labels),
            )
            subprocess.run(
                [sys.executable, __file__, *sys.argv[1:], "--mesh-npz", path], check=True
            )
        return
    measure(args)


def measure(args: argparse.Namespace) -> None:
    data = np.load(args.mesh_npz)
    mesh = SceneMesh(
        vertices=data["vertices"],
        faces=data["faces"],
        face_material=data["face_material"],
        materials=tuple(data["materials"].tolist()),
        face_label=data["face_label"],
        labels=tuple(data["labels"].tolist()),
        face_object=data["face_object"],
    )
    rng = np.random.default_rng(1)
    rss_before = peak_rss_mb()
    settings = NavigationSettings(cell_m=args.cell_m)
    t0 = time.perf_counter()
    nav = build_navigation(mesh, settings)
    t_nav = time.perf_counter() - t0
    grid = nav.grid(0)
    print(
        f"build_navigation: {t_nav:.2f} s, peak RSS {peak_rss_mb():.0f} MB "
        f"(with the mesh loaded, before: {rss_before:.0f} MB)"
    )
    heights = ", ".join(f"{f.z_m:.3f}" for f in nav.floors)
    print(
        f"  floors at z = {heights} m, grid {grid.shape}, walkable "
        f"{grid.area_m2:.1f} m² in {grid.n_components} components "
        f"(largest {grid.component_areas_m2()[0]:.1f} m²)"
    )

    ends = sample_walkable_points(grid, 2 * args.queries, rng, component=0)
    t0 = time.perf_counter()
    first = shortest_path(grid, ends[0], ends[1])
    t_first = time.perf_counter() - t0
    times, ratio = [], []
    for a, b in zip(ends[2::2], ends[3::2], strict=True):
        t0 = time.perf_counter()
        path = shortest_path(grid, a, b)
        times.append(time.perf_counter() - t0)
        ratio.append(path.length_m / max(np.linalg.norm((b - a)[:2]), 1e-9))
    print(
        f"shortest_path: first {t_first * 1e3:.0f} ms (builds the graph; "
        f"{first.length_m:.1f} m), then median {np.median(times) * 1e3:.0f} ms, "
        f"max {np.max(times) * 1e3:.0f} ms over {len(times)} queries "
        f"(median length / straight {np.median(ratio):.2f})"
    )

    placement = PlacementSettings()
    t0 = time.perf_counter()
    tries = []
    for seed in range(args.groups):
        p = sample_placement(
            nav,
            placement,
            scene_id="apartment",
            speech=["shortest_path"] * 3,
            noise=True,
            music=True,
            rng=np.random.default_rng(seed),
        )
        tries.append(p.tries)
    t_place = (time.perf_counter() - t0) / args.groups
    print(
        f"sample_placement: {t_place * 1e3:.0f} ms per group (3 paths + noise + music), "
        f"median {int(np.median(tries))} tries"
    )


if __name__ == "__main__":
    main()
