"""Mesh repair and the leak test, on a synthetic scanned house and small hand-made defects."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.errors import GeometryError, SonicspecWarning, StageError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.procedural import add_obstacles, box_obstacle, shoebox
from sonicspec.geometry.repair import RepairSettings, leak_test, mesh_stats, repair_mesh
from sonicspec.testing.meshes import ScannedHouse, house_contains_air, house_mesh, scanned_house

HOUSE_SETTINGS = RepairSettings(
    max_hole_size_m=1.5, leak_test_rays=20_000, if_not_watertight="error"
)


@pytest.fixture(scope="module")
def house():
    return scanned_house(np.random.default_rng(7))


@pytest.fixture(scope="module")
def repaired(house):
    return repair_mesh(house.damaged, HOUSE_SETTINGS, np.random.default_rng(5))


def test_scanned_house_is_damaged_and_leaks(house):
    stats = mesh_stats(house.damaged.faces, house.damaged.vertices.shape[0])
    assert not stats.watertight
    assert stats.boundary_edges > 0 and stats.inconsistent_edges > 0
    assert leak_test(house.clean, np.random.default_rng(1), 20_000).leak_fraction == 0.0
    leaks = leak_test(house.damaged, np.random.default_rng(1), 20_000)
    assert leaks.escaped > 0  # through the missing panel and the cracks


def test_repair_makes_the_house_watertight(house, repaired):
    mesh, report = repaired
    assert report.watertight and report.after.inconsistent_edges == 0
    assert mesh.to_trimesh().is_watertight
    assert report.holes_closed == 1 and report.hole_faces_added >= 2
    assert report.duplicate_faces_removed == house.n_duplicated_faces
    assert report.debris_components_removed == 1 and report.debris_faces_removed == 2
    assert report.merged_vertices == house.n_split_vertices  # every crack closed
    assert report.after.components == 1
    # the repaired surface is the house's: same vertex count, volume within the scan noise
    assert mesh.vertices.shape == house.clean.vertices.shape
    assert mesh.air_volume() == pytest.approx(house.clean.air_volume(), rel=2e-3)
    assert report.leak.rays == 20_000 and report.leak.leak_fraction == 0.0
    leaks = leak_test(mesh, np.random.default_rng(2), 20_000)
    assert leaks.leak_fraction == 0.0


def test_repaired_normals_point_into_the_air(repaired):
    mesh, _ = repaired
    # 2 cm in front of every face is in a room or door (the noise is 3 mm), 2 cm behind is not
    assert np.all(ScannedHouse.contains_air(mesh.face_centroids + 0.02 * mesh.face_normals))
    assert not np.any(ScannedHouse.contains_air(mesh.face_centroids - 0.02 * mesh.face_normals))


def test_repair_keeps_labels_and_patches_with_the_neighbours_label(house, repaired):
    mesh, _ = repaired
    labels = np.array(mesh.labels)[mesh.face_label]
    normals = mesh.face_normals
    assert np.all(normals[labels == "floor"][:, 2] > 0.99)
    assert np.all(normals[labels == "ceiling"][:, 2] < -0.99)
    y0, y1, z0, z1 = house.missing_panel_m
    c = mesh.face_centroids
    patch = (
        (np.abs(c[:, 0]) < 0.05) & (c[:, 1] > y0) & (c[:, 1] < y1) & (c[:, 2] > z0) & (c[:, 2] < z1)
    )
    assert patch.sum() >= 2 and set(labels[patch]) == {"wall"}


def test_inverted_room_with_obstacles_is_turned_to_the_air():
    room = shoebox((5.0, 4.0, 3.0))
    table = box_obstacle((2.0, 2.0, 0.5), (1.0, 1.0, 1.0))
    pillar = box_obstacle((4.0, 1.0, 1.5), (0.4, 0.4, 1.0))
    scene = add_obstacles(room, [table, pillar])
    # everything inverted, plus one obstacle inverted back: pieces disagree
    faces = np.array(scene.faces)[:, ::-1]
    faces[scene.face_object == 1] = faces[scene.face_object == 1][:, ::-1]
    broken = scene.replace(faces=faces)
    settings = RepairSettings(leak_test_rays=5000, if_not_watertight="error")
    fixed, report = repair_mesh(broken, settings, np.random.default_rng(0))
    assert report.leak.leak_fraction == 0.0  # the table stands flush on the floor
    assert report.components_flipped == 2  # the room and the table
    assert fixed.air_volume() == pytest.approx(scene.air_volume())
    np.testing.assert_allclose(fixed.face_normals, scene.face_normals, atol=1e-12)
    np.testing.assert_array_equal(fixed.face_object, scene.face_object)


def test_degenerate_duplicate_and_non_manifold_faces():
    room = shoebox((3.0, 3.0, 3.0))
    v = np.array(room.vertices)
    # a fin: one small triangle hanging off the floor edge from vertex 0 to vertex 1
    v = np.vstack([v, [[1.5, 0.0, 0.2]]])
    fin = [0, 1, 8]
    extra = np.array([fin, [0, 0, 1], [2, 2, 2], list(room.faces[3][::-1])])
    faces = np.vstack([room.faces, extra])
    broken = SceneMesh(v, faces, 0, ("x",))
    stats = mesh_stats(broken.faces, len(v))
    assert stats.non_manifold_edges >= 1
    fixed, report = repair_mesh(
        broken, RepairSettings(min_component_area_m2=0.0), np.random.default_rng(0)
    )
    assert report.degenerate_faces_removed == 2
    assert report.duplicate_faces_removed == 1  # the reversed copy of face 3
    assert report.non_manifold_faces_removed == 1  # the fin, the smallest on the shared edge
    assert report.watertight and fixed.n_faces == 12
    assert fixed.air_volume() == pytest.approx(27.0)


def test_not_watertight_is_a_warning_or_an_error(house):
    small_holes_only = RepairSettings(max_hole_size_m=0.5, leak_test_rays=20_000)
    with pytest.warns(SonicspecWarning, match="expected a watertight mesh that does not leak"):
        _, report = repair_mesh(house.damaged, small_holes_only, np.random.default_rng(3))
    assert report.holes_closed == 0 and not report.watertight
    assert report.leak.leak_fraction > 0
    strict = RepairSettings(max_hole_size_m=0.5, leak_test_rays=20_000, if_not_watertight="error")
    with pytest.raises(GeometryError, match=r"1 holes left open\); a leak fraction of"):
        repair_mesh(house.damaged, strict, np.random.default_rng(3))


def test_a_closed_mesh_facing_away_from_the_air_leaks():
    # watertight but inside out, and orientation repair switched off: every ray from the
    # sampled origins meets a back face, so the leak test fails it
    inverted = shoebox((3.0, 3.0, 3.0))
    inverted = inverted.replace(faces=inverted.faces[:, ::-1])
    settings = RepairSettings(orient=False, leak_test_rays=500, if_not_watertight="error")
    with pytest.raises(GeometryError, match=r"got a leak fraction of 1\.00e\+00 > 0\.0001"):
        repair_mesh(inverted, settings, np.random.default_rng(0))


def test_leak_test_with_given_interior_points():
    room = shoebox((2.0, 2.0, 2.0))
    inside = np.array([[1.0, 1.0, 1.0], [0.5, 1.5, 0.3]])
    assert (
        leak_test(room, np.random.default_rng(0), 2000, interior_points=inside).leak_fraction == 0
    )
    open_room = room.subset(np.arange(room.n_faces) != 0)  # one wall triangle missing
    report = leak_test(open_room, np.random.default_rng(0), 4000, interior_points=inside)
    # one of the 12 triangles gone: a sizeable share of rays escape, none hit a back face
    assert 0.01 < report.escaped / report.rays < 0.3 and report.backface == 0
    outside = np.array([[5.0, 5.0, 5.0]])
    # from outside, rays toward the room see its back faces
    assert leak_test(room, np.random.default_rng(0), 4000, interior_points=outside).backface > 0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"merge_distance_m": -1.0}, "merge_distance_m: expected a finite value >= 0"),
        ({"if_not_watertight": "ignore"}, "expected 'warn' or 'error', got 'ignore'"),
        ({"leak_test_rays": -1}, "leak_test_rays: expected an integer >= 0"),
        ({"max_leak_fraction": 2.0}, r"max_leak_fraction: expected a fraction in \[0, 1\]"),
    ],
)
def test_bad_settings(kwargs, message):
    with pytest.raises(GeometryError, match=message):
        RepairSettings(**kwargs)


def test_bad_calls():
    room = shoebox((1.0, 1.0, 1.0))
    with pytest.raises(GeometryError, match="n_rays: expected a positive count"):
        leak_test(room, np.random.default_rng(0), 0)
    with pytest.raises(
        GeometryError, match=r"interior_points: expected an array of shape \(P, 3\)"
    ):
        leak_test(room, np.random.default_rng(0), 10, interior_points=np.zeros((0, 3)))
    with pytest.raises(GeometryError, match="expected faces to remain after cleaning"):
        repair_mesh(room, RepairSettings(min_component_area_m2=100.0, leak_test_rays=0))
    empty = SceneMesh(np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros(0, int), ("x",))
    with pytest.raises(GeometryError, match="repair_mesh: expected a mesh with faces"):
        repair_mesh(empty, RepairSettings(leak_test_rays=0))
    with pytest.raises(
        GeometryError, match=r"repair_mesh\.rng: expected a numpy\.random\.Generator"
    ):
        repair_mesh(room, RepairSettings(leak_test_rays=10))


def test_report_to_dict(repaired):
    _, report = repaired
    data = report.to_dict()
    assert data["watertight"] is True and data["before"]["watertight"] is False
    assert data["holes_closed"] == 1
    assert data["leak"] == {"rays": 20_000, "escaped": 0, "backface": 0, "leak_fraction": 0.0,
                            "origins": "navigable", "places": []}


def test_two_storey_house_fixture_is_closed_and_repair_keeps_it():
    mesh = house_mesh(floors=2)
    one_floor = house_mesh()
    assert mesh.to_trimesh().is_watertight
    assert mesh.air_volume() == pytest.approx(2 * one_floor.air_volume())
    assert np.all(house_contains_air(mesh.face_centroids + 1e-3 * mesh.face_normals, floors=2))
    # a clean mesh passes repair unchanged (two storeys: two closed pieces)
    settings = RepairSettings(leak_test_rays=5000, if_not_watertight="error")
    fixed, report = repair_mesh(mesh, settings, np.random.default_rng(0))
    assert report.after.components == 2 and report.components_flipped == 0
    assert report.faces_flipped_coherent == 0 and report.merged_vertices == 0
    np.testing.assert_array_equal(fixed.faces, mesh.faces)


def _pymeshlab_measures(mesh: SceneMesh) -> dict:
    pymeshlab = pytest.importorskip("pymeshlab")
    meshset = pymeshlab.MeshSet()
    meshset.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.array(mesh.vertices), face_matrix=np.array(mesh.faces, np.int32)
        )
    )
    return meshset.get_topological_measures()


def test_mesh_stats_agree_with_pymeshlab(house, repaired):
    # pymeshlab (MeshLab's topology) as a peer for the before/after counts in the report
    for mesh in (house.damaged, repaired[0]):
        peer = _pymeshlab_measures(mesh)
        ours = mesh_stats(mesh.faces, mesh.vertices.shape[0])
        assert ours.boundary_edges == peer["boundary_edges"]
        assert ours.non_manifold_edges == peer["non_two_manifold_edges"]
        assert ours.components == peer["connected_components_number"]
    assert _pymeshlab_measures(repaired[0])["is_mesh_two_manifold"]


def test_hole_patch_takes_the_label_of_the_surface_it_continues():
    room = shoebox((4.0, 3.0, 2.5), floor_material="carpet")
    labels = np.array(room.labels)[room.face_label]
    floor_face = int(np.flatnonzero(labels == "floor")[0])
    holed = room.subset(np.arange(room.n_faces) != floor_face)  # walls border 2 of 3 edges
    fixed, report = repair_mesh(holed, RepairSettings(max_hole_size_m=10.0))
    assert report.holes_closed == 1 and report.watertight
    new = np.array(fixed.labels)[fixed.face_label][-report.hole_faces_added :]
    assert set(new) == {"floor"}
    assert set(np.array(fixed.materials)[fixed.face_material[-1:]]) == {"carpet"}
    assert fixed.air_volume() == pytest.approx(30.0)


def test_many_pieces_each_turned_to_the_air():
    # 36 boxes on a grid in a hall, a random third of them (and the hall) inside out
    rng = np.random.default_rng(11)
    hall = shoebox((12.0, 12.0, 3.0))
    boxes = [
        box_obstacle((1.5 + 1.8 * i, 1.5 + 1.8 * j, 0.8), (0.5, 0.7, 0.6), yaw_deg=15.0 * i)
        for i in range(6)
        for j in range(6)
    ]
    scene = add_obstacles(hall, boxes)
    piece = scene.face_object + 1
    inverted = rng.random(piece.max() + 1) < 0.33
    inverted[0] = True
    faces = np.array(scene.faces)
    faces[inverted[piece]] = faces[inverted[piece]][:, ::-1]
    fixed, report = repair_mesh(scene.replace(faces=faces))
    assert report.components_flipped == inverted.sum()
    np.testing.assert_allclose(fixed.face_normals, scene.face_normals, atol=1e-12)


def test_edge_keys_do_not_overflow_int32_on_large_meshes() -> None:
    """Regression: merged vertex ids came back as int32, and the edge keys min·n + max
    overflowed beyond ~46 000 vertices, so coherent orientation scrambled large scans."""
    import trimesh.remesh

    room = shoebox((10.0, 8.0, 3.0))
    vertices, faces = trimesh.remesh.subdivide_to_size(room.vertices, room.faces, max_edge=0.12)
    rng = np.random.default_rng(0)
    faces = np.array(faces)
    assert len(vertices) > 50_000
    flip = rng.random(len(faces)) < 0.05
    faces[flip] = faces[flip][:, ::-1]
    split = np.flatnonzero(rng.random(len(faces)) < 0.02)  # merging runs on these copies
    fresh = np.arange(len(vertices), len(vertices) + 3 * len(split)).reshape(-1, 3)
    vertices = np.concatenate([vertices, vertices[faces[split]].reshape(-1, 3)])
    faces[split] = fresh
    mesh = SceneMesh(
        vertices=vertices,
        faces=faces,
        face_material=np.zeros(len(faces), np.int32),
        materials=("m",),
    )
    repaired, report = repair_mesh(mesh, RepairSettings())
    stats = mesh_stats(repaired.faces, len(repaired.vertices))
    assert stats.inconsistent_edges == 0 and report.watertight
    assert repaired.air_volume() == pytest.approx(240.0, rel=1e-6)


def test_a_crack_walk_through_a_shared_vertex_splits_into_simple_loops() -> None:
    """Regression: boundary walks that revisit a vertex (cracks meeting at a T-junction) were
    skipped as non-simple, leaving those holes open."""
    from sonicspec.geometry.repair import _simple_loops

    assert _simple_loops([0, 1, 2, 3, 1, 4, 5]) == [[1, 2, 3], [0, 1, 4, 5]]
    assert _simple_loops([0, 1, 2]) == [[0, 1, 2]]
    assert _simple_loops([0, 1, 0, 2]) == []  # degenerate pieces are dropped


# --------------------------------------------------------------------------- T-junctions
def _grid_patch(origin, u, v, nu: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle origin + [0, 1]·u + [0, 1]·v cut into nu × nv quads, normal along u × v."""
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    vertices = np.asarray(origin) + s.reshape(-1, 1) * u + t.reshape(-1, 1) * v
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b, c, d = a + nv + 1, a + nv + 2, a + 1
    return vertices, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def _box_halves_with_t_junctions(offset_m: float = 0.0) -> SceneMesh:
    """A closed unit cube (normals inward) in two halves that meet at z = 0.5.

    The lower half's walls are cut in 2 along the seam, the upper half's in 3: every seam edge
    of one half has a vertex of the other half inside it (T-junctions, no shared vertices but
    the corners). The upper half's seam vertices between corners sit ``offset_m`` off the
    lower half's edges, into the room.
    """
    x, y, z = np.eye(3)
    parts = []
    for z0, n, floor in ((0.0, 2, True), (0.5, 3, False)):
        h = 0.5 * z
        walls = [
            ((0, 0, z0), h, x),  # y = 0, normal +y
            ((0, 1, z0), x, h),  # y = 1, normal -y
            ((0, 0, z0), y, h),  # x = 0, normal +x
            ((1, 0, z0), h, y),  # x = 1, normal -x
        ]
        for origin, u, v in walls:
            nu, nv = (1, n) if np.allclose(u, h) else (n, 1)
            parts.append(_grid_patch(origin, u, v, nu, nv))
        parts.append(
            _grid_patch((0, 0, 0), x, y, n, n) if floor else _grid_patch((0, 0, 1), y, x, n, n)
        )
    sizes = [len(v) for v, _ in parts]
    starts = np.cumsum([0, *sizes[:-1]])
    vertices = np.concatenate([v for v, _ in parts])
    faces = np.concatenate([f + start for (_, f), start in zip(parts, starts, strict=True)])
    upper_start = starts[5]  # parts 0-4: the lower half's four walls and floor
    # upper-half seam vertices that are not cube corners move into the room
    seam = (np.abs(vertices[:, 2] - 0.5) < 1e-12) & (np.arange(len(vertices)) >= upper_start)
    on_edge = seam & ~np.all(np.isclose(vertices[:, :2] % 1.0, 0.0), axis=1)
    inward = np.where(np.isclose(vertices[:, :2], 0.0), 1.0, 0.0) - np.isclose(vertices[:, :2], 1.0)
    vertices[on_edge, :2] += offset_m * inward[on_edge]
    return SceneMesh(vertices, faces, np.zeros(len(faces), np.int32), ("plaster",))


@pytest.mark.parametrize("offset_m", [0.0, 3e-4])
def test_t_junction_crack_is_stitched_watertight(offset_m) -> None:
    """Regression: two sides of a seam tessellated differently (T-junctions) stayed open."""
    cube = _box_halves_with_t_junctions(offset_m)
    raw = mesh_stats(cube.faces, cube.vertices.shape[0])
    assert raw.boundary_edges > 0
    # Hole closing alone made it "watertight" with patches across the room (13 % leak); the
    # stitching leaves no hole to close.
    settings = RepairSettings(max_hole_size_m=2.0, leak_test_rays=20_000, if_not_watertight="error")
    fixed, report = repair_mesh(cube, settings, np.random.default_rng(0))
    # per wall: 1/3 into the lower edge (0, 1/2), 2/3 into (1/2, 1), 1/2 into (1/3, 2/3)
    assert report.t_junctions_stitched == 12
    assert report.watertight and report.after.inconsistent_edges == 0
    assert report.holes_found == 0 and report.components_flipped == 0
    assert fixed.to_trimesh().is_watertight
    assert report.leak.leak_fraction == 0.0
    assert fixed.air_volume() == pytest.approx(1.0, abs=1e-3)


def test_t_junction_farther_than_the_merge_distance_is_not_stitched() -> None:
    cube = _box_halves_with_t_junctions(offset_m=5e-3)  # 5 mm off, merge distance 1 mm
    settings = RepairSettings(max_hole_size_m=0.0)
    with pytest.warns(SonicspecWarning, match=r"got 20 open and 0 non-manifold edges"):
        _, report = repair_mesh(cube, settings)
    assert report.t_junctions_stitched == 0 and not report.watertight


def test_t_junction_stitching_keeps_attributes_and_winding() -> None:
    cube = _box_halves_with_t_junctions()
    labels = np.where(cube.face_centroids[:, 2] < 0.5, 0, 1).astype(np.int32)
    cube = cube.replace(face_label=labels, labels=("lower", "upper"))
    fixed, report = repair_mesh(cube, RepairSettings(max_hole_size_m=0.0))
    assert report.watertight and report.faces_flipped_coherent == 0
    lower = np.array(fixed.labels)[fixed.face_label] == "lower"
    np.testing.assert_array_equal(lower, fixed.face_centroids[:, 2] < 0.5)
    # every face still points into the cube (the original winding)
    inside = fixed.face_centroids + 1e-3 * fixed.face_normals
    assert np.all((inside > 0) & (inside < 1))


# --------------------------------------------------------------------------- touching pieces
def _welded(mesh: SceneMesh) -> SceneMesh:
    """The mesh with coincident vertices welded into one (as a scan or a careless export)."""
    unique, inverse = np.unique(np.round(mesh.vertices, 9), axis=0, return_inverse=True)
    return mesh.replace(vertices=unique, faces=inverse.reshape(-1)[mesh.faces])


@pytest.mark.parametrize(
    ("second_box", "shared_vertices", "non_manifold_edges"),
    [
        (((2.0, 2.0, 0.5), (1.0, 1.0, 1.0)), 2, 1),  # boxes share a vertical edge
        (((2.0, 2.0, 1.5), (1.0, 1.0, 1.0)), 1, 0),  # boxes share a corner only (a pinch)
    ],
)
def test_welded_touching_boxes_are_split_not_torn(second_box, shared_vertices, non_manifold_edges):
    """Regression: four faces on an edge where two welded closed pieces touch lost two faces
    (the smallest), tearing both pieces and scrambling their orientation."""
    room = shoebox((3.0, 3.0, 2.5))
    first = box_obstacle((1.0, 1.0, 0.5), (1.0, 1.0, 1.0))
    scene = add_obstacles(room, [first, box_obstacle(*second_box)])
    welded = _welded(scene)
    stats = mesh_stats(welded.faces, welded.vertices.shape[0])
    assert stats.non_manifold_edges == non_manifold_edges
    assert stats.components == 2  # the boxes are one piece through their shared vertices
    settings = RepairSettings(leak_test_rays=20_000, if_not_watertight="error")
    fixed, report = repair_mesh(welded, settings, np.random.default_rng(0))
    assert report.touching_vertices_split == shared_vertices
    assert report.non_manifold_faces_removed == 0 and report.watertight
    assert report.after.components == 3 and report.leak.leak_fraction == 0.0
    np.testing.assert_allclose(fixed.face_normals, scene.face_normals, atol=1e-12)
    assert fixed.air_volume() == pytest.approx(scene.air_volume())


def test_a_fin_on_an_edge_is_not_split_but_dropped():
    # a piece with an open edge on the crowded edge is not a closed piece touching another
    room = shoebox((3.0, 3.0, 3.0))
    v = np.vstack([room.vertices, [[1.5, 0.0, 0.2]]])
    faces = np.vstack([room.faces, [[0, 1, 8]]])
    fixed, report = repair_mesh(SceneMesh(v, faces, 0, ("x",)), RepairSettings())
    assert report.touching_vertices_split == 0 and report.non_manifold_faces_removed == 1
    assert report.watertight and fixed.n_faces == 12


def test_close_vertices_of_a_closed_surface_are_not_merged():
    """Regression: merging two close vertices of an already closed surface (a fine or noisy
    tessellation) collapsed it into fins, non-manifold edges and open edges."""
    room = shoebox((3.0, 3.0, 3.0))
    # a wall vertex pair 0.5 mm apart, on a closed surface: split a wall triangle at a point
    # 0.5 mm from its corner
    a, b, c = room.faces[0]
    pa, pb, pc = room.vertices[[a, b, c]]
    near = (
        pa + 5e-4 * (pb - pa) / np.linalg.norm(pb - pa) + 1e-4 * (pc - pa) / np.linalg.norm(pc - pa)
    )
    v = np.vstack([room.vertices, near])
    m = len(v) - 1
    faces = np.vstack([room.faces[1:], [[a, b, m], [b, c, m], [c, a, m]]])
    mesh = SceneMesh(v, faces, 0, ("x",))
    assert mesh_stats(mesh.faces, len(v)).watertight
    fixed, report = repair_mesh(mesh, RepairSettings(merge_distance_m=1e-3))
    assert report.merged_vertices == 0 and report.degenerate_faces_removed == 0
    assert report.watertight and fixed.n_faces == 14


# --------------------------------------------------------------------------- intersecting obstacles
def test_leak_test_origins_are_not_taken_inside_intersecting_obstacles():
    """Regression: a point inside two intersecting boxes crosses three surfaces (odd), so the
    leak test took it for air and counted its rays, which hit back faces, as leaks."""
    room = shoebox((4.0, 4.0, 2.5))
    table = box_obstacle((2.0, 2.0, 0.4), (1.5, 1.5, 0.8))
    cabinet = box_obstacle((2.6, 2.6, 0.6), (1.0, 1.0, 1.2), yaw_deg=30.0)  # through the table
    scene = add_obstacles(room, [table, cabinet])
    report = leak_test(scene, np.random.default_rng(0), 20_000)
    assert report.leak_fraction == 0.0


def test_a_post_through_a_table_keeps_its_orientation():
    """Regression: the faces of a post mostly inside a table voted from points inside both,
    which parity took for air, and the post was turned inside out."""
    room = shoebox((4.0, 4.0, 2.5))
    table = box_obstacle((2.0, 2.0, 0.4), (1.5, 1.5, 0.8))
    post = box_obstacle((2.0, 2.0, 0.5), (0.2, 0.2, 1.0))  # 0.2 m of it above the table
    scene = add_obstacles(room, [table, post])
    settings = RepairSettings(leak_test_rays=20_000, if_not_watertight="error")
    fixed, report = repair_mesh(scene, settings, np.random.default_rng(0))
    assert report.components_flipped == 0 and report.leak.leak_fraction == 0.0
    np.testing.assert_allclose(fixed.face_normals, scene.face_normals, atol=1e-12)


def test_air_test_layers_never_put_overlapping_boxes_together():
    from sonicspec.geometry.repair import _layers

    rng = np.random.default_rng(3)
    # many small boxes (fragments) and a few large ones (rooms), like a cracked scan
    lo = np.concatenate([rng.uniform(0, 10, (2000, 3)), rng.uniform(0, 3, (5, 3))])
    hi = lo + np.concatenate([rng.uniform(0.01, 0.3, (2000, 3)), rng.uniform(3, 8, (5, 3))])
    colour = _layers(lo, hi, margin=0.01)
    overlap = np.all((lo[:, None] - 0.01 <= hi[None]) & (hi[:, None] + 0.01 >= lo[None]), axis=2)
    np.fill_diagonal(overlap, False)
    assert not np.any(overlap & (colour[:, None] == colour[None]))
    assert colour.max() < 20  # greedy colouring stays near the largest overlap count


def test_the_mesh_steps_report_reads_as_typed_fields_and_keeps_its_bytes(house, repaired):
    # Issue 29: the mesh step's report (weld, repair, leak as the library's reports dump
    # them) is a model; what the step did not run stays absent (not null), and a report read
    # from JSON is written back byte for byte.
    from sonicspec.artifacts import decode, encode
    from sonicspec.artifacts.mesh_report import SceneReport
    from sonicspec.geometry.repair import weld_seams
    from sonicspec.hashing import canonical_json

    _, weld = weld_seams(house.damaged, 0.01)
    leak = leak_test(house.damaged, np.random.default_rng(3), 2000)
    assert leak.places  # the damaged house leaks: places with labels, materials, sizes
    _, rep = repaired
    report = {"scene_id": "house", "kind": "mesh", "weld": weld.to_dict(),
              "repair": rep.to_dict(), "warnings": ["w"], "leak": leak.to_dict()}
    typed = SceneReport.model_validate(report)
    assert typed.leak.places[0].describe() == leak.places[0].describe()
    assert typed.repair.after.watertight and typed.weld.distance_m == 0.01
    assert canonical_json(typed.model_dump(mode="json")) == canonical_json(report)
    facts = {"materials": ["a"], "labels": [], "bounds_m": [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]],
             "faces": 12}
    room = {"scene_id": "room", "kind": "shoebox", "repair": None, **facts}
    assert encode("mesh", room) == room  # no weld, leak or warnings: absent, not null
    assert decode("mesh", room).weld is None and "weld" not in encode("mesh", room)
    scan = {"scene_id": "scan", "kind": "mesh", "weld": weld.to_dict(), **facts}
    assert encode("mesh", scan) == scan  # repair disabled: absent, not null
    with pytest.raises(StageError, match=r"repair\.before\.vertices: Field required"):
        decode("mesh", {**scan, "repair": {"before": {}}})
