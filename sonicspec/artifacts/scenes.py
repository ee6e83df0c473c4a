"""Scenes as a spec declares them, built: procedural rooms with obstacles, or mesh files with
their label map, repaired and leak-tested (the mesh stage, ``scene inspect``, ``validate
--check-files`` and :meth:`sonicspec.Scene.from_spec` all build scenes here, below the
stages, so the Python API needs none of them)."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from sonicspec.artifacts.mesh_report import SceneReport
from sonicspec.errors import GeometryError, SonicspecWarning
from sonicspec.geometry import procedural as proc
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.plan.params import MeshParams, SceneParams
from sonicspec.spec.scene import (
    UNIT_SCALE_M,
    BoxObstacleSpec,
    CylinderObstacleSpec,
    CylinderSceneSpec,
    LShapeSceneSpec,
    MeshSceneSpec,
    ObstacleSpec,
    PolygonSceneSpec,
    ShoeboxSceneSpec,
)


def _room(scene: SceneParams) -> SceneMesh:
    m = scene.materials
    mats = {"wall_material": m.walls, "floor_material": m.floor, "ceiling_material": m.ceiling}
    if isinstance(scene, ShoeboxSceneSpec):
        return proc.shoebox(scene.size_m, **mats)
    if isinstance(scene, CylinderSceneSpec):
        return proc.cylinder(scene.radius_m, scene.height_m, scene.segments, **mats)
    if isinstance(scene, LShapeSceneSpec):
        return proc.l_shape(scene.size_m, scene.cutout_m, **mats)
    if isinstance(scene, PolygonSceneSpec):
        return proc.extruded_polygon(scene.floor_m, scene.height_m, **mats)
    raise GeometryError(f"scene kind: expected a procedural kind, got {scene.kind!r}")


def _obstacle(ob: ObstacleSpec, path: str | None) -> SceneMesh:
    if isinstance(ob, BoxObstacleSpec):
        return proc.box_obstacle(ob.center_m, ob.size_m, ob.yaw_deg, material=ob.material,
                                 label=ob.label)
    if isinstance(ob, CylinderObstacleSpec):
        return proc.cylinder_obstacle(ob.center_xy_m, ob.radius_m, ob.height_m, ob.base_z_m,
                                      material=ob.material, label=ob.label)
    from sonicspec.geometry.io import load_mesh

    return proc.mesh_obstacle(load_mesh(path), ob.position_m, ob.yaw_deg, ob.scale,
                              material=ob.material, label=ob.label)


def load_scan(scene: MeshSceneSpec, paths: dict[str, str], *, obj_labels: bool = False,
              weld: bool = True) -> SceneMesh:
    """The file of a ``mesh`` scene read as the mesh stage reads it (before materials and
    repair), its seams welded by ``scene.weld_distance_m`` unless ``weld`` is False;
    ``validate --check-files`` reads meshes through it too. ``obj_labels``: an obj file's
    lone object keeps its name and a file without objects is labelled by its groups
    (``geometry.io.load_mesh``; the plan sets it for obj scenes)."""
    from sonicspec.geometry.io import load_matterport, load_mesh

    scale = UNIT_SCALE_M[scene.unit]
    default = scene.default_material or "default"
    weld_m = scene.weld_distance_m if weld else 0.0
    if "semantic" in paths:
        up = "z" if scene.up_axis == "auto" else scene.up_axis
        return load_matterport(paths["mesh"], paths["semantic"], paths.get("house"),
                               up_axis=up, unit_scale=scale, material=default,
                               weld_distance_m=weld_m)
    return load_mesh(paths["mesh"], scene.up_axis, scale, material=default,
                     obj_labels=obj_labels, weld_distance_m=weld_m)


def build_scene_mesh(
    params: MeshParams, paths: dict[str, str], rng: np.random.Generator
) -> tuple[SceneMesh, SceneReport]:
    """The repaired scene mesh of a ``mesh`` job and a report of what was done."""
    from sonicspec.geometry.materials import assign_materials, load_library
    from sonicspec.geometry.repair import RepairSettings, leak_test, repair_mesh, weld_seams

    scene = params.scene
    scene_id = params.scene_id
    report: dict[str, Any] = {"scene_id": scene_id, "kind": scene.kind}
    obstacles = [_obstacle(ob, paths.get(f"obstacle{j}")) for j, ob in enumerate(scene.obstacles)]
    if not isinstance(scene, MeshSceneSpec):
        mesh = proc.add_obstacles(_room(scene), obstacles)
        report["repair"] = None
        return mesh, SceneReport.model_validate(report)

    # seams welded here rather than in the loader, so the report says what was joined
    mesh, weld = weld_seams(load_scan(scene, paths, obj_labels=params.obj_labels, weld=False),
                            scene.weld_distance_m)
    report["weld"] = weld.to_dict()
    mesh = assign_materials(mesh, load_library(params.library), params.label_materials or {},
                            scene.default_material, where=f"scene {scene_id!r}")
    repair = scene.repair
    if repair.enabled:
        settings = RepairSettings.from_spec(repair.model_dump())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SonicspecWarning)
            mesh, rep = repair_mesh(mesh, settings)
        report["repair"] = rep.to_dict()
        report["warnings"] = [str(w.message) for w in caught]
    if obstacles:
        mesh = proc.add_obstacles(mesh, obstacles)
    if repair.leak_test_rays > 0:
        leak = leak_test(mesh, rng, repair.leak_test_rays)
        report["leak"] = leak.to_dict()
        if leak.leak_fraction > repair.max_leak_fraction:
            message = (
                f"scene {scene_id!r}: {leak.leak_fraction:.2%} of {leak.rays} test rays "
                f"from the {leak.origins} air leave the mesh (allowed: "
                f"{repair.max_leak_fraction:.2%}): {leak.where()}; raise "
                "repair.max_hole_size_m or fix the scan there"
            )
            if repair.on_leak == "error":
                raise GeometryError(message)
            warnings.warn(message, SonicspecWarning, stacklevel=2)
            report.setdefault("warnings", []).append(message)
    return mesh, SceneReport.model_validate(report)
