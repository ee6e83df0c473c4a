"""Fewer, larger triangles on flat areas: the same surfaces, materials and creases.

Why: the tracer's cost per surface hit grows with the triangle count (Embree's tree gets
deeper and incoherent rays visit more of it): 2.2 M hits/s on a 12-triangle shoebox, 0.6 M on
the same walls cut into 786 k triangles. Scene meshes are often finely tessellated where the
surface is flat (scans re-meshed to a uniform edge length, procedural rooms subdivided), and
geometric acoustics sees the surface, not its triangles. So before the RIR stage builds its
Embree scene, flat areas are re-triangulated by half-edge collapses that move no surface by
more than a tolerance: a vertex is removed only when every face around it stays (within the
tolerance) in its plane, creases stay on their lines and a boundary between two materials
stays where it is; each face keeps its own coefficients, so nothing is re-assigned.
"""

from __future__ import annotations

import numpy as np

from sonicspec.acoustics.room._simplify_kernels import simplify
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError

__all__ = ["MAX_TURN_DEG", "simplified_scene", "simplify_flat_areas"]

#: Largest turn of a re-pointed face's normal: it keeps specular reflections within 2× this.
MAX_TURN_DEG = 2.0
_EXACT_M = 1e-9  # flat to rounding


def simplify_flat_areas(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_class: np.ndarray,
    tolerance_m: float,
    max_turn_deg: float = MAX_TURN_DEG,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Remove vertices from flat areas of a closed mesh without moving its surface.

    Parameters
    ----------
    vertices : (V, 3) float
        Vertex positions, metres (never moved: collapses only drop vertices).
    faces : (F, 3) int
        Triangles; orientation is kept.
    face_class : (F,) int
        Material class of each face; an edge between two classes is a boundary that stays.
    tolerance_m : float
        Largest distance between the new surface and the old one, summed over the collapses
        that made each face (a bound, not an estimate). 0 collapses exactly flat areas only
        (to rounding: 1e-9 m).
    max_turn_deg : float
        Largest change of a face's normal in one collapse.

    Returns
    -------
    vertices : (V', 3) float
        The vertices still used, in their original order.
    faces : (F', 3) int
        The new triangles, indexing the returned vertices.
    face_index : (F',) int
        For every new triangle the original face it grew from (its coefficients).

    Notes
    -----
    Edges with one face (holes) or more than two (non-manifold) keep their vertices, and so
    does a vertex with more than 128 faces around it. An edge that folds by more than 90°
    (two faces back to back, as on a zero-thickness panel) is pinned like a material
    boundary. About a second for a million triangles.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.array(faces, dtype=np.int64, copy=True)
    face_class = np.ascontiguousarray(face_class, dtype=np.int64)
    if not np.isfinite(tolerance_m) or tolerance_m < 0:
        raise AcousticsError(f"tolerance_m: expected a distance >= 0 m, got {tolerance_m!r}")
    # The compiled pass does not check bounds: bad indices must not reach it.
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise AcousticsError(f"vertices: expected shape (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise AcousticsError(f"faces: expected shape (F, 3), got {faces.shape}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise AcousticsError(
            f"faces: expected vertex indices in [0, {len(vertices) - 1}], "
            f"got [{faces.min()}, {faces.max()}]")
    if face_class.shape != (len(faces),):
        raise AcousticsError(
            f"face_class: expected shape ({len(faces)},), got {face_class.shape}")
    extent = float(np.max(np.ptp(vertices, axis=0))) if len(vertices) else 0.0
    tol = max(float(tolerance_m), _EXACT_M)
    # Twice the smallest area a re-pointed face may have: far below any real triangle.
    min_area2 = (1e-6 * max(extent, 1.0)) ** 2
    alive = np.ones(len(faces), dtype=np.bool_)
    face_err = np.zeros(len(faces))
    cos_min = float(np.cos(np.radians(max_turn_deg)))
    # Exactly flat areas first: a collapse that spends tolerance early (a corner moved by a
    # millimetre) would otherwise leave its neighbours slightly bent and block exact ones.
    for step_tol in sorted({_EXACT_M, tol}):
        simplify(vertices, faces, alive, face_class, face_err, step_tol, cos_min, min_area2)
    face_index = np.flatnonzero(alive)
    kept = faces[face_index]
    used = np.unique(kept)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept], face_index


def simplified_scene(scene: AcousticScene, tolerance_m: float) -> AcousticScene:
    """``scene`` with its flat areas re-triangulated by :func:`simplify_flat_areas` (each
    face's coefficients carried over); ``scene`` itself when nothing could be removed."""
    classes = scene.coefficient_classes()[0]
    vertices, faces, index = simplify_flat_areas(scene.vertices, scene.faces, classes,
                                                 tolerance_m)
    if len(index) == scene.n_faces:
        return scene
    return AcousticScene(vertices, faces, scene.absorption[index], scene.scattering[index],
                         scene.transmission[index])
