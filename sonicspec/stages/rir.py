"""From a scene and the spec's acoustics settings to RIRs: the glue over the tracer libraries.

For one microphone and many source positions (a trajectory), the ray tracer runs once, from
the microphone, with every position as a receiver (reciprocity: the RIR from A to B equals the
RIR from B to A for omnidirectional ends). Direct sound and image sources are exact and cheap,
so they are computed per position. Each position's RIR is then synthesised
(:mod:`sonicspec.acoustics.synthesis`).

Receivers: mono, linear/circular/custom arrays and ambisonics
(:mod:`sonicspec.acoustics.receivers`), and binaural through the rigid-sphere head or a
measured HRIR set read from a SOFA file (:mod:`sonicspec.acoustics.hrtf`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sonicspec.acoustics.air import air_energy_coefficient_per_m
from sonicspec.acoustics.arrivals import Arrivals
from sonicspec.acoustics.bands import default_bands
from sonicspec.acoustics.direct import direct_sound
from sonicspec.acoustics.image_sources import image_sources, planar_regions
from sonicspec.acoustics.metrics import figures_from_energy
from sonicspec.acoustics.raytrace import RayTraceSettings, trace_rays
from sonicspec.acoustics.scene import AcousticScene
from sonicspec.acoustics.simplify import simplify_flat_areas
from sonicspec.acoustics.synthesis import synthesize_rir
from sonicspec.errors import AcousticsError
from sonicspec.geometry.materials import custom_material, load_library
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.units import OCTAVE_BANDS_HZ

if TYPE_CHECKING:
    from sonicspec.acoustics.hrtf import HrirSet


@dataclass(frozen=True)
class RirSettings:
    """What the tracer needs from the spec (``acoustics``, sample rate, speed of sound)."""

    sample_rate_hz: int
    bands_hz: tuple[float, ...]
    rays: int
    image_source_order: int
    max_rir_length_s: float
    energy_threshold_db: float
    air_absorption: bool
    temperature_c: float
    relative_humidity_pct: float
    transmission: bool
    diffuse_rain: bool
    receiver_radius_m: float
    histogram_bin_s: float
    speed_of_sound_m_s: float
    ray_splitting: float = 0.0
    free_air_ball_m: float = 0.0
    roulette_db: float = 0.0
    horizontal_guiding: float = 0.0
    simplify_tolerance_m: float = 0.0

    @classmethod
    def from_spec(cls, acoustics: dict[str, Any], sample_rate_hz: int,
                  speed_of_sound_m_s: float) -> RirSettings:
        bands = acoustics["bands_hz"]
        bands = default_bands(sample_rate_hz) if bands == "auto" else tuple(
            float(b) for b in bands)
        return cls(sample_rate_hz=sample_rate_hz, bands_hz=bands, rays=acoustics["rays"],
                   image_source_order=acoustics["image_source_order"],
                   max_rir_length_s=acoustics["max_rir_length_s"],
                   energy_threshold_db=acoustics["energy_threshold_db"],
                   air_absorption=acoustics["air_absorption"],
                   temperature_c=acoustics["temperature_c"],
                   relative_humidity_pct=acoustics["relative_humidity_pct"],
                   transmission=acoustics["transmission"],
                   diffuse_rain=acoustics["detection"] == "diffuse_rain",
                   receiver_radius_m=acoustics["receiver_radius_m"],
                   ray_splitting=acoustics["ray_splitting"],
                   free_air_ball_m=acoustics["free_air_ball_m"],
                   roulette_db=acoustics["roulette_db"],
                   horizontal_guiding=acoustics["horizontal_guiding"],
                   simplify_tolerance_m=acoustics["simplify_tolerance_m"],
                   histogram_bin_s=acoustics["histogram_bin_s"],
                   speed_of_sound_m_s=speed_of_sound_m_s)

    def air(self) -> np.ndarray | None:
        if not self.air_absorption:
            return None
        return air_energy_coefficient_per_m(self.bands_hz, self.temperature_c,
                                            self.relative_humidity_pct)


def acoustic_scene(mesh: SceneMesh, materials: dict[str, Any], settings: RirSettings
                   ) -> AcousticScene:
    """The mesh with per-face coefficients from the library and the spec's own materials."""
    lib = load_library(materials["library"])
    custom = {
        name: custom_material(name, m["absorption"], m["scattering"], m["transmission"],
                              OCTAVE_BANDS_HZ, m.get("description", ""))
        for name, m in materials.get("custom", {}).items()
    }
    lib = lib.with_materials(custom)
    a, s, t = lib.coefficients(mesh.materials, settings.bands_hz)
    if not settings.transmission:
        t = np.zeros_like(t)
    vertices, faces, kept = traced_geometry(mesh, settings.simplify_tolerance_m)
    index = np.asarray(mesh.face_material)[kept]
    return AcousticScene(vertices, faces, a[index], s[index], t[index])


def traced_geometry(mesh: SceneMesh, tolerance_m: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The vertices and faces the rir stage traces, and for each face its index in ``mesh``:
    flat areas merged within ``tolerance_m`` (0: the mesh as given), the materials being the
    classes whose boundaries stay."""
    if tolerance_m <= 0:
        return mesh.vertices, mesh.faces, np.arange(mesh.n_faces)
    return simplify_flat_areas(mesh.vertices, mesh.faces, mesh.face_material, tolerance_m)


def ray_trace_settings(settings: RirSettings, specular_order: int) -> RayTraceSettings:
    """The tracer's settings for one RIR job; ``specular_order`` is the image-source order
    completed (those purely specular paths are left out of the trace)."""
    ball = settings.free_air_ball_m
    return RayTraceSettings(
        n_rays=settings.rays, max_time_s=settings.max_rir_length_s,
        energy_threshold_db=settings.energy_threshold_db, bin_s=settings.histogram_bin_s,
        receiver_radius_m=settings.receiver_radius_m,
        specular_order_excluded=specular_order, speed_of_sound_m_s=settings.speed_of_sound_m_s,
        diffuse_rain=settings.diffuse_rain, splitting=settings.ray_splitting,
        roulette_db=settings.roulette_db, free_air_volume=ball > 0,
        guiding=settings.horizontal_guiding,
        max_receiver_radius_m=(max(ball, settings.receiver_radius_m) if ball > 0
                               else RayTraceSettings.max_receiver_radius_m),
        # No renderer reads the late field's directions (the tails are diffuse): skip them.
        directions=False)


# The late envelope a RIR is synthesised from is the tracer's histogram averaged over ±2.5 %
# of the time (``EnergyHistogram.smoothed``): late in the decay few rays remain and 1 ms bins
# come in bursts of Monte-Carlo noise. In the bench apartment with the `sonicset` preset a
# third of the 10 ms windows between 0.3 and 1.5 s were empty at 1 kHz; T30 moves by <= 0.3 %.
LATE_ENVELOPE_RELATIVE_WIDTH = 0.05


def simulate_rirs(scene: AcousticScene, mic_m: np.ndarray, sources_m: np.ndarray,
                  settings: RirSettings, rng: np.random.Generator,
                  regions=None, microphone: dict[str, Any] | None = None,
                  hrirs: HrirSet | None = None, n_threads: int = 1,
                  expected_figures: bool = False, progress=None,
                  ) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """RIRs ``(channels, samples)`` from every source position to the microphone, and facts.

    ``microphone`` is the spec's microphone section (default: mono). For directional
    receivers the early arrivals are traced from each source to the microphone, so their
    directions are directions of arrival at the microphone. A binaural microphone with a SOFA
    HRTF needs its measured set in ``hrirs`` (see :func:`load_hrirs`). ``n_threads`` only
    changes how fast the rays are traced, never the bytes. ``expected_figures`` adds each
    RIR's figures without the late noise's draw (``metrics.figures_from_energy``) to its
    facts as ``"expected"``. ``progress(rays_done, rays_total)`` is called as the trace goes.
    """
    microphone = microphone or {"kind": "mono", "trajectory": {"kind": "static"}}
    check_receiver(microphone, hrirs)
    mic = np.asarray(mic_m, dtype=np.float64).reshape(3)
    points = np.asarray(sources_m, dtype=np.float64).reshape(-1, 3)
    air = settings.air()
    c = settings.speed_of_sound_m_s
    regions = regions if regions is not None else planar_regions(scene)
    direct = direct_sound(scene, mic, points, air, c)
    ism = image_sources(scene, mic, points, settings.image_source_order, air, c, regions,
                        max_path_length_m=c * settings.max_rir_length_s)
    traces = trace_rays(scene, mic, points, rng, ray_trace_settings(settings, ism.max_order),
                        air, n_threads=n_threads, progress=progress)
    blocked = scene.occluded(np.repeat(mic[None], len(points), axis=0), points)
    render = _renderer(microphone, settings, hrirs)
    rirs, facts = [], []
    for k in range(len(points)):
        if microphone["kind"] == "mono":
            arrivals = Arrivals.concatenate([direct[k], ism.arrivals[k]])
        else:  # the same paths, traced towards the mic: directions of arrival at the mic
            (d,) = direct_sound(scene, points[k], mic[None], air, c)
            early = image_sources(scene, points[k], mic[None], ism.max_order, air, c, regions,
                                  max_path_length_m=c * settings.max_rir_length_s)
            arrivals = Arrivals.concatenate([d, early.arrivals[0]])
        late = traces[k].histogram.smoothed(LATE_ENVELOPE_RELATIVE_WIDTH)
        rirs.append(render(arrivals, late, rng).astype(np.float32))
        path = "visible" if not blocked[k] else (
            "through walls" if len(direct[k]) else "blocked")
        facts.append({"arrivals": len(arrivals), "direct": path,
                      "image_source_order": ism.max_order,
                      "escaped_ray_fraction": traces[k].escaped_ray_fraction})
        if expected_figures:
            energy = late.energy + arrivals.energy_histogram(late.bin_s, late.n_bins)
            facts[-1]["expected"] = figures_from_energy(energy, late.bin_s)
    return rirs, facts


def _renderer(microphone: dict[str, Any], settings: RirSettings, hrirs: HrirSet | None = None):
    """A function (arrivals, histogram, rng) -> (channels, samples) for the receiver kind."""
    from sonicspec.acoustics.receivers import (
        capsule_offsets,
        synthesize_ambisonic_rir,
        synthesize_array_rir,
    )

    common = {"max_length_s": settings.max_rir_length_s, "bands_hz": settings.bands_hz}
    fs = settings.sample_rate_hz
    kind = microphone["kind"]
    if kind == "mono":
        return lambda a, h, rng: synthesize_rir(a, h, fs, rng, **common)[None, :]
    if kind == "ambisonics":
        return lambda a, h, rng: synthesize_ambisonic_rir(a, h, microphone["order"], fs, rng,
                                                          **common)
    if kind == "binaural":
        from sonicspec.acoustics.hrtf import (
            SphereHead,
            synthesize_hrir_binaural_rir,
            synthesize_sphere_binaural_rir,
        )

        hrtf = microphone["hrtf"]
        orientation = {"yaw_deg": microphone["yaw_deg"], "pitch_deg": microphone["pitch_deg"]}
        if hrtf["kind"] == "sofa":
            return lambda a, h, rng: synthesize_hrir_binaural_rir(
                a, h, hrirs, fs, rng, **orientation, **common)
        head = SphereHead(head_radius_m=hrtf["head_radius_m"],
                          ear_angle_deg=hrtf["ear_angle_deg"])
        return lambda a, h, rng: synthesize_sphere_binaural_rir(
            a, h, head, fs, rng, speed_of_sound_m_s=settings.speed_of_sound_m_s, **orientation,
            **common)
    offsets = capsule_offsets(
        kind, n=microphone.get("n", 0), spacing_m=microphone.get("spacing_m", 0.0),
        radius_m=microphone.get("radius_m", 0.0), positions_m=microphone.get("positions_m", ()),
        yaw_deg=microphone["yaw_deg"], pitch_deg=microphone["pitch_deg"])
    return lambda a, h, rng: synthesize_array_rir(
        a, h, offsets, fs, rng, speed_of_sound_m_s=settings.speed_of_sound_m_s, **common)


RENDERED_KINDS = ("mono", "linear_array", "circular_array", "custom", "ambisonics",
                  "binaural")


def load_hrirs(path: str | Path) -> HrirSet:
    """The measured HRIR set of a SOFA file (SimpleFreeFieldHRIR), read with ``sofar``."""
    from sonicspec.acoustics.hrtf import hrir_set_from_sofa

    try:
        import sofar
    except ImportError:
        raise AcousticsError("microphone.hrtf: reading SOFA files needs the 'sofar' package; "
                             "install it with pip install 'sonicspec[sofa]'") from None
    if not Path(path).is_file():
        raise AcousticsError(f"microphone.hrtf.path: SOFA file {path} does not exist")
    try:
        sofa = sofar.read_sofa(str(path), verify=False, verbose=False)
    except Exception as exc:  # sofar/netCDF raise many kinds
        raise AcousticsError(f"microphone.hrtf.path: cannot read SOFA file {path}: "
                             f"{type(exc).__name__}: {exc}") from exc
    try:
        return hrir_set_from_sofa(sofa)
    except AcousticsError as exc:
        raise AcousticsError(f"microphone.hrtf.path: {path}: {exc}") from exc


def check_receiver(microphone: dict[str, Any], hrirs: HrirSet | None = None) -> None:
    """Refuse receivers this version cannot render (or that lack their HRIR set)."""
    if (microphone["kind"] == "binaural" and microphone["hrtf"]["kind"] == "sofa"
            and hrirs is None):
        raise AcousticsError("microphone.hrtf: a SOFA HRTF needs its HRIR set loaded "
                             "(load_hrirs) before RIRs can be rendered")
    if microphone["kind"] not in RENDERED_KINDS:
        raise AcousticsError(f"microphone.kind: RIRs for {microphone['kind']!r} receivers are "
                             "not in this version of sonicspec; use one of "
                             f"{', '.join(RENDERED_KINDS)}")
    if microphone["trajectory"]["kind"] != "static":
        raise AcousticsError("microphone.trajectory: a moving microphone is not in this version "
                             "of sonicspec; use kind: static")


def rir_from_spec(loaded, scene_id: str, source_m, mic_m) -> tuple[np.ndarray, dict[str, Any]]:
    """One RIR in a spec's scene (``sonicspec rir``), and the facts to report with it."""
    from sonicspec.acoustics.metrics import room_acoustic_figures
    from sonicspec.hashing import rng_for
    from sonicspec.stages.inspect import build_scene

    spec = loaded.spec
    microphone = spec.microphone.model_dump(mode="json")
    hrirs = None
    if microphone["kind"] == "binaural" and microphone["hrtf"]["kind"] == "sofa":
        hrirs = load_hrirs(loaded.base_dir / microphone["hrtf"]["path"])
    check_receiver(microphone, hrirs)
    mesh, _, mesh_job, _, warnings = build_scene(loaded, scene_id)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    for name, p in (("--source", source_m), ("--mic", mic_m)):
        if np.any(np.asarray(p) < lo) or np.any(np.asarray(p) > hi):
            raise AcousticsError(f"{name}: {list(p)} is outside scene {scene_id!r} "
                                 f"(bounds {lo.round(2).tolist()} .. {hi.round(2).tolist()})")
    settings = RirSettings.from_spec(spec.acoustics.model_dump(mode="json"),
                                     spec.sample_rate_hz, spec.speed_of_sound_m_s)
    scene = acoustic_scene(mesh, spec.materials.model_dump(mode="json"), settings)
    rng = rng_for(spec.seed, "rir-cli", mesh_job.key, repr(list(source_m)), repr(list(mic_m)))
    (rir,), (facts,) = simulate_rirs(scene, np.asarray(mic_m), np.asarray([source_m]),
                                     settings, rng, microphone=microphone, hrirs=hrirs,
                                     expected_figures=True)
    # Figures of the first channel (the omni W channel for ambisonics).
    figures = room_acoustic_figures(rir[0], spec.sample_rate_hz, settings.bands_hz)
    facts = {**facts, "scene_id": scene_id, "source_m": list(source_m), "mic_m": list(mic_m),
             "channels": int(rir.shape[0]),
             "distance_m": float(np.linalg.norm(np.subtract(source_m, mic_m))),
             "sample_rate_hz": spec.sample_rate_hz, "samples": int(rir.shape[-1]),
             "mesh_triangles": mesh.n_faces, "traced_triangles": scene.n_faces,
             "figures": figures.to_dict(), "warnings": warnings}
    return rir, facts


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
        f"{'band (Hz)':>10} " + " ".join(f"{b:>7g}" for b in fig["bands_hz"]),
        *per_band(fig),
    ]
    if "expected" in facts:  # the same fits on the energy the RIR was synthesised to have
        lines.append("expected (the energy it was synthesised to have, without the noise draw):")
        lines += per_band(facts["expected"])
    lines += [
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


def _source_points(placement: dict[str, Any]) -> list[tuple[str, np.ndarray]]:
    """(name, RIR points) of every source of a group: speech1..N, then noise and music."""
    out = [(f"source{k + 1}", np.asarray(s["rir_points_m"], dtype=np.float64))
           for k, s in enumerate(placement["speech"])]
    for kind in ("noise", "music"):
        if placement.get(kind) is not None:
            out.append((kind, np.asarray(placement[kind]["rir_points_m"], dtype=np.float64)))
    return out


def run(ctx) -> None:
    """Stage ``rir``: every source's RIRs along its path, for every group of a shard."""
    from sonicspec.acoustics.metrics import room_acoustic_figures
    from sonicspec.stages.mesh import load_scene_mesh

    params = ctx.params
    hrirs = load_hrirs(ctx.job.paths["hrtf"]) if "hrtf" in ctx.job.paths else None
    check_receiver(params["microphone"], hrirs)
    mesh_art = ctx.input("mesh")
    mesh = load_scene_mesh(mesh_art.arrays, mesh_art.data)
    settings = RirSettings.from_spec(params["acoustics"], params["sample_rate_hz"],
                                     params["speed_of_sound_m_s"])
    materials = dict(params["materials"])
    scene = acoustic_scene(mesh, materials, settings)
    regions = planar_regions(scene)
    placements = ctx.input_data("placement")[0]["groups"]
    arrays: dict[str, np.ndarray] = {}
    groups = []
    for g, placement in enumerate(placements):
        sources = _source_points(placement)
        points = np.concatenate([p for _, p in sources])
        rng = ctx.rng("rir", ctx.job.key, placement["group"])

        def progress(done: int, total: int, g: int = g, n: int = len(points)) -> None:
            ctx.progress(f"group {g + 1}/{len(placements)}: {n} points, "
                         f"{done:,}/{total:,} rays")

        rirs, facts = simulate_rirs(scene, np.asarray(placement["mic_m"]), points, settings,
                                    rng, regions, params["microphone"], hrirs,
                                    progress=progress)
        entries, start = [], 0
        for s, (name, pts) in enumerate(sources):
            block = rirs[start:start + len(pts)]
            length = max(r.shape[-1] for r in block)
            stack = np.zeros((len(block), block[0].shape[0], length), dtype=np.float32)
            for i, r in enumerate(block):
                stack[i, :, :r.shape[-1]] = r
            key = f"g{g}_s{s}"
            arrays[key] = stack
            first = room_acoustic_figures(block[0][0], settings.sample_rate_hz,
                                          settings.bands_hz).to_dict()  # NaN -> None
            entries.append({"name": name, "array": key, "points": len(pts),
                            "t30_s": first["broadband"]["t30_s"], "drr_db": first["drr_db"],
                            "direct": facts[start]["direct"],
                            "escaped_ray_fraction": facts[start]["escaped_ray_fraction"]})
            start += len(pts)
        groups.append({"group": placement["group"], "sources": entries})
    ctx.write(arrays, {"groups": groups, "bands_hz": list(settings.bands_hz),
                       "sample_rate_hz": settings.sample_rate_hz})
