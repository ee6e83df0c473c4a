"""Navigation: floors, walkable area, shortest paths and sampling, against closed forms."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from sonicspec.errors import GeometryError, PlacementError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.navigation import (
    NavigationSettings,
    PathNotFoundError,
    _first_hits,
    build_navigation,
    cumulative_length,
    detect_floors,
    resample_polyline,
    sample_walkable_points,
    shortest_path,
    walkable_grid,
)
from sonicspec.geometry.procedural import (
    add_obstacles,
    box_obstacle,
    cylinder,
    l_shape,
    shoebox,
)

R = 0.25  # walker radius used throughout
H = 0.05  # cell size used throughout
SETTINGS = NavigationSettings(cell_m=H, walker_radius_m=R)


def moved(mesh: SceneMesh, offset) -> SceneMesh:
    return mesh.replace(vertices=mesh.vertices + np.asarray(offset, float))


def two_storey() -> SceneMesh:
    """A 6 × 5 m ground floor (3 m high), a 0.2 m slab, a 6 × 5 m upper floor from z = 3.2."""
    return SceneMesh.concatenate([shoebox([6, 5, 3]), moved(shoebox([6, 5, 2.8]), [0, 0, 3.2])])


def tangent_detour(start, goal, corners, r, clockwise=True) -> float:
    """Length of a path from start, around circles of radius r at the corners, to goal.

    Closed form for the taut string wrapped (the same way round) around convex corners: the
    tangent segments plus the arcs plus the straight runs between consecutive circles.
    ``clockwise``: the path turns right round the corners (they are on its right).
    """
    side = 1.0 if clockwise else -1.0
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    c_first, c_last = np.asarray(corners[0], float), np.asarray(corners[-1], float)
    d1 = np.linalg.norm(start - c_first)
    d2 = np.linalg.norm(goal - c_last)
    length = math.sqrt(d1**2 - r**2) + math.sqrt(d2**2 - r**2)
    # Direction of each tangent point and of each run between circles, as angles about the
    # circles' centres; the path turns by the same total angle as its direction does.
    out_start = math.atan2(*(c_first - start)[::-1]) + side * math.asin(r / d1)
    in_goal = math.atan2(*(goal - c_last)[::-1]) - side * math.asin(r / d2)
    runs = [np.asarray(b, float) - np.asarray(a, float) for a, b in itertools.pairwise(corners)]
    headings = [out_start, *(math.atan2(v[1], v[0]) for v in runs), in_goal]
    turn = sum(abs(math.remainder(b - a, 2 * math.pi)) for a, b in itertools.pairwise(headings))
    return length + sum(float(np.linalg.norm(v)) for v in runs) + r * turn


# --------------------------------------------------------------------------- floors
@pytest.mark.parametrize(
    ("mesh", "area"),
    [
        (shoebox([5, 4, 3]), 20.0),
        (l_shape([6, 5, 2.7], [2, 3]), 30.0 - 6.0),
        (cylinder(2.0, 3.0, 48), 0.5 * 48 * 4.0 * math.sin(2 * math.pi / 48)),
    ],
)
def test_one_room_has_one_floor_at_zero(mesh, area):
    floors = detect_floors(mesh, SETTINGS)
    assert len(floors) == 1
    assert floors[0].index == 0
    assert floors[0].z_m == pytest.approx(0.0, abs=1e-9)
    assert floors[0].surface_area_m2 == pytest.approx(area, rel=1e-9)


def test_furniture_tops_are_not_floors():
    room = add_obstacles(
        shoebox([6, 5, 3]),
        [
            box_obstacle([2, 2, 0.375], [2.0, 1.5, 0.75]),
            box_obstacle([4.5, 3.5, 0.25], [1, 2, 0.5]),
        ],
    )
    floors = detect_floors(room, SETTINGS)
    assert [f.z_m for f in floors] == pytest.approx([0.0])


def test_two_storey_building_has_two_floors():
    floors = detect_floors(two_storey(), SETTINGS)
    assert [f.index for f in floors] == [0, 1]
    assert [f.z_m for f in floors] == pytest.approx([0.0, 3.2], abs=1e-9)
    assert [f.surface_area_m2 for f in floors] == pytest.approx([30.0, 30.0])


def test_each_storey_walkable_area_is_its_own():
    nav = build_navigation(two_storey(), SETTINGS)
    expected = (6 - 2 * R) * (5 - 2 * R)
    assert [g.area_m2 for g in nav.grids] == pytest.approx([expected, expected], rel=1e-9)
    # The upper grid stands on the slab top (z = 3.2), not on the ground floor.
    upper = nav.grid(1)
    assert np.nanmin(upper.floor_z_m) == pytest.approx(3.2)
    assert np.nanmax(upper.floor_z_m) == pytest.approx(3.2)
    assert nav.to_dict()["floors"][1]["floor"]["z_m"] == pytest.approx(3.2)


def test_scan_like_building_keeps_its_floors_and_area():
    # Finely tessellated, with ±5 mm vertex noise, like a scan: the same two floors and about
    # the same walkable area (the noise moves walls by millimetres).
    import trimesh.remesh

    building = two_storey()
    vertices, faces, index = trimesh.remesh.subdivide_to_size(
        building.vertices, building.faces, max_edge=0.5, return_index=True
    )
    rng = np.random.default_rng(0)
    scan = SceneMesh(
        vertices=vertices + rng.uniform(-0.005, 0.005, vertices.shape),
        faces=faces,
        face_material=building.face_material[index],
        materials=building.materials,
    )
    assert scan.n_faces > 2000
    nav = build_navigation(scan, SETTINGS)
    assert [f.z_m for f in nav.floors] == pytest.approx([0.0, 3.2], abs=0.006)
    expected = (6 - 2 * R) * (5 - 2 * R)
    assert [g.area_m2 for g in nav.grids] == pytest.approx([expected] * 2, rel=0.02)
    assert [g.n_components for g in nav.grids] == [1, 1]


def test_floors_need_upward_faces():
    room = shoebox([4, 4, 3])
    walls_only = room.subset(room.face_label == room.labels.index("wall"))
    with pytest.raises(GeometryError, match="upward-facing"):
        detect_floors(walls_only, SETTINGS)


def test_floors_need_enough_area():
    with pytest.raises(GeometryError, match="at least 50 m²"):
        detect_floors(shoebox([4, 4, 3]), NavigationSettings(min_floor_area_m2=50.0))


# --------------------------------------------------------------------------- walkable area
@pytest.mark.parametrize(
    ("size", "offset", "radius"),
    [
        ((5.0, 4.0, 3.0), (0.0, 0.0), 0.25),  # walls on cell edges: exact
        ((7.3, 3.15, 2.5), (0.013, -0.021), 0.25),  # walls anywhere: within a cell
        ((4.0, 6.0, 3.0), (1.0, 2.0), 0.4),
    ],
)
def test_empty_shoebox_walkable_area_is_the_shrunk_rectangle(size, offset, radius):
    settings = NavigationSettings(cell_m=H, walker_radius_m=radius)
    room = moved(shoebox(size), [*offset, 0.0])
    grid = build_navigation(room, settings).grid(0)
    length, width = size[0] - 2 * radius, size[1] - 2 * radius
    # Each boundary cell is in or out as a whole: error below half a cell along the perimeter.
    assert grid.area_m2 == pytest.approx(length * width, abs=(length + width) * H)
    assert grid.n_components == 1
    if offset == (0.0, 0.0):
        assert grid.area_m2 == pytest.approx(length * width, rel=1e-9)


def test_round_room_walkable_area_is_the_shrunk_polygon():
    # A regular n-gon of inradius a shrunk by r is the n-gon of inradius a - r.
    n, radius_m = 48, 2.5
    grid = build_navigation(cylinder(radius_m, 3.0, n), SETTINGS).grid(0)
    inradius = radius_m * math.cos(math.pi / n) - R
    expected = n * inradius**2 * math.tan(math.pi / n)
    assert grid.area_m2 == pytest.approx(expected, abs=math.pi * inradius * H)


def test_furniture_removes_its_inflated_footprint():
    a, b = 1.2, 0.8
    room = add_obstacles(shoebox([6, 5, 3]), [box_obstacle([3, 2.5, 0.4], [a, b, 0.8])])
    grid = build_navigation(room, SETTINGS).grid(0)
    # Minkowski sum of an a × b rectangle and a disc of radius r.
    inflated = a * b + 2 * R * (a + b) + math.pi * R**2
    expected = (6 - 2 * R) * (5 - 2 * R) - inflated
    assert grid.area_m2 == pytest.approx(expected, abs=2 * (a + b + 2 * math.pi * R) * H)
    # Distances: a cell centre 1 m left of the box is 1 m from it and 2 m from the nearest wall.
    point = np.array([3 - a / 2 - 1.0, 2.5])
    assert grid.obstacle_distance_at(point) == pytest.approx(1.0, abs=0.01)
    assert grid.wall_distance_at(point) == pytest.approx(min(point[0], 2.5), abs=0.01)


def test_only_geometry_in_the_head_room_blocks():
    def area_with(obstacle):
        room = add_obstacles(shoebox([5, 4, 3]), [obstacle])
        return build_navigation(room, SETTINGS).grid(0).area_m2

    free = (5 - 2 * R) * (4 - 2 * R)
    footprint = 1.0 * 1.0 + 4 * R + math.pi * R**2
    rug = box_obstacle([2.5, 2, 0.01], [1, 1, 0.02])  # below the step height
    lamp = box_obstacle([2.5, 2, 2.3], [1, 1, 0.2])  # above head height
    table_top = box_obstacle([2.5, 2, 0.75], [1, 1, 0.05])  # floating: the ray sees its top
    assert area_with(rug) == pytest.approx(free, rel=1e-9)
    assert area_with(lamp) == pytest.approx(free, rel=1e-9)
    assert area_with(table_top) == pytest.approx(free - footprint, abs=0.1)


def test_low_ceiling_leaves_no_walkable_area():
    room = shoebox([4, 4, 1.6])  # lower than the walker's 1.8 m
    floors = detect_floors(room, SETTINGS)
    grid = walkable_grid(room, floors[0], SETTINGS)
    assert grid.area_m2 == 0.0
    assert grid.n_components == 0
    with pytest.raises(GeometryError, match="expected walkable cells on floor 0, got none"):
        sample_walkable_points(grid, 3, np.random.default_rng(0))
    with pytest.raises(GeometryError, match=r"expected a floor with at least 1 m² of walkable"):
        build_navigation(room, SETTINGS)


def test_partition_tops_flush_with_the_ceiling_are_not_a_floor():
    # Box partitions reaching the ceiling have upward tops at ceiling height: a level with
    # upward area but no walkable area, which build_navigation drops.
    partitions = [
        box_obstacle([3, 1.5, 1.35], [0.15, 3.0, 2.7], label="wall"),
        box_obstacle([1.5, 3, 1.35], [3.0, 0.15, 2.7], label="wall"),
        box_obstacle([4.5, 3, 1.35], [3.0, 0.15, 2.7], label="wall"),
    ]
    room = add_obstacles(shoebox([6, 6, 2.7]), partitions)
    levels = detect_floors(room, NavigationSettings(min_floor_area_m2=0.5))
    assert [f.z_m for f in levels] == pytest.approx([0.0, 2.7])
    nav = build_navigation(room, NavigationSettings(min_floor_area_m2=0.5))
    assert [(f.index, f.z_m) for f in nav.floors] == [(0, 0.0)]
    assert nav.grid(0).floor is nav.floors[0]


@pytest.mark.parametrize("thickness", [0.2, 0.02])
def test_partition_wall_splits_the_room_unless_it_has_a_door(thickness):
    # A thin partition is found by the slice of the head-room band even when vertical rays
    # between its faces never hit it (0.02 m < one cell).
    def partition(y_from, y_to):
        return box_obstacle(
            [3, 0.5 * (y_from + y_to), 1.5], [thickness, y_to - y_from, 3.0], label="wall"
        )

    closed = add_obstacles(shoebox([6, 4, 3]), [partition(0, 4)])
    grid = build_navigation(closed, SETTINGS).grid(0)
    assert grid.n_components == 2
    assert grid.component_areas_m2() == pytest.approx(
        [(3 - thickness / 2 - 2 * R) * (4 - 2 * R)] * 2, rel=0.03
    )
    with pytest.raises(PathNotFoundError, match="one walkable component"):
        shortest_path(grid, [1, 2], [5, 2])

    door = add_obstacles(shoebox([6, 4, 3]), [partition(0, 1.5), partition(2.5, 4)])
    grid = build_navigation(door, SETTINGS).grid(0)
    assert grid.n_components == 1
    path = shortest_path(grid, [1, 0.5], [5, 0.5])
    # The path goes through the door gap (y in [1.5 + r, 2.5 - r] where it crosses x = 3).
    dense = resample_polyline(path.points_m, 0.01)
    crossing = dense[np.argmin(np.abs(dense[:, 0] - 3))]
    assert 1.5 + R - H <= crossing[1] <= 2.5 - R + H
    corners = [(3 - thickness / 2, 1.5), (3 + thickness / 2, 1.5)]
    expected = tangent_detour([1, 0.5], [5, 0.5], corners, R)
    assert path.length_m == pytest.approx(expected, rel=0.01)


def test_walls_are_walls_and_furniture_is_obstacle():
    room = add_obstacles(shoebox([6, 4, 3]), [box_obstacle([4, 2, 0.5], [1, 1, 1])])
    grid = build_navigation(room, SETTINGS).grid(0)
    point = np.array([1.0, 2.0])  # 1 m from the west wall, 2.5 m from the box
    assert grid.wall_distance_at(point) == pytest.approx(1.0, abs=0.01)
    assert grid.obstacle_distance_at(point) == pytest.approx(2.0, abs=1e-6)  # clipped at limit


# --------------------------------------------------------------------------- shortest paths
def test_open_room_path_is_the_straight_line():
    grid = build_navigation(shoebox([8, 6, 3]), SETTINGS).grid(0)
    path = shortest_path(grid, [1, 1, 0.0], [6.5, 4.2, 0.0], height_m=1.6)
    assert path.points_m.shape == (2, 3)
    assert path.points_m[:, :2] == pytest.approx(np.array([[1, 1], [6.5, 4.2]]))
    assert path.points_m[:, 2] == pytest.approx([1.6, 1.6])
    assert path.length_m == pytest.approx(math.hypot(5.5, 3.2), rel=1e-12)
    assert path.floor_index == 0


def test_box_forces_the_analytic_detour():
    # A long box standing on the south wall of a corridor: the walker must pass north of it,
    # around the box's corners inflated by the walker radius.
    room = add_obstacles(shoebox([10, 4, 3]), [box_obstacle([5, 1.5, 0.5], [1, 3, 1])])
    grid = build_navigation(room, SETTINGS).grid(0)
    start, goal = (2.0, 1.0), (8.0, 1.0)
    path = shortest_path(grid, start, goal, height_m=1.5)
    expected = tangent_detour(start, goal, [(4.5, 3.0), (5.5, 3.0)], R)
    assert expected > 7.5  # far longer than the 6 m straight line
    assert path.length_m == pytest.approx(expected, rel=0.01)
    assert path.length_m >= expected * (1 - 0.005)  # cannot beat the true geodesic by much
    # Every point of the path keeps the walker's radius from the box (within a cell).
    dense = resample_polyline(path.points_m, 0.01)
    dx = np.maximum(np.abs(dense[:, 0] - 5) - 0.5, 0)
    dy = np.maximum(np.abs(dense[:, 1] - 1.5) - 1.5, 0)
    assert np.hypot(dx, dy).min() >= R - H
    assert dense[:, 1].max() <= 4 - R + H
    # Unsmoothed, the 8-connected grid path is longer but close (octile metric, ≤ 8.3 %).
    raw = shortest_path(grid, start, goal, smooth=False)
    assert expected < raw.length_m <= 1.09 * expected


def test_l_shaped_room_path_wraps_the_inner_corner():
    room = l_shape([6, 6, 3], [3, 3])  # reflex corner at (3, 3)
    grid = build_navigation(room, SETTINGS).grid(0)
    start, goal = (1.0, 5.0), (5.0, 1.0)
    path = shortest_path(grid, start, goal)
    expected = tangent_detour(start, goal, [(3.0, 3.0)], R, clockwise=False)
    assert path.length_m == pytest.approx(expected, rel=0.01)


def test_path_between_disconnected_rooms_is_an_error():
    rooms = SceneMesh.concatenate([shoebox([4, 4, 3]), moved(shoebox([4, 4, 3]), [4.5, 0, 0])])
    grid = build_navigation(rooms, SETTINGS).grid(0)
    assert grid.n_components == 2
    with pytest.raises(PathNotFoundError, match=r"components 0 and 1 on floor 0"):
        shortest_path(grid, [2, 2], [6.5, 2])
    assert issubclass(PathNotFoundError, PlacementError)


def test_path_endpoints_must_be_walkable():
    grid = build_navigation(shoebox([4, 4, 3]), SETTINGS).grid(0)
    with pytest.raises(GeometryError, match=r"shortest_path.start: expected a point on the walk"):
        shortest_path(grid, [0.1, 2], [2, 2])
    with pytest.raises(GeometryError, match=r"shortest_path.goal: expected a point on the walk"):
        shortest_path(grid, [2, 2], [9, 9])
    with pytest.raises(GeometryError, match="expected a finite point"):
        shortest_path(grid, [2, np.nan], [2, 2])


# --------------------------------------------------------------------------- sampling
def test_sampled_points_are_uniform_over_the_walkable_area():
    room = add_obstacles(shoebox([6, 4, 3]), [box_obstacle([1.5, 2, 0.5], [1, 1, 1])])
    grid = build_navigation(room, SETTINGS).grid(0)
    rng = np.random.default_rng(7)
    points = sample_walkable_points(grid, 20_000, rng, height_m=1.2)
    assert np.all(grid.component_at(points) >= 0)
    assert points[:, 2] == pytest.approx(np.full(len(points), 1.2))
    # The share of points in the east half equals that half's share of walkable area.
    iy, ix = np.nonzero(grid.walkable)
    east_share = np.mean(grid.cell_centers_xy(iy, ix)[:, 0] > 3.0)
    observed = np.mean(points[:, 0] > 3.0)
    assert observed == pytest.approx(east_share, abs=4 * math.sqrt(0.25 / len(points)))
    again = sample_walkable_points(grid, 20_000, np.random.default_rng(7), height_m=1.2)
    assert np.array_equal(points, again)


def test_sampling_one_component():
    rooms = SceneMesh.concatenate([shoebox([4, 4, 3]), moved(shoebox([2, 2, 3]), [5, 0, 0])])
    grid = build_navigation(rooms, SETTINGS).grid(0)
    points = sample_walkable_points(grid, 500, np.random.default_rng(1), component=1)
    assert np.all(grid.component_at(points) == 1)
    assert np.all(points[:, 0] > 5)  # the smaller room
    assert grid.component_areas_m2() == pytest.approx([3.5**2, 1.5**2])


# --------------------------------------------------------------------------- polylines
def test_resample_polyline_keeps_ends_and_spacing():
    points = np.array([[0, 0, 1.5], [3, 0, 1.5], [3, 4, 1.5]], float)
    out = resample_polyline(points, 0.3)
    assert out[0] == pytest.approx(points[0])
    assert out[-1] == pytest.approx(points[-1])
    steps = np.linalg.norm(np.diff(out, axis=0), axis=1)
    # Seven metres in ceil(7 / 0.3) = 24 equal steps along the path (the corner cut is tiny).
    assert len(out) == 25
    assert cumulative_length(points)[-1] == pytest.approx(7.0)
    assert steps.max() <= 0.3 + 1e-12
    # Every point lies on the polyline.
    on_first = (out[:, 1] == 0) & (out[:, 0] <= 3)
    on_second = np.isclose(out[:, 0], 3) & (out[:, 1] >= 0)
    assert np.all(on_first | on_second)
    assert resample_polyline(points[:1], 0.3).shape == (1, 3)
    assert resample_polyline(points, 100.0).shape == (2, 3)


def test_resample_polyline_errors():
    with pytest.raises(GeometryError, match="spacing_m: expected a finite positive"):
        resample_polyline(np.zeros((2, 3)), 0.0)
    with pytest.raises(GeometryError, match=r"points: expected an \(N, D\) array"):
        resample_polyline(np.zeros(3), 0.5)


# --------------------------------------------------------------------------- backends, settings
def brute_force_first_hits(triangles, origins, direction):
    """Möller–Trumbore against every triangle: the reference for the Embree rays."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origins[:, None, :] - a[None]
    u = np.einsum("rij,ij->ri", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("j,rij->ri", direction, q) * inv
    t = np.einsum("rij,ij->ri", q, e2) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    t = np.where(hit, t, np.inf)
    return np.where(np.isfinite(t.min(axis=1)), t.argmin(axis=1), -1), t.min(axis=1)


def test_embree_rays_match_a_brute_force_intersector():
    room = add_obstacles(shoebox([3, 2, 2.5]), [box_obstacle([1.5, 1, 0.4], [0.6, 0.4, 0.8])])
    triangles = room.vertices[room.faces]
    rng = np.random.default_rng(3)
    n = 400
    origins = np.column_stack(
        [rng.uniform(-0.5, 3.5, n), rng.uniform(-0.5, 2.5, n), np.full(n, 1.8)]
    )
    down = np.array([0.0, 0.0, -1.0])
    face_e, dist_e = _first_hits(triangles, origins, down)
    face_b, dist_b = brute_force_first_hits(triangles, origins, down)
    assert np.array_equal(np.isfinite(dist_e), np.isfinite(dist_b))
    hit = np.isfinite(dist_e)
    assert hit.sum() > 100 and (~hit).sum() > 50
    assert dist_e[hit] == pytest.approx(dist_b[hit], abs=1e-5)
    # Faces may differ only on a shared edge of two coplanar triangles: compare their planes.
    normals = room.face_normals
    assert normals[face_e[hit]] == pytest.approx(normals[face_b[hit]])
    assert set(np.unique(dist_e[hit].round(4))) == {1.0, 1.8}  # box top and floor


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cell_m": 0.3}, "cell_m: expected a cell no larger than walker_radius_m"),
        ({"cell_m": -1.0}, "cell_m: expected a finite positive number"),
        ({"step_height_m": 2.0}, "step_height_m: expected less than walker_height_m"),
        ({"step_height_m": -0.1}, "step_height_m: expected a finite number >= 0"),
        ({"floor_normal_z": 1.5}, r"floor_normal_z: expected a value in \(0, 1\]"),
    ],
)
def test_navigation_settings_errors(kwargs, match):
    with pytest.raises(GeometryError, match=match):
        NavigationSettings(**kwargs)


def test_grid_errors():
    nav = build_navigation(shoebox([3, 3, 3]), SETTINGS)
    with pytest.raises(GeometryError, match=r"expected a floor index in \[0, 0\], got 2"):
        nav.grid(2)
    empty = SceneMesh(np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros(0, int), ("x",))
    with pytest.raises(GeometryError, match="walkable_grid: expected a mesh with faces"):
        walkable_grid(empty, nav.floors[0], SETTINGS)
    with pytest.raises(GeometryError, match="build_navigation: expected a mesh with faces"):
        build_navigation(empty, SETTINGS)
