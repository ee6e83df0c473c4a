"""Stage ``rir`` and ``sonicspec rir SPEC``: a spec's scene and settings into the RIR engine.

The engine (:mod:`sonicspec.acoustics.engine`) does the work: one trace from the microphone
serves every source position of a group (reciprocity), direct sound and image sources are
exact, each RIR is synthesised for the spec's receiver. This module reads the artifacts, calls
it, and writes the RIRs.
"""

from __future__ import annotations

import logging
import warnings
from typing import Any

import numpy as np

from sonicspec.acoustics.engine import (
    SimulationSettings,
    acoustic_scene,
    check_inside,
    check_receiver,
    early_part,
    load_hrirs,
    rir_results,
    simulate_rirs,
)
from sonicspec.acoustics.image_sources import planar_regions
from sonicspec.acoustics.moving import PathSet
from sonicspec.errors import SonicspecWarning
from sonicspec.geometry.materials import material_library
from sonicspec.plan.params import MaterialTable, RirParams
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.spec.microphone import SofaHrtfSpec
from sonicspec.stages import artifacts
from sonicspec.stages.artifacts import (
    GroupPlacement,
    RirData,
    RirGroup,
    RirSource,
    speech_track_name,
)

log = logging.getLogger("sonicspec.stages.rir")


def spec_materials(materials: MaterialsSpec | MaterialTable):
    """The material library of a spec's ``materials`` section, custom ones added."""
    return material_library(materials.library, materials.model_dump(mode="json")["custom"])


def rir_from_spec(loaded, scene_id: str, source_m, mic_m) -> tuple[np.ndarray, dict[str, Any]]:
    """One RIR in a spec's scene (``sonicspec rir``), and the facts to report with it."""
    from sonicspec.hashing import rng_for
    from sonicspec.stages.inspect import build_scene

    spec = loaded.spec
    microphone = spec.microphone.model_dump(mode="json")
    hrtf = getattr(spec.microphone, "hrtf", None)
    hrirs = load_hrirs(loaded.base_dir / hrtf.path) if isinstance(hrtf, SofaHrtfSpec) else None
    check_receiver(microphone, hrirs)
    mesh, _, mesh_job, _, scene_warnings = build_scene(loaded, scene_id)
    check_inside(mesh.vertices, f"scene {scene_id!r}", **{"--source": source_m, "--mic": mic_m})
    settings = SimulationSettings.from_spec(spec.acoustics.model_dump(mode="json"),
                                            spec.sample_rate_hz, spec.speed_of_sound_m_s)
    scene = acoustic_scene(mesh, spec_materials(spec.materials), settings)
    rng = rng_for(spec.seed, "rir-cli", mesh_job.key, repr(list(source_m)), repr(list(mic_m)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        (result,) = rir_results(scene, np.asarray(mic_m), np.asarray([source_m]), settings,
                                rng, microphone=microphone, hrirs=hrirs,
                                where=f"scene {scene_id!r}")
    for w in caught:
        if not issubclass(w.category, SonicspecWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    facts = {"scene_id": scene_id, **result.to_dict(), "mesh_triangles": mesh.n_faces,
             "warnings": scene_warnings + [str(w.message) for w in caught
                                           if issubclass(w.category, SonicspecWarning)]}
    return result.rir, facts


def _material_lines(areas: dict[str, float] | None) -> list[str]:
    """The materials of a scene and their share of its surface, on one line."""
    if not areas:
        return []
    total = sum(areas.values()) or 1.0
    return ["materials: " + ", ".join(f"{name} {area:.1f} m² ({100 * area / total:.0f} %)"
                                      for name, area in areas.items())]


def format_rir_facts(facts: dict[str, Any]) -> str:
    fig = facts["figures"]

    def num(v, fmt):
        return "—" if v is None else format(v, fmt)

    def per_band(figures: dict[str, Any]) -> list[str]:
        return [f"{label:>10} " + " ".join(num(v, fmt) for v in figures[key])
                for label, key, fmt in (("T30 (s)", "t30_s", "7.3f"), ("EDT (s)", "edt_s", "7.3f"),
                                        ("C50 (dB)", "c50_db", "7.2f"))]

    lines = [
        f"RIR in {facts['scene_id']}: source {facts['source_m']} -> mic {facts['mic_m']} "
        f"({facts['distance_m']:.2f} m), {facts['channels']} channel"
        f"{'s' * (facts['channels'] != 1)} x {facts['samples']} samples at "
        f"{facts['sample_rate_hz']} Hz, {facts['arrivals']} early arrivals (image sources to "
        f"order {facts['image_source_order']}), direct path {facts['direct']}",
        f"mesh: {facts['mesh_triangles']:,} triangles, traced as {facts['traced_triangles']:,} "
        "(flat areas merged within acoustics.simplify_tolerance_m)",
        *_material_lines(facts.get("materials_m2")),
        f"{'band (Hz)':>10} " + " ".join(f"{b:>7g}" for b in fig["bands_hz"]),
        *per_band(fig),
    ]
    if "expected" in facts:  # the same fits on the energy the RIR was synthesised to have
        lines.append("expected (the energy it was synthesised to have, without the noise draw):")
        lines += per_band(facts["expected"])
    lines += [
        _tail_line(facts),
        f"broadband: T30 {num(fig['broadband']['t30_s'], '.3f')} s, EDT "
        f"{num(fig['broadband']['edt_s'], '.3f')} s, C50 {num(fig['broadband']['c50_db'], '.2f')}"
        f" dB, DRR {num(fig['drr_db'], '.2f')} dB; escaped rays "
        f"{facts['escaped_ray_fraction']:.2e}",
    ]
    if "output" in facts:
        lines.append(f"written: {facts['output']}")
    if "plot" in facts:
        lines.append(f"plot: {facts['plot']}")
    return "\n".join(lines)


def _tail_line(facts: dict[str, Any]) -> str:
    """How the RIR's length was chosen, on one line."""
    tail = facts["tail"]
    bands = facts["figures"]["bands_hz"]
    rule = ("max_rir_length_s: auto, every band's decay 60 dB down" if tail["rule"] == "auto"
            else f"max_rir_length_s: {tail['limit_s']:g}, every band's decay 60 dB down")
    line = (f"length: {facts['samples'] / facts['sample_rate_hz']:.3f} s ({rule}, at most "
            f"{tail['limit_s']:g} s)")
    continued = [f"{b:g} Hz from {t:.2f} s" for b, t in zip(bands, tail["continued_from_s"],
                                                           strict=True) if t is not None]
    if continued:
        line += "; rays ran out, decay fitted to its last 20 dB continued: " + ", ".join(
            continued)
    cut = [f"{b:g} Hz at {v:.0f} dB" for b, v in zip(bands, tail["level_at_limit_db"],
                                                   strict=True) if v is not None]
    if cut:
        line += "; cut at the limit: " + ", ".join(cut)
    return line


def _source_points(placement: GroupPlacement) -> list[tuple[str, np.ndarray]]:
    """(track name, RIR points) of every source of a group: speech, then noise and music."""
    out = [(speech_track_name(k), np.asarray(s.rir_points_m, dtype=np.float64))
           for k, s in enumerate(placement.speech)]
    for kind in ("noise", "music"):
        source = getattr(placement, kind)
        if source is not None:
            out.append((kind, np.asarray(source.rir_points_m, dtype=np.float64)))
    return out


def run(ctx) -> None:
    """Stage ``rir``: every source's RIRs along its path, for every group of a shard."""
    from sonicspec.acoustics.metrics import room_acoustic_figures

    params: RirParams = ctx.params
    microphone = params.microphone.model_dump(mode="json")
    hrirs = load_hrirs(ctx.job.paths["hrtf"]) if "hrtf" in ctx.job.paths else None
    check_receiver(microphone, hrirs)
    mesh_art = ctx.input("mesh")
    mesh = artifacts.read_mesh(mesh_art.arrays, mesh_art.data)
    settings = SimulationSettings.from_spec(params.acoustics.model_dump(mode="json"),
                                            params.sample_rate_hz, params.speed_of_sound_m_s)
    scene = acoustic_scene(mesh, spec_materials(params.materials), settings)
    regions = planar_regions(scene)
    placements = artifacts.read(ctx, "placement").groups
    arrays: dict[str, np.ndarray] = {}
    groups = []
    for g, placement in enumerate(placements):
        sources = _source_points(placement)
        points = np.concatenate([p for _, p in sources])
        rng = ctx.rng("rir", ctx.job.key, placement.group)

        def progress(done: int, total: int, g: int = g, n: int = len(points)) -> None:
            ctx.progress(f"group {g + 1}/{len(placements)}: {n} points, "
                         f"{done:,}/{total:,} rays")

        # A decay cut short by the longest RIR allowed is a warning in the job's log,
        # which the build summary collects.
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SonicspecWarning)
            rirs, facts = simulate_rirs(
                scene, np.asarray(placement.mic_m), points, settings, rng, regions, microphone,
                hrirs, progress=progress, where=f"scene {mesh_art.data.get('scene_id', '?')!r}",
                keep_arrivals=params.early_paths)
        for w in caught:
            if issubclass(w.category, SonicspecWarning):
                log.warning("%s", w.message)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        entries, start = [], 0
        for s, (name, pts) in enumerate(sources):
            block = rirs[start:start + len(pts)]
            length = max(r.shape[-1] for r in block)
            stack = np.zeros((len(block), block[0].shape[0], length), dtype=np.float32)
            for i, r in enumerate(block):
                stack[i, :, :r.shape[-1]] = r
            key = f"g{g}_s{s}"
            arrays[key] = stack
            paths = None
            if params.early_paths:
                paths = f"{key}_paths"
                facts_s = facts[start:start + len(pts)]
                from_mic = [f["early_arrivals"] for f in facts_s]
                at_mic = [f["early_arrivals_at_mic"] for f in facts_s]
                directional = microphone["kind"] != "mono"
                arrays.update(artifacts.path_set_arrays(paths, PathSet.identify(
                    pts, from_mic, at_mic=at_mic if directional else None)))
                late = stack.astype(np.float64)
                for i, early in enumerate(at_mic):  # each as long as its own RIR was made
                    n = block[i].shape[-1]
                    late[i, :, :n] -= early_part(early, settings, n, microphone)
                arrays[f"{paths}_late"] = late.astype(np.float32)
            first = room_acoustic_figures(block[0][0], settings.sample_rate_hz,
                                          settings.bands_hz)
            entries.append(RirSource(
                name=name, array=key, points=len(pts),
                t30_s=_finite(first.broadband["t30_s"]), drr_db=_finite(first.drr_db),
                direct=facts[start]["direct"], tail=facts[start]["tail"],
                escaped_ray_fraction=facts[start]["escaped_ray_fraction"], paths=paths))
            start += len(pts)
        groups.append(RirGroup(group=placement.group, sources=entries))
    ctx.write(arrays, artifacts.encode("rir", RirData(
        groups=groups, bands_hz=list(settings.bands_hz), sample_rate_hz=settings.sample_rate_hz)))


def _finite(value: float) -> float | None:
    """JSON has no NaN: a figure that could not be fitted is None."""
    return None if value is None or not np.isfinite(value) else float(value)
