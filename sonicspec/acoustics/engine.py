"""The RIR engine: a scene with materials, a microphone and source positions in, RIRs out.

For one microphone and many source positions (a trajectory), the ray tracer runs once, from
the microphone, with every position as a receiver (reciprocity: the RIR from A to B equals the
RIR from B to A for omnidirectional ends). Direct sound and image sources are exact and cheap,
so they are computed per position. Each position's RIR is then synthesised
(:mod:`sonicspec.acoustics.receivers.synthesis`).

Receivers: mono, linear/circular/custom arrays and ambisonics
(:mod:`sonicspec.acoustics.receivers.arrays`), and binaural through the rigid-sphere head or a
measured HRIR set read from a SOFA file (:mod:`sonicspec.acoustics.receivers.hrtf`); capsules
of mono microphones and arrays with first-order patterns
(:mod:`sonicspec.acoustics.receivers.capsules`), and device presets
(:mod:`sonicspec.acoustics.receivers.devices`: free-field arrays, or capsules on a rigid
sphere rendered by the sphere head's model). A receiver is
described by a mapping with the spec's microphone fields (``{"kind": "ambisonics", "order":
1, ...}``, what ``MicrophoneSpec.model_dump()`` gives).

This is the one acoustics module that reads the geometry library's types (a
:class:`~sonicspec.geometry.mesh.SceneMesh` and a
:class:`~sonicspec.geometry.materials.MaterialLibrary`): it is where a scene's materials become
per-face coefficients. The rir stage, ``sonicspec rir`` and :func:`sonicspec.compute_rir` all
call it.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sonicspec.acoustics.air import air_energy_coefficient_per_m
from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank, default_bands
from sonicspec.acoustics.directivity import (
    SourceDirectivity,
    departure_directions,
    directional_arrivals,
    emission_gains,
)
from sonicspec.acoustics.late.raytrace import RayTraceSettings, trace_rays
from sonicspec.acoustics.late.tails import TailFacts, TailReport, cut_warning, shape_tail
from sonicspec.acoustics.metrics import (
    RoomAcousticFigures,
    figures_from_energy,
    room_acoustic_figures,
)
from sonicspec.acoustics.paths.direct import direct_sound
from sonicspec.acoustics.paths.edge_paths import close_pairs, diffracted_sound
from sonicspec.acoustics.paths.edges import DiffractingEdges, EdgeChoice, diffracting_edges
from sonicspec.acoustics.paths.image_sources import (
    PlanarRegions,
    image_sources,
    planar_regions,
)
from sonicspec.acoustics.receivers.synthesis import synthesize_early, synthesize_rir
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.acoustics.room.simplify import simplify_flat_areas
from sonicspec.errors import AcousticsError, SonicspecWarning

if TYPE_CHECKING:
    from sonicspec.acoustics.receivers.hrtf import HrirSet
    from sonicspec.geometry.materials import MaterialLibrary
    from sonicspec.geometry.mesh import SceneMesh

__all__ = [
    "LATE_ENVELOPE_RELATIVE_WIDTH",
    "RENDERED_KINDS",
    "RirResult",
    "SimulationSettings",
    "acoustic_scene",
    "capsule_facts",
    "check_inside",
    "check_receiver",
    "diffraction_arrivals",
    "directional_paths",
    "early_part",
    "late_envelope",
    "load_hrirs",
    "load_source_directivity",
    "microphone_capsules",
    "needs_directions",
    "ray_trace_settings",
    "receiver_renderer",
    "rir_results",
    "scene_capsules",
    "scene_edges",
    "simulate_rirs",
    "traced_geometry",
    "warn_cut_tails",
    "with_diffraction_focus",
]

#: The receiver a call without one gets: one omnidirectional capsule that stays put.
MONO: Mapping[str, Any] = {"kind": "mono", "trajectory": {"kind": "static"}}


MIRROR_STRICT_M = 1e-4
"""``mirror_tolerance_m`` at which only exactly flat surfaces merge (planar_regions' default)."""
MIRROR_ANGLE_RAD = 0.5
"""Largest angle between a triangle's normal and its mirror's plane at scan tolerances: a
small triangle's normal tilts far with millimetres of noise; its vertices decide."""

@dataclass(frozen=True)
class SimulationSettings:
    """What the engine needs to simulate RIRs: the spec's ``acoustics`` section in the
    tracer's terms, the sample rate and the speed of sound.

    Built from the spec's settings by :meth:`from_spec` (the rir stage, ``sonicspec rir``,
    :class:`sonicspec.RirSettings`), so the spec's defaults are the only ones a user meets;
    the defaults below are the tracer's own (roulette, guiding and splitting off), which
    tests and benches use to measure the tracer alone.

    ``max_rir_length_s`` is a number of seconds or ``"auto"``: either way a RIR ends where
    every band's late decay is 60 dB below its early level (:mod:`~sonicspec.acoustics.late.tails`),
    at most that number or, with ``"auto"``, ``max_rir_cap_s``.
    """

    sample_rate_hz: int
    bands_hz: tuple[float, ...]
    rays: int
    image_source_order: int
    max_rir_length_s: float | str
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
    mirror_tolerance_m: float = MIRROR_STRICT_M
    diffraction: bool = False
    diffraction_max_edges: int = 256
    max_rir_cap_s: float = 10.0
    diffraction_focus_m: tuple[tuple[float, float, float], ...] = ()
    """The source and receiver positions the diffracting edges are chosen for
    (:func:`scene_edges`): the rir stage sets every position of a group, so all the group's
    RIRs and the points added between them use one set of edges; empty: each call's own
    microphone and sources (:func:`with_diffraction_focus`)."""

    def __post_init__(self) -> None:
        length = self.max_rir_length_s
        if not (length == "auto" or (isinstance(length, int | float)
                                     and not isinstance(length, bool) and length > 0)):
            raise AcousticsError(f"max_rir_length_s: expected 'auto' or seconds > 0, got "
                                 f"{length!r}")
        if not self.max_rir_cap_s > 0:
            raise AcousticsError(f"max_rir_cap_s: expected seconds > 0, got "
                                 f"{self.max_rir_cap_s!r}")

    @property
    def rir_limit_s(self) -> float:
        """The longest RIR allowed, seconds: ``max_rir_length_s``, or ``max_rir_cap_s``
        when it is ``"auto"`` (the tracer follows rays that long, the decay decides where
        each RIR ends)."""
        if self.max_rir_length_s == "auto":
            return float(self.max_rir_cap_s)
        return float(self.max_rir_length_s)

    @property
    def rir_limit_field(self) -> str:
        """The spec field that sets :attr:`rir_limit_s`."""
        return "max_rir_cap_s" if self.max_rir_length_s == "auto" else "max_rir_length_s"

    @classmethod
    def from_spec(cls, acoustics: Mapping[str, Any], sample_rate_hz: int,
                  speed_of_sound_m_s: float) -> SimulationSettings:
        """The settings of a spec's ``acoustics`` section (as ``model_dump(mode="json")``
        gives it), ``bands_hz: auto`` resolved for the sample rate."""
        # Same names as the spec's fields: every field the spec has is taken by name; the
        # two that differ in form are translated.
        same = ({f.name for f in fields(cls)} & set(acoustics)) - {
            "bands_hz", "sample_rate_hz", "speed_of_sound_m_s"}
        bands = acoustics["bands_hz"]
        bands = default_bands(sample_rate_hz) if bands == "auto" else tuple(
            float(b) for b in bands)
        return cls(**{name: acoustics[name] for name in same},
                   sample_rate_hz=sample_rate_hz, bands_hz=bands,
                   diffuse_rain=acoustics["detection"] == "diffuse_rain",
                   speed_of_sound_m_s=speed_of_sound_m_s)

    def air(self) -> np.ndarray | None:
        """Air's energy attenuation per metre and band (ISO 9613-1), or None without it."""
        if not self.air_absorption:
            return None
        return air_energy_coefficient_per_m(self.bands_hz, self.temperature_c,
                                            self.relative_humidity_pct)


def scene_regions(scene: AcousticScene, settings: SimulationSettings) -> PlanarRegions:
    """The image-source mirrors of ``scene``: :func:`planar_regions` at the settings'
    ``mirror_tolerance_m`` (exactly flat surfaces at the default; scan tolerances above it,
    normals within :data:`MIRROR_ANGLE_RAD`)."""
    tol = float(settings.mirror_tolerance_m)
    if tol <= MIRROR_STRICT_M:
        return planar_regions(scene)
    return planar_regions(scene, angle_tol_rad=MIRROR_ANGLE_RAD, distance_tol_m=tol)


def acoustic_scene(mesh: SceneMesh, library: MaterialLibrary, settings: SimulationSettings
                   ) -> AcousticScene:
    """The mesh in the tracer, each face with its material's coefficients.

    Parameters
    ----------
    mesh : SceneMesh
        The scene; its ``materials`` are names in ``library``.
    library : MaterialLibrary
        Where the names resolve (a built-in library, with the user's own materials added by
        :meth:`~sonicspec.geometry.materials.MaterialLibrary.with_materials`).
    settings : SimulationSettings
        The bands, whether surfaces transmit, and the flat-area tolerance
        (``simplify_tolerance_m``; 0 traces the mesh as given).

    Returns
    -------
    AcousticScene
        Absorption, scattering and transmission per face and band.

    Raises
    ------
    GeometryError
        A material name is not in the library (with a did-you-mean hint).
    """
    a, s, t = library.coefficients(mesh.materials, settings.bands_hz)
    if not settings.transmission:
        t = np.zeros_like(t)
    vertices, faces, kept = traced_geometry(mesh, settings.simplify_tolerance_m)
    index = np.asarray(mesh.face_material)[kept]
    return AcousticScene(vertices, faces, a[index], s[index], t[index])


def traced_geometry(mesh: SceneMesh, tolerance_m: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The vertices and faces the engine traces, and for each face its index in ``mesh``:
    flat areas merged within ``tolerance_m`` (0: the mesh as given), the materials being the
    classes whose boundaries stay."""
    if tolerance_m <= 0:
        return mesh.vertices, mesh.faces, np.arange(mesh.n_faces)
    return simplify_flat_areas(mesh.vertices, mesh.faces, mesh.face_material, tolerance_m)


def ray_trace_settings(settings: SimulationSettings, specular_order: int) -> RayTraceSettings:
    """The tracer's settings for one simulation; ``specular_order`` is the image-source order
    completed (those purely specular paths are left out of the trace)."""
    ball = settings.free_air_ball_m
    return RayTraceSettings(
        n_rays=settings.rays, max_time_s=settings.rir_limit_s,
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
                  settings: SimulationSettings, rng: np.random.Generator,
                  regions=None, microphone: Mapping[str, Any] | None = None,
                  hrirs: HrirSet | None = None, n_threads: int = 1,
                  expected_figures: bool = False, progress=None, where: str = "the scene",
                  keep_arrivals: bool = False,
                  directivity: Sequence[SourceDirectivity | None] | None = None,
                  ) -> tuple[list[np.ndarray], list[RirFacts]]:
    """RIRs from every source position to the microphone, and facts about each.

    Parameters
    ----------
    scene : AcousticScene
        The scene with its coefficients (:func:`acoustic_scene`).
    mic_m : (3,) float
        Microphone position (the array or head centre), metres.
    sources_m : (N, 3) float
        Source positions, metres; one trace serves them all.
    settings : SimulationSettings
        The simulation's settings.
    rng : numpy.random.Generator
        The only randomness used (rays and the late noise's draw).
    regions
        The scene's planar regions
        (:func:`~sonicspec.acoustics.paths.image_sources.planar_regions`), when the caller
        reuses them over many calls.
    microphone : mapping, optional
        The receiver, with the spec's microphone fields (default: mono). For directional
        receivers the early arrivals are traced from each source to the microphone, so their
        directions are directions of arrival at the microphone.
    hrirs : HrirSet, optional
        The measured set of a binaural microphone with a SOFA HRTF (:func:`load_hrirs`).
    n_threads : int
        Threads for the trace; changes how fast rays are traced, never the bytes.
    expected_figures : bool
        Add each RIR's figures without the late noise's draw
        (:func:`~sonicspec.acoustics.metrics.figures_from_energy`) to its facts
        (:attr:`RirFacts.expected`).
    progress : callable, optional
        ``progress(rays_done, rays_total)``, called as the trace goes.
    where : str
        What the cap warning calls the scene (``"scene 'flat'"``).
    keep_arrivals : bool
        Add each RIR's direct sound and image-source arrivals to its facts: as traced from
        the microphone (:attr:`RirFacts.early_arrivals`, directions at the source point: where
        each path's image of the microphone is) and towards it
        (:attr:`RirFacts.early_arrivals_at_mic`,
        directions of arrival at the microphone, as rendered into the RIR). A moving source's
        paths are rendered from them (:class:`~sonicspec.acoustics.moving.delays.PathSet`), its late
        part is the RIR less :func:`early_part` of the latter. Edge-diffracted paths are in
        both lists (directions at the microphone), identified by their ``path_id``.
        Receivers of :data:`PATH_RECEIVERS`. With ``directivity``, ``"early_arrivals"``
        stay omnidirectional (a moving source's pattern is applied as it turns,
        :func:`~sonicspec.acoustics.moving.delays.render_paths`) and
        ``"early_arrivals_at_mic"`` carry the pattern, as the RIR does.
    directivity : sequence of SourceDirectivity or None, optional
        One per source position (None: omnidirectional), its ``yaw_deg`` one yaw: each
        early path weighted by the pattern's gain for the direction it leaves the source in
        (:func:`~sonicspec.acoustics.directivity.departure_directions`), the late envelope
        by the pattern's diffuse-field power per band.

    Returns
    -------
    rirs : list of (channels, samples) float32 arrays
        One per source position.
    facts : list of RirFacts
        One per position: the early arrivals, the direct path, the image-source order
        reached, the escaped energy, how the length was chosen (:class:`RirFacts`).

    Warns
    -----
    SonicspecWarning
        Once per call when ``max_rir_cap_s`` (with ``max_rir_length_s: auto``) cut a band's
        decay before it was 60 dB below its early level (:func:`late_envelope`), naming
        ``where`` and the bands.

    Raises
    ------
    AcousticsError
        A receiver this version cannot render (:func:`check_receiver`).
    """
    microphone = microphone or MONO
    check_receiver(microphone, hrirs)
    if keep_arrivals and microphone["kind"] not in PATH_RECEIVERS:
        raise AcousticsError(f"keep_arrivals: the early paths of a moving source are rendered "
                             f"for {', '.join(PATH_RECEIVERS)} receivers, got "
                             f"{microphone['kind']!r}")
    mic = np.asarray(mic_m, dtype=np.float64).reshape(3)
    points = np.asarray(sources_m, dtype=np.float64).reshape(-1, 3)
    air = settings.air()
    regions = regions if regions is not None else scene_regions(scene, settings)
    early = early_arrivals(scene, mic, points, settings, regions,
                           directional=needs_directions(microphone))
    traces = trace_rays(scene, mic, points, rng,
                        ray_trace_settings(settings, early.image_source_order),
                        air, n_threads=n_threads, progress=progress)
    blocked = scene.occluded(np.repeat(mic[None], len(points), axis=0), points)
    edge_choice = (_diffraction_edges(scene, settings, mic, points)[0].choice()
                   if settings.diffraction else None)
    render = receiver_renderer(microphone, settings, hrirs)
    if directivity is not None and len(directivity) != len(points):
        raise AcousticsError(f"directivity: expected one per source position ({len(points)}), "
                             f"got {len(directivity)}")
    rirs, facts, reports = [], [], []
    powers: dict[int, np.ndarray] = {}
    for k in range(len(points)):
        arrivals = early.at_mic[k]
        late, report = late_envelope(traces[k].histogram, settings)
        reports.append(report)
        source = None if directivity is None else directivity[k]
        if source is not None:
            if id(source.pattern) not in powers:  # once per pattern, not per point
                powers[id(source.pattern)] = source.pattern.diffuse_power(settings.bands_hz)
            arrivals, late = directional_paths(arrivals, late, source, points[k], mic,
                                               settings.bands_hz,
                                               arrivals is early.from_mic[k],
                                               powers[id(source.pattern)])
        rirs.append(render(arrivals, late, rng).astype(np.float32))
        path = "visible" if not blocked[k] else (
            "through walls" if len(early.direct[k]) else
            "diffracted" if len(early.diffracted[k]) else "blocked")
        expected = None
        if expected_figures:
            energy = late.energy + arrivals.energy_histogram(late.bin_s, late.n_bins)
            expected = figures_from_energy(energy, late.bin_s)
        facts.append(RirFacts(
            arrivals=len(arrivals), direct=path,
            image_source_order=early.image_source_order,
            image_source_order_asked=settings.image_source_order,
            image_source_order_stopped=early.image_source_stopped,
            escaped_ray_fraction=traces[k].escaped_ray_fraction, tail=report.facts(),
            diffracted_paths=len(early.diffracted[k]) if settings.diffraction else 0,
            diffraction_edges=edge_choice, expected=expected,
            early_arrivals=early.from_mic[k] if keep_arrivals else None,
            # as rendered: with the source's pattern
            early_arrivals_at_mic=arrivals if keep_arrivals else None))
    warn_cut_tails(reports, where)
    return rirs, facts


def directional_paths(arrivals: Arrivals, late: EnergyHistogram, source: SourceDirectivity,
                      source_m: np.ndarray, mic_m: np.ndarray, bands_hz,
                      traced_from_mic: bool, diffuse_power: np.ndarray | None = None
                      ) -> tuple[Arrivals, EnergyHistogram]:
    """One source position's early ``arrivals`` and ``late`` envelope as a directional
    source radiates them: each path times the pattern's gains for its departure direction
    (``traced_from_mic``: the arrivals were traced from the microphone), the late energy
    times the pattern's diffuse-field power per band (``diffuse_power``, when the caller
    has it)."""
    d = departure_directions(arrivals, source_m, mic_m,
                             "receiver" if traced_from_mic else "source")
    gains = emission_gains(source.pattern, d, float(source.yaw_deg.reshape(-1)[0]), bands_hz,
                           source.pitch_deg)
    power = (source.pattern.diffuse_power(bands_hz) if diffuse_power is None
             else np.asarray(diffuse_power, dtype=np.float64))
    return (directional_arrivals(arrivals, gains),
            replace(late, energy=late.energy * power[None, :]))


@dataclass(frozen=True, eq=False)
class RirFacts:
    """What :func:`simulate_rirs` knows about one RIR besides its samples: typed, so the
    steps read fields, not string keys (a new fact is a new field with a default).

    Attributes
    ----------
    arrivals : int
        Early arrivals rendered exactly: the direct sound, the image sources and the
        edge-diffracted paths.
    direct : {"visible", "through walls", "diffracted", "blocked"}
        The direct path: in sight, heard through transmitting surfaces, heard round edges
        (out of sight, with ``acoustics.diffraction``), or absent.
    image_source_order : int
        The image-source order completed (lower than asked when a scene has too many).
    image_source_order_asked : int
        The order the settings asked.
    image_source_order_stopped : str or None
        Why the completed order is lower than asked (``"order 3 needs more than 2,000,000
        candidates"``; the ray tracer covers the rest), None when it is not.
    escaped_ray_fraction : float
        Share of the traced energy that left the scene (a leaking mesh shows here).
    tail : TailFacts
        How the RIR's length was chosen.
    diffracted_paths : int
        Edge-diffracted arrivals among ``arrivals`` (0 with diffraction off).
    diffraction_edges : EdgeChoice or None
        How the diffracting edges were chosen (None with diffraction off).
    expected : dict or None
        T30, EDT and C50 per band of the energy the RIR was synthesised to have
        (:func:`~sonicspec.acoustics.metrics.figures_from_energy`; with ``expected_figures``).
    early_arrivals, early_arrivals_at_mic : Arrivals or None
        The exact early paths as traced from the microphone and towards it (with
        ``keep_arrivals``).
    """

    arrivals: int
    direct: str
    image_source_order: int
    image_source_order_asked: int
    image_source_order_stopped: str | None
    escaped_ray_fraction: float
    tail: TailFacts
    diffracted_paths: int = 0
    diffraction_edges: EdgeChoice | None = None
    expected: dict[str, Any] | None = None
    early_arrivals: Arrivals | None = None
    early_arrivals_at_mic: Arrivals | None = None


@dataclass(frozen=True, eq=False)
class EarlyArrivals:
    """The exact early paths of every source position at one microphone: as traced from the
    microphone (``from_mic``: directions at the source point, where each path's image of the
    microphone is; isometries) and towards it (``at_mic``: directions of arrival at the
    microphone, as rendered into the RIR; the same list for a mono receiver). Edge-diffracted
    paths are in both, with directions at the microphone."""

    from_mic: list[Arrivals]
    at_mic: list[Arrivals]
    direct: list[Arrivals]
    diffracted: list[Arrivals]
    image_source_order: int
    """The image-source order completed (the candidate limit may stop it early)."""
    image_source_stopped: str | None = None
    """Why the completed order is lower than asked, None when it is not."""


def early_arrivals(scene: AcousticScene, mic_m: np.ndarray, sources_m: np.ndarray,
                   settings: SimulationSettings, regions=None, directional: bool = False,
                   image_source_order: int | None = None) -> EarlyArrivals:
    """Direct sound, image sources and edge-diffracted paths from every source position to
    the microphone — the deterministic part of :func:`simulate_rirs`, without the ray trace
    (so cheap enough to evaluate between RIR points). ``image_source_order``: the order to
    search (default the settings'; a caller matching an earlier call passes its completed
    order)."""
    mic = np.asarray(mic_m, dtype=np.float64).reshape(3)
    points = np.asarray(sources_m, dtype=np.float64).reshape(-1, 3)
    air = settings.air()
    c = settings.speed_of_sound_m_s
    regions = regions if regions is not None else scene_regions(scene, settings)
    order = settings.image_source_order if image_source_order is None else image_source_order
    direct = direct_sound(scene, mic, points, air, c)
    ism = image_sources(scene, mic, points, order, air, c, regions,
                        max_path_length_m=c * settings.rir_limit_s)
    diffracted = diffraction_arrivals(scene, mic, points, settings, regions)
    from_mic, at_mic = [], []
    for k in range(len(points)):
        from_mic.append(Arrivals.concatenate([direct[k], ism.arrivals[k], diffracted[k]]))
        if not directional:
            at_mic.append(from_mic[-1])
            continue
        # the same paths, traced towards the mic: directions of arrival at the mic
        (d,) = direct_sound(scene, points[k], mic[None], air, c)
        towards = image_sources(scene, points[k], mic[None], ism.max_order, air, c, regions,
                                max_path_length_m=c * settings.rir_limit_s)
        at_mic.append(Arrivals.concatenate([d, towards.arrivals[0], diffracted[k]]))
    return EarlyArrivals(from_mic, at_mic, direct, diffracted, ism.max_order, ism.stopped)


def with_diffraction_focus(settings: SimulationSettings, *points_m: np.ndarray
                           ) -> SimulationSettings:
    """``settings`` whose diffracting edges are chosen for these source and receiver
    positions (each ``(3,)`` or ``(N, 3)``, metres): the edges a group's RIRs share."""
    flat = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in points_m])
    focus = tuple(tuple(float(v) for v in row) for row in np.unique(flat, axis=0))
    return dataclasses.replace(settings, diffraction_focus_m=focus)


def scene_edges(scene: AcousticScene, max_edges: int,
                near_m: np.ndarray | tuple = ()) -> DiffractingEdges:
    """The traced scene's diffracting edges, the ``max_edges`` most important for sources and
    receivers at ``near_m`` (by length and exposure alone without them;
    :func:`~sonicspec.acoustics.paths.edges.edge_importance`), memoized per scene and positions."""
    near = np.asarray(near_m, dtype=np.float64).reshape(-1, 3)
    found = scene.memoized("diffracting_edges", lambda: _unburied(scene, diffracting_edges(
        scene.vertices, scene.faces, scene.normals)))  # found once, ranked per positions
    key = f"diffracting_edges:{max_edges}:{hash(near.tobytes())}:{len(near)}"
    if not len(near):
        return scene.memoized(key, lambda: found.ranked(max_edges))
    return scene.memoized(key, lambda: found.ranked(max_edges, near,
                                                    _edges_in_sight(scene, found, near)))


def _unburied(scene: AcousticScene, edges: DiffractingEdges) -> DiffractingEdges:
    """``edges`` less the wedges another surface cuts into: a box standing on the floor or
    against a wall is a closed solid whose edges there are inner corners of the room (its air
    spans a quarter turn, not three), so they diffract nothing. An edge is buried where a
    chord of the arc round it (:meth:`~sonicspec.acoustics.paths.edges.DiffractingEdges.arc_points`)
    is occluded at two of its three places along it (a box half against a wall keeps its
    free half's edge)."""
    if len(edges) == 0:
        return edges
    arcs = edges.arc_points()  # (m, 3, s, 3)
    m, k, s = arcs.shape[:3]
    cut = scene.occluded(arcs[:, :, :-1].reshape(-1, 3), arcs[:, :, 1:].reshape(-1, 3))
    cut = cut.reshape(m, k, s - 1).any(axis=2)
    return edges.without(cut.sum(axis=1) >= 2)


#: Most positions :func:`scene_edges` tests the edges' visibility from (evenly picked).
SIGHT_POSITIONS = 32


def _edges_in_sight(scene: AcousticScene, edges: DiffractingEdges, near: np.ndarray
                    ) -> np.ndarray:
    """``(m,)`` share of the positions (at most :data:`SIGHT_POSITIONS` of ``near``) in sight
    of each edge: of three points along it, 1 cm off into the air, one seen is enough."""
    if len(edges) == 0:
        return np.zeros(0)
    pick = np.unique(np.linspace(0, len(near) - 1, min(len(near), SIGHT_POSITIONS)).round()
                     .astype(np.int64))
    points = near[pick]
    samples = edges.air_points()  # (m, 3, 3)
    m, k = samples.shape[:2]
    origins = np.repeat(samples.reshape(-1, 3), len(points), axis=0)
    targets = np.tile(points, (m * k, 1))
    visible = ~scene.occluded(origins, targets)
    return visible.reshape(m, k, len(points)).any(axis=1).mean(axis=1)


def _diffraction_edges(scene: AcousticScene, settings: SimulationSettings, mic: np.ndarray,
                       points: np.ndarray) -> tuple[DiffractingEdges, np.ndarray]:
    """The edges (and their close pairs) of one call: chosen for the settings' focus, or
    for the call's microphone and sources."""
    if settings.diffraction_focus_m:
        near = np.asarray(settings.diffraction_focus_m, dtype=np.float64)
    else:
        near = np.unique(np.concatenate([mic.reshape(1, 3), points]), axis=0)
    edges = scene_edges(scene, settings.diffraction_max_edges, near)
    key = f"diffracting_edge_pairs:{settings.diffraction_max_edges}:{hash(near.tobytes())}"
    return edges, scene.memoized(key, lambda: close_pairs(edges))


def diffraction_arrivals(scene: AcousticScene, mic_m: np.ndarray, sources_m: np.ndarray,
                         settings: SimulationSettings, regions=None) -> list[Arrivals]:
    """Edge-diffracted arrivals from every source position at the microphone (empty ones
    when ``settings.diffraction`` is off): over one edge, two edges, and one edge with a
    reflection (:mod:`~sonicspec.acoustics.paths.edge_paths`), directions of arrival at the
    microphone."""
    points = np.asarray(sources_m, dtype=np.float64).reshape(-1, 3)
    if not settings.diffraction:
        return [Arrivals.empty(scene.n_bands) for _ in points]
    edges, pairs = _diffraction_edges(scene, settings, np.asarray(mic_m, dtype=np.float64),
                                      points)
    return diffracted_sound(scene, edges, points, np.asarray(mic_m, dtype=np.float64),
                            settings.bands_hz, settings.air(), settings.speed_of_sound_m_s,
                            regions=regions, pairs=pairs)


def early_part(arrivals: Arrivals, settings: SimulationSettings, n_samples: int,
               microphone: Mapping[str, Any] = MONO, hrirs: HrirSet | None = None
               ) -> np.ndarray:
    """The exact early part an RIR of ``n_samples`` holds, ``(channels, n_samples)`` float64:
    its ``arrivals`` (directions of arrival at the microphone) synthesised as the receiver's
    renderer does. The RIR less this is its late, ray-traced part. Receivers of
    :data:`PATH_RECEIVERS` (a SOFA HRTF with its ``hrirs``)."""
    from sonicspec.acoustics.receivers.arrays import ambisonic_early, array_early

    bank = OctaveFilterBank(settings.sample_rate_hz, settings.bands_hz)
    kind = microphone["kind"]
    capsules = scene_capsules(microphone)
    if capsules is not None and capsules.sphere_radius_m is not None:
        from sonicspec.acoustics.receivers.hrtf import SphereHead, sphere_capsules_early

        return sphere_capsules_early(arrivals, SphereHead(head_radius_m=capsules.sphere_radius_m),
                                     capsules.axes, bank, n_samples,
                                     speed_of_sound_m_s=settings.speed_of_sound_m_s)
    if capsules is not None:
        return array_early(arrivals, capsules.offsets_m, bank, n_samples,
                           settings.speed_of_sound_m_s, capsules=capsules)
    if kind == "mono":
        return synthesize_early(arrivals, bank, n_samples)[None, :]
    if kind == "ambisonics":
        return ambisonic_early(arrivals, microphone["order"], bank, n_samples,
                               yaw_deg=microphone["yaw_deg"], pitch_deg=microphone["pitch_deg"])
    if kind == "binaural" and microphone["hrtf"]["kind"] == "sofa":
        from sonicspec.acoustics.receivers.hrtf import hrir_binaural_early

        check_receiver(microphone, hrirs)
        return hrir_binaural_early(arrivals, hrirs.resampled(settings.sample_rate_hz), bank,
                                   n_samples, yaw_deg=microphone["yaw_deg"],
                                   pitch_deg=microphone["pitch_deg"])
    if kind == "binaural" and microphone["hrtf"]["kind"] == "sphere":
        from sonicspec.acoustics.receivers.hrtf import sphere_binaural_early

        return sphere_binaural_early(arrivals, sphere_head(microphone), bank, n_samples,
                                     yaw_deg=microphone["yaw_deg"],
                                     pitch_deg=microphone["pitch_deg"],
                                     speed_of_sound_m_s=settings.speed_of_sound_m_s)
    if kind in PATH_RECEIVERS and kind != "binaural":
        return array_early(arrivals, array_offsets(microphone), bank, n_samples,
                           settings.speed_of_sound_m_s)
    raise AcousticsError(f"microphone.kind: the early part of {kind!r} receivers is not "
                         f"separated (expected one of {', '.join(PATH_RECEIVERS)})")


def receiver_aperture_m(microphone: Mapping[str, Any]) -> float:
    """The largest path difference between two of a receiver's channels for one plane wave,
    metres: twice the farthest capsule's offset (arrays), Woodworth's lateral path
    ``a (π/2 + 1)`` (the sphere head), the speed of sound times a SOFA set's interaural
    delay bound (taken as a 0.2 m head's), 0 for coincident channels (mono, ambisonics)."""
    kind = microphone["kind"]
    if kind in ("mono", "ambisonics"):
        return 0.0
    if kind == "binaural":
        radius = microphone["hrtf"].get("head_radius_m", 0.1) if microphone["hrtf"][
            "kind"] == "sphere" else 0.1
        return radius * (np.pi / 2 + 1)
    return 2.0 * float(np.max(np.linalg.norm(array_offsets(microphone), axis=1)))


def direction_responses(directions: np.ndarray, settings: SimulationSettings,
                        microphone: Mapping[str, Any] = MONO, hrirs: HrirSet | None = None
                        ) -> np.ndarray:
    """Each direction's unit plane wave as the receiver renders it, ``(N, channels, taps)``:
    one flat arrival per direction (scene-frame directions of arrival), spaced ``taps``
    apart in one call to :func:`early_part` and cut apart, so every receiver, orientation and
    pattern the early part models applies (the diffuse background's per-direction responses,
    :mod:`sonicspec.acoustics.receivers.diffuse`). Each response sits wholly inside its
    ``taps`` (a power of two), after a lead common to all."""
    from sonicspec.acoustics.arrivals import KIND_DIRECT
    from sonicspec.acoustics.receivers.synthesis import DEFAULT_TAPS

    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    fs = settings.sample_rate_hz
    reach = receiver_aperture_m(microphone) / settings.speed_of_sound_m_s * fs
    lead = int(np.ceil(reach)) + DEFAULT_TAPS // 2 + 2
    h_len = 0
    if microphone["kind"] == "binaural" and microphone["hrtf"]["kind"] == "sofa":
        check_receiver(microphone, hrirs)
        h_len = hrirs.resampled(fs).hrirs.shape[-1]
    # The lead before, the same after, plus an HRIR's length and a sphere head's shadow
    # filter's ring (its poles decay within a few samples; 64 leave it below 1e-12).
    taps = 1 << int(np.ceil(np.log2(2 * lead + DEFAULT_TAPS + h_len + 64)))
    n = len(d)
    bank_bands = len(settings.bands_hz)
    arrivals = Arrivals((np.arange(n) * taps + lead) / fs, np.ones((n, bank_bands)), d,
                        np.zeros(n, dtype=np.int64), np.full(n, KIND_DIRECT, dtype=np.int8),
                        np.zeros(n))
    out = early_part(arrivals, settings, n * taps, microphone, hrirs)
    return np.ascontiguousarray(out.reshape(out.shape[0], n, taps).transpose(1, 0, 2))


# --- where a RIR ends (issue 19): kept apart from the paths above ----------------------------

def late_envelope(histogram: EnergyHistogram, settings: SimulationSettings
                  ) -> tuple[EnergyHistogram, TailReport]:
    """The late envelope one RIR is synthesised from: the tracer's histogram smoothed
    (:data:`LATE_ENVELOPE_RELATIVE_WIDTH`), each band's decay continued by the fit to its
    last 20 dB where the rays ran out, ending where every band is 60 dB below its early
    level or at the longest RIR allowed (:func:`~sonicspec.acoustics.late.tails.shape_tail`)."""
    late = histogram.smoothed(LATE_ENVELOPE_RELATIVE_WIDTH)
    rule = "auto" if settings.max_rir_length_s == "auto" else "fixed"
    return shape_tail(late, settings.bands_hz, rule, settings.rir_limit_s,
                      settings.rir_limit_field)


def warn_cut_tails(reports: list[TailReport], where: str) -> None:
    """One :class:`SonicspecWarning` for the RIRs of a call whose decay ``max_rir_cap_s``
    cut short (``max_rir_length_s: auto``): the scene, the bands and levels (of the worst
    position) and the field to raise. A number of seconds is taken as asked: a decay it cuts
    is reported in the RIR facts (``tail.level_at_limit_db``), without a warning."""
    cut = [r for r in reports if r.cut_bands_hz and r.rule == "auto"]
    if not cut:
        return
    worst = max(cut, key=lambda r: max(d.level_at_end_db for d in r.decays
                                       if d.level_at_end_db is not None))
    message = cut_warning(worst, where, positions=len(cut))
    if message:
        warnings.warn(message, SonicspecWarning, stacklevel=3)


@dataclass(frozen=True, eq=False)
class RirResult:
    """One RIR and the facts about it.

    Attributes
    ----------
    rir : (channels, samples) float32
        Sound pressure for a unit point source (free-field direct sound 1/(4πr) at r/c);
        channels as the receiver renders them (ACN/SN3D for ambisonics, left/right ears).
    sample_rate_hz : int
    bands_hz : tuple of float
        The octave bands simulated (and of the per-band figures).
    source_m, mic_m : tuple of float
        The positions, metres.
    arrivals : int
        Early arrivals rendered exactly: the direct sound, the image sources and the
        edge-diffracted paths.
    direct : {"visible", "through walls", "diffracted", "blocked"}
        The direct path: in sight, heard through transmitting surfaces, heard round edges
        (out of sight, with ``acoustics.diffraction``), or absent.
    image_source_order : int
        The image-source order completed (lower than asked when a scene has too many).
    image_source_order_asked : int
        The order the settings asked.
    image_source_order_stopped : str or None
        Why the completed order is lower than asked (``"order 3 needs more than 2,000,000
        candidates"``; the ray tracer covers the rest), None when it is not.
    escaped_ray_fraction : float
        Share of the traced energy that left the scene (a leaking mesh shows here).
    expected : dict
        T30, EDT and C50 per band of the energy the RIR was synthesised to have, without the
        late noise's draw (:func:`~sonicspec.acoustics.metrics.figures_from_energy`).
    traced_faces : int
        Triangles traced (after flat areas were merged).
    tail : TailFacts
        How the RIR's length was chosen
        (:class:`~sonicspec.acoustics.late.tails.TailFacts`):
        the rule (``auto`` or ``fixed``), the longest RIR allowed, per band when the decay
        is 60 dB down, where a fitted continuation starts (the rays ran out before), and the
        level a cut band reached at the limit.
    diffracted_paths : int
        Edge-diffracted arrivals among ``arrivals`` (0 with diffraction off).
    diffraction_edges : EdgeChoice or None
        How the diffracting edges were chosen (None with diffraction off):
        :class:`~sonicspec.acoustics.paths.edges.EdgeChoice` (found, kept, the rule,
        seams left out).
    """

    rir: np.ndarray
    sample_rate_hz: int
    bands_hz: tuple[float, ...]
    source_m: tuple[float, ...]
    mic_m: tuple[float, ...]
    arrivals: int
    direct: str
    image_source_order: int
    escaped_ray_fraction: float
    expected: dict[str, Any]
    traced_faces: int
    tail: TailFacts | None = None
    diffracted_paths: int = 0
    diffraction_edges: EdgeChoice | None = None
    image_source_order_asked: int | None = None
    image_source_order_stopped: str | None = None

    @cached_property
    def figures(self) -> RoomAcousticFigures:
        """ISO 3382-1 figures of the first channel (the omni W channel for ambisonics, the
        left ear for binaural), per band and broadband."""
        return room_acoustic_figures(self.rir[0], self.sample_rate_hz, self.bands_hz)

    @property
    def t30_s(self) -> np.ndarray:
        """T30 per band, seconds (NaN where the decay does not reach -35 dB)."""
        return self.figures.t30_s

    @property
    def edt_s(self) -> np.ndarray:
        """Early decay time per band, seconds."""
        return self.figures.edt_s

    @property
    def c50_db(self) -> np.ndarray:
        """Clarity C50 per band, dB."""
        return self.figures.c50_db

    @property
    def drr_db(self) -> float:
        """Direct-to-reverberant ratio, dB (broadband)."""
        return self.figures.drr_db

    @property
    def direct_visible(self) -> bool:
        """Whether the source is in sight of the microphone."""
        return self.direct == "visible"

    @property
    def distance_m(self) -> float:
        return float(np.linalg.norm(np.subtract(self.source_m, self.mic_m)))

    def to_dict(self) -> dict[str, Any]:
        """The facts, JSON-ready (what ``sonicspec rir --json`` prints, without the RIR)."""
        return {"arrivals": self.arrivals, "direct": self.direct,
                "image_source_order": self.image_source_order,
                "image_source_order_asked": self.image_source_order_asked,
                "image_source_order_stopped": self.image_source_order_stopped,
                "escaped_ray_fraction": self.escaped_ray_fraction, "expected": self.expected,
                "source_m": list(self.source_m), "mic_m": list(self.mic_m),
                "channels": int(self.rir.shape[0]), "distance_m": self.distance_m,
                "sample_rate_hz": self.sample_rate_hz, "samples": int(self.rir.shape[-1]),
                "traced_triangles": self.traced_faces, "diffracted_paths": self.diffracted_paths,
                "diffraction_edges": (None if self.diffraction_edges is None
                                      else self.diffraction_edges.to_dict()),
                "figures": self.figures.to_dict(),
                "length_s": self.rir.shape[-1] / self.sample_rate_hz,
                "tail": {} if self.tail is None else self.tail.to_dict()}


def rir_results(scene: AcousticScene, mic_m: np.ndarray, sources_m: np.ndarray,
                settings: SimulationSettings, rng: np.random.Generator,
                microphone: Mapping[str, Any] | None = None, hrirs: HrirSet | None = None,
                n_threads: int = 1, where: str = "the scene",
                directivity: SourceDirectivity | None = None) -> list[RirResult]:
    """:func:`simulate_rirs` for a few positions, each RIR with its facts and figures.

    Parameters and randomness as :func:`simulate_rirs` (with ``expected_figures``), whose
    RIRs these are, byte for byte; ``directivity``: one directional source at every position
    (its ``yaw_deg`` one yaw, or one per position).

    Returns
    -------
    list of RirResult
        One per source position.
    """
    points = np.asarray(sources_m, dtype=np.float64).reshape(-1, 3)
    per_point = None if directivity is None else [
        SourceDirectivity(directivity.pattern, directivity.yaw_at(k) if
                          directivity.yaw_deg.ndim else directivity.yaw_deg,
                          directivity.pitch_deg) for k in range(len(points))]
    rirs, facts = simulate_rirs(scene, mic_m, points, settings, rng, microphone=microphone,
                                hrirs=hrirs, n_threads=n_threads, expected_figures=True,
                                where=where, directivity=per_point)
    mic = tuple(float(v) for v in np.asarray(mic_m, dtype=np.float64).reshape(3))
    return [RirResult(rir=rir, sample_rate_hz=settings.sample_rate_hz,
                      bands_hz=tuple(settings.bands_hz),
                      source_m=tuple(float(v) for v in point), mic_m=mic,
                      arrivals=f.arrivals, direct=f.direct,
                      image_source_order=f.image_source_order,
                      escaped_ray_fraction=f.escaped_ray_fraction, expected=f.expected or {},
                      traced_faces=scene.n_faces, tail=f.tail,
                      diffracted_paths=f.diffracted_paths,
                      diffraction_edges=f.diffraction_edges,
                      image_source_order_asked=f.image_source_order_asked,
                      image_source_order_stopped=f.image_source_order_stopped)
            for rir, f, point in zip(rirs, facts, points, strict=True)]


Renderer = Callable[[Arrivals, Any, np.random.Generator], np.ndarray]


def receiver_renderer(microphone: Mapping[str, Any], settings: SimulationSettings,
                      hrirs: HrirSet | None = None) -> Renderer:
    """A function ``(arrivals, late histogram, rng) -> (channels, samples)`` for the
    receiver kind of ``microphone`` (the spec's microphone fields)."""
    from sonicspec.acoustics.receivers.arrays import (
        synthesize_ambisonic_rir,
        synthesize_array_rir,
    )

    common = {"max_length_s": settings.rir_limit_s, "bands_hz": settings.bands_hz}
    fs = settings.sample_rate_hz
    kind = microphone["kind"]
    capsules = scene_capsules(microphone)
    if capsules is not None and capsules.sphere_radius_m is not None:
        from sonicspec.acoustics.receivers.hrtf import synthesize_sphere_array_rir

        return lambda a, h, rng: synthesize_sphere_array_rir(
            a, h, capsules, fs, rng, speed_of_sound_m_s=settings.speed_of_sound_m_s, **common)
    if capsules is not None:  # directional capsules in free field (a mono one too)
        return lambda a, h, rng: synthesize_array_rir(
            a, h, capsules.offsets_m, fs, rng, speed_of_sound_m_s=settings.speed_of_sound_m_s,
            capsules=capsules, **common)
    if kind == "mono":
        return lambda a, h, rng: synthesize_rir(a, h, fs, rng, **common)[None, :]
    if kind == "ambisonics":
        return lambda a, h, rng: synthesize_ambisonic_rir(
            a, h, microphone["order"], fs, rng, yaw_deg=microphone["yaw_deg"],
            pitch_deg=microphone["pitch_deg"], **common)
    if kind == "binaural":
        from sonicspec.acoustics.receivers.hrtf import (
            synthesize_hrir_binaural_rir,
            synthesize_sphere_binaural_rir,
        )

        hrtf = microphone["hrtf"]
        orientation = {"yaw_deg": microphone["yaw_deg"], "pitch_deg": microphone["pitch_deg"]}
        if hrtf["kind"] == "sofa":
            return lambda a, h, rng: synthesize_hrir_binaural_rir(
                a, h, hrirs, fs, rng, **orientation, **common)
        head = sphere_head(microphone)
        return lambda a, h, rng: synthesize_sphere_binaural_rir(
            a, h, head, fs, rng, speed_of_sound_m_s=settings.speed_of_sound_m_s, **orientation,
            **common)
    offsets = array_offsets(microphone)
    return lambda a, h, rng: synthesize_array_rir(
        a, h, offsets, fs, rng, speed_of_sound_m_s=settings.speed_of_sound_m_s, **common)


def array_offsets(microphone: Mapping[str, Any]) -> np.ndarray:
    """Where an array microphone's capsules are, ``(M, 3)`` offsets from its centre in the
    scene's frame, metres."""
    from sonicspec.acoustics.receivers.arrays import capsule_offsets, rotation

    if microphone["kind"] == "device":
        return microphone_capsules(microphone).rotated(
            rotation(microphone["yaw_deg"], microphone["pitch_deg"])).offsets_m
    return capsule_offsets(
        microphone["kind"], n=microphone.get("n", 0), spacing_m=microphone.get("spacing_m", 0.0),
        radius_m=microphone.get("radius_m", 0.0), positions_m=microphone.get("positions_m", ()),
        yaw_deg=microphone["yaw_deg"], pitch_deg=microphone["pitch_deg"])


def _capsule_axis(capsule: Mapping[str, Any], offset: np.ndarray) -> np.ndarray:
    """A capsule's axis in the array's frame from the spec's ``capsule`` fields."""
    from sonicspec.acoustics.receivers.capsules import unit_axis

    if capsule.get("axis") is not None:
        axis = np.asarray(capsule["axis"], dtype=np.float64)
        return axis / np.linalg.norm(axis)
    base = 0.0
    if capsule.get("facing", "front") == "outward" and np.hypot(offset[0], offset[1]) > 1e-9:
        base = float(np.degrees(np.arctan2(offset[1], offset[0])))
    return unit_axis(base + float(capsule.get("azimuth_deg", 0.0)),
                     float(capsule.get("elevation_deg", 0.0)))


def microphone_capsules(microphone: Mapping[str, Any]):
    """The :class:`~sonicspec.acoustics.receivers.capsules.Capsules` of a mono, array or
    device microphone (the spec's fields) in its own frame (not yet turned by its yaw and
    pitch): offsets, axes and patterns; a device's from its preset
    (:func:`~sonicspec.acoustics.receivers.devices.device`). None for binaural and
    ambisonic receivers."""
    from sonicspec.acoustics.receivers.arrays import capsule_offsets
    from sonicspec.acoustics.receivers.capsules import Capsules, pattern_alpha
    from sonicspec.acoustics.receivers.devices import device

    kind = microphone["kind"]
    if kind == "device":
        return device(microphone["device"]).capsules
    if kind not in ("mono", "linear_array", "circular_array", "custom"):
        return None
    offsets = capsule_offsets(
        kind, n=microphone.get("n", 0), spacing_m=microphone.get("spacing_m", 0.0),
        radius_m=microphone.get("radius_m", 0.0), positions_m=microphone.get("positions_m", ()))
    specs = microphone.get("capsules") or [microphone.get("capsule") or {}] * len(offsets)
    axes = np.array([_capsule_axis(c, o) for c, o in zip(specs, offsets, strict=True)])
    alphas = np.array([pattern_alpha(c.get("pattern", "omni")) for c in specs])
    return Capsules(offsets, axes, alphas)


def capsule_facts(microphone: Mapping[str, Any]) -> dict[str, Any] | None:
    """The microphone's capsules as plain data, in its own frame: ``device`` (the preset or
    None), ``sphere_radius_m`` (None in free field) and ``capsules``, per channel a
    ``position_m``, a ``pattern`` name and an ``axis`` (rounded to 1 µm / 1e-6); None when
    every capsule is omni in free field and no device is named (nothing to record)."""
    from sonicspec.acoustics.receivers.capsules import PATTERNS

    caps = microphone_capsules(microphone)
    if caps is None or (caps.omni and microphone["kind"] != "device"):
        return None
    names = {alpha: name for name, alpha in PATTERNS.items()}

    def vec(v: np.ndarray) -> list[float]:
        return [round(float(x), 6) + 0.0 for x in v]

    return {"device": microphone.get("device"), "sphere_radius_m": caps.sphere_radius_m,
            "capsules": [{"position_m": vec(p), "pattern": names[float(a)], "axis": vec(u)}
                         for p, a, u in zip(caps.offsets_m, caps.alphas, caps.axes,
                                            strict=True)]}


def scene_capsules(microphone: Mapping[str, Any]):
    """:func:`microphone_capsules` turned into the scene's frame by the microphone's yaw and
    pitch; None where the receiver has no capsules or every capsule is omni in free field
    (the plain array renderer's case, bit for bit as before capsules had patterns)."""
    from sonicspec.acoustics.receivers.arrays import rotation

    capsules = microphone_capsules(microphone)
    if capsules is None or capsules.omni:
        return None
    return capsules.rotated(rotation(microphone["yaw_deg"], microphone["pitch_deg"]))


def needs_directions(microphone: Mapping[str, Any]) -> bool:
    """Whether the receiver needs each path's direction of arrival: all but a mono
    microphone with an omni capsule."""
    return microphone["kind"] != "mono" or scene_capsules(microphone) is not None


PATH_RECEIVERS = ("mono", "linear_array", "circular_array", "custom", "ambisonics",
                  "binaural", "device")
"""Receivers whose early paths a moving source's renderer follows (``keep_arrivals``):
every kind (binaural with the sphere head or a SOFA HRTF set)."""


def sphere_head(microphone: Mapping[str, Any]):
    """The :class:`~sonicspec.acoustics.receivers.hrtf.SphereHead` of a binaural microphone with the
    sphere-head model."""
    from sonicspec.acoustics.receivers.hrtf import SphereHead

    hrtf = microphone["hrtf"]
    return SphereHead(head_radius_m=hrtf["head_radius_m"], ear_angle_deg=hrtf["ear_angle_deg"])


RENDERED_KINDS = ("mono", "linear_array", "circular_array", "custom", "ambisonics",
                  "binaural", "device")


def load_hrirs(path: str | Path) -> HrirSet:
    """The measured HRIR set of a SOFA file (SimpleFreeFieldHRIR), read with ``sofar``.

    Raises
    ------
    AcousticsError
        ``sofar`` is not installed, the file is missing or unreadable, or it holds no
        usable HRIR set; the message names the file.
    """
    from sonicspec.acoustics.receivers.hrtf import hrir_set_from_sofa

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


def load_source_directivity(path: str | Path, bands_hz, name: str | None = None):
    """A measured source pattern from a SOFA ``FreeFieldDirectivityTF`` file
    (:meth:`~sonicspec.acoustics.directivity.SofaPattern.from_sofa`) at ``bands_hz``."""
    from sonicspec.acoustics.directivity import SofaPattern

    try:
        import sofar
    except ImportError as err:  # pragma: no cover - sofar is a dependency
        raise AcousticsError("a SOFA source directivity needs sofar (pip install sofar)"
                             ) from err
    try:
        sofa = sofar.read_sofa(str(path), verbose=False)
    except Exception as err:  # sofar raises many kinds for a file that is not SOFA
        raise AcousticsError(f"{path}: cannot read it as a SOFA file ({err})") from None
    return SofaPattern.from_sofa(sofa, bands_hz, name=name or Path(path).name)


def check_inside(vertices: np.ndarray, where: str, **points: Any) -> None:
    """Refuse positions outside the bounding box of a scene's ``vertices``.

    Raises
    ------
    AcousticsError
        Naming the position (the keyword it came as), the scene (``where``) and its bounds.
    """
    lo, hi = np.min(vertices, axis=0), np.max(vertices, axis=0)
    for name, p in points.items():
        if np.any(np.asarray(p) < lo) or np.any(np.asarray(p) > hi):
            raise AcousticsError(f"{name}: {list(p)} is outside {where} "
                                 f"(bounds {lo.round(2).tolist()} .. {hi.round(2).tolist()})")


def check_receiver(microphone: Mapping[str, Any], hrirs: HrirSet | None = None) -> None:
    """Refuse receivers this version cannot render (or that lack their HRIR set).

    Raises
    ------
    AcousticsError
        A SOFA HRTF without its loaded set, or a kind outside :data:`RENDERED_KINDS`.
    """
    if (microphone["kind"] == "binaural" and microphone["hrtf"]["kind"] == "sofa"
            and hrirs is None):
        raise AcousticsError("microphone.hrtf: a SOFA HRTF needs its HRIR set loaded "
                             "(load_hrirs) before RIRs can be rendered")
    if microphone["kind"] not in RENDERED_KINDS:
        raise AcousticsError(f"microphone.kind: RIRs for {microphone['kind']!r} receivers are "
                             "not in this version of sonicspec; use one of "
                             f"{', '.join(RENDERED_KINDS)}")


#: How finely :func:`refined_early_paths` locates where a path appears or disappears between
#: two RIR points (metres of either end's movement): a path cut off by an edge is cut there
#: within this, not faded over the RIR spacing.
PATH_RESOLUTION_M = 0.01
#: ... and where a path's band factor changes by more than this between two points (dB).
PATH_TOLERANCE_DB = 1.0


@dataclass(frozen=True, eq=False)
class RefinedPaths:
    """Early arrivals at the RIR points and at points added between them where the paths
    change: ``at_index`` (sorted) is each point's fractional index along the RIR points."""

    at_index: np.ndarray
    sources_m: np.ndarray
    mics_m: np.ndarray
    from_mic: list[Arrivals]
    at_mic: list[Arrivals]


def refined_early_paths(scene: AcousticScene, settings: SimulationSettings, sources_m,
                        mics_m, from_mic: list[Arrivals], at_mic: list[Arrivals], *,
                        regions=None, directional: bool = False,
                        image_source_order: int | None = None,
                        resolution_m: float = PATH_RESOLUTION_M,
                        tolerance_db: float = PATH_TOLERANCE_DB) -> RefinedPaths:
    """Where between two consecutive RIR points a path appears or disappears (a wall or an
    edge comes between the source and the microphone, a reflection leaves its wall) or its
    band factor changes by more than ``tolerance_db`` (a diffracted path near its shadow
    boundary) — among the paths within 40 dB of the loudest
    (:func:`~sonicspec.acoustics.moving.delays.paths_differ`) — the interval is halved
    (:func:`early_arrivals` at its middle, no ray trace) until neither end moves more than
    ``resolution_m`` across it: the renderer then switches and shapes the path there, as the
    geometry does, instead of fading it over the spacing.

    ``sources_m``, ``mics_m``: ``(N, 3)`` the source and the microphone at each RIR point;
    ``from_mic``, ``at_mic``: their early arrivals (:class:`EarlyArrivals`).
    """
    from sonicspec.acoustics.moving.delays import heard_paths, paths_differ

    src = np.asarray(sources_m, dtype=np.float64).reshape(-1, 3)
    mic = np.asarray(mics_m, dtype=np.float64).reshape(-1, 3)
    if settings.diffraction and not settings.diffraction_focus_m:
        # the edges the RIR points' arrivals were found with (:func:`simulate_rirs` chooses
        # them for its microphone and sources), so the points added share them
        settings = with_diffraction_focus(settings, src, mic)
    moving = bool(np.any(mic != mic[:1]))
    at = np.arange(len(src), dtype=np.float64)
    known: dict[float, tuple[np.ndarray, np.ndarray, Arrivals, Arrivals, dict]] = {
        float(j): (src[j], mic[j], from_mic[j], at_mic[j],
                   heard_paths(from_mic[j], src[j], moving)) for j in range(len(src))}

    def place(x: float) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([np.interp(x, at, src[:, i]) for i in range(3)]),
                np.array([np.interp(x, at, mic[:, i]) for i in range(3)]))

    segments = [(float(j), float(j + 1)) for j in range(len(src) - 1)
                if paths_differ(known[float(j)][4], known[float(j + 1)][4], tolerance_db)]
    while segments:
        wide = [(a, b) for a, b in segments
                if max(np.linalg.norm(known[b][0] - known[a][0]),
                       np.linalg.norm(known[b][1] - known[a][1])) > resolution_m]
        if not wide:
            break
        middles = [0.5 * (a + b) for a, b in wide]
        places = [place(x) for x in middles]
        by_mic: dict[tuple, list[int]] = {}
        for i, (_, m) in enumerate(places):
            by_mic.setdefault(tuple(m.tolist()), []).append(i)
        for m, idx in by_mic.items():
            early = early_arrivals(scene, np.asarray(m), np.array([places[i][0] for i in idx]),
                                   settings, regions, directional, image_source_order)
            for n, i in enumerate(idx):
                known[middles[i]] = (places[i][0], places[i][1], early.from_mic[n],
                                     early.at_mic[n],
                                     heard_paths(early.from_mic[n], places[i][0], moving))
        segments = []
        for (a, b), x in zip(wide, middles, strict=True):
            if paths_differ(known[a][4], known[x][4], tolerance_db):
                segments.append((a, x))
            if paths_differ(known[x][4], known[b][4], tolerance_db):
                segments.append((x, b))
    order = sorted(known)
    return RefinedPaths(np.asarray(order), np.array([known[x][0] for x in order]),
                        np.array([known[x][1] for x in order]),
                        [known[x][2] for x in order], [known[x][3] for x in order])
