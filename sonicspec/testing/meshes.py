"""Fixture writers: small scenes on disk in the real file formats, for tests and the demo.

Each writer returns the paths it wrote and the :class:`SceneMesh` an importer should give back
(z up, metres), so a test can compare what was read with what was meant.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sonicspec.geometry.io import mpcat40_table
from sonicspec.geometry.mesh import UNLABELED, SceneMesh
from sonicspec.geometry.procedural import box_obstacle, shoebox

__all__ = [
    "HOUSE_DOORS",
    "HOUSE_DOOR_HEIGHT_M",
    "HOUSE_HEIGHT_M",
    "HOUSE_ROOMS",
    "HOUSE_SLAB_M",
    "MatterportFixture",
    "PlainMeshFixture",
    "ScannedHouse",
    "house_contains_air",
    "house_mesh",
    "scanned_house",
    "voxel_air_surface",
    "write_matterport_scene",
    "write_plain_meshes",
]


def _z_up_to_gltf(vertices: np.ndarray) -> np.ndarray:
    """Scene frame (z up) → glTF frame (y up): (x, y, z) → (x, z, −y)."""
    return np.column_stack([vertices[:, 0], vertices[:, 2], -vertices[:, 1]])


# --------------------------------------------------------------------------- plain files
@dataclass(frozen=True)
class PlainMeshFixture:
    """A room with a table, written as glb, gltf, ply and obj.

    ``mesh`` has labels ``"room"`` and ``"table"`` and ``face_object`` -1 (room) / 0 (table).
    The glb and gltf are y up with the table as a separate node translated by its transform;
    the ply and obj are z up; the ply carries integer face properties ``label`` (the index into
    ``mesh.labels``) and ``object_id``.
    """

    glb: Path
    gltf: Path
    ply: Path
    obj: Path
    mesh: SceneMesh


def write_plain_meshes(directory: str | Path, stem: str = "scene") -> PlainMeshFixture:
    """Write ``<stem>.glb/.gltf/.ply/.obj`` into ``directory`` (created if needed)."""
    import trimesh
    from trimesh.exchange.gltf import export_gltf

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    room = shoebox((4.0, 3.0, 2.5))
    table_center = np.array([1.5, 1.2, 0.6])
    table_local = box_obstacle((0.0, 0.0, 0.0), (1.2, 0.8, 0.4), yaw_deg=20.0)
    table = table_local.replace(vertices=table_local.vertices + table_center)
    labels = ("room", "table")
    mesh = SceneMesh.concatenate(
        [
            room.replace(
                face_label=np.zeros(room.n_faces, np.int32),
                labels=labels[:1],
                face_object=np.full(room.n_faces, -1, np.int32),
            ),
            table.replace(
                face_label=np.zeros(table.n_faces, np.int32),
                labels=labels[1:],
                face_object=np.zeros(table.n_faces, np.int32),
            ),
        ]
    ).with_materials("default")

    # glTF: y up; the table's vertices are local and its node carries the translation.
    scene = trimesh.Scene()
    scene.add_geometry(
        trimesh.Trimesh(_z_up_to_gltf(room.vertices), room.faces, process=False),
        geom_name="room",
        node_name="room",
    )
    transform = np.eye(4)
    transform[:3, 3] = _z_up_to_gltf(table_center[None, :])[0]
    scene.add_geometry(
        trimesh.Trimesh(_z_up_to_gltf(table_local.vertices), table_local.faces, process=False),
        geom_name="table",
        node_name="table",
        transform=transform,
    )
    glb = directory / f"{stem}.glb"
    glb.write_bytes(scene.export(file_type="glb"))
    gltf = directory / f"{stem}.gltf"
    gltf.write_bytes(export_gltf(scene, embed_buffers=True)["model.gltf"])

    ply = directory / f"{stem}.ply"
    _write_binary_ply(
        ply,
        mesh.vertices,
        mesh.faces,
        face_properties={"label": mesh.face_label, "object_id": mesh.face_object},
    )

    obj = directory / f"{stem}.obj"
    lines = ["# sonicspec test fixture: a room and a table, z up, metres"]
    offset = 0
    for name, part in (("room", room), ("table", table)):
        lines.append(f"o {name}")
        lines.extend(f"v {x!r} {y!r} {z!r}" for x, y, z in part.vertices.tolist())
        lines.extend(f"f {a} {b} {c}" for a, b, c in part.faces + 1 + offset)
        offset += part.vertices.shape[0]
    obj.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return PlainMeshFixture(glb=glb, gltf=gltf, ply=ply, obj=obj, mesh=mesh)


def _write_binary_ply(
    path: Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    face_properties: dict[str, np.ndarray],
    vertex_colors: np.ndarray | None = None,
) -> None:
    """A binary little-endian PLY: float xyz (+ uchar rgb), uchar/int face lists, int properties."""
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}"]
    header += [f"property float {axis}" for axis in "xyz"]
    vertex_fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if vertex_colors is not None:
        header += [f"property uchar {c}" for c in ("red", "green", "blue")]
        vertex_fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    header += [f"property int {name}" for name in face_properties]
    header.append("end_header")
    vertex_data = np.zeros(len(vertices), dtype=vertex_fields)
    for k, axis in enumerate("xyz"):
        vertex_data[axis] = vertices[:, k]
    if vertex_colors is not None:
        for k, channel in enumerate(("red", "green", "blue")):
            vertex_data[channel] = vertex_colors[:, k]
    face_fields = [("n", "u1"), ("v", "<i4", (3,))] + [(n, "<i4") for n in face_properties]
    face_data = np.zeros(len(faces), dtype=face_fields)  # packed: 1 + 12 + 4 per property
    face_data["n"] = 3
    face_data["v"] = faces
    for name, values in face_properties.items():
        face_data[name] = values
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vertex_data.tobytes())
        f.write(face_data.tobytes())


# --------------------------------------------------------------------------- Matterport3D
@dataclass(frozen=True)
class MatterportFixture:
    """A small Matterport3D-shaped scene: ``<id>.glb``, ``<id>_semantic.ply``, ``<id>.house``.

    ``mesh`` is what :func:`sonicspec.geometry.io.load_matterport` should return with all three
    files: mpcat40 labels per face and house object ids in ``face_object``.
    """

    glb: Path
    semantic_ply: Path
    house: Path
    mesh: SceneMesh


# House objects of the fixture: (object index, raw category name or None, mpcat40 name)
_OBJECTS = (
    (0, "wall", "wall"),
    (1, "floor", "floor"),
    (2, "ceiling", "ceiling"),
    (3, "dining table", "table"),
    (4, "chair", "chair"),
    (5, None, UNLABELED),  # annotated object without category
)


def write_matterport_scene(
    directory: str | Path, scene_id: str = "mp3dFixture0"
) -> MatterportFixture:
    """Write a one-room Matterport3D-shaped scene in the formats Habitat serves.

    The room (5 × 4 × 2.6 m) holds a table and a chair. Object ids follow the house file's
    ``O`` lines; the chair's underside is object 5, which has no category, and the table's
    underside has object id -1 (no object); both read back as ``"unlabeled"``. All files are
    z up in metres, as MP3D's are (the glb too, against the glTF convention).

    * ``<id>_semantic.ply``: binary little-endian, ``float x y z``, ``uchar red green blue``
      per vertex, ``list uchar int vertex_indices`` and ``int object_id`` per face (the layout
      habitat-sim writes).
    * ``<id>.house``: ``ASCII 1.1`` with H, L, R, P, C, O and E lines.
    * ``<id>.glb``: the same surface as the render mesh.
    """
    import trimesh

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    room = shoebox((5.0, 4.0, 2.6))
    table = box_obstacle((2.0, 2.0, 0.375), (1.2, 0.8, 0.75), yaw_deg=10.0)
    chair = box_obstacle((3.4, 2.6, 0.45), (0.5, 0.5, 0.9))
    room_object = np.array([0, 1, 2], np.int32)[room.face_label]  # wall, floor, ceiling
    downward = np.array([0.0, 0.0, -1.0])
    table_object = np.where(table.face_normals @ downward > 0.99, -1, 3).astype(np.int32)
    chair_object = np.where(chair.face_normals @ downward > 0.99, 5, 4).astype(np.int32)
    geometry = SceneMesh.concatenate([room, table, chair])
    face_object = np.concatenate([room_object, table_object, chair_object])

    object_label = {index: name for index, _, name in _OBJECTS}
    order = {c.name: c.index for c in mpcat40_table()}
    present = {object_label.get(int(i), UNLABELED) for i in np.unique(face_object)}
    labels = tuple(sorted(present, key=lambda name: order[name]))
    face_label = np.array(
        [labels.index(object_label.get(int(i), UNLABELED)) for i in face_object], np.int32
    )
    mesh = SceneMesh(
        vertices=geometry.vertices,
        faces=geometry.faces,
        face_material=np.zeros(geometry.n_faces, np.int32),
        materials=("default",),
        face_label=face_label,
        labels=labels,
        face_object=face_object,
    )

    # Vertex colours as habitat's semantic meshes have them: the category's mpcat40 colour.
    colors = {c.name: c.color_hex for c in mpcat40_table()}
    rgb = np.zeros((mesh.vertices.shape[0], 3), np.uint8)
    for face, label in zip(mesh.faces, face_label, strict=True):
        hex_color = colors[labels[label]].lstrip("#")
        rgb[face] = [int(hex_color[k : k + 2], 16) for k in (0, 2, 4)]
    semantic_ply = directory / f"{scene_id}_semantic.ply"
    _write_binary_ply(
        semantic_ply, mesh.vertices, mesh.faces, {"object_id": face_object}, vertex_colors=rgb
    )

    glb = directory / f"{scene_id}.glb"
    render = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=rgb, process=False)
    glb.write_bytes(trimesh.Scene({"mesh_0": render}).export(file_type="glb"))

    house = directory / f"{scene_id}.house"
    house.write_text(_house_text(scene_id, mesh), encoding="ascii")
    return MatterportFixture(glb=glb, semantic_ply=semantic_ply, house=house, mesh=mesh)


def _fmt(values) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def _house_text(scene_id: str, mesh: SceneMesh) -> str:
    lo, hi = mesh.bounds
    center = (lo + hi) / 2
    categories = [(raw, name) for _, raw, name in _OBJECTS if raw is not None]
    mpcat40 = {c.name: c.index for c in mpcat40_table()}
    n_objects, n_categories = len(_OBJECTS), len(categories)
    lines = [
        "ASCII 1.1",
        # H name label #images #panoramas #vertices #surfaces #segments #objects #categories
        #   #regions #portals #levels  0 0 0 0 0  xlo ylo zlo xhi yhi zhi  0 0 0 0 0
        f"H {scene_id} fixture 0 1 4 1 {n_objects} {n_objects} {n_categories} 1 1 1  0 0 0 0 0  "
        f"{_fmt(lo)}  {_fmt(hi)}  0 0 0 0 0",
        # L level_index #regions label  px py pz  xlo ylo zlo xhi yhi zhi  0 0 0 0 0
        f"L 0 1 -  {_fmt(center)}  {_fmt(lo)}  {_fmt(hi)}  0 0 0 0 0",
        # R region_index level_index 0 0 label  px py pz  xlo ylo zlo xhi yhi zhi height 0 0 0 0
        f"R 0 0 0 0 d  {_fmt(center)}  {_fmt(lo)}  {_fmt(hi)}  {hi[2] - lo[2]:.6f}  0 0 0 0",
        # P portal_index region0_index region1_index label  xlo ylo zlo xhi yhi zhi  0 0 0 0
        f"P 0 0 -1 door  {_fmt([0.0, 1.5, 0.0])}  {_fmt([0.0, 2.4, 2.1])}  0 0 0 0",
    ]
    for index, (raw, name) in enumerate(categories):
        # C category_index category_mapping_index category_mapping_name mpcat40_index
        #   mpcat40_name 0 0 0 0 0
        raw_token = raw.replace(" ", "#")
        lines.append(f"C {index} {index + 1} {raw_token} {mpcat40[name]} {name}  0 0 0 0 0")
    category_of = {raw: k for k, (raw, _) in enumerate(categories)}
    for index, raw, _ in _OBJECTS:
        faces = mesh.face_object == index
        points = mesh.vertices[mesh.faces[faces].ravel()]
        o_lo, o_hi = points.min(axis=0), points.max(axis=0)
        radius = np.maximum((o_hi - o_lo) / 2, 0.01)
        category = -1 if raw is None else category_of[raw]
        # O object_index region_index category_index px py pz  a0x a0y a0z  a1x a1y a1z
        #   r0 r1 r2 0 0 0 0 0 0 0 0
        lines.append(
            f"O {index} 0 {category}  {_fmt((o_lo + o_hi) / 2)}  1 0 0  0 1 0  "
            f"{_fmt(radius)}  0 0 0 0 0 0 0 0"
        )
    for index, _, _ in _OBJECTS:
        faces = mesh.face_object == index
        area = float(mesh.face_areas[faces].sum())
        points = mesh.vertices[mesh.faces[faces].ravel()]
        # E segment_index object_index id area px py pz xlo ylo zlo xhi yhi zhi 0 0 0 0 0
        lines.append(
            f"E {index} {index} {index + 1000} {area:.6f}  {_fmt(points.mean(axis=0))}  "
            f"{_fmt(points.min(axis=0))}  {_fmt(points.max(axis=0))}  0 0 0 0 0"
        )
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- scanned house
#: Rooms of the synthetic house, (x0, x1, y0, y1) in metres: two rooms side by side and a long
#: room behind them, separated by 0.2 m walls.
HOUSE_ROOMS = ((0.0, 4.0, 0.0, 5.0), (4.2, 8.0, 0.0, 5.0), (0.0, 8.0, 5.2, 8.0))
#: Door openings through the walls, (x0, x1, y0, y1) in metres, from the floor to 2.1 m.
HOUSE_DOORS = ((4.0, 4.2, 2.0, 3.0), (1.0, 2.0, 5.0, 5.2), (6.0, 7.0, 5.0, 5.2))
HOUSE_HEIGHT_M = 2.6
HOUSE_DOOR_HEIGHT_M = 2.1
#: Thickness of the slab between the floors of a multi-storey house, metres.
HOUSE_SLAB_M = 0.3


@dataclass(frozen=True)
class ScannedHouse:
    """A synthetic multi-room house: the intact surface and a copy damaged like a scan.

    ``clean`` is watertight with normals into the air. ``damaged`` has, on top of it: vertex
    noise, duplicated (split) vertices that open cracks, one missing wall panel, flipped faces,
    duplicated faces, a small piece of floating debris and, if asked for, T-junctions (an edge
    bisected on one side only). ``missing_panel_m`` is the panel's (y0, y1, z0, z1) on the
    west wall x = 0 of the first room.
    """

    clean: SceneMesh
    damaged: SceneMesh
    missing_panel_m: tuple[float, float, float, float]
    n_flipped: int
    n_split_vertices: int
    n_duplicated_faces: int
    n_t_junctions: int = 0

    @staticmethod
    def contains_air(points: np.ndarray) -> np.ndarray:
        """True for points in a room or a door opening (the oracle for 'inside the air')."""
        return house_contains_air(points)


def house_contains_air(
    points: np.ndarray, floors: int = 1, slab_m: float = HOUSE_SLAB_M
) -> np.ndarray:
    """True for points in a room or door opening of the synthetic house (any of its floors)."""
    points = np.atleast_2d(points)
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    inside = np.zeros(len(points), bool)
    for floor in range(floors):
        z0 = floor * (HOUSE_HEIGHT_M + slab_m)
        for x0, x1, y0, y1 in HOUSE_ROOMS:
            inside |= (
                (x > x0) & (x < x1) & (y > y0) & (y < y1) & (z > z0) & (z < z0 + HOUSE_HEIGHT_M)
            )
        for x0, x1, y0, y1 in HOUSE_DOORS:
            inside |= (
                (x > x0)
                & (x < x1)
                & (y > y0)
                & (y < y1)
                & (z > z0)
                & (z < z0 + HOUSE_DOOR_HEIGHT_M)
            )
    return inside


def _grid(breaks: list[float], max_step_m: float) -> np.ndarray:
    """Grid lines through every break, at most ``max_step_m`` apart."""
    lines = [breaks[0]]
    for a, b in itertools.pairwise(breaks):
        n = max(1, int(np.ceil((b - a) / max_step_m - 1e-9)))
        lines.extend(np.linspace(a, b, n + 1)[1:].tolist())
    return np.array(lines)


def voxel_air_surface(xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, air: np.ndarray) -> SceneMesh:
    """The surface between air cells and solid cells of a rectilinear grid, normals into the air.

    ``air[i, j, k]`` says whether the cell [xs[i], xs[i+1]] × [ys[j], ys[j+1]] × [zs[k], zs[k+1]]
    is air; everything outside the grid is solid. Faces lie on the grid, so the surface is
    conforming and watertight unless two air cells touch along an edge only. Faces are labelled
    ``floor`` (normal up), ``ceiling`` (normal down) or ``wall``.
    """
    nx, ny, nz = air.shape
    padded = np.zeros((nx + 2, ny + 2, nz + 2), bool)
    padded[1:-1, 1:-1, 1:-1] = air

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    quads = []
    # For each axis: faces between cell c-1 and c along that axis; the quad's corner order
    # (u, v in-plane with u × v = +axis) gives normal +axis, reversed when the air is behind.
    for axis in range(3):
        shape = [nx, ny, nz]
        shape[axis] += 1
        idx = np.indices(shape).reshape(3, -1).T
        lo = idx.copy()
        hi = idx.copy() + 1  # indices into padded array
        lo = lo + 1
        lo[:, axis] -= 1
        a_lo = padded[lo[:, 0], lo[:, 1], lo[:, 2]]
        a_hi = padded[hi[:, 0], hi[:, 1], hi[:, 2]]
        change = a_lo != a_hi
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for (i, j, k), air_ahead in zip(idx[change], a_hi[change], strict=True):
            base = np.array([i, j, k])
            du, dv = np.eye(3, dtype=int)[u], np.eye(3, dtype=int)[v]
            corners = [base, base + du, base + du + dv, base + dv]
            ids = [node(*c) for c in corners]
            quads.append(ids if air_ahead else ids[::-1])
    quads = np.array(quads, dtype=np.int64)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    used, inverse = np.unique(faces.ravel(), return_inverse=True)
    i, rest = np.divmod(used, (ny + 1) * (nz + 1))
    j, k = np.divmod(rest, nz + 1)
    vertices = np.column_stack([xs[i], ys[j], zs[k]])
    mesh = SceneMesh(vertices, inverse.reshape(-1, 3), np.zeros(len(faces), np.int32), ("default",))
    nz_component = mesh.face_normals[:, 2]
    label = np.where(nz_component > 0.5, 1, np.where(nz_component < -0.5, 2, 0)).astype(np.int32)
    return mesh.replace(face_label=label, labels=("wall", "floor", "ceiling"))


def house_mesh(max_step_m: float = 1.0, floors: int = 1, slab_m: float = HOUSE_SLAB_M) -> SceneMesh:
    """The intact synthetic house (:data:`HOUSE_ROOMS`, :data:`HOUSE_DOORS`) as a voxel surface.

    With ``floors > 1`` the same plan is stacked, each storey ``HOUSE_HEIGHT_M`` high with a
    ``slab_m`` slab in between (no stairs: the storeys are separate closed air volumes). Grid
    cells are at most ``max_step_m`` across, which sets the triangle count.
    """
    boxes = HOUSE_ROOMS + HOUSE_DOORS
    xs = _grid(sorted({v for b in boxes for v in b[:2]}), max_step_m)
    ys = _grid(sorted({v for b in boxes for v in b[2:]}), max_step_m)
    z_breaks = []
    for floor in range(floors):
        z0 = floor * (HOUSE_HEIGHT_M + slab_m)
        z_breaks += [z0, z0 + HOUSE_DOOR_HEIGHT_M, z0 + HOUSE_HEIGHT_M]
    zs = _grid(z_breaks, max_step_m)
    centers = np.stack(
        np.meshgrid(
            (xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2, (zs[:-1] + zs[1:]) / 2, indexing="ij"
        ),
        axis=-1,
    )
    air = house_contains_air(centers.reshape(-1, 3), floors, slab_m).reshape(centers.shape[:3])
    return voxel_air_surface(xs, ys, zs, air)


def scanned_house(
    rng: np.random.Generator,
    *,
    noise_m: float = 0.003,
    flipped_fraction: float = 0.05,
    split_fraction: float = 0.05,
    duplicated_faces: int = 10,
    t_junctions: int = 0,
) -> ScannedHouse:
    """The synthetic house and a copy with scan damage (see :class:`ScannedHouse`).

    Randomness (noise, which faces flip, which vertices split) comes from ``rng``;
    ``t_junctions`` faces (drawn last, so the other damage does not depend on it) get one edge
    bisected at its midpoint on their side only, while the face across keeps the whole edge:
    the two sides of that seam are tessellated differently, as where scan tiles meet.
    """
    clean = house_mesh()
    vertices = clean.vertices + rng.normal(scale=noise_m, size=clean.vertices.shape)
    faces = np.array(clean.faces)
    n_faces = len(faces)

    # Missing wall panel: one grid cell of the west wall of room 0, y 1..2 m, z 0.7..1.4 m
    centroids = clean.face_centroids
    panel = (1.0, 2.0, 0.7, 1.4)
    on_panel = (
        (np.abs(centroids[:, 0]) < 1e-9)
        & (centroids[:, 1] > panel[0])
        & (centroids[:, 1] < panel[1])
        & (centroids[:, 2] > panel[2])
        & (centroids[:, 2] < panel[3])
    )
    keep = ~on_panel

    # Split vertices: a copy a hair away (0.1 mm) that some of the faces use instead (a crack).
    n_split = int(split_fraction * len(vertices))
    split = rng.choice(len(vertices), size=n_split, replace=False)
    copies = vertices[split] + rng.normal(scale=1e-4, size=(n_split, 3))
    copy_index = np.full(len(vertices), -1)
    copy_index[split] = len(vertices) + np.arange(n_split)
    vertices = np.concatenate([vertices, copies])
    use_copy = rng.random(faces.shape) < 0.5
    redirected = np.where(use_copy & (copy_index[faces] >= 0), copy_index[faces], faces)

    # Flipped faces and duplicated faces.
    flip = rng.random(n_faces) < flipped_fraction
    redirected[flip] = redirected[flip][:, ::-1]
    face_ids = np.flatnonzero(keep)
    duplicates = rng.choice(face_ids, size=duplicated_faces, replace=False)
    order = np.concatenate([face_ids, duplicates])

    # Debris: a small floating triangle pair in the middle of room 0 (about 4 cm across).
    debris_vertices = np.array(
        [[2.0, 2.5, 1.2], [2.04, 2.5, 1.2], [2.04, 2.54, 1.2], [2.0, 2.54, 1.2]]
    )
    debris_faces = np.array([[0, 1, 2], [0, 2, 3]]) + len(vertices)
    vertices = np.concatenate([vertices, debris_vertices])
    faces = redirected[order]
    face_label = clean.face_label[order]
    n_t = 0
    if t_junctions > 0:
        vertices, faces, face_label, n_t = _add_t_junctions(
            vertices, faces, face_label, t_junctions, rng
        )
    damaged = SceneMesh(
        vertices=vertices,
        faces=np.concatenate([faces, debris_faces]),
        face_material=np.zeros(len(faces) + 2, np.int32),
        materials=clean.materials,
        face_label=np.concatenate([face_label, [0, 0]]),
        labels=clean.labels,
    )
    return ScannedHouse(
        clean=clean,
        damaged=damaged,
        missing_panel_m=panel,
        n_flipped=int(np.count_nonzero(flip & keep)),
        n_split_vertices=n_split,
        n_duplicated_faces=duplicated_faces,
        n_t_junctions=n_t,
    )


def _add_t_junctions(vertices, faces, face_label, count: int, rng: np.random.Generator):
    """Bisect one edge of ``count`` random faces on their own side only (T-junctions).

    Each picked face (a, b, c) becomes (a, m, c), (m, b, c) with m the midpoint of a-b; the
    face across a-b keeps it whole. Duplicated faces are not picked (their copy would keep the
    edge whole on the same side), and an edge picked twice (from both sides) is bisected once.
    Returns (vertices, faces, face_label, number of T-junctions).
    """
    triples = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(triples, axis=0, return_inverse=True, return_counts=True)
    single = np.flatnonzero(counts[inverse.ravel()] == 1)
    picked = rng.choice(single, size=min(count, len(single)), replace=False)
    corner = rng.integers(0, 3, len(picked))
    a, b = faces[picked, corner], faces[picked, (corner + 1) % 3]
    c = faces[picked, (corner + 2) % 3]
    # split vertices have copies 0.1 mm away: tell edges apart by their midpoints (to 1 mm)
    midpoint = np.round(0.5 * (vertices[a] + vertices[b]), 3)
    _, first = np.unique(midpoint, axis=0, return_index=True)
    first = np.sort(first)
    picked, a, b, c = picked[first], a[first], b[first], c[first]
    m = len(vertices) + np.arange(len(picked))
    kept = np.ones(len(faces), bool)
    kept[picked] = False
    faces = np.concatenate([faces[kept], np.column_stack([a, m, c]), np.column_stack([m, b, c])])
    face_label = np.concatenate([face_label[kept], face_label[picked], face_label[picked]])
    vertices = np.concatenate([vertices, 0.5 * (vertices[a] + vertices[b])])
    return vertices, faces, face_label, len(picked)
