"""Stage ``mesh``: build a procedural room or import a scan, add obstacles, repair, leak-test."""

from __future__ import annotations

import logging
import warnings
from typing import Any

import numpy as np

from sonicspec.errors import GeometryError, SonicspecWarning
from sonicspec.geometry import procedural as proc
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.stages.context import JobContext

log = logging.getLogger("sonicspec.stages.mesh")

UNIT_SCALE_M = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}


def _room(scene: dict[str, Any]) -> SceneMesh:
    m = scene["materials"]
    mats = {
        "wall_material": m["walls"],
        "floor_material": m["floor"],
        "ceiling_material": m["ceiling"],
    }
    kind = scene["kind"]
    if kind == "shoebox":
        return proc.shoebox(scene["size_m"], **mats)
    if kind == "cylinder":
        return proc.cylinder(scene["radius_m"], scene["height_m"], scene["segments"], **mats)
    if kind == "l_shape":
        return proc.l_shape(scene["size_m"], scene["cutout_m"], **mats)
    if kind == "polygon":
        return proc.extruded_polygon(scene["floor_m"], scene["height_m"], **mats)
    raise GeometryError(f"scene kind: expected a procedural kind, got {kind!r}")


def _obstacle(ob: dict[str, Any], path: str | None) -> SceneMesh:
    kind = ob["kind"]
    if kind == "box":
        return proc.box_obstacle(
            ob["center_m"], ob["size_m"], ob["yaw_deg"], material=ob["material"], label=ob["label"]
        )
    if kind == "cylinder":
        return proc.cylinder_obstacle(
            ob["center_xy_m"],
            ob["radius_m"],
            ob["height_m"],
            ob["base_z_m"],
            material=ob["material"],
            label=ob["label"],
        )
    from sonicspec.geometry.io import load_mesh

    return proc.mesh_obstacle(
        load_mesh(path),
        ob["position_m"],
        ob["yaw_deg"],
        ob["scale"],
        material=ob["material"],
        label=ob["label"],
    )


def load_scan(scene: dict[str, Any], paths: dict[str, str], *, obj_labels: bool = False
              ) -> SceneMesh:
    """The file of a ``mesh`` scene read as the mesh stage reads it (before materials and
    repair); ``validate --check-files`` reads meshes through it too. ``obj_labels``: an obj
    file's lone object keeps its name and a file without objects is labelled by its groups
    (``geometry.io.load_mesh``; the plan sets it for obj scenes)."""
    from sonicspec.geometry.io import load_matterport, load_mesh

    scale = UNIT_SCALE_M[scene["unit"]]
    default = scene["default_material"] or "default"
    if "semantic" in paths:
        up = "z" if scene["up_axis"] == "auto" else scene["up_axis"]
        return load_matterport(
            paths["mesh"],
            paths["semantic"],
            paths.get("house"),
            up_axis=up,
            unit_scale=scale,
            material=default,
        )
    return load_mesh(paths["mesh"], scene["up_axis"], scale, material=default,
                     obj_labels=obj_labels)


def build_scene_mesh(
    params: dict[str, Any], paths: dict[str, str], rng: np.random.Generator
) -> tuple[SceneMesh, dict[str, Any]]:
    """The repaired scene mesh of a ``mesh`` job and a report of what was done."""
    from sonicspec.geometry.materials import assign_materials, load_library
    from sonicspec.geometry.repair import RepairSettings, leak_test, repair_mesh

    scene = params["scene"]
    scene_id = params["scene_id"]
    report: dict[str, Any] = {"scene_id": scene_id, "kind": scene["kind"]}
    obstacles = [
        _obstacle(ob, paths.get(f"obstacle{j}")) for j, ob in enumerate(scene["obstacles"])
    ]
    if scene["kind"] != "mesh":
        mesh = proc.add_obstacles(_room(scene), obstacles)
        report["repair"] = None
        return mesh, report

    mesh = load_scan(scene, paths, obj_labels=params.get("obj_labels", False))
    mesh = assign_materials(mesh, load_library(params["library"]), params["label_materials"],
                            scene["default_material"], where=f"scene {scene_id!r}")
    repair = scene["repair"]
    if repair["enabled"]:
        settings = RepairSettings.from_spec(repair)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SonicspecWarning)
            mesh, rep = repair_mesh(mesh, settings)
        report["repair"] = rep.to_dict()
        report["warnings"] = [str(w.message) for w in caught]
    if obstacles:
        mesh = proc.add_obstacles(mesh, obstacles)
    if repair["leak_test_rays"] > 0:
        leak = leak_test(mesh, rng, repair["leak_test_rays"])
        report["leak"] = {
            "rays": leak.rays,
            "escaped": leak.escaped,
            "backface": leak.backface,
            "fraction": leak.leak_fraction,
        }
        if leak.leak_fraction > repair["max_leak_fraction"]:
            message = (
                f"scene {scene_id!r}: {leak.leak_fraction:.2%} of {leak.rays} test rays "
                f"leave the mesh (allowed: {repair['max_leak_fraction']:.2%}); raise "
                "repair.max_hole_size_m or fix the scan"
            )
            if repair["on_leak"] == "error":
                raise GeometryError(message)
            warnings.warn(message, SonicspecWarning, stacklevel=2)
            report.setdefault("warnings", []).append(message)
    return mesh, report


def run(ctx: JobContext) -> None:
    # Warnings raised while the mesh is built (faces that fell back to the library's default
    # material) go to the job's log as WARNING lines, which the build summary collects.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        mesh, report = build_scene_mesh(ctx.params, dict(ctx.job.paths),
                                        ctx.rng("mesh", ctx.job.key))
    for w in caught:
        if issubclass(w.category, SonicspecWarning):
            log.warning("%s", w.message)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    arrays = {"vertices": mesh.vertices, "faces": mesh.faces, "face_material": mesh.face_material}
    if mesh.face_label is not None:
        arrays["face_label"] = mesh.face_label
    if mesh.face_object is not None:
        arrays["face_object"] = mesh.face_object
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    report.update(
        materials=list(mesh.materials),
        labels=list(mesh.labels),
        bounds_m=[lo.tolist(), hi.tolist()],
        faces=int(mesh.faces.shape[0]),
    )
    ctx.write(arrays, report)


def load_scene_mesh(arrays: dict[str, np.ndarray], data: dict[str, Any]) -> SceneMesh:
    """The :class:`SceneMesh` stored by :func:`run`."""
    return SceneMesh(
        vertices=arrays["vertices"],
        faces=arrays["faces"],
        face_material=arrays["face_material"],
        materials=tuple(data["materials"]),
        face_label=arrays.get("face_label"),
        labels=tuple(data["labels"]),
        face_object=arrays.get("face_object"),
    )
