"""Scene import: glb/gltf/ply/obj through trimesh, and Matterport3D as served for Habitat.

Everything lands in the scene frame: metres, right-handed, **z up**. glTF files are y up by
specification, so ``up_axis="auto"`` rotates them with (x, y, z)_gltf → (x, −z, y), a proper
rotation (+90° about x) that keeps faces' winding, hence their normals' side. The importers do
not re-orient faces; :mod:`sonicspec.geometry.repair` makes normals point into the air.

Imported faces get one material (``material=``, default ``"default"``) until
:meth:`SceneMesh.with_materials` maps their labels to acoustic materials.

Matterport3D as served for Habitat
----------------------------------
A scene ``<id>`` comes as ``<id>.glb`` (textured render mesh), ``<id>_semantic.ply`` (the same
surface with an ``object_id`` per face, written by habitat-sim) and ``<id>.house`` (the ASCII
annotation file whose ``O`` lines give each object's category and whose ``C`` lines give each
category's mpcat40 index and name). All three are in the scan's own frame, z up, metres —
including the glb, which breaks the glTF y-up convention (habitat-sim loads ``.glb`` stages
assuming "MP3D glb with gravity = -Z", and writes the semantic PLY without rotating the scan's
vertices), so :func:`load_matterport` reads them with ``up_axis="z"``.

:func:`load_matterport` uses **the semantic mesh as the acoustic geometry**: its faces carry
the object ids, which map through the house file to mpcat40 categories, and it is the same
surface as the render mesh without the texture payload. The glb is read only when no semantic
mesh is given (then faces have no labels).
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from sonicspec.errors import GeometryError, SonicspecWarning
from sonicspec.geometry.mesh import UNLABELED, WELD_DISTANCE_M, SceneMesh

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "WELD_DISTANCE_M",
    "HouseCategory",
    "HouseObject",
    "MatterportHouse",
    "Mpcat40Category",
    "load_matterport",
    "load_mesh",
    "mpcat40_table",
    "read_house",
]

SUPPORTED_EXTENSIONS = (".glb", ".gltf", ".obj", ".ply")
DEFAULT_MATERIAL = "default"


#: PLY face properties read as a semantic label (integers, kept as their decimal text) ...
_PLY_LABEL_PROPERTIES = ("label", "category", "category_id", "semantic_label")
#: ... and as an object id (-1 or any negative value: no object).
_PLY_OBJECT_PROPERTIES = ("object_id", "objectid", "instance", "instance_id")


# --------------------------------------------------------------------------- mpcat40
@dataclass(frozen=True)
class Mpcat40Category:
    """One of Matterport3D's 40 object categories (plus ``void`` 0 and ``unlabeled`` 41)."""

    index: int
    name: str
    color_hex: str


@cache
def mpcat40_table() -> tuple[Mpcat40Category, ...]:
    """The mpcat40 categories in index order, from ``sonicspec/data/mpcat40.tsv``."""
    text = resources.files("sonicspec").joinpath("data/mpcat40.tsv").read_text(encoding="utf-8")
    rows = [line.split("\t") for line in text.splitlines() if line and not line.startswith("#")]
    return tuple(Mpcat40Category(int(r[0]), r[1], r[2]) for r in rows[1:])


# --------------------------------------------------------------------------- generic import
MAX_MESH_MB = 1024
"""Largest scene file read, in MiB, unless the environment variable ``SONICSPEC_MAX_MESH_MB``
says otherwise. Real scans are far smaller (a Matterport3D building: a 20-150 MB glb, a
semantic ply of 10-60 MB); a mesh is loaded whole and takes about twice its file size in
memory, so a wrong file (a 2 GB point cloud, a dump) would cost minutes and gigabytes before
anything could say it is wrong."""

MAX_MESH_MB_VARIABLE = "SONICSPEC_MAX_MESH_MB"


def max_mesh_bytes() -> int:
    """The size bound of :data:`MAX_MESH_MB`, raised or lowered by ``SONICSPEC_MAX_MESH_MB``."""
    text = os.environ.get(MAX_MESH_MB_VARIABLE, "").strip()
    if not text:
        return MAX_MESH_MB * 2**20
    try:
        mb = float(text)
    except ValueError:
        mb = float("nan")
    if not (mb > 0 and np.isfinite(mb)):
        raise GeometryError(f"{MAX_MESH_MB_VARIABLE}: expected a positive number of MiB, got "
                            f"{text!r}")
    return int(mb * 2**20)


def _mib(n: int) -> str:
    mib = n / 2**20
    return f"{mib:,.0f} MiB" if mib >= 10 else f"{mib:.2g} MiB"


def _check_path(path: str | Path, where: str, extensions: tuple[str, ...]) -> Path:
    path = Path(path)
    if path.suffix.lower() not in extensions:
        raise GeometryError(
            f"{where}: expected a file ending in {', '.join(extensions)}, got '{path}'"
        )
    if not path.is_file():
        raise GeometryError(f"{where}: expected an existing file, got missing path '{path}'")
    check_mesh_size(path)
    return path


def check_mesh_size(path: Path) -> None:
    """Refuse a scene file larger than :func:`max_mesh_bytes` (before it is read or hashed)."""
    size, limit = path.stat().st_size, max_mesh_bytes()
    if size > limit:
        raise GeometryError(
            f"{path}: expected a scene file of at most {_mib(limit)}, got {_mib(size)} "
            f"({size:,} bytes); it would be read whole (about twice "
            f"its size in memory). Is it the right file? To read it anyway, set "
            f"{MAX_MESH_MB_VARIABLE}={int(np.ceil(size / 2**20)) + 1} (MiB)"
        )


def _check_scale(unit_scale: float) -> float:
    if not np.isfinite(unit_scale) or unit_scale <= 0:
        raise GeometryError(
            f"unit_scale: expected a finite positive factor to metres, got {unit_scale!r}"
        )
    return float(unit_scale)


def _resolve_up(up_axis: str, path: Path) -> str:
    if up_axis not in ("auto", "y", "z"):
        raise GeometryError(f"up_axis: expected 'auto', 'y' or 'z', got {up_axis!r}")
    if up_axis == "auto":
        return "y" if path.suffix.lower() in (".glb", ".gltf") else "z"
    return up_axis


def _to_scene_frame(vertices: np.ndarray, up: str, unit_scale: float) -> np.ndarray:
    vertices = np.asarray(vertices, dtype=np.float64)
    if up == "y":
        # +90° about x: y-up (x, y, z) → z-up (x, −z, y). A rotation, so windings are kept.
        vertices = np.column_stack([vertices[:, 0], -vertices[:, 2], vertices[:, 1]])
    return vertices * unit_scale


def _trimesh_load(path: Path, **kwargs: object):
    try:
        import trimesh
    except ImportError as exc:  # pragma: no cover - trimesh is a core dependency
        raise GeometryError(
            f"{path}: expected trimesh to be installed to read meshes, got ImportError; "
            "pip install trimesh"
        ) from exc
    try:
        return trimesh.load(str(path), process=False, skip_materials=True, **kwargs)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise GeometryError(
            f"{path}: expected a readable {path.suffix.lower()[1:]} mesh, got a read error "
            f"({type(exc).__name__}: {exc}); is the file corrupt or truncated?"
        ) from exc


def _ply_face_property(mesh, names: tuple[str, ...]) -> np.ndarray | None:
    """A scalar integer face property of a PLY file loaded by trimesh, if present."""
    # trimesh keeps the parsed PLY elements in metadata["_ply_raw"]: a structured array for
    # binary files, a dict of arrays for ASCII ones.
    raw = mesh.metadata.get("_ply_raw", {}).get("face", {}).get("data", {})
    keys = raw.dtype.names or () if isinstance(raw, np.ndarray) else tuple(raw)
    lowered = {str(k).lower(): k for k in keys}
    for name in names:
        if name in lowered:
            values = np.asarray(raw[lowered[name]])
            if values.ndim == 2 and values.shape[1] == 1:
                values = values[:, 0]
            if values.ndim == 1 and np.issubdtype(values.dtype, np.number):
                return values
    return None


def _strip_dedupe_suffix(names: list[str]) -> list[str]:
    """Undo trimesh's renaming of repeated geometry names (``wall``, ``wall_1``, ...)."""
    present = set(names)
    out = []
    for name in names:
        match = re.fullmatch(r"(.+)_\d+", name)
        out.append(match.group(1) if match and match.group(1) in present else name)
    return out


def _obj_object_names(path: Path) -> list[str]:
    """The distinct names of an obj file's ``o`` lines, in order."""
    names: dict[str, None] = {}
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if line.startswith("o ") and line[2:].strip():
                names[line[2:].strip()] = None
    return list(names)


def load_mesh(
    path: str | Path,
    up_axis: str = "auto",
    unit_scale: float = 1.0,
    *,
    material: str = DEFAULT_MATERIAL,
    obj_labels: bool = False,
    weld_distance_m: float = WELD_DISTANCE_M,
) -> SceneMesh:
    """Read a glb, gltf, ply or obj file into one :class:`SceneMesh` in the scene frame.

    Parameters
    ----------
    path
        The mesh file.
    up_axis : {"auto", "y", "z"}
        The file's up axis; ``"auto"`` is ``"y"`` for glb/gltf (the glTF convention) and
        ``"z"`` otherwise. y-up coordinates are rotated to z up: (x, y, z) → (x, −z, y).
    unit_scale : float
        Factor from file units to metres (0.01 for a file in centimetres).
    material : str
        Material name given to every face.
    obj_labels : bool
        Label an obj file's faces as a person reads the file: a lone object keeps its name
        (trimesh drops it), and a file without objects (``o`` lines) is labelled by its
        groups (``g`` lines). Off by default: the mesh stage reads obj files without it
        (new labels would change what existing scenes' meshes are made of).
    weld_distance_m : float
        Vertices of open edges closer than this (metres, default 0.1 mm) are joined, across
        objects, groups and meshes, and T-junctions along those seams stitched
        (:func:`~sonicspec.geometry.repair.weld_seams`): a file written one object per
        material loads as one surface. 0 keeps the file's vertices as they are.

    Returns
    -------
    SceneMesh
        Scene graphs flattened with their node transforms (nodes in name order), seams
        welded, each face with its own label and material. Labels,
        when the file has them: per geometry, its name (glb/gltf meshes, obj objects); per
        face, a PLY integer face property ``label``/``category``/``category_id``/
        ``semantic_label`` (as decimal text). A PLY ``object_id``/``instance`` property
        becomes ``face_object``.

    Raises
    ------
    GeometryError
        Missing file, unsupported extension, unreadable or corrupt file, no triangles, or
        invalid contents; the message names the file.

    Warns
    -----
    SonicspecWarning
        A PLY face property cannot be kept because the file has polygon faces.
    """
    path = _check_path(path, "load_mesh", SUPPORTED_EXTENSIONS)
    up = _resolve_up(up_axis, path)
    unit_scale = _check_scale(unit_scale)
    is_obj = path.suffix.lower() == ".obj"
    loaded = _trimesh_load(
        path, **({"split_objects": True, "group_material": False} if is_obj else {})
    )
    import trimesh

    lone_name = None
    if is_obj and obj_labels and isinstance(loaded, trimesh.Trimesh):
        objects = _obj_object_names(path)
        if len(objects) == 1:
            lone_name = objects[0]
        elif not objects:
            by_group = _trimesh_load(path, split_groups=True, group_material=False)
            if isinstance(by_group, trimesh.Scene):
                loaded = by_group

    parts: list[tuple[str | None, np.ndarray, np.ndarray, object]] = []
    if isinstance(loaded, trimesh.Scene):
        nodes = sorted(loaded.graph.nodes_geometry)
        geometry_names = [loaded.graph[node][1] for node in nodes]
        labels = _strip_dedupe_suffix([str(name) for name in geometry_names])
        for node, geometry_name, label in zip(nodes, geometry_names, labels, strict=True):
            transform, _ = loaded.graph[node]
            geometry = loaded.geometry[geometry_name]
            if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
                continue  # points and lines carry no surface
            vertices = trimesh.transform_points(np.asarray(geometry.vertices), transform)
            if np.linalg.det(transform[:3, :3]) < 0:
                faces = np.asarray(geometry.faces)[:, ::-1]  # a mirroring node flips windings
            else:
                faces = np.asarray(geometry.faces)
            parts.append((label, vertices, faces, geometry))
    elif isinstance(loaded, trimesh.Trimesh) and len(loaded.faces):
        parts.append((lone_name, np.asarray(loaded.vertices), np.asarray(loaded.faces), loaded))
    if not parts:
        raise GeometryError(
            f"{path}: expected a mesh with triangles, got none (an empty mesh, points or lines)"
        )

    pieces = []
    for label, vertices, faces, geometry in parts:
        n_faces = len(faces)
        face_label = None
        labels: tuple[str, ...] = ()
        face_object = None
        ply_label = _ply_face_property(geometry, _PLY_LABEL_PROPERTIES)
        ply_object = _ply_face_property(geometry, _PLY_OBJECT_PROPERTIES)
        for kind, values in (("label", ply_label), ("object id", ply_object)):
            if values is not None and len(values) != n_faces:
                # trimesh splits polygons into triangles and reorders them, so per-face values
                # can no longer be matched to triangles
                warnings.warn(
                    f"{path}: expected one {kind} per triangle, got {len(values)} values for "
                    f"{n_faces} triangles (the file has polygon faces); {kind}s are not kept, "
                    "triangulate the file to keep them",
                    SonicspecWarning,
                    stacklevel=2,
                )
        if ply_label is not None and len(ply_label) == n_faces:
            values, face_label = np.unique(ply_label.astype(np.int64), return_inverse=True)
            labels = tuple(str(v) for v in values)
        elif label is not None:
            face_label, labels = np.zeros(n_faces, np.int32), (label,)
        if ply_object is not None and len(ply_object) == n_faces:
            face_object = np.maximum(ply_object.astype(np.int64), -1)
        try:
            pieces.append(
                SceneMesh(
                    vertices=_to_scene_frame(vertices, up, unit_scale),
                    faces=faces,
                    face_material=np.zeros(n_faces, np.int32),
                    materials=(material,),
                    face_label=face_label,
                    labels=labels,
                    face_object=face_object,
                ).validate()
            )
        except GeometryError as exc:
            raise GeometryError(f"{path}: {exc}") from exc
    return _welded(SceneMesh.concatenate(pieces), weld_distance_m)


def _welded(mesh: SceneMesh, distance_m: float) -> SceneMesh:
    from sonicspec.geometry.repair import weld_seams

    return weld_seams(mesh, distance_m)[0]


# --------------------------------------------------------------------------- Matterport3D
@dataclass(frozen=True)
class HouseCategory:
    """A ``C`` line: a raw annotation category and its mpcat40 category."""

    index: int
    raw_name: str
    mpcat40_index: int
    mpcat40_name: str


@dataclass(frozen=True)
class HouseObject:
    """An ``O`` line: an annotated object, its region and category (-1: none)."""

    index: int
    region_index: int
    category_index: int
    center_m: tuple[float, float, float]


@dataclass(frozen=True)
class MatterportHouse:
    """What sonicspec needs from a ``.house`` file: name, categories, objects, segments."""

    name: str
    categories: dict[int, HouseCategory]
    objects: dict[int, HouseObject]
    segment_to_object: dict[int, int]

    def object_mpcat40(self, object_index: int) -> str:
        """mpcat40 name of an object; ``"unlabeled"`` for no object or no category."""
        obj = self.objects.get(object_index)
        if obj is None or obj.category_index < 0:
            return UNLABELED
        return self.categories[obj.category_index].mpcat40_name


def read_house(path: str | Path) -> MatterportHouse:
    """Parse a Matterport3D ``.house`` file (format ``ASCII 1.1``).

    Only the lines sonicspec uses are interpreted: ``H`` (name), ``C`` (category_index
    mapping_index mapping_name mpcat40_index mpcat40_name ...), ``O`` (object_index
    region_index category_index px py pz ...) and ``E`` (segment_index object_index id ...).
    Raw names use ``#`` for spaces, as in the files.

    Raises
    ------
    GeometryError
        Missing file, wrong header, malformed line, an object whose category is not
        declared, or a category whose mpcat40 name is not in the mpcat40 table; the
        message names the file and line.
    """
    path = _check_path(path, "read_house", (".house",))
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise GeometryError(
            f"{path}: expected a readable ASCII house file, got {type(exc).__name__}: {exc}"
        ) from exc
    if not lines or lines[0].strip() != "ASCII 1.1":
        header = lines[0].strip()[:40] if lines else ""
        raise GeometryError(
            f"{path}: expected a Matterport3D house file starting with 'ASCII 1.1', got {header!r}"
        )
    known = {c.name: c.index for c in mpcat40_table()}
    name = path.stem
    categories: dict[int, HouseCategory] = {}
    objects: dict[int, HouseObject] = {}
    segments: dict[int, int] = {}
    for number, line in enumerate(lines[1:], start=2):
        tokens = line.split()
        if not tokens:
            continue
        kind = tokens[0]
        try:
            if kind == "H":
                name = tokens[1]
            elif kind == "C":
                category = HouseCategory(
                    index=int(tokens[1]),
                    raw_name=tokens[3].replace("#", " "),
                    mpcat40_index=int(tokens[4]),
                    mpcat40_name=tokens[5],
                )
                if category.mpcat40_name not in known:
                    raise GeometryError(
                        f"{path}:{number}: expected an mpcat40 category name, got "
                        f"{category.mpcat40_name!r}"
                    )
                categories[category.index] = category
            elif kind == "O":
                obj = HouseObject(
                    index=int(tokens[1]),
                    region_index=int(tokens[2]),
                    category_index=int(tokens[3]),
                    center_m=(float(tokens[4]), float(tokens[5]), float(tokens[6])),
                )
                objects[obj.index] = obj
            elif kind == "E":
                segments[int(tokens[3])] = int(tokens[2])
        except GeometryError:
            raise
        except (IndexError, ValueError) as exc:
            raise GeometryError(
                f"{path}:{number}: expected a well-formed {kind!r} line, got {line.strip()!r}"
            ) from exc
    for obj in objects.values():
        if obj.category_index >= 0 and obj.category_index not in categories:
            raise GeometryError(
                f"{path}: expected object {obj.index}'s category {obj.category_index} to be "
                "declared by a C line, got none"
            )
    return MatterportHouse(name, categories, objects, segments)


def _read_semantic_ply(path: Path, up: str, unit_scale: float) -> tuple[SceneMesh, np.ndarray]:
    """The semantic mesh and its per-face object ids (-1: none)."""
    loaded = _trimesh_load(path)
    import trimesh

    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise GeometryError(
            f"{path}: expected a semantic mesh with triangles, got none (an empty mesh or points)"
        )
    object_id = _ply_face_property(loaded, ("object_id",))
    if object_id is not None and len(object_id) != len(loaded.faces):
        raise GeometryError(
            f"{path}: expected one object_id per triangle, got {len(object_id)} for "
            f"{len(loaded.faces)} triangles (the file has polygon faces)"
        )
    if object_id is None:
        raise GeometryError(
            f"{path}: expected a face property 'object_id' (habitat-sim's semantic PLY), "
            "got none; is this the <id>_semantic.ply file?"
        )
    object_id = np.maximum(object_id.astype(np.int64), -1)
    try:
        mesh = SceneMesh(
            vertices=_to_scene_frame(loaded.vertices, up, unit_scale),
            faces=np.asarray(loaded.faces),
            face_material=np.zeros(len(loaded.faces), np.int32),
            materials=(DEFAULT_MATERIAL,),
            face_object=object_id,
        ).validate()
    except GeometryError as exc:
        raise GeometryError(f"{path}: {exc}") from exc
    return mesh, object_id


def load_matterport(
    glb_path: str | Path,
    semantic_ply_path: str | Path | None = None,
    house_path: str | Path | None = None,
    *,
    up_axis: str = "z",
    unit_scale: float = 1.0,
    material: str = DEFAULT_MATERIAL,
    weld_distance_m: float = WELD_DISTANCE_M,
) -> SceneMesh:
    """Import a Matterport3D scene as served for Habitat, faces labelled with mpcat40 names.

    Parameters
    ----------
    glb_path
        ``<id>.glb``. Must exist; read only when ``semantic_ply_path`` is None.
    semantic_ply_path
        ``<id>_semantic.ply``: the acoustic geometry, with an ``object_id`` per face.
    house_path
        ``<id>.house``: object → category → mpcat40 name. Needs ``semantic_ply_path``.
    up_axis, unit_scale
        As in :func:`load_mesh`; MP3D files are z up in metres (see the module docstring).
    material
        Material name for every face, until :meth:`SceneMesh.with_materials`.
    weld_distance_m
        As in :func:`load_mesh`: seams (vertices of open edges this close, metres) joined.

    Returns
    -------
    SceneMesh
        With semantic mesh and house: ``face_label`` indexes mpcat40 names (ordered by
        mpcat40 index; faces of no object, or of an object without category, are
        ``"unlabeled"``) and ``face_object`` holds the house object index. With the semantic
        mesh only: object ids, no labels. With the glb only: geometry without labels.

    Raises
    ------
    GeometryError
        A missing or unreadable file, a house file without a semantic mesh, or a semantic
        mesh whose object ids the house file does not declare; messages name the files.
    """
    glb_path = _check_path(glb_path, "load_matterport", (".glb",))
    if semantic_ply_path is None:
        if house_path is not None:
            raise GeometryError(
                "load_matterport: expected semantic_ply_path with house_path (the house file "
                "labels the semantic mesh's objects), got house_path only"
            )
        # Render-mesh submesh names are not categories: drop them.
        render = load_mesh(glb_path, up_axis=up_axis, unit_scale=unit_scale, material=material,
                           weld_distance_m=weld_distance_m)
        return render.replace(face_label=None, labels=())
    semantic_path = _check_path(semantic_ply_path, "load_matterport", (".ply",))
    up = _resolve_up(up_axis, semantic_path)
    mesh, _ = _read_semantic_ply(semantic_path, up, _check_scale(unit_scale))
    mesh = _welded(mesh.with_materials(material), weld_distance_m)
    object_id = np.asarray(mesh.face_object, dtype=np.int64)
    if house_path is None:
        return mesh
    house = read_house(house_path)
    ids = np.unique(object_id)
    undeclared = [int(i) for i in ids if i >= 0 and int(i) not in house.objects]
    if undeclared:
        raise GeometryError(
            f"{semantic_path}: expected object ids declared in {house_path}, got "
            f"{len(undeclared)} undeclared (first {undeclared[:5]}); are the files of one scene?"
        )
    order = {c.name: c.index for c in mpcat40_table()}
    names_per_id = {int(i): house.object_mpcat40(int(i)) for i in ids}
    labels = tuple(sorted(set(names_per_id.values()), key=lambda name: order[name]))
    # Map object id → label index through a lookup table shifted by one for id -1.
    lookup = np.zeros(int(ids.max()) + 2, dtype=np.int32)
    for i, name in names_per_id.items():
        lookup[i + 1] = labels.index(name)
    return mesh.replace(face_label=lookup[object_id + 1], labels=labels)
