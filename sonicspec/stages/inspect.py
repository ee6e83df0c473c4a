"""`sonicspec scene inspect`: one scene of a spec, built as the pipeline builds it, in numbers.

Runs the ``mesh`` and ``navigation`` stage code in process (no store, no Snakemake) and draws
one group's placement with the spec's rules, so what a person inspects is what a build uses.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel

from sonicspec.artifacts import GroupPlacement
from sonicspec.artifacts.mesh_report import LeakFacts, RepairFacts, WeldFacts
from sonicspec.artifacts.scenes import build_scene_mesh
from sonicspec.errors import CompileError, PlacementError, SonicspecWarning
from sonicspec.geometry.navigation import build_navigation
from sonicspec.hashing import rng_for
from sonicspec.plan.compile import FileDigests, expand_scenes, scene_jobs
from sonicspec.plan.params import PlacementParams, read_params
from sonicspec.spec.load import LoadedSpec, did_you_mean
from sonicspec.stages.navigation import settings_from as nav_settings
from sonicspec.stages.placement import place_group
from sonicspec.stages.placement import settings_from as placement_settings

if TYPE_CHECKING:
    from sonicspec.acoustics.paths.edges import EdgeChoice
    from sonicspec.geometry.navigation import WalkableGrid

def scene_ids(loaded: LoadedSpec) -> list[str]:
    return [e.id for e in expand_scenes(loaded.spec, loaded.base_dir.resolve())]


def build_scene(loaded: LoadedSpec, scene_id: str):
    """One scene's repaired mesh, the mesh stage's report, its jobs, and warnings raised."""
    spec = loaded.spec
    base = loaded.base_dir.resolve()
    entries = expand_scenes(spec, base)
    chosen = [e for e in entries if e.id == scene_id]
    if not chosen:
        ids = [e.id for e in entries]
        raise CompileError(f"--scene: expected one of {', '.join(ids)}, got {scene_id!r}"
                           + did_you_mean(scene_id, ids))
    ((_, mesh_job, nav_job),) = scene_jobs(spec, chosen, base, FileDigests())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        mesh, report = build_scene_mesh(read_params("mesh", mesh_job.params, mesh_job.label),
                                        dict(mesh_job.paths),
                                        rng_for(spec.seed, "mesh", mesh_job.key))
    return mesh, report, mesh_job, nav_job, [str(w.message) for w in caught]


@dataclass(frozen=True, eq=False)
class SceneFacts:
    """What ``sonicspec scene inspect`` says about one scene: the mesh and what its step did
    to it, the materials, the floors, the diffracting edges and a sampled placement.
    :meth:`to_dict` is what ``--json`` prints, :meth:`format` the text."""

    scene_id: str
    kind: str
    bounds_m: tuple[tuple[float, ...], tuple[float, ...]]
    vertices: int
    faces: int
    simplify_tolerance_m: float
    traced_faces: int
    diffraction_edges: EdgeChoice | None
    surface_area_m2: float
    air_volume_m3: float
    weld: WeldFacts | None
    """The mesh step's report of the seams welded on load."""
    repair: RepairFacts | None
    """Its repair report."""
    leak: LeakFacts | None
    """Its leak test."""
    warnings: tuple[str, ...]
    materials_m2: dict[str, float]
    labels: tuple[str, ...]
    floors: tuple[WalkableGrid, ...]
    """Each floor's walkable grid."""
    placement: GroupPlacement | None
    placement_error: str | None
    plot: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (``sonicspec scene inspect --json``)."""
        out = {
            "scene_id": self.scene_id, "kind": self.kind,
            "bounds_m": [list(self.bounds_m[0]), list(self.bounds_m[1])],
            "vertices": self.vertices, "faces": self.faces,
            "simplify_tolerance_m": self.simplify_tolerance_m,
            "traced_faces": self.traced_faces,
            "diffraction_edges": (None if self.diffraction_edges is None
                                  else self.diffraction_edges.to_dict()),
            "surface_area_m2": self.surface_area_m2, "air_volume_m3": self.air_volume_m3,
            "weld": _json(self.weld), "repair": _json(self.repair), "leak": _json(self.leak),
            "warnings": list(self.warnings), "materials_m2": self.materials_m2,
            "labels": list(self.labels), "floors": [g.to_dict() for g in self.floors],
            "placement": (None if self.placement is None
                          else self.placement.model_dump(mode="json")),
            "placement_error": self.placement_error,
        }
        if self.plot is not None:
            out["plot"] = self.plot
        return out

    def format(self) -> str:
        """The facts as a short report for a terminal."""
        return format_facts(self)


def inspect_scene(loaded: LoadedSpec, scene_id: str, *, plot: Path | None = None) -> SceneFacts:
    """Facts about one scene (bounds, repair, materials, floors, walkable area, a placement)."""
    from sonicspec.acoustics.engine import traced_geometry  # the acoustics stack: only when asked

    spec = loaded.spec
    mesh, report, _, nav_job, caught = build_scene(loaded, scene_id)
    nav = build_navigation(mesh, nav_settings(read_params("navigation", nav_job.params)))
    areas = mesh.face_areas
    by_material: dict[str, float] = {}
    for index, name in enumerate(mesh.materials):
        by_material[name] = float(areas[mesh.face_material == index].sum())
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    params = PlacementParams(
        groups=("inspect",), split="inspect", seed=spec.seed, scene_id=scene_id,
        placement=spec.placement, trajectory=spec.trajectory, microphone=spec.microphone,
        speakers=spec.mixture.speakers, noise=spec.corpora.noise is not None,
        music=spec.corpora.music is not None)
    placement: GroupPlacement | None = None
    placement_error = None
    try:
        placement = place_group(nav, placement_settings(params), params, "inspect",
                                rng_for(spec.seed, "inspect", scene_id))
    except PlacementError as exc:
        placement_error = str(exc)
    traced_vertices, traced_faces, _ = traced_geometry(mesh,
                                                       spec.acoustics.simplify_tolerance_m)
    edges = None
    if spec.acoustics.diffraction:
        edges = _edge_choice(traced_vertices, traced_faces, spec.acoustics.diffraction_max_edges,
                             placement)
    if plot is not None:
        from sonicspec.export.plots import plot_floor_plan

        plot_floor_plan(mesh, nav, placement, plot, title=f"{spec.name}: {scene_id}")
    return SceneFacts(
        scene_id=scene_id, kind=report.kind,
        bounds_m=(tuple(lo.tolist()), tuple(hi.tolist())),
        vertices=int(mesh.vertices.shape[0]), faces=int(mesh.faces.shape[0]),
        simplify_tolerance_m=spec.acoustics.simplify_tolerance_m,
        traced_faces=len(traced_faces), diffraction_edges=edges,
        surface_area_m2=float(areas.sum()), air_volume_m3=float(mesh.air_volume()),
        weld=report.weld, repair=report.repair, leak=report.leak,
        warnings=tuple(caught + report.warnings),
        materials_m2=dict(sorted(by_material.items(), key=lambda kv: -kv[1])),
        labels=tuple(mesh.labels), floors=tuple(nav.grids),
        placement=placement, placement_error=placement_error,
        plot=None if plot is None else str(plot))


def _edge_choice(vertices: np.ndarray, faces: np.ndarray, max_edges: int,
                 placement: GroupPlacement | None) -> EdgeChoice:
    """The diffracting edges a group's RIRs would use (for the sampled group's microphone and
    RIR points, else by length and exposure), as the RIR facts report them."""
    from sonicspec.acoustics.paths.edges import diffracting_edges

    near = None
    if placement is not None:
        sources = [*placement.speech, placement.noise, placement.music]
        near = np.array([*placement.mic_path_m, *(p for s in sources if s is not None
                                                  for p in s.rir_points_m)], dtype=np.float64)
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                     vertices[faces[:, 2]] - vertices[faces[:, 0]])
    normals = cross / np.maximum(np.linalg.norm(cross, axis=1, keepdims=True), 1e-300)
    return diffracting_edges(vertices, faces, normals, max_edges=max_edges,
                             near_m=near).choice()


def _json(facts: BaseModel | None) -> dict[str, Any] | None:
    return None if facts is None else facts.model_dump(mode="json")


def format_facts(facts: SceneFacts) -> str:
    """The facts as a short report for a terminal."""
    lo, hi = facts.bounds_m
    size = np.subtract(hi, lo)
    lines = [
        f"scene {facts.scene_id} ({facts.kind}): {facts.faces} faces, "
        f"{facts.vertices} vertices; the rir stage traces {facts.traced_faces} "
        f"(acoustics.simplify_tolerance_m {facts.simplify_tolerance_m:g} m)",
        f"bounds [{', '.join(f'{v:.2f}' for v in lo)}] .. [{', '.join(f'{v:.2f}' for v in hi)}]"
        f" m (size {' x '.join(f'{v:.2f}' for v in size)} m)",
        f"surface {facts.surface_area_m2:.1f} m², air volume {facts.air_volume_m3:.1f} m³",
    ]
    weld = facts.weld
    if weld is not None:
        lines.append(
            f"seams welded on load (weld_distance_m {weld.distance_m:g} m): "
            f"{weld.merged_vertices} vertices joined, {weld.t_junctions_stitched} "
            f"T-junctions stitched; open edges {weld.open_edges_before} -> "
            f"{weld.open_edges_after}")
    rep = facts.repair
    if rep is not None:
        lines.append(
            f"repair: faces {rep.before.faces} -> {rep.after.faces}, merged "
            f"{rep.merged_vertices} vertices, closed {rep.holes_closed}/{rep.holes_found}"
            f" holes, removed {rep.debris_components_removed} debris pieces; watertight "
            f"{'yes' if rep.watertight else 'NO'}")
    leak = facts.leak
    if leak is not None:
        where = "; ".join(p.describe() for p in leak.places[:3])
        lines.append(f"leak test: {leak.fraction:.4%} of {leak.rays} rays from the "
                     f"{leak.origins} air escape" + (f": {where}" if where else ""))
    edges = facts.diffraction_edges
    if edges is not None:
        lines.append(f"diffraction: {edges.kept} of {edges.found} edges kept "
                     f"({edges.rule}); {edges.seams_left_out} open edges left out as seams")
    lines.append("materials (area):")
    total = sum(facts.materials_m2.values()) or 1.0
    for name, area in facts.materials_m2.items():
        lines.append(f"  {name:<28} {area:9.1f} m²  {100 * area / total:5.1f} %")
    for g in facts.floors:
        lines.append(f"floor {g.floor.index} at z = {g.floor.z_m:.2f} m: walkable "
                     f"{g.area_m2:.1f} m² in {len(g.component_areas_m2())} component(s)")
    p = facts.placement
    if p is not None:
        lines.append(f"sampled group: mic at [{', '.join(f'{v:.2f}' for v in p.mic_m)}], "
                     + ", ".join(f"speaker {i + 1} walks {s.path_length_m:.2f} m "
                                 f"({len(s.rir_points_m)} RIR points)"
                                 for i, s in enumerate(p.speech)))
    else:
        lines.append(f"placement impossible: {facts.placement_error}")
    for w in facts.warnings:
        lines.append(f"warning: {w}")
    if facts.plot is not None:
        lines.append(f"floor plan: {facts.plot}")
    return "\n".join(lines)


def image_source_outlook(loaded: LoadedSpec, plan, *, estimate: int = 3) -> list[dict[str, Any]]:
    """Per scene of ``plan``: the image-source order asked and what the build reached or will.

    Where the store holds the scene's RIR artifacts, the order they reached (the lowest over
    every source's points, as the rir facts record it) and why it is lower; otherwise, for the
    first ``estimate`` such scenes, an estimate: the scene built as the mesh step builds it,
    simplified and merged into mirrors as the rir step does, one group's placement drawn with
    the spec's rules, and the image-source search from its microphone to one talker's RIR
    points — the candidates per order against the cap. The rest are listed, not estimated."""
    from sonicspec.acoustics.paths.image_sources import MAX_CANDIDATES
    from sonicspec.artifacts import decode
    from sonicspec.store import ArtifactStore

    store = ArtifactStore(plan.store_dir)
    asked = loaded.spec.acoustics.image_source_order
    scene_of = {j.key: read_params("mesh", j.params, j.label).scene_id
                for j in plan.jobs if j.step == "mesh"}
    scenes: dict[str, dict[str, Any]] = {}
    for job in plan.jobs:
        if job.step != "rir":
            continue
        sid = next((scene_of[k] for k in job.inputs if k in scene_of), "?")
        entry = scenes.setdefault(sid, {"scene_id": sid, "asked": asked, "rir_jobs": 0,
                                        "built": 0, "sources": 0, "lower": 0, "reached": None,
                                        "stopped": None, "estimate": None})
        entry["rir_jobs"] += 1
        if not store.exists("rir", job.key):
            continue
        entry["built"] += 1
        for group in decode("rir", store.read_data("rir", job.key)).groups:
            for source in group.sources:
                if source.image_source_order is None:  # written before it was recorded
                    continue
                entry["sources"] += 1
                entry["lower"] += source.image_source_order < asked
                if entry["reached"] is None or source.image_source_order < entry["reached"]:
                    entry["reached"] = source.image_source_order
                    entry["stopped"] = source.image_source_order_stopped
    left = estimate
    for entry in scenes.values():
        if entry["built"] or entry["scene_id"] == "?" or asked == 0:
            continue
        if left <= 0:
            entry["estimate"] = {"skipped": True}
            continue
        left -= 1
        entry["estimate"] = estimate_image_source_order(loaded, entry["scene_id"])
        entry["estimate"]["cap"] = MAX_CANDIDATES
    return list(scenes.values())


def estimate_image_source_order(loaded: LoadedSpec, scene_id: str) -> dict[str, Any]:
    """The image-source search of one drawn group of ``scene_id`` (see
    :func:`image_source_outlook`): order reached, why lower, candidates per order."""
    from sonicspec.acoustics.engine import SimulationSettings, acoustic_scene, scene_regions
    from sonicspec.acoustics.paths.image_sources import image_sources
    from sonicspec.geometry.materials import material_library

    spec = loaded.spec
    mesh, _, _, nav_job, _ = build_scene(loaded, scene_id)
    nav = build_navigation(mesh, nav_settings(read_params("navigation", nav_job.params)))
    params = PlacementParams(
        groups=("inspect",), split="inspect", seed=spec.seed, scene_id=scene_id,
        placement=spec.placement, trajectory=spec.trajectory, microphone=spec.microphone,
        speakers=spec.mixture.speakers, noise=spec.corpora.noise is not None,
        music=spec.corpora.music is not None)
    try:
        placement = place_group(nav, placement_settings(params), params, "inspect",
                                rng_for(spec.seed, "inspect", scene_id))
    except PlacementError as exc:
        return {"error": f"no group could be placed: {exc}"}
    settings = SimulationSettings.from_spec(spec.acoustics.model_dump(mode="json"),
                                            spec.sample_rate_hz, spec.speed_of_sound_m_s)
    library = material_library(spec.materials.library,
                               spec.materials.model_dump(mode="json")["custom"])
    scene = acoustic_scene(mesh, library, settings)
    regions = scene_regions(scene, settings)
    mic = np.asarray(placement.mic_path_m[0], dtype=np.float64)
    points = np.asarray(placement.speech[0].rir_points_m, dtype=np.float64)
    c = settings.speed_of_sound_m_s
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SonicspecWarning)
        found = image_sources(scene, mic, points, settings.image_source_order, settings.air(),
                              c, regions, max_path_length_m=c * settings.rir_limit_s)
    return {"reached": found.max_order, "stopped": found.stopped,
            "candidates": list(found.candidates), "mirrors": regions.n_regions,
            "traced_faces": scene.n_faces, "points": len(points)}


def format_outlook(scenes: list[dict[str, Any]]) -> list[str]:
    """:func:`image_source_outlook` as lines for a terminal."""
    if not scenes:
        return []
    lines = [f"image-source order (acoustics.image_source_order {scenes[0]['asked']}), per "
             "scene:"]
    skipped = [e for e in scenes if (e["estimate"] or {}).get("skipped")]
    for e in scenes:
        if e in skipped:
            continue
        head = f"  {e['scene_id']}: "
        if e["built"]:
            why = f" ({e['stopped']})" if e["stopped"] else ""
            part = (f"; {e['built']} of {e['rir_jobs']} rir jobs built"
                    if e["built"] < e["rir_jobs"] else "")
            if e["reached"] is None:
                lines.append(head + "built before the order was recorded" + part)
            elif e["lower"]:
                lines.append(head + f"order {e['reached']} reached{why} for {e['lower']} of "
                             f"{e['sources']} sources' RIRs; the ray tracer covers the higher "
                             f"orders, less exactly{part}")
            else:
                lines.append(head + f"order {e['reached']} reached by all {e['sources']} "
                             f"sources' RIRs{part}")
            continue
        est = e["estimate"]
        if est is None:
            lines.append(head + "no RIRs asked")
        elif "error" in est:
            lines.append(head + f"not built yet, not estimated: {est['error']}")
        else:
            counts = " / ".join(f"{n:,}" for n in est["candidates"]) or "none"
            peak = max(est["candidates"], default=0)
            verdict = (f"the cap cuts it to order {est['reached']} ({est['stopped']})"
                       if est["stopped"] else
                       "near the cap: other positions may be cut" if peak > est["cap"] // 2
                       else "well under the cap")
            lines.append(head + f"not built yet; estimate from one drawn group "
                         f"({est['points']} RIR points, {est['traced_faces']:,} traced "
                         f"triangles in {est['mirrors']:,} mirrors): order {est['reached']}, "
                         f"candidates per order {counts} against the cap of {est['cap']:,}: "
                         f"{verdict}")
    if skipped:
        lines.append(f"  {len(skipped)} more scene{'s' * (len(skipped) > 1)} not built yet, "
                     "not estimated (sonicspec plan --summary --estimate-scenes N)")
    return lines
