"""Scenes: procedural rooms, obstacles and mesh files (Matterport3D scans or any glb/ply/obj)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator
from pydantic_core import PydanticCustomError

from sonicspec.spec.base import Identifier, SpecModel, vector

MAX_EXTENT_M = 1000.0
"""Largest size or coordinate of a procedural room or obstacle, metres (each extent)."""

MAX_FLOOR_AREA_M2 = 10_000.0
"""Largest floor-plan bounding box of a procedural room, m². The walkable-area grid has a cell
every 5 cm over that box, and a 100 m x 100 m floor already takes 4.9 GB at its peak
(bench/RESULTS.md, issue 16); a larger one would exhaust a workstation's memory."""

_LIMIT = (
    f"at most {MAX_EXTENT_M:g} m per extent and {MAX_FLOOR_AREA_M2:,.0f} m² of floor plan "
    "(the walkable-area grid's memory grows with the floor area)"
)
Vec2 = vector(2, ge=-MAX_EXTENT_M, le=MAX_EXTENT_M)
Vec3 = vector(3, ge=-MAX_EXTENT_M, le=MAX_EXTENT_M)
PositiveVec2 = vector(2, gt=0, le=MAX_EXTENT_M)
PositiveVec3 = vector(3, gt=0, le=MAX_EXTENT_M)


class SurfaceMaterialsSpec(SpecModel):
    """Materials of a procedural room's boundary, by name from the material library."""

    walls: str = Field("plaster_on_brick", description="Material of every wall.")
    floor: str = Field("parquet_on_concrete", description="Material of the floor.")
    ceiling: str = Field("plaster_on_concrete", description="Material of the ceiling.")


class BoxObstacleSpec(SpecModel):
    """An axis-aligned box (before yaw) standing in the room, e.g. a cabinet or a partition."""

    kind: Literal["box"] = Field(description="Obstacle type.")
    center_m: Vec3 = Field(
        description="Centre of the box in scene coordinates, metres (within ±1000)."
    )
    size_m: PositiveVec3 = Field(
        description="Edge lengths along x, y, z before rotation, metres (at most 1000)."
    )
    yaw_deg: float = Field(0.0, description="Rotation about the vertical axis, degrees.")
    material: str = Field("wood_panel", description="Material of every face of the box.")
    label: str = Field("furniture", description="Semantic label (mpcat40 category) of the box.")


class CylinderObstacleSpec(SpecModel):
    """A vertical cylinder, e.g. a column or a round table."""

    kind: Literal["cylinder"] = Field(description="Obstacle type.")
    center_xy_m: Vec2 = Field(
        description="Axis position on the floor plan, metres (within ±1000)."
    )
    radius_m: float = Field(gt=0, le=MAX_EXTENT_M / 2, description="Radius, metres (at most 500).")
    height_m: float = Field(gt=0, le=MAX_EXTENT_M, description="Height, metres (at most 1000).")
    base_z_m: float = Field(
        0.0,
        ge=-MAX_EXTENT_M,
        le=MAX_EXTENT_M,
        description="Height of the bottom face above z = 0, metres (within ±1000).",
    )
    material: str = Field("concrete_painted", description="Material of the cylinder.")
    label: str = Field("column", description="Semantic label (mpcat40 category).")


class MeshObstacleSpec(SpecModel):
    """An object loaded from a mesh file and placed in the scene."""

    kind: Literal["mesh"] = Field(description="Obstacle type.")
    path: str = Field(
        min_length=1, description="Mesh file (glb, gltf, ply, obj), relative to the spec file."
    )
    position_m: Vec3 = Field(
        description="Where the mesh's origin is placed, metres (within ±1000)."
    )
    yaw_deg: float = Field(0.0, description="Rotation about the vertical axis, degrees.")
    scale: float = Field(1.0, gt=0, description="Uniform scale applied before placing (unitless).")
    material: str = Field("wood_panel", description="Material of every face of the object.")
    label: str = Field("furniture", description="Semantic label (mpcat40 category).")


ObstacleSpec = Annotated[
    BoxObstacleSpec | CylinderObstacleSpec | MeshObstacleSpec, Field(discriminator="kind")
]


class _SceneBase(SpecModel):
    id: Identifier = Field(description="Unique scene id; splits refer to scenes by it.")


class _ProceduralBase(_SceneBase):
    materials: SurfaceMaterialsSpec = Field(
        default_factory=SurfaceMaterialsSpec, description="Boundary materials."
    )
    obstacles: list[ObstacleSpec] = Field(
        default_factory=list, description="Objects placed in the room, each with its own material."
    )

    def floor_polygon(self) -> list[tuple[float, float]]:
        """The room's floor outline (x, y), metres: every room kind below defines its own."""
        raise TypeError(f"{type(self).__name__} must define its floor outline")

    @model_validator(mode="after")
    def _floor_area_bounded(self) -> _ProceduralBase:
        xs, ys = zip(*self.floor_polygon(), strict=True)
        dx, dy = max(xs) - min(xs), max(ys) - min(ys)
        if dx * dy > MAX_FLOOR_AREA_M2:
            raise PydanticCustomError(
                "floor_area",
                "expected at most {limit} m² of floor plan, e.g. 100 m x 100 m (got a {dx} m x "
                "{dy} m bounding box, {area} m²); the walkable-area grid has a cell every 5 cm "
                "and its memory grows with the area (4.9 GB for 100 m x 100 m)",
                {"limit": f"{MAX_FLOOR_AREA_M2:,.0f}", "dx": f"{dx:g}", "dy": f"{dy:g}",
                 "area": f"{dx * dy:,.0f}"},
            )
        return self


class ShoeboxSceneSpec(_ProceduralBase):
    """A rectangular room occupying [0, size] along x, y and z (z up)."""

    kind: Literal["shoebox"] = Field(description="Scene type.")
    size_m: PositiveVec3 = Field(description=f"Length, width, height, metres; {_LIMIT}.")

    def floor_polygon(self) -> list[tuple[float, float]]:
        x, y, _ = self.size_m
        return [(0.0, 0.0), (x, 0.0), (x, y), (0.0, y)]

    def height(self) -> float:
        return self.size_m[2]


class CylinderSceneSpec(_ProceduralBase):
    """A round room centred on (radius, radius), floor at z = 0."""

    kind: Literal["cylinder"] = Field(description="Scene type.")
    radius_m: float = Field(
        gt=0, le=MAX_EXTENT_M / 2, description=f"Radius, metres (at most 500); {_LIMIT}."
    )
    height_m: float = Field(gt=0, le=MAX_EXTENT_M, description="Height, metres (at most 1000).")
    segments: int = Field(48, ge=8, le=1024, description="Facets approximating the circle.")

    def floor_polygon(self) -> list[tuple[float, float]]:
        import math

        r = self.radius_m
        return [
            (
                r + r * math.cos(2 * math.pi * k / self.segments),
                r + r * math.sin(2 * math.pi * k / self.segments),
            )
            for k in range(self.segments)
        ]

    def height(self) -> float:
        return self.height_m


class LShapeSceneSpec(_ProceduralBase):
    """An L-shaped room: the ``size_m`` box minus a ``cutout_m`` corner at its +x, +y end."""

    kind: Literal["l_shape"] = Field(description="Scene type.")
    size_m: PositiveVec3 = Field(description=f"Outer length, width, height, metres; {_LIMIT}.")
    cutout_m: PositiveVec2 = Field(
        description="Size along x and y of the corner removed at (+x, +y), metres; "
        "smaller than the outer size."
    )

    def floor_polygon(self) -> list[tuple[float, float]]:
        x, y, _ = self.size_m
        cx, cy = self.cutout_m
        return [(0.0, 0.0), (x, 0.0), (x, y - cy), (x - cx, y - cy), (x - cx, y), (0.0, y)]

    def height(self) -> float:
        return self.size_m[2]


class PolygonSceneSpec(_ProceduralBase):
    """A room whose floor plan is any simple polygon, extruded to a flat ceiling."""

    kind: Literal["polygon"] = Field(description="Scene type.")
    floor_m: list[Vec2] = Field(
        min_length=3,
        description=f"Floor-plan vertices [x, y] in order (either direction), metres; {_LIMIT}.",
    )
    height_m: float = Field(
        gt=0, le=MAX_EXTENT_M, description="Ceiling height, metres (at most 1000)."
    )

    def floor_polygon(self) -> list[tuple[float, float]]:
        return [tuple(p) for p in self.floor_m]

    def height(self) -> float:
        return self.height_m


class RepairSpec(SpecModel):
    """How a scanned mesh is repaired so that sound cannot leak through holes."""

    enabled: bool = Field(True, description="Run the repair steps at all.")
    merge_distance_m: float = Field(
        1e-3, ge=0, description="Vertices closer than this are merged, metres."
    )
    min_component_area_m2: float = Field(
        0.01,
        ge=0,
        description="Disconnected pieces with less total area are removed as debris, m².",
    )
    max_hole_size_m: float = Field(
        1.0,
        ge=0,
        description="Holes whose boundary fits in a box of this diagonal are closed, metres "
        "(0: none).",
    )
    orient: bool = Field(True, description="Re-orient faces so normals point into the air.")
    leak_test_rays: int = Field(
        10000,
        ge=0,
        description="Random rays from interior points used to measure leakage (0: skip).",
    )
    max_leak_fraction: float = Field(
        1e-4, ge=0, le=1, description="Largest acceptable fraction of rays escaping to infinity."
    )
    on_leak: Literal["error", "warn"] = Field(
        "error",
        description="What a scene that stays open (not watertight, or leaking more than "
        "max_leak_fraction) does: stop with an error, or warn and go on.",
    )


class MeshSceneSpec(_SceneBase):
    """Scenes from mesh files; a glob in ``path`` makes one scene per file, ``<id>/<stem>``."""

    kind: Literal["mesh"] = Field(description="Scene type.")
    path: str = Field(
        min_length=1,
        description="Mesh file or glob (glb, gltf, ply, obj), relative to the spec file.",
    )
    format: Literal["auto", "plain", "matterport"] = Field(
        "auto",
        description="'matterport' reads <id>_semantic.ply and <id>.house beside the glb for "
        "per-face categories; 'auto' does so when they exist.",
    )
    up_axis: Literal["auto", "y", "z"] = Field(
        "auto", description="Up axis of the file; 'auto' is y for glb/gltf and z otherwise."
    )
    unit: Literal["m", "cm", "mm", "in", "ft"] = Field("m", description="Length unit of the file.")
    weld_distance_m: float = Field(
        1e-4,
        ge=0,
        le=0.01,
        description="On load, vertices of open edges closer than this are joined across "
        "objects, groups and meshes, and T-junctions along those seams stitched (a file "
        "written one object per material loads as one surface), metres, after the unit "
        "conversion; 0 keeps the file's vertices.",
    )
    label_materials: dict[str, str] = Field(
        default_factory=dict,
        description="Semantic label -> material name, overriding the library's label rule.",
    )
    default_material: str | None = Field(
        None, description="Material of faces without a label (null: the library's default)."
    )
    obstacles: list[ObstacleSpec] = Field(
        default_factory=list, description="Objects added to the scan, each with its own material."
    )
    repair: RepairSpec = Field(default_factory=RepairSpec, description="Mesh repair options.")


SceneSpec = Annotated[
    ShoeboxSceneSpec | CylinderSceneSpec | LShapeSceneSpec | PolygonSceneSpec | MeshSceneSpec,
    Field(discriminator="kind"),
]
ProceduralSceneSpec = ShoeboxSceneSpec | CylinderSceneSpec | LShapeSceneSpec | PolygonSceneSpec

UNIT_SCALE_M = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}
