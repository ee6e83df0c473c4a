"""Flat-area simplification: fewer triangles, the same surface, materials and acoustics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from sonicspec.acoustics.engine import SimulationSettings, acoustic_scene
from sonicspec.acoustics.paths.image_sources import image_sources
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.acoustics.room.simplify import simplified_scene, simplify_flat_areas
from sonicspec.errors import AcousticsError
from sonicspec.geometry.materials import load_library
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.procedural import add_obstacles, box_obstacle, l_shape
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.testing.rooms import shoebox, uniform_scene


def furnished_l_room(levels: int, names: bool = False):
    """An L-shaped room (three materials) with two boxes of a fourth, subdivided ``levels``
    times: every face cut into 4**levels coplanar triangles (+ the material names)."""
    room = l_shape([6.0, 5.0, 2.7], [2.5, 2.0])
    room = add_obstacles(room, [box_obstacle([1.5, 1.5, 0.4], [1.0, 0.6, 0.8]),
                                box_obstacle([3.0, 3.5, 0.5], [0.8, 0.8, 1.0], yaw_deg=30.0)])
    verts, faces, material = room.vertices, room.faces, room.face_material
    for _ in range(levels):
        verts, faces, index = trimesh.remesh.subdivide(verts, faces, return_index=True)
        children = np.zeros(len(faces), dtype=np.int64)
        for parent, kids in index.items():
            children[kids] = parent
        material = material[children]
    if names:
        return verts, faces, np.asarray(material), room.materials
    return verts, faces, np.asarray(material)


def edge_use(faces: np.ndarray) -> np.ndarray:
    """How many faces use each undirected edge."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(edges, axis=0, return_counts=True)[1]


def random_rays(n: int, seed: int = 0):
    """Rays from points well inside the L room's open part, in every direction."""
    rng = np.random.default_rng(seed)
    origins = np.c_[rng.uniform(0.3, 3.2, n), rng.uniform(0.3, 2.7, n), rng.uniform(1.2, 2.4, n)]
    d = rng.normal(size=(n, 3))
    return origins, d / np.linalg.norm(d, axis=1, keepdims=True)


def test_flat_areas_go_back_to_few_triangles_with_the_same_surface_and_materials():
    verts, faces, material = furnished_l_room(levels=3)
    v2, f2, kept = simplify_flat_areas(verts, faces, material, 0.001)
    assert len(faces) == 64 * len(furnished_l_room(0)[1])
    assert len(f2) <= 2 * len(furnished_l_room(0)[1])  # back to about the unsubdivided mesh
    # Still closed and manifold, nothing degenerate, vertices never moved.
    assert np.all(edge_use(f2) == 2)
    tri = v2[f2]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert area.min() > 1e-6
    assert np.all(np.isin(v2.view([("", v2.dtype)] * 3), verts.view([("", verts.dtype)] * 3)))
    # The same area of every material (no boundary moved) ...
    old = verts[faces]
    old_area = 0.5 * np.linalg.norm(np.cross(old[:, 1] - old[:, 0], old[:, 2] - old[:, 0]),
                                    axis=1)
    np.testing.assert_allclose(np.bincount(material[kept], area, minlength=4),
                               np.bincount(material, old_area, minlength=4), rtol=1e-9)
    # ... and every ray meets the same surface, of the same material, at the same distance.
    fine = uniform_scene(verts, faces)
    coarse = uniform_scene(v2, f2)
    origins, dirs = random_rays(20_000)
    f_fine, t_fine = fine.intersect(origins, dirs)
    f_coarse, t_coarse = coarse.intersect(origins, dirs)
    assert np.all(f_fine >= 0) and np.all(f_coarse >= 0)
    np.testing.assert_allclose(t_coarse, t_fine, atol=1e-9)
    np.testing.assert_array_equal(material[kept][f_coarse], material[f_fine])
    # Orientation kept: the same normal at every hit.
    np.testing.assert_allclose(coarse.normals[f_coarse], fine.normals[f_fine], atol=1e-9)


def test_a_material_boundary_inside_a_plane_stays_where_it_is():
    verts, faces = shoebox(4.0, 3.0, 2.5)
    for _ in range(4):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    centre = verts[faces].mean(axis=1)
    # A rug: floor triangles in 1 <= x <= 2.5, 0.5625 <= y <= 1.875 (lines of the 0.25 m ×
    # 0.1875 m grid of the subdivided floor) are of another material.
    rug = (centre[:, 2] < 1e-9) & (np.abs(centre[:, 0] - 1.75) < 0.75) & (
        np.abs(centre[:, 1] - 1.21875) < 0.65625)
    material = rug.astype(np.int64)
    v2, f2, kept = simplify_flat_areas(verts, faces, material, 0.001)
    assert len(f2) < len(faces) / 20
    rug_tri = v2[f2[material[kept] == 1]]
    np.testing.assert_allclose(rug_tri[..., 0].min(), 1.0, atol=1e-12)
    np.testing.assert_allclose(rug_tri[..., 0].max(), 2.5, atol=1e-12)
    np.testing.assert_allclose(rug_tri[..., 1].min(), 0.5625, atol=1e-12)
    np.testing.assert_allclose(rug_tri[..., 1].max(), 1.875, atol=1e-12)
    area = 0.5 * np.linalg.norm(np.cross(rug_tri[:, 1] - rug_tri[:, 0],
                                         rug_tri[:, 2] - rug_tri[:, 0]), axis=1)
    np.testing.assert_allclose(area.sum(), 1.5 * 1.3125, rtol=1e-12)


def test_curved_and_noisy_surfaces_move_no_more_than_the_tolerance():
    verts, faces = shoebox(4.0, 3.0, 2.5)
    for _ in range(5):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    material = np.zeros(len(faces), dtype=np.int64)
    rng = np.random.default_rng(3)
    # A 4 cm bump in the floor (no two of its faces are coplanar) and 5 mm noise on the walls.
    bumped = verts.copy()
    floor = verts[:, 2] == 0
    bumped[floor, 2] += 0.04 * np.exp(
        -((verts[floor, 0] - 2) ** 2 + (verts[floor, 1] - 1.5) ** 2) / 0.8**2)
    walls = (verts[:, 2] > 0.1) & (verts[:, 2] < 2.4)
    bumped[walls] += rng.uniform(-0.005, 0.005, (int(walls.sum()), 3))
    assert len(simplify_flat_areas(bumped, faces, material, 0.0)[1]) < len(faces)  # ceiling
    before = uniform_scene(bumped, faces)
    origins = np.c_[rng.uniform(0.1, 3.9, 20_000), rng.uniform(0.1, 2.9, 20_000),
                    rng.uniform(0.2, 2.3, 20_000)]
    # A 30° turn limit leaves the distance bound alone in charge.
    for tol, turn, most in ((0.002, 2.0, 0.8), (0.002, 30.0, 0.8), (0.01, 30.0, 0.5)):
        v2, f2, _ = simplify_flat_areas(bumped, faces, material, tol, turn)
        assert len(f2) < most * len(faces)
        assert np.all(edge_use(f2) == 2)
        # Rays square to the floor, the ceiling and the walls: the distance to the surface
        # changes by no more than the tolerance (the surfaces are within 3° of square).
        after = uniform_scene(v2, f2)
        for axis in range(3):
            for sign in (-1.0, 1.0):
                dirs = np.zeros_like(origins)
                dirs[:, axis] = sign
                _, t_before = before.intersect(origins, dirs)
                _, t_after = after.intersect(origins, dirs)
                assert np.max(np.abs(t_after - t_before)) <= tol * 1.01


def test_holes_keep_their_outline():
    """An open plate (edges with one face) keeps every vertex of its boundary."""
    verts = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    for _ in range(4):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    counts = edge_use(faces)
    boundary_before = int(np.sum(counts == 1))
    _, f2, _ = simplify_flat_areas(verts, faces, np.zeros(len(faces), dtype=np.int64), 0.001)
    assert len(f2) < len(faces)
    assert int(np.sum(edge_use(f2) == 1)) == boundary_before


def test_image_sources_are_unchanged_and_the_output_is_deterministic():
    verts, faces, material = furnished_l_room(levels=2)
    alpha = np.array([0.1, 0.3, 0.5, 0.2])[material][:, None]
    fine = AcousticScene(verts, faces, alpha, np.zeros_like(alpha), np.zeros_like(alpha))
    coarse = simplified_scene(fine, 0.001)
    assert coarse.n_faces < fine.n_faces / 10
    again = simplified_scene(fine, 0.001)
    np.testing.assert_array_equal(again.faces, coarse.faces)
    np.testing.assert_array_equal(again.vertices, coarse.vertices)
    src, mic = np.array([0.8, 0.7, 1.3]), np.array([[2.9, 2.4, 1.6]])
    a = image_sources(fine, src, mic, max_order=2).arrivals[0]
    b = image_sources(coarse, src, mic, max_order=2).arrivals[0]
    order_a, order_b = np.lexsort((a.amplitudes[:, 0], a.times_s)), np.lexsort(
        (b.amplitudes[:, 0], b.times_s))
    assert len(a.times_s) == len(b.times_s) > 10
    np.testing.assert_allclose(b.times_s[order_b], a.times_s[order_a], rtol=1e-12)
    np.testing.assert_allclose(b.amplitudes[order_b], a.amplitudes[order_a], rtol=1e-9)


def test_an_already_coarse_scene_is_returned_as_is():
    scene = uniform_scene(*shoebox(4.0, 3.0, 2.5))
    assert simplified_scene(scene, 0.001) is scene


@pytest.mark.parametrize("tol", [-0.001, float("nan")])
def test_a_bad_tolerance_is_named(tol):
    verts, faces = shoebox(4.0, 3.0, 2.5)
    with pytest.raises(AcousticsError, match="tolerance_m"):
        simplify_flat_areas(verts, faces, np.zeros(len(faces), dtype=np.int64), tol)


def test_bad_arrays_are_named_before_the_compiled_pass():
    verts, faces = shoebox(4.0, 3.0, 2.5)
    classes = np.zeros(len(faces), dtype=np.int64)
    with pytest.raises(AcousticsError, match=r"faces: expected vertex indices in \[0, 7\]"):
        simplify_flat_areas(verts, np.where(faces == 7, 8, faces), classes, 0.001)
    with pytest.raises(AcousticsError, match="faces: expected shape"):
        simplify_flat_areas(verts, faces[:, :2], classes, 0.001)
    with pytest.raises(AcousticsError, match="face_class: expected shape"):
        simplify_flat_areas(verts, faces, classes[:-1], 0.001)


@pytest.mark.parametrize(("tolerance_m", "simplified"), [(None, True), (0.0, False)])
def test_the_rir_stage_traces_the_simplified_mesh_unless_told_not_to(tolerance_m, simplified):
    verts, faces, material, names = furnished_l_room(levels=2, names=True)
    mesh = SceneMesh(verts, faces, material, names)
    acoustics = AcousticsSpec().model_dump(mode="json")
    if tolerance_m is not None:
        acoustics["simplify_tolerance_m"] = tolerance_m
    settings = SimulationSettings.from_spec(acoustics, 16_000, 343.0)
    scene = acoustic_scene(mesh, load_library("sonicspec"), settings)
    assert (scene.n_faces < len(faces) / 10) is simplified
    # The same coefficients on the same areas either way.
    full = acoustic_scene(mesh, load_library("sonicspec"),
                          dataclasses.replace(settings, simplify_tolerance_m=0.0))
    np.testing.assert_allclose(scene.face_areas_m2 @ scene.absorption,
                               full.face_areas_m2 @ full.absorption, rtol=1e-9)


def test_a_flat_double_sided_panel_keeps_its_outline_and_stays_manifold():
    """A square panel of zero thickness: a top layer fanned around a centre vertex and a
    bottom layer of two triangles on the other diagonal, back to back. Its rim edges are
    folds (the two faces' planes coincide), so the corners stay; the centre may go, but not
    onto a corner of the bottom layer's diagonal (the two layers would then share that
    diagonal: four faces on one edge)."""
    a, b, c, d, v = range(5)
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]], dtype=float)
    top = [(a, b, v), (b, c, v), (c, d, v), (d, a, v)]
    bottom = [(a, d, c), (a, c, b)]
    faces = np.array(top + bottom)
    v2, f2, _ = simplify_flat_areas(verts, faces, np.zeros(len(faces), dtype=np.int64), 0.001)
    assert len(f2) == 4  # the centre is gone ...
    assert np.all(edge_use(f2) == 2)  # ... onto b or d, not a or c
    tri = v2[f2]
    normal_z = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    np.testing.assert_allclose(0.5 * normal_z[normal_z > 0].sum(), 1.0)  # top: whole square
    np.testing.assert_allclose(-0.5 * normal_z[normal_z < 0].sum(), 1.0)  # bottom too


def test_a_noisy_scan_stays_closed_and_within_the_tolerance():
    """The scanned-house fixture (noisy walls, repaired): a centimetre merges about a third of
    its triangles; the mesh stays closed and no ray from inside its rooms finds a surface
    more than that further or nearer (within the 2° turn of the faces)."""
    from sonicspec.geometry.repair import RepairSettings, repair_mesh
    from sonicspec.testing.meshes import HOUSE_ROOMS, scanned_house

    mesh, _ = repair_mesh(scanned_house(np.random.default_rng(11)).damaged,
                          RepairSettings(max_hole_size_m=2.0))
    assert np.all(edge_use(mesh.faces) == 2)
    tol = 0.01
    v2, f2, _ = simplify_flat_areas(mesh.vertices, mesh.faces, mesh.face_material, tol)
    assert len(f2) < 0.8 * mesh.n_faces
    assert np.all(edge_use(f2) == 2)
    rng = np.random.default_rng(5)
    origins = np.concatenate([
        np.c_[rng.uniform(x0 + 0.5, x1 - 0.5, 3000), rng.uniform(y0 + 0.5, y1 - 0.5, 3000),
              rng.uniform(0.5, 2.0, 3000)] for x0, x1, y0, y1 in HOUSE_ROOMS])
    dirs = rng.normal(size=origins.shape)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    before = uniform_scene(mesh.vertices, mesh.faces)
    after = uniform_scene(v2, f2)
    f_before, t_before = before.intersect(origins, dirs)
    f_after, t_after = after.intersect(origins, dirs)
    assert np.all(f_before >= 0) and np.all(f_after >= 0)  # closed: no ray escapes
    # Along a ray at incidence θ a surface moved by tol shifts the hit by tol / cos θ.
    cos_in = np.abs(np.einsum("ij,ij->i", dirs, before.normals[f_before]))
    steep = cos_in > 0.5
    assert np.max(np.abs(t_after - t_before)[steep]) <= 2 * tol * 1.01
