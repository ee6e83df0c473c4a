"""Tiny rooms as plain arrays, for the acoustics tests and benchmarks (no geometry import)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sonicspec.acoustics.room.scene import AcousticScene


def extruded_room(polygon_ccw: Sequence[Sequence[float]],
                  floor_triangles: Sequence[Sequence[int]],
                  height: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed prism over a CCW floor polygon, normals into the room (the mesh convention)."""
    poly = np.asarray(polygon_ccw, dtype=float)
    n = len(poly)
    verts = np.vstack([np.c_[poly, np.zeros(n)], np.c_[poly, np.full(n, height)]])
    faces = []
    for a, b, c in floor_triangles:
        faces.append((a, b, c))  # CCW from above: normal +z, into the room
        faces.append((a + n, c + n, b + n))  # ceiling: normal -z
    for i in range(n):
        j = (i + 1) % n
        # wall over edge i->j; the room lies left of the edge, so (a, c, b) faces inward
        faces.append((i, j + n, j))
        faces.append((i, i + n, j + n))
    return verts, np.array(faces)


def shoebox(lx: float, ly: float, lz: float) -> tuple[np.ndarray, np.ndarray]:
    """The [0, lx] × [0, ly] × [0, lz] box as (vertices, faces)."""
    return extruded_room([(0, 0), (lx, 0), (lx, ly), (0, ly)], [(0, 1, 2), (0, 2, 3)], lz)


def uniform_scene(verts: np.ndarray, faces: np.ndarray, alpha: float = 0.2, s: float = 0.0,
                  tau: float = 0.0, n_bands: int = 7) -> AcousticScene:
    """Every face with the same absorption, scattering and transmission in every band."""
    f = len(faces)
    return AcousticScene(verts, faces, np.full((f, n_bands), alpha), np.full((f, n_bands), s),
                         np.full((f, n_bands), tau))


def flutter_scene(tau_high_band: float = 0.0) -> AcousticScene:
    """A 10 × 7 × 2.7 m room whose late field is not diffuse, in two bands: absorbing ceiling
    (α 0.6), floor α 0.3, hard walls α 0.05, scattering 0.1 everywhere, so near-horizontal
    rays carry the tail; transmission ``tau_high_band`` in the second band."""
    verts, faces = shoebox(10.0, 7.0, 2.7)
    tri = verts[faces]
    horizontal = np.abs(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]) > 0
    ceiling = horizontal & (tri[:, 0, 2] > 1.0)
    alpha = np.where(ceiling, 0.6, np.where(horizontal, 0.3, 0.05))[:, None].repeat(2, axis=1)
    tau = np.zeros((len(faces), 2))
    tau[:, 1] = tau_high_band
    return AcousticScene(verts, faces, alpha, np.full((len(faces), 2), 0.1), tau)


def partitioned_shoebox(lx: float, ly: float, lz: float, x_m: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """A shoebox split at ``x = x_m`` by a single-sheet, full-height partition whose two
    triangles are the last two faces (so tests can give it its own coefficients)."""
    verts, faces = shoebox(lx, ly, lz)
    wall = np.array([[x_m, 0, 0], [x_m, ly, 0], [x_m, ly, lz], [x_m, 0, lz]], dtype=float)
    return (np.vstack([verts, wall]),
            np.vstack([faces, np.array([[0, 1, 2], [0, 2, 3]]) + len(verts)]))


def door_rooms(room_m: tuple[float, float, float] = (5.0, 4.0, 3.0),
               door_m: tuple[float, float, float] = (1.5, 0.9, 2.1)
               ) -> tuple[np.ndarray, np.ndarray]:
    """Two equal boxes ``room_m`` side by side along x, joined by a door opening in the
    single-sheet wall between them at ``x = room_m[0]``: ``door_m`` is (y of its edge,
    width, height), from the floor. The wall's six triangles (left of the door, right of it,
    above it) are the last six faces."""
    lx, ly, lz = room_m
    y0, width, height = door_m
    y1 = y0 + width
    if not (0 < y0 < y1 < ly and 0 < height < lz):
        raise ValueError(f"door_m: expected a door inside the {ly} x {lz} m wall, got {door_m}")
    verts, faces = shoebox(2 * lx, ly, lz)
    quads = [((0.0, 0.0), (y0, lz)), ((y1, 0.0), (ly, lz)), ((y0, height), (y1, lz))]
    wall_v, wall_f = [], []
    for (ya, za), (yb, zb) in quads:
        base = len(verts) + len(wall_v)
        wall_v += [(lx, ya, za), (lx, yb, za), (lx, yb, zb), (lx, ya, zb)]
        wall_f += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.vstack([verts, np.array(wall_v)]), np.vstack([faces, np.array(wall_f)])
