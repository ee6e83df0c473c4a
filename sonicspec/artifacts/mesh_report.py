"""The ``mesh`` step's report: what was welded, repaired and leak-tested, as typed fields.

The step records only what it ran: a procedural room has ``repair: null`` and no ``weld`` or
``leak``; a scan has ``weld``, ``repair`` only with ``repair.enabled`` and ``leak`` only with
``repair.leak_test_rays > 0``. :class:`SceneReport` keeps "absent" apart from null: a field
left out when the report was made (or read) stays out of its JSON, whatever its dump's
options, so a mesh artifact keeps the bytes it had when the report was a dict. The values are
those of the geometry library's reports (:class:`~sonicspec.geometry.repair.WeldReport`,
:class:`~sonicspec.geometry.repair.RepairReport`, :class:`~sonicspec.geometry.repair.LeakReport`
and their ``to_dict``).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_serializer

from sonicspec.geometry.repair import LeakPlace


class _Facts(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class WeldFacts(_Facts):
    """Seams welded on load (:class:`~sonicspec.geometry.repair.WeldReport`)."""

    distance_m: float = Field(description="scene.weld_distance_m (m).")
    merged_vertices: int
    t_junctions_stitched: int
    collapsed_faces: int
    open_edges_before: int
    open_edges_after: int


class MeshStatsFacts(_Facts):
    vertices: int
    faces: int
    boundary_edges: int
    non_manifold_edges: int
    inconsistent_edges: int
    components: int
    watertight: bool


class LeakPlaceFacts(_Facts):
    """Where leaking rays leave the air (:class:`~sonicspec.geometry.repair.LeakPlace`)."""

    kind: str = Field(description="hole, face or escaped.")
    where_m: tuple[float, float, float]
    size_m: float
    rays: int
    face: int
    label: str | None
    material: str | None

    def describe(self) -> str:
        return LeakPlace(**{**self.__dict__, "where_m": tuple(self.where_m)}).describe()


class LeakFacts(_Facts):
    """The leak test (:meth:`~sonicspec.geometry.repair.LeakReport.to_dict`)."""

    rays: int
    escaped: int
    backface: int
    fraction: float = Field(description="(escaped + backface) / rays.")
    origins: str
    places: list[LeakPlaceFacts]


class RepairLeakFacts(_Facts):
    """A leak test run by the repair itself (its ``leak``; ``leak_fraction`` for
    ``fraction``)."""

    rays: int
    escaped: int
    backface: int
    leak_fraction: float
    origins: str
    places: list[LeakPlaceFacts]


class RepairFacts(_Facts):
    """What the repair found and changed (:class:`~sonicspec.geometry.repair.RepairReport`)."""

    before: MeshStatsFacts
    after: MeshStatsFacts
    merged_vertices: int
    degenerate_faces_removed: int
    duplicate_faces_removed: int
    t_junctions_stitched: int
    touching_vertices_split: int
    non_manifold_faces_removed: int
    debris_components_removed: int
    debris_faces_removed: int
    faces_flipped_coherent: int
    holes_found: int
    holes_closed: int
    hole_faces_added: int
    components_flipped: int
    watertight: bool
    leak: RepairLeakFacts | None


class SceneReport(_Facts):
    """What building a scene's mesh did (:func:`~sonicspec.artifacts.scenes.build_scene_mesh`).
    Fields not set are left out of its JSON (absent, not null)."""

    scene_id: str
    kind: str = Field(description="The scene's kind (shoebox, mesh, ...).")
    weld: WeldFacts | None = None
    repair: RepairFacts | None = None
    leak: LeakFacts | None = None
    warnings: list[str] = Field([], description="Warnings the repair and the leak test "
                                "raised.")

    @model_serializer(mode="wrap")
    def _set_only(self, handler: Any) -> Any:
        out = handler(self)
        return {k: v for k, v in out.items() if k in self.model_fields_set}


class MeshData(SceneReport):
    """The ``mesh`` artifact's data: the report and the facts :func:`read_mesh
    <sonicspec.artifacts.read_mesh>` needs with the arrays."""

    materials: list[str]
    labels: list[str]
    bounds_m: tuple[tuple[float, float, float], tuple[float, float, float]]
    faces: int
