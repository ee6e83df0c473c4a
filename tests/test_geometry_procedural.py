"""Procedural rooms and obstacles: closed, analytic volume and area, normals into the air."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.path import Path

from sonicspec.errors import GeometryError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.procedural import (
    add_obstacles,
    box_obstacle,
    cylinder,
    cylinder_obstacle,
    extruded_polygon,
    l_shape,
    mesh_obstacle,
    shoebox,
    triangulate_polygon,
)

# A U-shaped hall with a collinear vertex on its south wall, in counter-clockwise order.
U_HALL = [[0, 0], [3, 0], [6, 0], [6, 5], [4, 5], [4, 2], [2, 2], [2, 5], [0, 5]]
U_HALL_AREA = 6 * 5 - 2 * 3


def polygon_area(xy) -> float:
    x, y = np.asarray(xy, float).T
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def regular_prism_volume(radius, height, segments):
    return 0.5 * segments * radius**2 * np.sin(2 * np.pi / segments) * height


def regular_prism_area(radius, height, segments):
    side = 2 * radius * np.sin(np.pi / segments)
    return 2 * 0.5 * segments * radius**2 * np.sin(2 * np.pi / segments) + segments * side * height


# kind, mesh, analytic volume (m³), analytic surface area (m²), footprint outline for the oracle
ROOMS = {
    "shoebox": (
        shoebox((5.0, 4.0, 3.0)),
        60.0,
        2 * (20 + 15 + 12),
        [[0, 0], [5, 0], [5, 4], [0, 4]],
    ),
    "cylinder": (
        cylinder(2.0, 3.0, segments=16),
        regular_prism_volume(2.0, 3.0, 16),
        regular_prism_area(2.0, 3.0, 16),
        2.0
        + 2.0
        * np.column_stack([np.cos(np.arange(16) * np.pi / 8), np.sin(np.arange(16) * np.pi / 8)]),
    ),
    "l_shape": (
        l_shape((6.0, 5.0, 2.5), (2.0, 3.0)),
        (30 - 6) * 2.5,
        2 * 24 + 2 * (6 + 5) * 2.5,
        [[0, 0], [6, 0], [6, 2], [4, 2], [4, 5], [0, 5]],
    ),
    "polygon_ccw": (
        extruded_polygon(U_HALL, 2.7),
        U_HALL_AREA * 2.7,
        2 * U_HALL_AREA + 28 * 2.7,
        U_HALL,
    ),
    "polygon_cw": (
        extruded_polygon(U_HALL[::-1], 2.7),
        U_HALL_AREA * 2.7,
        2 * U_HALL_AREA + 28 * 2.7,
        U_HALL,
    ),
}


@pytest.fixture(params=sorted(ROOMS))
def room(request):
    return ROOMS[request.param]


def test_room_is_watertight_with_analytic_volume_and_area(room):
    mesh, volume, area, _ = room
    mesh.validate()
    tm = mesh.to_trimesh()
    assert tm.is_watertight
    assert tm.is_winding_consistent
    assert mesh.face_areas.sum() == pytest.approx(area, rel=1e-12)
    # Normals into the air: the divergence theorem gives +volume for the air, and trimesh
    # (which assumes outward normals) the negative of it.
    assert mesh.air_volume() == pytest.approx(volume, rel=1e-12)
    assert tm.volume == pytest.approx(-volume, rel=1e-12)


def test_room_labels_and_materials():
    mesh = shoebox(
        (4.0, 3.0, 2.5), wall_material="brick", floor_material="carpet", ceiling_material="tile"
    )
    normals = mesh.face_normals
    label = np.array(mesh.labels)[mesh.face_label]
    material = np.array(mesh.materials)[mesh.face_material]
    assert set(label) == {"wall", "floor", "ceiling"}
    np.testing.assert_allclose(normals[label == "floor"], [[0, 0, 1]] * 2)
    np.testing.assert_allclose(normals[label == "ceiling"], [[0, 0, -1]] * 2)
    assert np.all(np.abs(normals[label == "wall"][:, 2]) < 1e-12)
    assert set(material[label == "wall"]) == {"brick"}
    assert set(material[label == "floor"]) == {"carpet"}
    assert set(material[label == "ceiling"]) == {"tile"}
    np.testing.assert_allclose(mesh.bounds, [[0, 0, 0], [4, 3, 2.5]])


def inside_room(points, outline, height):
    return (
        Path(np.asarray(outline, float)).contains_points(points[:, :2])
        & (points[:, 2] > 0)
        & (points[:, 2] < height)
    )


def test_point_in_front_of_each_face_is_in_the_room(room):
    mesh, _, _, outline = room
    height = mesh.bounds[1, 2]
    probes = mesh.face_centroids + 1e-4 * mesh.face_normals
    assert np.all(inside_room(probes, outline, height))
    behind = mesh.face_centroids - 1e-4 * mesh.face_normals
    assert not np.any(inside_room(behind, outline, height))


def test_rays_from_inside_hit_faces_from_their_front(room):
    # What the tracer relies on: a ray leaving an interior point meets the boundary from the
    # side the normal points to, so dot(direction, normal) < 0 at every first hit.
    mesh, _, _, outline = room
    rng = np.random.default_rng(3)
    lo, hi = mesh.bounds
    candidates = rng.uniform(lo, hi, size=(400, 3))
    origins = candidates[inside_room(candidates, outline, hi[2])][:50]
    directions = rng.normal(size=(len(origins), 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    tm = mesh.to_trimesh()
    _, ray_index, face_index = tm.ray.intersects_location(origins, directions, multiple_hits=False)
    assert len(np.unique(ray_index)) == len(origins)  # a closed room: every ray hits
    dots = np.einsum("ij,ij->i", directions[ray_index], mesh.face_normals[face_index])
    assert np.all(dots < 0)


def test_obstacles_in_a_room_point_into_the_air():
    room = shoebox((6.0, 5.0, 3.0))
    table = box_obstacle(
        (2.0, 2.0, 0.6), (1.2, 0.8, 0.8), yaw_deg=30.0, material="wood", label="table"
    )
    column = cylinder_obstacle((4.5, 3.5), 0.3, 2.0, base_z_m=0.5, segments=12, material="concrete")
    scene = add_obstacles(room, [table, column])
    scene.validate()
    tm = scene.to_trimesh()
    assert tm.is_watertight  # room and obstacles are each closed and disjoint
    expected = 90.0 - 1.2 * 0.8 * 0.8 - regular_prism_volume(0.3, 2.0, 12)
    assert scene.air_volume() == pytest.approx(expected, rel=1e-12)
    np.testing.assert_array_equal(np.unique(scene.face_object), [-1, 0, 1])
    assert np.all(scene.face_object[: room.n_faces] == -1)
    labels = np.array(scene.labels)[scene.face_label]
    assert set(labels[scene.face_object == 0]) == {"table"}
    assert set(np.array(scene.materials)[scene.face_material[scene.face_object == 1]]) == {
        "concrete"
    }

    probes = scene.face_centroids + 1e-4 * scene.face_normals
    in_room = inside_room(probes, [[0, 0], [6, 0], [6, 5], [0, 5]], 3.0)
    # Oracles for the obstacles' interiors: the rotated box in its own frame, the column radially
    # (inside the inscribed 12-gon is within radius·cos(π/12) of the axis along each face normal).
    t = np.deg2rad(30.0)
    local = (probes - [2.0, 2.0, 0.6]) @ np.array(
        [[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]]
    )
    in_table = np.all(np.abs(local) < [0.6, 0.4, 0.4], axis=1)
    in_column = trimesh.Trimesh(column.vertices, column.faces).contains(probes)
    assert np.all(in_room)
    assert not np.any(in_table)
    assert not np.any(in_column)
    # and just behind every obstacle face is inside that obstacle
    behind = scene.face_centroids - 1e-4 * scene.face_normals
    local_b = (behind - [2.0, 2.0, 0.6]) @ np.array(
        [[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]]
    )
    assert np.all(np.all(np.abs(local_b) < [0.6, 0.4, 0.4], axis=1)[scene.face_object == 0])


def test_obstacle_volumes_are_positive_solids():
    box = box_obstacle((1.0, 1.0, 1.0), (0.5, 1.0, 2.0), yaw_deg=45.0)
    assert box.to_trimesh().volume == pytest.approx(1.0)  # outward normals: trimesh volume > 0
    assert box.air_volume() == pytest.approx(-1.0)
    col = cylinder_obstacle((1.0, 1.0), 0.5, 2.0, segments=24)
    assert col.to_trimesh().volume == pytest.approx(regular_prism_volume(0.5, 2.0, 24))
    np.testing.assert_allclose(col.bounds[:, 2], [0.0, 2.0])


def test_mesh_obstacle_transforms_and_keeps_materials():
    chair = box_obstacle((0.0, 0.0, 0.5), (1.0, 2.0, 1.0), material="fabric", label="chair")
    placed = mesh_obstacle(chair, (3.0, 2.0, 0.0), yaw_deg=90.0, scale=0.5)
    # scaled by 0.5 about the origin, turned 90°: x-extent 1.0 (from y), y-extent 0.5
    np.testing.assert_allclose(placed.bounds, [[2.5, 1.75, 0.0], [3.5, 2.25, 0.5]], atol=1e-12)
    assert placed.materials == ("fabric",)
    assert placed.labels == ("chair",)
    assert placed.to_trimesh().volume == pytest.approx(0.5 * 1.0 * 0.5, rel=1e-12)
    relabeled = mesh_obstacle(chair, (0, 0, 0), material="steel", label="misc")
    assert relabeled.materials == ("steel",) and relabeled.labels == ("misc",)


def test_mesh_obstacle_rejects_inward_mesh_and_bad_scale():
    with pytest.raises(GeometryError, match="normals point inwards"):
        mesh_obstacle(shoebox((1, 1, 1)), (0, 0, 0))
    with pytest.raises(GeometryError, match=r"mesh_obstacle\.scale: expected a positive"):
        mesh_obstacle(box_obstacle((0, 0, 0), (1, 1, 1)), (0, 0, 0), scale=-1.0)


def test_add_obstacles_rejects_obstacle_outside_room():
    with pytest.raises(GeometryError, match="expected obstacle 0 inside the room bounds"):
        add_obstacles(shoebox((2, 2, 2)), [box_obstacle((1.9, 1.0, 1.0), (0.5, 0.5, 0.5))])


def test_self_intersecting_polygon_is_an_error():
    bowtie = [[0, 0], [2, 2], [2, 0], [0, 2]]
    with pytest.raises(GeometryError, match="self-intersecting"):
        extruded_polygon(bowtie, 2.0)
    touching = [[0, 0], [4, 0], [4, 4], [2, 0.0], [0, 4]]  # vertex 3 touches the south edge
    with pytest.raises(GeometryError, match="self-intersecting"):
        extruded_polygon(touching, 2.0)


@pytest.mark.parametrize(
    ("outline", "message"),
    [
        ([[0, 0], [1, 0]], "at least 3 vertices"),
        ([[0, 0], [1, 0], [2, 0]], "spike"),
        ([[0, 0], [1, 0], [0.5, 1e-10]], "non-zero area"),
        ([[0, 0], [1, 0], [1, 0], [0, 1]], "distinct consecutive vertices"),
        ([[0, 0], [2, 0], [1, 0], [1, 1]], "spike"),
        ([[0, 0], [1, np.nan], [0, 1]], "finite"),
    ],
)
def test_degenerate_polygons_are_errors(outline, message):
    with pytest.raises(GeometryError, match=message):
        triangulate_polygon(outline)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: shoebox((1, 0, 1)), "shoebox.size_m: expected 3 finite positive"),
        (lambda: l_shape((4, 4, 3), (4, 1)), "cutout smaller than the room"),
        (lambda: cylinder(1.0, 2.0, segments=2), "cylinder.segments: expected an integer >= 3"),
        (lambda: extruded_polygon(U_HALL, -1.0), "height_m: expected a finite positive"),
        (lambda: shoebox((1, 1, 1), wall_material=""), "wall_material: expected a material name"),
        (lambda: box_obstacle((0, 0), (1, 1, 1)), "box_obstacle.center_m: expected 3 finite"),
    ],
)
def test_bad_arguments_are_errors(call, message):
    with pytest.raises(GeometryError, match=message):
        call()


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(min_value=3, max_value=14),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    clockwise=st.booleans(),
)
def test_random_star_polygons_triangulate_and_close(n, seed, clockwise):
    # Star-shaped polygons (sorted angles, random radii) are always simple, often very concave.
    rng = np.random.default_rng(seed)
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    gaps = np.diff(np.r_[angles, angles[0] + 2 * np.pi])
    if gaps.min() < 1e-3 or gaps.max() > np.pi - 1e-2:
        return  # each edge must stay inside its own sector of less than π to be simple
    radii = rng.uniform(0.3, 3.0, n)
    xy = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)]) + 5.0
    if clockwise:
        xy = xy[::-1]
    triangles = triangulate_polygon(xy)
    assert triangles.shape == (n - 2, 3)
    a, b, c = (xy[triangles[:, k]] for k in range(3))
    twice_area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (
        c[:, 0] - a[:, 0]
    )
    assert np.all(twice_area > 0)  # counter-clockwise from +z whatever the input order
    assert twice_area.sum() / 2 == pytest.approx(abs(polygon_area(xy)), rel=1e-9)
    room = extruded_polygon(xy, 2.0)
    assert room.to_trimesh().is_watertight
    assert room.air_volume() == pytest.approx(2.0 * abs(polygon_area(xy)), rel=1e-9)


def test_scene_mesh_checks():
    room = shoebox((2, 2, 2))
    with pytest.raises(GeometryError, match="vertex indices in"):
        SceneMesh(room.vertices, room.faces + 10, room.face_material, room.materials).validate()
    with pytest.raises(GeometryError, match="expected finite coordinates"):
        bad = np.array(room.vertices)
        bad[3, 1] = np.nan
        SceneMesh(bad, room.faces, room.face_material, room.materials).validate()
    with pytest.raises(GeometryError, match="face_material: expected one value per face"):
        SceneMesh(room.vertices, room.faces, [0, 0], room.materials)
    with pytest.raises(GeometryError, match="face_material: expected indices in"):
        SceneMesh(room.vertices, room.faces, room.face_material + 5, room.materials).validate()
    with pytest.raises(GeometryError, match="vertices: expected an array of shape"):
        SceneMesh(np.zeros((3, 2)), room.faces, 0, ("x",))
    assert room.vertices.flags.writeable is False


def test_with_materials_and_concatenate():
    room = shoebox((3, 3, 3))
    mapped = room.with_materials({"wall": "glass", "floor": "carpet"}, default="plaster")
    material = np.array(mapped.materials)[mapped.face_material]
    label = np.array(mapped.labels)[mapped.face_label]
    assert set(material[label == "wall"]) == {"glass"}
    assert set(material[label == "ceiling"]) == {"plaster"}
    by_callable = room.with_materials(lambda lb: lb.upper())
    assert set(by_callable.materials) == {"WALL", "FLOOR", "CEILING"}
    with pytest.raises(GeometryError, match="got none for label 'ceiling'"):
        room.with_materials({"wall": "glass", "floor": "carpet"})
    bare = SceneMesh(room.vertices, room.faces, 0, ("x",))
    with pytest.raises(GeometryError, match="without labels"):
        bare.with_materials({"wall": "glass"})
    merged = SceneMesh.concatenate([room, bare])
    assert merged.labels == ("wall", "floor", "ceiling", "unlabeled")
    assert merged.materials == (
        "plaster_on_brick",
        "parquet_on_concrete",
        "plaster_on_concrete",
        "x",
    )
    assert merged.n_faces == 24 and merged.faces.max() == 15
    with pytest.raises(GeometryError, match="at least one mesh"):
        SceneMesh.concatenate([])
    sub = merged.subset(np.arange(12))
    assert sub.n_faces == 12 and sub.vertices.shape == (8, 3)


def test_add_obstacles_keeps_existing_object_ids():
    room = shoebox((4.0, 4.0, 3.0))
    scanned = room.replace(face_object=np.arange(room.n_faces) % 3 - 1)  # ids -1, 0, 1
    scene = add_obstacles(scanned, [box_obstacle((2, 2, 0.5), (1, 1, 1))])
    np.testing.assert_array_equal(scene.face_object[: room.n_faces], scanned.face_object)
    assert set(scene.face_object[room.n_faces :]) == {2}
