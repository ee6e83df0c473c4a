"""Stage ``rir`` and ``sonicspec rir SPEC``: a spec's scene and settings into the RIR engine.

The engine (:mod:`sonicspec.acoustics.engine`) does the work: one trace from the microphone
serves every source position of a group (reciprocity), direct sound and image sources are
exact, each RIR is synthesised for the spec's receiver. This module reads the artifacts, calls
it, and writes the RIRs.
"""

from __future__ import annotations

import dataclasses
import logging
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from sonicspec import artifacts
from sonicspec.acoustics.directivity import SourceDirectivity, point_yaws_deg
from sonicspec.acoustics.engine import (
    RirFacts,
    RirResult,
    SimulationSettings,
    acoustic_scene,
    capsule_facts,
    check_inside,
    check_receiver,
    early_part,
    load_hrirs,
    needs_directions,
    refined_early_paths,
    rir_results,
    scene_edges,
    scene_regions,
    simulate_rirs,
    with_diffraction_focus,
)
from sonicspec.acoustics.late.tails import TailFacts
from sonicspec.acoustics.moving.delays import PathSet
from sonicspec.artifacts import (
    GroupPlacement,
    RirData,
    RirGroup,
    RirSource,
    speech_track_name,
)
from sonicspec.errors import SonicspecWarning, StageError
from sonicspec.geometry.materials import material_library
from sonicspec.plan.params import MaterialTable, RirParams
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.spec.microphone import SofaHrtfSpec
from sonicspec.stages.directivity import pair_yaws_deg, source_patterns, track_role
from sonicspec.stages.motion import Timeline, Walk, group_speech, timeline

log = logging.getLogger("sonicspec.stages.rir")


def spec_materials(materials: MaterialsSpec | MaterialTable):
    """The material library of a spec's ``materials`` section: custom ones added, every
    surface's scattering replaced where ``scattering_override`` says."""
    return material_library(materials.library,
                            {k: m.model_dump(mode="json") for k, m in materials.custom.items()},
                            materials.scattering_override)


@dataclass(frozen=True, eq=False)
class RirReport:
    """One RIR of ``sonicspec rir`` and what the command says about it: the engine's
    :class:`~sonicspec.acoustics.engine.RirResult` (its facts and figures), the scene, the
    warnings, and where the RIR and its plot were written. :meth:`to_dict` is what
    ``--json`` prints, :meth:`format` the text."""

    result: RirResult
    scene_id: str
    mesh_triangles: int
    warnings: tuple[str, ...] = ()
    materials_m2: dict[str, float] | None = None
    """Surface area of each material (a scene built through the Python API), m²."""
    output: str | None = None
    plot: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The facts, JSON-ready (``sonicspec rir --json``)."""
        out = {"scene_id": self.scene_id, **self.result.to_dict(),
               "mesh_triangles": self.mesh_triangles}
        if self.materials_m2 is not None:
            out["materials_m2"] = self.materials_m2
        out["warnings"] = list(self.warnings)
        if self.output is not None:
            out["output"] = self.output
        if self.plot is not None:
            out["plot"] = self.plot
        return out

    def format(self) -> str:
        """The facts as a short report for a terminal."""
        r = self.result
        fig = r.figures

        def num(v, fmt):
            return "—" if v is None or not np.isfinite(v) else format(v, fmt)

        def per_band(t30, edt, c50) -> list[str]:
            return [f"{label:>10} " + " ".join(num(v, fmt) for v in values)
                    for label, values, fmt in (("T30 (s)", t30, "7.3f"), ("EDT (s)", edt, "7.3f"),
                                               ("C50 (dB)", c50, "7.2f"))]

        samples = int(r.rir.shape[-1])
        channels = int(r.rir.shape[0])
        lines = [
            f"RIR in {self.scene_id}: source {list(r.source_m)} -> mic {list(r.mic_m)} "
            f"({r.distance_m:.2f} m), {channels} channel{'s' * (channels != 1)} x {samples} "
            f"samples at {r.sample_rate_hz} Hz, {r.arrivals} early arrivals (image sources to "
            f"order {r.image_source_order}), direct path {r.direct}",
            f"mesh: {self.mesh_triangles:,} triangles, traced as {r.traced_faces:,} "
            "(flat areas merged within acoustics.simplify_tolerance_m)",
            *_material_lines(self.materials_m2),
            f"{'band (Hz)':>10} " + " ".join(f"{b:>7g}" for b in fig.bands_hz),
            *per_band(fig.t30_s, fig.edt_s, fig.c50_db),
        ]
        if r.expected:  # the same fits on the energy the RIR was synthesised to have
            lines.append("expected (the energy it was synthesised to have, without the noise "
                         "draw):")
            lines += per_band(*(np.array(r.expected[k], dtype=float)  # None -> NaN
                                for k in ("t30_s", "edt_s", "c50_db")))
        broadband = fig.broadband
        lines += [
            _tail_line(r.tail, fig.bands_hz, samples / r.sample_rate_hz),
            f"broadband: T30 {num(broadband['t30_s'], '.3f')} s, EDT "
            f"{num(broadband['edt_s'], '.3f')} s, C50 {num(broadband['c50_db'], '.2f')}"
            f" dB, DRR {num(fig.drr_db, '.2f')} dB; escaped rays "
            f"{r.escaped_ray_fraction:.2e}",
        ]
        if self.output is not None:
            lines.append(f"written: {self.output}")
        if self.plot is not None:
            lines.append(f"plot: {self.plot}")
        return "\n".join(lines)


def rir_from_spec(loaded, scene_id: str, source_m, mic_m) -> RirReport:
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
    return RirReport(result, scene_id, mesh.n_faces, tuple(
        scene_warnings + [str(w.message) for w in caught
                          if issubclass(w.category, SonicspecWarning)]))


def _material_lines(areas: dict[str, float] | None) -> list[str]:
    """The materials of a scene and their share of its surface, on one line."""
    if not areas:
        return []
    total = sum(areas.values()) or 1.0
    return ["materials: " + ", ".join(f"{name} {area:.1f} m² ({100 * area / total:.0f} %)"
                                      for name, area in areas.items())]


def _tail_line(tail: TailFacts | None, bands_hz, length_s: float) -> str:
    """How the RIR's length was chosen, on one line."""
    if tail is None:
        return f"length: {length_s:.3f} s"
    rule = ("max_rir_length_s: auto, every band's decay 60 dB down" if tail.rule == "auto"
            else f"max_rir_length_s: {tail.limit_s:g}, every band's decay 60 dB down")
    line = f"length: {length_s:.3f} s ({rule}, at most {tail.limit_s:g} s)"
    continued = [f"{b:g} Hz from {t:.2f} s" for b, t in zip(bands_hz, tail.continued_from_s,
                                                           strict=True) if t is not None]
    if continued:
        line += "; rays ran out, decay fitted to its last 20 dB continued: " + ", ".join(
            continued)
    cut = [f"{b:g} Hz at {v:.0f} dB" for b, v in zip(bands_hz, tail.level_at_limit_db,
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


#: The closest a source may come to a moving microphone (the rir step refuses closer).
MIN_MOVING_GAP_M = 0.1


def _traces(sources: list[tuple[str, np.ndarray]], lines: list[Timeline | None], mic_m,
            yaw_deg: float
            ) -> tuple[list[tuple[np.ndarray, float, list[np.ndarray]]],
                       list[list[tuple[int, int]]]]:
    """Which traces a group needs: one per place and heading of the microphone, with the
    source positions heard there (each once), and for every source point the (trace,
    position) it is. A static microphone: one trace, every point in order."""
    traces: list[tuple[np.ndarray, float, list[np.ndarray]]] = []
    where: dict[tuple, int] = {}
    spots: dict[tuple, tuple[int, int]] = {}
    refs: list[list[tuple[int, int]]] = []
    for (_, pts), line in zip(sources, lines, strict=True):
        if line is None:
            mics, yaws, pts_ = np.repeat(np.asarray(mic_m)[None], len(pts), 0), \
                np.full(len(pts), yaw_deg), pts
        else:
            mics, yaws, pts_ = line.mic_m, line.yaw_deg, line.source_m
        ref = []
        for m, y, p in zip(mics, yaws, pts_, strict=True):
            key = (*np.asarray(m).tolist(), float(y))
            if key not in where:
                where[key] = len(traces)
                traces.append((np.asarray(m, dtype=np.float64), float(y), []))
            t = where[key]
            spot = (t, *np.asarray(p).tolist())
            if spot not in spots or line is None:  # a static microphone keeps every point
                spots[spot] = (t, len(traces[t][2]))
                traces[t][2].append(np.asarray(p, dtype=np.float64))
            ref.append(spots[spot])
        refs.append(ref)
    return traces, refs


def run(ctx) -> None:
    """Stage ``rir``: every source's RIRs along its path, for every group of a shard.

    A moving microphone: RIRs at the pairs of source and microphone positions of each
    source's timeline (:func:`sonicspec.stages.motion.timeline`), one trace per place and
    heading of the microphone."""
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
    regions = scene_regions(scene, settings)
    placements = artifacts.read(ctx, "placement").groups
    scene_name = f"scene {artifacts.decode('mesh', mesh_art.data, ctx.job.label).scene_id!r}"
    patterns = source_patterns(params.directivity, ctx.job.paths, settings.bands_hz)
    walk = arranged = None
    if params.walk is not None:
        walk = Walk(params.walk.speed_m_s, params.walk.walk_span, params.microphone)
        arranged = {a.group: a for a in artifacts.read(ctx, "arrange").groups}
    arrays: dict[str, np.ndarray] = {}
    groups = []
    for g, placement in enumerate(placements):
        sources = _source_points(placement)
        lines: list[Timeline | None] = [None] * len(sources)
        if walk is not None:
            check_inside(mesh.vertices, scene_name, **{
                f"microphone.trajectory point {j}": p for j, p in enumerate(placement.mic_path_m)})
            arr = arranged[placement.group]
            tracks = {t.name: t for t in arr.tracks}
            speech = group_speech(arr.tracks)
            lines = [timeline(placement.source(name), tracks[name].segment_list(), placement,
                              walk, speech, arr.clip_samples, params.sample_rate_hz)
                     for name, _ in sources]
            for (name, _), line in zip(sources, lines, strict=True):
                gap = np.linalg.norm(line.source_m - line.mic_m, axis=1)
                if gap.min() < MIN_MOVING_GAP_M:
                    at = float(np.interp(np.argmin(gap), line.index, np.arange(
                        len(line.index)))) / params.sample_rate_hz
                    raise StageError(
                        f"group {placement.group} {name}: the source comes within "
                        f"{gap.min():.2f} m of the moving microphone (at {at:.2f} s); expected "
                        f">= {MIN_MOVING_GAP_M} m (a point source model); move the "
                        "microphone's path (microphone.trajectory) or the sources' rules")
        traces, refs = _traces(sources, lines, placement.mic_m, params.microphone.yaw_deg)
        # a directional source: its pattern at every point, facing as the spec says
        point_dirs: list[list[SourceDirectivity | None]] = [[None] * len(p) for *_, p in traces]
        facings: list[np.ndarray | None] = []
        for (name, pts), line, ref in zip(sources, lines, refs, strict=True):
            role = track_role(name)
            if role not in patterns:
                facings.append(None)
                continue
            d = params.directivity.role(role)
            # a moving microphone: where the source faces at each pair's time
            yaws = (point_yaws_deg(pts, d.facing_rule, placement.mic_m) if line is None
                    else pair_yaws_deg(d, line, params.sample_rate_hz))
            facings.append(yaws)
            for (t, i), yaw in zip(ref, yaws, strict=True):
                point_dirs[t][i] = SourceDirectivity(patterns[role], float(yaw), d.pitch_deg)
        # one set of diffracting edges for the group: the most important for all of its
        # source and microphone positions
        group_settings, choice = settings, None
        if settings.diffraction:
            group_settings = with_diffraction_focus(
                settings, *[np.asarray(m) for m, _, _ in traces],
                *[np.asarray(p) for _, _, p in traces])
            choice = scene_edges(scene, settings.diffraction_max_edges,
                                 group_settings.diffraction_focus_m).choice()
            log.info("group %s: diffraction keeps %d of %d edges (%s; %d seam edges and %d "
                     "buried wedges left out)", placement.group, choice.kept,
                     choice.found, choice.rule, choice.seams_left_out,
                     choice.buried_left_out)
        rng = ctx.rng("rir", ctx.job.key, placement.group)
        results = []
        # A decay cut short by the longest RIR allowed is a warning in the job's log,
        # which the build summary collects.
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SonicspecWarning)
            for t, (mic_m, yaw, points) in enumerate(traces):
                def progress(done: int, total: int, g: int = g, n: int = len(points),
                             t: int = t, places: int = len(traces)) -> None:
                    where = f", microphone place {t + 1}/{places}" if places > 1 else ""
                    ctx.progress(f"group {g + 1}/{len(placements)}{where}: {n} points, "
                                 f"{done:,}/{total:,} rays")

                results.append(simulate_rirs(
                    scene, mic_m, np.asarray(points), group_settings, rng, regions,
                    {**microphone, "yaw_deg": yaw}, hrirs, progress=progress,
                    where=scene_name, keep_arrivals=params.early_paths,
                    directivity=point_dirs[t] if patterns else None))
        for w in caught:
            if issubclass(w.category, SonicspecWarning):
                if not str(w.message).startswith("image sources: order"):
                    log.warning("%s", w.message)  # the search's own: one line per group below
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        _warn_lower_order(scene_name, placement.group, settings.image_source_order,
                          [f for _, facts in results for f in facts])
        entries = []
        for s, ((name, _), line, ref) in enumerate(zip(sources, lines, refs, strict=True)):
            block = [results[t][0][i] for t, i in ref]
            facts = [results[t][1][i] for t, i in ref]
            yaws = [traces[t][1] for t, _ in ref]
            length = max(r.shape[-1] for r in block)
            stack = np.zeros((len(block), block[0].shape[0], length), dtype=np.float32)
            for i, r in enumerate(block):
                stack[i, :, :r.shape[-1]] = r
            key = f"g{g}_s{s}"
            arrays[key] = stack
            paths = None
            if params.early_paths:
                paths = f"{key}_paths"
                from_mic = [f.early_arrivals for f in facts]
                at_mic = [f.early_arrivals_at_mic for f in facts]
                directional = needs_directions(microphone)
                src_m = np.asarray(sources[s][1]) if line is None else line.source_m
                mic_m = (np.repeat(np.asarray(placement.mic_m)[None], len(src_m), 0)
                         if line is None else line.mic_m)
                # where a path appears or disappears between two points, points are added
                fine = refined_early_paths(
                    scene, group_settings, src_m, mic_m, from_mic, at_mic, regions=regions,
                    directional=directional,
                    image_source_order=facts[0].image_source_order)
                if line is None:
                    found = PathSet.identify(fine.sources_m, fine.from_mic,
                                             at_mic=fine.at_mic if directional else None)
                else:
                    found = PathSet.identify_moving(fine.sources_m, fine.mics_m, fine.from_mic)
                added = len(fine.at_index) > len(src_m)
                found = found.with_index(fine.at_index if added else None)
                if facings[s] is None:  # an omni source's paths: stored as before
                    found = dataclasses.replace(found, departures=None)
                arrays.update(artifacts.path_set_arrays(paths, found))
                late = stack.astype(np.float64)
                for i, early in enumerate(at_mic):  # each as long as its own RIR was made
                    n = block[i].shape[-1]
                    late[i, :, :n] -= early_part(early, settings, n,
                                                 {**microphone, "yaw_deg": yaws[i]}, hrirs)
                arrays[f"{paths}_late"] = late.astype(np.float32)
            first = room_acoustic_figures(block[0][0], settings.sample_rate_hz,
                                          settings.bands_hz)
            entries.append(RirSource(
                name=name, array=key, points=len(block),
                t30_s=_finite(first.broadband["t30_s"]), drr_db=_finite(first.drr_db),
                direct=facts[0].direct, tail=facts[0].tail,
                escaped_ray_fraction=facts[0].escaped_ray_fraction, paths=paths,
                facing_yaw_deg=None if facings[s] is None else [
                    round(float(y), 2) for y in facings[s]],
                **_order_reached(facts, settings.image_source_order)))
        groups.append(RirGroup(group=placement.group, sources=entries,
                               diffraction_edges=choice))
        cut = fixed_cut_warning([f for r in results for f in r[1]], settings.bands_hz,
                                f"{scene_name}, group {placement.group}")
        if cut:
            log.warning("%s", cut)
    ctx.write(arrays, artifacts.encode("rir", RirData(
        groups=groups, bands_hz=list(settings.bands_hz), sample_rate_hz=settings.sample_rate_hz,
        capsules=capsule_facts(microphone))))


def _order_reached(facts: list[RirFacts], asked: int) -> dict[str, Any]:
    """The image-source order a source's RIRs reached (the lowest over its points), the order
    asked and why it is lower: :class:`RirSource`'s fields."""
    low = min(facts, key=lambda f: f.image_source_order)
    return dict(image_source_order=low.image_source_order, image_source_order_asked=asked,
                image_source_order_stopped=low.image_source_order_stopped)


def _warn_lower_order(scene_name: str, group: str, asked: int,
                      facts: list[RirFacts]) -> None:
    """One warning line (the job's log, which the build summary collects) when the image-source
    search stopped below the asked order for some of a group's RIRs."""
    low = [f for f in facts if f.image_source_order < asked]
    if not low:
        return
    worst = min(low, key=lambda f: f.image_source_order)
    log.warning("%s, group %s: image-source order %d asked, %d reached in %d "
                "of %d RIRs (%s); the ray tracer covers the higher orders, less exactly; lower "
                "acoustics.image_source_order for this scene or simplify its mesh "
                "(acoustics.simplify_tolerance_m)", scene_name, group, asked,
                worst.image_source_order, len(low), len(facts),
                worst.image_source_order_stopped or "the candidate limit")


def fixed_cut_warning(facts: list[RirFacts], bands_hz, where: str) -> str | None:
    """The job log's warning for RIRs a fixed ``max_rir_length_s`` cut while still decaying
    (the library reports such a cut in the facts only: the length was asked for; ``auto``
    cuts warn there). A dataset of such RIRs understates its reverberation, so the build
    summary and the report say so (issue 28 item 8)."""
    tails = [f.tail for f in facts if f.tail.cut_at_limit]
    if not tails:
        return None
    worst = max(tails, key=lambda t: max(v for v in t.level_at_limit_db if v is not None))
    levels = ", ".join(f"{b:g} Hz at {v:.0f} dB" for b, v in
                       zip(bands_hz, worst.level_at_limit_db, strict=True) if v is not None)
    t60 = [v for t in tails for v in t.fitted_t60_s if v is not None]
    needs = f"; its decay needs about {max(t60):.1f} s" if t60 else ""
    return (f"{where}: {len(tails)} of {len(facts)} RIRs cut at {worst.limit_s:g} s "
            f"(acoustics.max_rir_length_s) while still decaying ({levels}, 60 dB down is the "
            f"end){needs}; T30 and the band figures understate it: raise "
            "acoustics.max_rir_length_s or set it to auto")


def _finite(value: float) -> float | None:
    """JSON has no NaN: a figure that could not be fitted is None."""
    return None if value is None or not np.isfinite(value) else float(value)
