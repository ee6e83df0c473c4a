"""The scene mesh: one triangle soup with per-face material, semantic label and object id.

Orientation convention (the tracer relies on it)
------------------------------------------------
**Every face normal points into the air.** The normal of face ``(a, b, c)`` is
``(b - a) × (c - a)``, i.e. the vertices run counter-clockwise when seen from the air side.
A room's boundary (walls, floor, ceiling) therefore has *inward* normals and an obstacle
standing in the room has *outward* normals. For a closed scene this makes the divergence-theorem
volume ``-(1/6) Σ a · (b × c)`` equal to the volume of air (room minus obstacles), which
:meth:`SceneMesh.air_volume` returns and the tests use as an orientation oracle.

Frame and units: metres, right-handed, z up.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from sonicspec.errors import GeometryError

__all__ = ["UNLABELED", "WELD_DISTANCE_M", "SceneMesh"]

#: Label given to faces that carry none when meshes with and without labels are merged
#: (the same word as mpcat40's category 41).
UNLABELED = "unlabeled"

#: Default distance within which loading joins the vertices of open edges, metres (0.1 mm:
#: far below any feature of a room, far above the rounding of coordinates written as text;
#: :func:`sonicspec.geometry.repair.weld_seams`).
WELD_DISTANCE_M = 1e-4


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class SceneMesh:
    """A triangle mesh of a scene, normals into the air (see the module docstring).

    Attributes
    ----------
    vertices : (V, 3) float64
        Vertex positions in metres, z up.
    faces : (F, 3) int64
        Vertex indices per triangle, counter-clockwise seen from the air.
    face_material : (F,) int32
        Index into ``materials`` per face.
    materials : tuple of str
        Acoustic material names.
    face_label : (F,) int32 or None
        Index into ``labels`` per face (semantic category, e.g. an mpcat40 name).
    labels : tuple of str
        Semantic label names; empty when ``face_label`` is None.
    face_object : (F,) int32 or None
        Object (obstacle, scanned object) each face belongs to; -1 for none.

    The arrays are stored read-only; derive new meshes with :meth:`with_materials`,
    :meth:`concatenate` or :meth:`subset`.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    materials: tuple[str, ...]
    face_label: np.ndarray | None = None
    labels: tuple[str, ...] = ()
    face_object: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        # Shape checks are cheap and catch the common mistakes at construction; the index and
        # finiteness checks, which cost a pass over the data, live in validate().
        vertices = np.array(self.vertices, dtype=np.float64, copy=True)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise GeometryError(
                f"SceneMesh.vertices: expected an array of shape (V, 3), got {vertices.shape}"
            )
        faces = np.array(self.faces, dtype=np.int64, copy=True)
        if faces.size == 0:
            faces = faces.reshape(0, 3)
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise GeometryError(
                f"SceneMesh.faces: expected an array of shape (F, 3), got {faces.shape}"
            )
        n_faces = faces.shape[0]
        object.__setattr__(self, "vertices", _readonly(vertices))
        object.__setattr__(self, "faces", _readonly(faces))
        object.__setattr__(self, "materials", tuple(str(m) for m in self.materials))
        object.__setattr__(self, "labels", tuple(str(lb) for lb in self.labels))
        object.__setattr__(
            self, "face_material", self._per_face("face_material", self.face_material, n_faces)
        )
        if self.face_label is not None:
            object.__setattr__(
                self, "face_label", self._per_face("face_label", self.face_label, n_faces)
            )
        elif self.labels:
            raise GeometryError(
                "SceneMesh.labels: expected no labels when face_label is None, "
                f"got {len(self.labels)} labels"
            )
        if self.face_object is not None:
            object.__setattr__(
                self, "face_object", self._per_face("face_object", self.face_object, n_faces)
            )

    @staticmethod
    def _per_face(name: str, values: np.ndarray, n_faces: int) -> np.ndarray:
        array = np.asarray(values)
        if array.ndim == 0:
            array = np.full(n_faces, array)
        if array.shape != (n_faces,):
            raise GeometryError(
                f"SceneMesh.{name}: expected one value per face, shape ({n_faces},), "
                f"got {array.shape}"
            )
        if array.size and not np.issubdtype(array.dtype, np.integer):
            raise GeometryError(f"SceneMesh.{name}: expected integers, got dtype {array.dtype}")
        return _readonly(array.astype(np.int32, copy=True))

    # ------------------------------------------------------------------ checks
    def validate(self) -> SceneMesh:
        """Check indices and values; return ``self`` so calls can be chained.

        Raises
        ------
        GeometryError
            A vertex is not finite, a face index is out of range, a material or label index
            is out of range, or an object id is below -1.
        """
        if not np.all(np.isfinite(self.vertices)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(self.vertices), axis=1))[0])
            raise GeometryError(
                f"SceneMesh.vertices: expected finite coordinates, got {self.vertices[bad]} "
                f"at vertex {bad}"
            )
        n_vertices = self.vertices.shape[0]
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= n_vertices):
            raise GeometryError(
                f"SceneMesh.faces: expected vertex indices in [0, {n_vertices - 1}], got "
                f"range [{self.faces.min()}, {self.faces.max()}]"
            )
        self._check_index("face_material", self.face_material, self.materials)
        if self.face_label is not None:
            self._check_index("face_label", self.face_label, self.labels)
        if self.face_object is not None and self.face_object.size and self.face_object.min() < -1:
            raise GeometryError(
                "SceneMesh.face_object: expected object ids >= -1 (-1 for none), got "
                f"{self.face_object.min()}"
            )
        return self

    @staticmethod
    def _check_index(name: str, index: np.ndarray, names: tuple[str, ...]) -> None:
        if index.size and (index.min() < 0 or index.max() >= len(names)):
            raise GeometryError(
                f"SceneMesh.{name}: expected indices in [0, {len(names) - 1}] "
                f"({len(names)} names), got range [{index.min()}, {index.max()}]"
            )

    # ------------------------------------------------------------------ measures
    @property
    def n_faces(self) -> int:
        """Number of triangles."""
        return int(self.faces.shape[0])

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounding box, ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` in metres."""
        if self.vertices.shape[0] == 0:
            raise GeometryError("SceneMesh.bounds: expected at least one vertex, got none")
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def _cross(self) -> np.ndarray:
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return np.cross(b - a, c - a)

    @property
    def face_normals(self) -> np.ndarray:
        """Unit normals (F, 3), pointing into the air; zero for degenerate faces."""
        cross = self._cross()
        norm = np.linalg.norm(cross, axis=1, keepdims=True)
        return np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)

    @property
    def face_areas(self) -> np.ndarray:
        """Triangle areas (F,) in m²."""
        return 0.5 * np.linalg.norm(self._cross(), axis=1)

    @property
    def face_centroids(self) -> np.ndarray:
        """Triangle centroids (F, 3) in metres."""
        return self.vertices[self.faces].mean(axis=1)

    def air_volume(self) -> float:
        """Volume of air enclosed by a closed mesh, in m³ (divergence theorem).

        With normals into the air, ``-(1/6) Σ a · (b × c)`` is the room volume minus the
        obstacles' volumes. Meaningless (but computed) for a mesh with holes; a negative
        result on a closed mesh means its faces point out of the air.
        """
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return float(-np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)

    # ------------------------------------------------------------------ derived meshes
    def with_materials(
        self,
        assign: str | Mapping[str, str] | Callable[[str], str],
        *,
        default: str | None = None,
    ) -> SceneMesh:
        """Return a copy whose faces get materials from their labels.

        Parameters
        ----------
        assign
            A material name for every face; or a mapping label → material name; or a
            callable label → material name (e.g. ``library.material_for_label``).
        default
            Material for labels the mapping does not contain (mappings only); without it
            an unmapped label is an error.

        Raises
        ------
        GeometryError
            Labels are needed but the mesh has none, or a label has no material.
        """
        if isinstance(assign, str):
            return self.replace(face_material=np.zeros(self.n_faces, np.int32), materials=(assign,))
        if self.face_label is None:
            raise GeometryError(
                "SceneMesh.with_materials: expected a mesh with face labels to map, got a mesh "
                "without labels; pass one material name instead"
            )
        per_label: list[str] = []
        for label in self.labels:
            if callable(assign) and not isinstance(assign, Mapping):
                per_label.append(str(assign(label)))
            elif label in assign:
                per_label.append(str(assign[label]))
            elif default is not None:
                per_label.append(default)
            else:
                raise GeometryError(
                    f"SceneMesh.with_materials: expected a material for every label, got none "
                    f"for label {label!r}; add it to the mapping or pass default="
                )
        materials = tuple(dict.fromkeys(per_label))
        label_to_material = np.array([materials.index(m) for m in per_label], dtype=np.int32)
        face_material = (
            label_to_material[self.face_label] if label_to_material.size else np.zeros(0, np.int32)
        )
        return self.replace(face_material=face_material, materials=materials)

    def subset(self, face_indices: np.ndarray) -> SceneMesh:
        """Return the mesh of the given faces (indices or boolean mask), unused vertices dropped."""
        selected = np.arange(self.n_faces)[np.asarray(face_indices)]
        faces = self.faces[selected]
        used, inverse = np.unique(faces.ravel(), return_inverse=True)
        return SceneMesh(
            vertices=self.vertices[used],
            faces=inverse.reshape(-1, 3),
            face_material=self.face_material[selected],
            materials=self.materials,
            face_label=None if self.face_label is None else self.face_label[selected],
            labels=self.labels,
            face_object=None if self.face_object is None else self.face_object[selected],
        )

    def replace(self, **changes: object) -> SceneMesh:
        """Return a copy with some fields changed (checked like a new mesh)."""
        fields = {
            "vertices": self.vertices,
            "faces": self.faces,
            "face_material": self.face_material,
            "materials": self.materials,
            "face_label": self.face_label,
            "labels": self.labels,
            "face_object": self.face_object,
        }
        fields.update(changes)
        return SceneMesh(**fields)  # type: ignore[arg-type]

    @staticmethod
    def concatenate(meshes: Iterable[SceneMesh]) -> SceneMesh:
        """Merge meshes into one (vertices are not welded).

        Material and label names are merged in order of first appearance. If some meshes have
        labels and others not, the unlabeled faces get the label ``"unlabeled"``; if some have
        object ids and others not, the missing ones are -1.
        """
        meshes = list(meshes)
        if not meshes:
            raise GeometryError("SceneMesh.concatenate: expected at least one mesh, got none")
        materials = tuple(dict.fromkeys(m for mesh in meshes for m in mesh.materials))
        any_labels = any(mesh.face_label is not None for mesh in meshes)
        labels: tuple[str, ...] = ()
        if any_labels:
            names = [
                lb
                for mesh in meshes
                for lb in (mesh.labels if mesh.face_label is not None else (UNLABELED,))
            ]
            labels = tuple(dict.fromkeys(names))
        any_objects = any(mesh.face_object is not None for mesh in meshes)

        vertices, faces, face_material, face_label, face_object = [], [], [], [], []
        offset = 0
        for mesh in meshes:
            vertices.append(mesh.vertices)
            faces.append(mesh.faces + offset)
            offset += mesh.vertices.shape[0]
            remap = np.array([materials.index(m) for m in mesh.materials], dtype=np.int32)
            face_material.append(remap[mesh.face_material] if mesh.n_faces else mesh.face_material)
            if any_labels:
                if mesh.face_label is None:
                    face_label.append(np.full(mesh.n_faces, labels.index(UNLABELED), np.int32))
                else:
                    remap = np.array([labels.index(lb) for lb in mesh.labels], dtype=np.int32)
                    face_label.append(remap[mesh.face_label] if mesh.n_faces else mesh.face_label)
            if any_objects:
                face_object.append(
                    np.full(mesh.n_faces, -1, np.int32)
                    if mesh.face_object is None
                    else mesh.face_object
                )
        return SceneMesh(
            vertices=np.concatenate(vertices),
            faces=np.concatenate(faces),
            face_material=np.concatenate(face_material),
            materials=materials,
            face_label=np.concatenate(face_label) if any_labels else None,
            labels=labels,
            face_object=np.concatenate(face_object) if any_objects else None,
        )

    # ------------------------------------------------------------------ interop
    def to_trimesh(self):  # -> trimesh.Trimesh (lazy import keeps trimesh off the import path)
        """Return a :class:`trimesh.Trimesh` with the same vertices and faces (no processing).

        Per-face ``material``, ``label`` and ``object`` indices are attached as
        ``face_attributes``.
        """
        try:
            import trimesh
        except ImportError as exc:  # pragma: no cover - trimesh is a core dependency
            raise GeometryError(
                "SceneMesh.to_trimesh: expected trimesh to be installed, got ImportError; "
                "pip install trimesh"
            ) from exc
        face_attributes = {"material": np.array(self.face_material)}
        if self.face_label is not None:
            face_attributes["label"] = np.array(self.face_label)
        if self.face_object is not None:
            face_attributes["object"] = np.array(self.face_object)
        return trimesh.Trimesh(
            vertices=np.array(self.vertices),
            faces=np.array(self.faces),
            face_attributes=face_attributes,
            process=False,
            validate=False,
        )

    def __repr__(self) -> str:
        n_objects = (
            "none" if self.face_object is None else int(self.face_object.max(initial=-1)) + 1
        )
        return (
            f"SceneMesh({self.vertices.shape[0]} vertices, {self.n_faces} faces, "
            f"materials={list(self.materials)}, labels={list(self.labels)}, "
            f"objects={n_objects})"
        )
