"""Procedural scenes: closed rooms with inward normals and obstacles with outward normals.

Every room is a vertical prism over a floor polygon, from the floor at z = 0 to the ceiling at
z = ``height``; its footprint starts at the origin (a shoebox occupies [0, x] × [0, y]).
Walls, floor and ceiling share their boundary vertices, so each room is watertight (every edge
is used by exactly two faces, in opposite directions). Faces are labelled ``"wall"``,
``"floor"`` and ``"ceiling"``. Normals point into the air (see :mod:`sonicspec.geometry.mesh`):
into a room, out of an obstacle.

Obstacles (furniture, partitions, the boxes of an occlusion study) are closed meshes with their
own material, label and object id; :func:`add_obstacles` merges them into a room.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sonicspec.errors import GeometryError
from sonicspec.geometry.mesh import SceneMesh

__all__ = [
    "add_obstacles",
    "box_obstacle",
    "cylinder",
    "cylinder_obstacle",
    "extruded_polygon",
    "l_shape",
    "mesh_obstacle",
    "shoebox",
    "triangulate_polygon",
]

#: Default materials: names in the built-in material library, the same defaults as the spec's
#: ``SurfaceMaterialsSpec`` and obstacle specs (override per call).
DEFAULT_WALL_MATERIAL = "plaster_on_brick"
DEFAULT_FLOOR_MATERIAL = "parquet_on_concrete"
DEFAULT_CEILING_MATERIAL = "plaster_on_concrete"
DEFAULT_OBSTACLE_MATERIAL = "wood_panel"
DEFAULT_COLUMN_MATERIAL = "concrete_painted"

_WALL, _FLOOR, _CEILING = 0, 1, 2
_ROOM_LABELS = ("wall", "floor", "ceiling")


# --------------------------------------------------------------------------- checks
def _positive_vector(name: str, value: Sequence[float], length: int) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (length,) or not np.all(np.isfinite(array)) or np.any(array <= 0):
        raise GeometryError(
            f"{name}: expected {length} finite positive lengths in metres, got {value!r}"
        )
    return array


def _positive(name: str, value: float) -> float:
    if not np.isfinite(value) or value <= 0:
        raise GeometryError(f"{name}: expected a finite positive number, got {value!r}")
    return float(value)


def _finite_vector(name: str, value: Sequence[float], length: int) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (length,) or not np.all(np.isfinite(array)):
        raise GeometryError(
            f"{name}: expected {length} finite coordinates in metres, got {value!r}"
        )
    return array


def _segments(name: str, segments: int, minimum: int = 3) -> int:
    if (
        isinstance(segments, bool)
        or not isinstance(segments, (int, np.integer))
        or segments < minimum
    ):
        raise GeometryError(f"{name}: expected an integer >= {minimum}, got {segments!r}")
    return int(segments)


# --------------------------------------------------------------------------- polygons
def _signed_area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Twice the signed area of triangle abc (> 0 when counter-clockwise)."""
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _crossing_pairs(xy: np.ndarray, eps: float) -> np.ndarray:
    """Index pairs (i, k), i < k, of non-adjacent polygon edges that cross or touch.

    Edge i runs from vertex i to i + 1. Two closed segments meet when each straddles the
    other's line (a proper crossing) or when an endpoint lies on the other segment (touching);
    ``eps`` is the tolerance on twice-areas. Vectorised over all pairs: O(n²) memory.
    """
    n = xy.shape[0]
    p, q = xy, np.roll(xy, -1, axis=0)

    def orient(a, b, c):
        return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
            c[..., 0] - a[..., 0]
        )

    pi, qi = p[:, None, :], q[:, None, :]
    rk, sk = p[None, :, :], q[None, :, :]
    d1, d2 = orient(rk, sk, pi), orient(rk, sk, qi)
    d3, d4 = orient(pi, qi, rk), orient(pi, qi, sk)

    def straddles(u, v):
        return ((u > eps) & (v < -eps)) | ((u < -eps) & (v > eps))

    def on_segment(a, b, point, d):
        lo, hi = np.minimum(a, b) - 1e-12, np.maximum(a, b) + 1e-12
        return (np.abs(d) <= eps) & np.all((point >= lo) & (point <= hi), axis=-1)

    meet = (straddles(d1, d2) & straddles(d3, d4)) | (
        on_segment(rk, sk, pi, d1)
        | on_segment(rk, sk, qi, d2)
        | on_segment(pi, qi, rk, d3)
        | on_segment(pi, qi, sk, d4)
    )
    i, k = np.triu_indices(n, 2)
    keep = ~((i == 0) & (k == n - 1))  # edges n-1 and 0 share vertex 0
    i, k = i[keep], k[keep]
    hits = meet[i, k]
    return np.column_stack([i[hits], k[hits]])


def _check_simple_polygon(name: str, xy: np.ndarray) -> None:
    """Raise GeometryError unless xy is a simple polygon with non-zero area."""
    n = xy.shape[0]
    scale = max(float(np.ptp(xy, axis=0).max()), 1e-300)
    eps = 1e-12 * scale * scale  # tolerance on twice-areas, relative to the polygon size
    edge = np.roll(xy, -1, axis=0) - xy
    lengths = np.linalg.norm(edge, axis=1)
    if np.any(lengths <= 1e-9 * scale):
        i = int(np.argmin(lengths))
        raise GeometryError(
            f"{name}: expected distinct consecutive vertices, got vertex {i} and "
            f"{(i + 1) % n} at the same point {xy[i].tolist()}"
        )
    following = np.roll(edge, -1, axis=0)
    cross = edge[:, 0] * following[:, 1] - edge[:, 1] * following[:, 0]
    # Adjacent edges meet only at their shared vertex unless the boundary folds back on itself.
    spikes = np.flatnonzero((np.abs(cross) <= eps) & (np.einsum("ij,ij->i", edge, following) < 0))
    if len(spikes):
        raise GeometryError(
            f"{name}: expected a simple polygon, got a spike folding back at vertex "
            f"{(int(spikes[0]) + 1) % n}"
        )
    pairs = _crossing_pairs(xy, eps)
    if len(pairs):
        i, k = (int(v) for v in pairs[0])
        raise GeometryError(
            f"{name}: expected a simple polygon, got edges {i}-{(i + 1) % n} and "
            f"{k}-{(k + 1) % n} intersecting; the polygon is self-intersecting"
        )
    area = _signed_area(xy)
    if abs(area) <= 1e-9 * scale * scale:
        raise GeometryError(f"{name}: expected a polygon with non-zero area, got area {area:g} m²")


def triangulate_polygon(vertices_xy_m: Sequence[Sequence[float]]) -> np.ndarray:
    """Triangulate a simple polygon by ear clipping.

    Parameters
    ----------
    vertices_xy_m : (N, 2) array_like
        Polygon vertices in metres, clockwise or counter-clockwise, without repeating the first.
        Collinear vertices are kept (they appear as triangle corners, so walls meeting the
        floor there stay watertight).

    Returns
    -------
    (N - 2, 3) int64
        Triangles as indices into the input, each counter-clockwise seen from +z.

    Raises
    ------
    GeometryError
        Fewer than 3 vertices, non-finite or repeated vertices, zero area, or self-intersection.
    """
    xy = np.asarray(vertices_xy_m, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 3:
        raise GeometryError(
            f"polygon: expected at least 3 vertices of shape (N, 2), got shape {xy.shape}"
        )
    if not np.all(np.isfinite(xy)):
        raise GeometryError("polygon: expected finite vertex coordinates, got NaN or infinity")
    _check_simple_polygon("polygon", xy)
    order = list(range(xy.shape[0]))
    if _signed_area(xy) < 0:
        order.reverse()  # work counter-clockwise; the output keeps the input's indices
    scale = float(np.ptp(xy, axis=0).max())
    eps = 1e-12 * scale * scale
    triangles: list[tuple[int, int, int]] = []
    # Ear clipping: an ear is a strictly convex vertex whose triangle with its neighbours
    # contains no other remaining vertex (boundary included, so a vertex on the cut diagonal
    # blocks it). O(n³) worst case, fine for room outlines.
    while len(order) > 3:
        m = len(order)
        for k in range(m):
            i_prev, i_cur, i_next = order[k - 1], order[k], order[(k + 1) % m]
            a, b, c = xy[i_prev], xy[i_cur], xy[i_next]
            if _orient(a, b, c) <= eps:
                continue  # reflex or collinear: not an ear
            others = [
                order[j] for j in range(m) if j not in (k - 1 if k else m - 1, k, (k + 1) % m)
            ]
            pts = xy[others]
            inside = (
                ((b[0] - a[0]) * (pts[:, 1] - a[1]) - (b[1] - a[1]) * (pts[:, 0] - a[0]) >= -eps)
                & ((c[0] - b[0]) * (pts[:, 1] - b[1]) - (c[1] - b[1]) * (pts[:, 0] - b[0]) >= -eps)
                & ((a[0] - c[0]) * (pts[:, 1] - c[1]) - (a[1] - c[1]) * (pts[:, 0] - c[0]) >= -eps)
            )
            if not np.any(inside):
                triangles.append((i_prev, i_cur, i_next))
                del order[k]
                break
        else:  # pragma: no cover - the two-ears theorem makes this unreachable for simple polygons
            raise GeometryError(
                "polygon: expected ear clipping to finish, got no ear among "
                f"{len(order)} remaining vertices; the polygon may be nearly self-touching"
            )
    a, b, c = (xy[i] for i in order)
    if _orient(a, b, c) <= eps:
        raise GeometryError(  # pragma: no cover - only reachable with all-collinear remainders
            "polygon: expected a final non-degenerate triangle, got collinear vertices"
        )
    triangles.append((order[0], order[1], order[2]))
    return np.asarray(triangles, dtype=np.int64)


# --------------------------------------------------------------------------- rooms
def _prism(
    xy: np.ndarray,
    floor_triangles: np.ndarray,
    height_m: float,
    materials: tuple[str, str, str],
    *,
    extra_floor_vertex: np.ndarray | None = None,
) -> SceneMesh:
    """A closed prism over a counter-clockwise polygon, normals pointing inwards.

    Vertices 0..n-1 are the floor ring, n..2n-1 the ceiling ring; an optional extra vertex pair
    (floor, ceiling) at 2n, 2n+1 serves fan triangulations. ``floor_triangles`` index the ring
    (and index n for the extra vertex) and are counter-clockwise seen from +z.
    """
    n = xy.shape[0]
    bottom = np.column_stack([xy, np.zeros(n)])
    top = np.column_stack([xy, np.full(n, height_m)])
    parts = [bottom, top]
    if extra_floor_vertex is not None:
        parts.append([[*extra_floor_vertex, 0.0], [*extra_floor_vertex, height_m]])
    vertices = np.concatenate(parts)

    i = np.arange(n)
    j = (i + 1) % n
    # For a counter-clockwise outline the air is left of each edge; (b_i, t_j, b_j) and
    # (b_i, t_i, t_j) have normal h·(-dy, dx, 0), the left-hand side, i.e. into the room.
    walls = np.concatenate([np.column_stack([i, j + n, j]), np.column_stack([i, i + n, j + n])])
    floor_tris = np.asarray(floor_triangles, dtype=np.int64)
    if extra_floor_vertex is not None:
        floor_idx = np.where(floor_tris == n, 2 * n, floor_tris)
        ceil_idx = np.where(floor_tris == n, 2 * n + 1, floor_tris + n)
    else:
        floor_idx, ceil_idx = floor_tris, floor_tris + n
    floor = floor_idx  # counter-clockwise from above: normal +z, up into the room
    ceiling = ceil_idx[:, ::-1]  # reversed: normal -z, down into the room
    faces = np.concatenate([walls, floor, ceiling])
    face_class = np.concatenate(
        [np.full(len(walls), _WALL), np.full(len(floor), _FLOOR), np.full(len(ceiling), _CEILING)]
    ).astype(np.int32)
    unique_materials = tuple(dict.fromkeys(materials))
    material_index = np.array([unique_materials.index(m) for m in materials], dtype=np.int32)
    return SceneMesh(
        vertices=vertices,
        faces=faces,
        face_material=material_index[face_class],
        materials=unique_materials,
        face_label=face_class,
        labels=_ROOM_LABELS,
    ).validate()


def _room_materials(wall: str, floor: str, ceiling: str) -> tuple[str, str, str]:
    for name, value in (
        ("wall_material", wall),
        ("floor_material", floor),
        ("ceiling_material", ceiling),
    ):
        if not isinstance(value, str) or not value:
            raise GeometryError(
                f"{name}: expected a material name (non-empty string), got {value!r}"
            )
    return (wall, floor, ceiling)


def extruded_polygon(
    vertices_xy_m: Sequence[Sequence[float]],
    height_m: float,
    *,
    wall_material: str = DEFAULT_WALL_MATERIAL,
    floor_material: str = DEFAULT_FLOOR_MATERIAL,
    ceiling_material: str = DEFAULT_CEILING_MATERIAL,
) -> SceneMesh:
    """A room whose floor plan is a simple polygon, extruded from z = 0 to ``height_m``.

    Parameters
    ----------
    vertices_xy_m : (N, 2) array_like
        Floor outline in metres, either orientation, first vertex not repeated.
    height_m : float
        Floor-to-ceiling height in metres.
    wall_material, floor_material, ceiling_material : str
        Material names for the faces labelled ``"wall"``, ``"floor"`` and ``"ceiling"``.

    Returns
    -------
    SceneMesh
        Watertight, normals pointing into the room.

    Raises
    ------
    GeometryError
        Degenerate or self-intersecting polygon, non-positive height, empty material name.
    """
    materials = _room_materials(wall_material, floor_material, ceiling_material)
    height_m = _positive("extruded_polygon.height_m", height_m)
    xy = np.asarray(vertices_xy_m, dtype=np.float64)
    triangles = triangulate_polygon(xy)
    if _signed_area(xy) < 0:
        # Reorder the outline counter-clockwise (the walls' winding depends on it); the
        # triangle indices follow the same permutation.
        n = xy.shape[0]
        xy = xy[::-1]
        triangles = (n - 1) - triangles  # relabelling keeps each triangle's winding in space
    return _prism(xy, triangles, height_m, materials)


def shoebox(
    size_m: Sequence[float],
    *,
    wall_material: str = DEFAULT_WALL_MATERIAL,
    floor_material: str = DEFAULT_FLOOR_MATERIAL,
    ceiling_material: str = DEFAULT_CEILING_MATERIAL,
) -> SceneMesh:
    """A rectangular room occupying [0, x] × [0, y] × [0, z] metres (12 triangles)."""
    x, y, z = _positive_vector("shoebox.size_m", size_m, 3)
    return extruded_polygon(
        [[0.0, 0.0], [x, 0.0], [x, y], [0.0, y]],
        z,
        wall_material=wall_material,
        floor_material=floor_material,
        ceiling_material=ceiling_material,
    )


def l_shape(
    size_m: Sequence[float],
    cutout_m: Sequence[float],
    *,
    wall_material: str = DEFAULT_WALL_MATERIAL,
    floor_material: str = DEFAULT_FLOOR_MATERIAL,
    ceiling_material: str = DEFAULT_CEILING_MATERIAL,
) -> SceneMesh:
    """An L-shaped room: the [0, x] × [0, y] rectangle minus a corner at (+x, +y).

    Parameters
    ----------
    size_m : (3,) float
        Bounding box (x, y, height) in metres.
    cutout_m : (2,) float
        Size of the removed corner along x and y, in metres; each smaller than the room's.
    """
    x, y, z = _positive_vector("l_shape.size_m", size_m, 3)
    cx, cy = _positive_vector("l_shape.cutout_m", cutout_m, 2)
    if cx >= x or cy >= y:
        raise GeometryError(
            f"l_shape.cutout_m: expected a cutout smaller than the room's x and y "
            f"({x:g}, {y:g}) m, got {list(cutout_m)}"
        )
    outline = [[0.0, 0.0], [x, 0.0], [x, y - cy], [x - cx, y - cy], [x - cx, y], [0.0, y]]
    return extruded_polygon(
        outline,
        z,
        wall_material=wall_material,
        floor_material=floor_material,
        ceiling_material=ceiling_material,
    )


def _circle(center_xy: np.ndarray, radius_m: float, segments: int) -> np.ndarray:
    angles = 2.0 * np.pi * np.arange(segments) / segments
    return center_xy + radius_m * np.column_stack([np.cos(angles), np.sin(angles)])


def cylinder(
    radius_m: float,
    height_m: float,
    segments: int = 32,
    *,
    wall_material: str = DEFAULT_WALL_MATERIAL,
    floor_material: str = DEFAULT_FLOOR_MATERIAL,
    ceiling_material: str = DEFAULT_CEILING_MATERIAL,
) -> SceneMesh:
    """A round room: a regular ``segments``-gon inscribed in a circle of ``radius_m``.

    The centre is at (radius, radius), so the room lies in [0, 2r] × [0, 2r]. Floor and ceiling
    are fans around a centre vertex (no sliver triangles). The enclosed volume is that of the
    polygonal prism, ``(segments / 2) r² sin(2π / segments) h``, slightly less than ``π r² h``.
    """
    materials = _room_materials(wall_material, floor_material, ceiling_material)
    radius_m = _positive("cylinder.radius_m", radius_m)
    height_m = _positive("cylinder.height_m", height_m)
    segments = _segments("cylinder.segments", segments)
    center = np.array([radius_m, radius_m])
    xy = _circle(center, radius_m, segments)
    i = np.arange(segments)
    fan = np.column_stack([np.full(segments, segments), i, (i + 1) % segments])
    return _prism(xy, fan, height_m, materials, extra_floor_vertex=center)


# --------------------------------------------------------------------------- obstacles
def _yaw_matrix(yaw_deg: float) -> np.ndarray:
    if not np.isfinite(yaw_deg):
        raise GeometryError(f"yaw_deg: expected a finite angle in degrees, got {yaw_deg!r}")
    t = np.deg2rad(yaw_deg)
    return np.array([[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0], [0.0, 0.0, 1.0]])


def _flip(mesh: SceneMesh) -> SceneMesh:
    """Reverse every face's winding: a room (normals in) becomes a solid (normals out)."""
    return mesh.replace(faces=mesh.faces[:, ::-1])


def _as_obstacle(mesh: SceneMesh, material: str, label: str) -> SceneMesh:
    if not isinstance(material, str) or not material:
        raise GeometryError(f"obstacle material: expected a material name, got {material!r}")
    if not isinstance(label, str) or not label:
        raise GeometryError(f"obstacle label: expected a label name, got {label!r}")
    return SceneMesh(
        vertices=mesh.vertices,
        faces=mesh.faces,
        face_material=np.zeros(mesh.n_faces, np.int32),
        materials=(material,),
        face_label=np.zeros(mesh.n_faces, np.int32),
        labels=(label,),
    )


def box_obstacle(
    center_m: Sequence[float],
    size_m: Sequence[float],
    yaw_deg: float = 0.0,
    *,
    material: str = DEFAULT_OBSTACLE_MATERIAL,
    label: str = "furniture",
) -> SceneMesh:
    """A closed box with outward normals.

    Parameters
    ----------
    center_m : (3,) float
        Centre of the box in metres (a box standing on the floor has z = height / 2).
    size_m : (3,) float
        Extent along its own x, y, z axes in metres.
    yaw_deg : float
        Rotation about the vertical axis through the centre, degrees, counter-clockwise from above.
    material, label : str
        Material and semantic label of all its faces.
    """
    center = _finite_vector("box_obstacle.center_m", center_m, 3)
    size = _positive_vector("box_obstacle.size_m", size_m, 3)
    room = shoebox(size)
    vertices = (room.vertices - size / 2.0) @ _yaw_matrix(yaw_deg).T + center
    return _as_obstacle(_flip(room.replace(vertices=vertices)), material, label)


def cylinder_obstacle(
    center_xy_m: Sequence[float],
    radius_m: float,
    height_m: float,
    base_z_m: float = 0.0,
    segments: int = 24,
    *,
    material: str = DEFAULT_COLUMN_MATERIAL,
    label: str = "column",
) -> SceneMesh:
    """A closed upright cylinder (a column, a person, a pot) with outward normals.

    The cross-section is a regular ``segments``-gon inscribed in the circle of ``radius_m``
    around ``center_xy_m``; it spans z from ``base_z_m`` to ``base_z_m + height_m`` (metres).
    """
    center = _finite_vector("cylinder_obstacle.center_xy_m", center_xy_m, 2)
    base = _finite_vector("cylinder_obstacle.base_z_m", [base_z_m], 1)[0]
    room = cylinder(radius_m, height_m, segments)
    vertices = room.vertices + np.array([center[0] - radius_m, center[1] - radius_m, base])
    return _as_obstacle(_flip(room.replace(vertices=vertices)), material, label)


def mesh_obstacle(
    mesh: SceneMesh,
    position_m: Sequence[float],
    yaw_deg: float = 0.0,
    scale: float | Sequence[float] = 1.0,
    *,
    material: str | None = None,
    label: str | None = None,
) -> SceneMesh:
    """Place an object mesh (normals pointing out of the object) in the scene.

    The mesh is scaled about its own origin, rotated by ``yaw_deg`` about the vertical axis
    and translated by ``position_m`` (metres). Its materials and labels are kept unless
    ``material`` / ``label`` replace them for every face.

    Raises
    ------
    GeometryError
        Non-positive scale, or a closed mesh that encloses negative volume (normals pointing
        into the object, the convention of a room, not an obstacle).
    """
    position = _finite_vector("mesh_obstacle.position_m", position_m, 3)
    factors = (
        np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
        if np.ndim(scale) == 0
        else (np.asarray(scale, dtype=np.float64))
    )
    if factors.shape != (3,) or not np.all(np.isfinite(factors)) or np.any(factors <= 0):
        raise GeometryError(
            "mesh_obstacle.scale: expected a positive factor or three positive factors, "
            f"got {scale!r}"
        )
    mesh.validate()
    if mesh.n_faces == 0:
        raise GeometryError("mesh_obstacle.mesh: expected a mesh with faces, got an empty mesh")
    if _is_closed(mesh.faces) and mesh.air_volume() > 0:
        raise GeometryError(
            "mesh_obstacle.mesh: expected normals pointing out of the object, got a closed mesh "
            "whose normals point inwards; reverse its faces (faces[:, ::-1])"
        )
    vertices = (mesh.vertices * factors) @ _yaw_matrix(yaw_deg).T + position
    placed = mesh.replace(vertices=vertices, face_object=None)
    if material is not None:
        placed = placed.with_materials(material)
    if label is not None:
        placed = placed.replace(face_label=np.zeros(placed.n_faces, np.int32), labels=(label,))
    return placed


def _is_closed(faces: np.ndarray) -> bool:
    """Every directed edge appears once and its reverse once (an oriented closed surface)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts != 1):
        return False
    reverse = np.unique(edges[:, ::-1], axis=0)
    return directed.shape == reverse.shape and bool(np.all(directed == reverse))


def add_obstacles(room: SceneMesh, obstacles: Sequence[SceneMesh]) -> SceneMesh:
    """Merge obstacles into a room, each obstacle with its own object id.

    Obstacle ``k`` gets ``face_object == base + k``, where ``base`` is 0 for a room without
    object ids (whose faces then get -1) and one more than the largest id otherwise (an
    imported scan keeps its objects' ids). The equivalent of Habitat's ``add_object`` in
    SonicSim's occlusion study. Each obstacle must lie within the room's bounding box
    (checked); that it does not cross a wall of a non-convex room, or another obstacle, is the
    caller's responsibility.

    Raises
    ------
    GeometryError
        An obstacle reaches outside the room's bounds, or is empty.
    """
    room.validate()
    lo, hi = room.bounds
    tolerance = 1e-9 * max(float(np.ptp(room.vertices, axis=0).max()), 1.0)
    if room.face_object is None:
        parts, base = [room.replace(face_object=np.full(room.n_faces, -1, np.int32))], 0
    else:
        parts, base = [room], int(room.face_object.max(initial=-1)) + 1
    for k, obstacle in enumerate(obstacles):
        obstacle.validate()
        if obstacle.n_faces == 0:
            raise GeometryError(f"add_obstacles: expected obstacle {k} to have faces, got none")
        o_lo, o_hi = obstacle.bounds
        if np.any(o_lo < lo - tolerance) or np.any(o_hi > hi + tolerance):
            raise GeometryError(
                f"add_obstacles: expected obstacle {k} inside the room bounds "
                f"{lo.round(3).tolist()}..{hi.round(3).tolist()} m, got "
                f"{o_lo.round(3).tolist()}..{o_hi.round(3).tolist()} m"
            )
        parts.append(obstacle.replace(face_object=np.full(obstacle.n_faces, base + k, np.int32)))
    return SceneMesh.concatenate(parts).validate()
