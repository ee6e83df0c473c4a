"""Diffracting edges of synthetic meshes (``acoustics.paths.edges``): a screen, a box, a door."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.paths.edges import diffracting_edges
from sonicspec.acoustics.theory import Wedge
from sonicspec.errors import AcousticsError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.procedural import box_obstacle, shoebox
from sonicspec.testing.meshes import voxel_air_surface


def edges_of(mesh: SceneMesh, **kw):
    return diffracting_edges(mesh.vertices, mesh.faces, mesh.face_normals, **kw)


def screen_mesh(width: float = 2.0, height: float = 1.5, cells: int = 4) -> SceneMesh:
    """A one-sided rectangular sheet in the plane y = 0, cut into cells × cells quads."""
    xs, zs = np.linspace(0, width, cells + 1), np.linspace(0, height, cells + 1)
    v = np.array([[x, 0.0, z] for x in xs for z in zs])
    f = []
    for i in range(cells):
        for k in range(cells):
            a, b = i * (cells + 1) + k, (i + 1) * (cells + 1) + k
            f += [[a, b, b + 1], [a, b + 1, a + 1]]
    return SceneMesh(v, np.array(f), np.zeros(len(f), np.int32), ("default",))


def door_room(thickness: float = 0.2) -> tuple[SceneMesh, dict]:
    """Two 3 × 3 × 2.5 m rooms side by side (x), joined by a 0.9 × 2.1 m door in a wall."""
    xs = np.array([0.0, 3.0, 3.0 + thickness, 6.0 + thickness])
    ys = np.array([0.0, 1.0, 1.9, 3.0])
    zs = np.array([0.0, 2.1, 2.5])
    air = np.ones((3, 3, 2), bool)
    air[1] = False
    air[1, 1, 0] = True  # the door opening
    return voxel_air_surface(xs, ys, zs, air), {"x0": 3.0, "x1": 3.0 + thickness}


def test_a_subdivided_screen_has_four_half_plane_edges() -> None:
    found = edges_of(screen_mesh())
    assert len(found) == found.n_found == 4
    np.testing.assert_allclose(found.open_angle, 2 * math.pi)
    np.testing.assert_allclose(sorted(found.length_m), [1.5, 1.5, 2.0, 2.0])
    # face0 points from each rim into the sheet
    centre = np.array([1.0, 0.0, 0.75])
    mid = 0.5 * (found.start + found.end)
    assert np.all(np.einsum("ij,ij->i", centre - mid, found.face0) > 0)


def test_a_box_has_twelve_right_angle_edges_the_room_none() -> None:
    box = box_obstacle([1.0, 1.0, 0.5], [0.6, 0.4, 1.0])
    found = edges_of(box)
    assert len(found) == 12
    np.testing.assert_allclose(found.open_angle, 1.5 * math.pi)
    np.testing.assert_allclose(sorted(found.length_m), [0.4] * 4 + [0.6] * 4 + [1.0] * 4)
    room = shoebox([4.0, 3.0, 2.5])
    assert len(edges_of(room)) == 0  # a room's corners are concave: no diffraction


def test_every_edge_is_a_valid_wedge_with_the_air_on_the_open_side() -> None:
    box = box_obstacle([1.0, 1.0, 0.5], [0.6, 0.4, 1.0])
    found = edges_of(box)
    normals, centroids = box.face_normals, box.face_centroids
    for i in range(len(found)):
        wedge = Wedge(found.start[i], found.direction[i], found.face0[i], found.open_angle[i])
        # face 1, face0 turned by θ_w about e, lies along the second face
        f1 = (math.cos(wedge.open_angle) * wedge.face0
              + math.sin(wedge.open_angle) * np.cross(wedge.edge, wedge.face0))
        face_b = found.faces[i, 1]
        assert abs(np.dot(f1, normals[face_b])) < 1e-9
        mid = 0.5 * (found.start[i] + found.end[i])
        assert np.dot(centroids[face_b] - mid, f1) > 0
        # a point just outside the box near the edge is in the air (θ within [0, θ_w])
        outside = mid + 0.05 * (normals[found.faces[i, 0]] + normals[face_b])
        wedge.cylindrical(outside)


def test_a_door_in_a_thick_wall_has_its_jambs_and_lintel() -> None:
    mesh, wall = door_room(0.2)
    found = edges_of(mesh)
    # the opening's rim on both faces of the wall: 2 jambs × 2 sides + lintel × 2 sides
    assert len(found) == 6
    np.testing.assert_allclose(found.open_angle, 1.5 * math.pi)
    vertical = np.abs(found.direction[:, 2]) > 0.99
    assert vertical.sum() == 4
    np.testing.assert_allclose(found.length_m[vertical], 2.1)
    np.testing.assert_allclose(found.length_m[~vertical], 0.9)
    assert set(np.round(found.start[:, 0], 6)) == {wall["x0"], wall["x1"]}


def test_the_edge_budget_keeps_the_longest() -> None:
    mesh, _ = door_room(0.2)
    found = edges_of(mesh, max_edges=4)
    assert len(found) == 4 and found.n_found == 6
    np.testing.assert_allclose(found.length_m, 2.1)
    assert len(edges_of(mesh, min_length_m=1.0)) == 4


def test_gentle_creases_do_not_diffract() -> None:
    # A roof: two faces meeting at 170° seen from above (10° turn) and at 150° (30° turn).
    for turn, expected in ((10.0, 0), (30.0, 1)):
        h = math.tan(math.radians(turn / 2))
        v = np.array([[0, 0, 0], [1, 0, h], [2, 0, 0], [0, 1, 0], [1, 1, h], [2, 1, 0.0]])
        f = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
        mesh = SceneMesh(v, f, np.zeros(4, np.int32), ("default",))
        assert mesh.face_normals[:, 2].min() > 0
        found = edges_of(mesh)
        ridge = np.abs(found.direction[:, 1]) > 0.99
        inner = ridge & (np.abs(found.start[:, 0] - 1) < 1e-9)
        assert inner.sum() == expected


def test_bad_inputs_are_named() -> None:
    mesh = screen_mesh()
    with pytest.raises(AcousticsError, match="max_edges: expected an integer >= 0"):
        edges_of(mesh, max_edges=-1)
    with pytest.raises(AcousticsError, match="faces/normals: expected"):
        diffracting_edges(mesh.vertices, mesh.faces, mesh.face_normals[:2])


def test_edges_in_sight_of_the_job_come_before_edges_behind_a_wall() -> None:
    """Two rooms through a door: a box in the sources' room, farther away, counts for more
    than a box just behind the wall (heard only after reflections)."""
    from sonicspec.acoustics.engine import scene_edges
    from sonicspec.acoustics.room.scene import AcousticScene

    xs = np.array([0.0, 0.3, 0.9, 3.0, 3.2, 3.5, 4.1, 6.2])
    ys = np.array([0.0, 2.0, 2.6, 4.0, 5.0])
    zs = np.array([0.0, 1.0, 2.5])
    air = np.ones((7, 4, 2), bool)
    air[3] = False  # the wall x in [3.0, 3.2] ...
    air[3, 3, 0] = True  # ... with a door at y in [4, 5]
    air[1, 1, 0] = False  # box A, the sources' room
    air[5, 1, 0] = False  # box B, behind the wall
    mesh = voxel_air_surface(xs, ys, zs, air)
    n, bands = mesh.n_faces, 3
    scene = AcousticScene(mesh.vertices, mesh.faces, np.full((n, bands), 0.1),
                          np.zeros((n, bands)), np.zeros((n, bands)))
    near = np.array([[2.7, 1.5, 0.5], [2.5, 1.2, 1.5]])

    def box(edges) -> np.ndarray:
        mid = 0.5 * (edges.start + edges.end)
        return np.where(mid[:, 0] < 1.0, "A", np.where(mid[:, 0] > 3.3, "B", "door"))

    by_distance = edges_of(mesh, near_m=near)
    assert box(by_distance)[0] == "B"  # nearer, through the wall
    by_sight = scene_edges(scene, 4, near)
    assert by_sight.by_sight and "share of them in sight" in by_sight.choice().rule
    assert box(by_sight)[0] == "A" and "B" not in box(by_sight)


def test_a_box_standing_on_the_floor_has_no_edges_where_it_stands() -> None:
    """Issue 32: edges of a closed solid that another surface cuts into (a box on the floor, a
    pillar from floor to ceiling) are inner corners of the room, not edges in the air."""
    from sonicspec.acoustics.engine import scene_edges
    from sonicspec.acoustics.room.scene import AcousticScene

    def edges_found(z0: float, height: float) -> tuple[int, int]:
        mesh = SceneMesh.concatenate([
            shoebox([6.0, 5.0, 3.0]),
            box_obstacle([2.5, 2.0, z0 + height / 2], [1.0, 0.8, height])])
        n, bands = mesh.n_faces, 3
        scene = AcousticScene(mesh.vertices, mesh.faces, np.full((n, bands), 0.1),
                              np.zeros((n, bands)), np.zeros((n, bands)))
        found = scene_edges(scene, 1000)
        assert found.choice().buried_left_out == found.buried
        return len(found), found.buried

    assert edges_found(0.5, 0.6) == (12, 0)  # floating: every edge of the box is in the air
    assert edges_found(0.0, 0.6) == (8, 4)  # on the floor: its four bottom edges are not
    assert edges_found(0.0, 3.0) == (4, 8)  # floor to ceiling: only the four vertical edges
