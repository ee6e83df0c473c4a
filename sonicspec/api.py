"""The public Python API: a scene with materials, and its RIRs, without a dataset spec.

>>> import sonicspec as ss
>>> scene = ss.Scene.shoebox(size_m=[6.0, 4.0, 3.0], materials={"floor": "carpet_on_concrete"})
>>> result = ss.compute_rir(scene, source=[1.0, 2.0, 1.5], mic=[4.0, 2.0, 1.5],
...                         settings=ss.RirSettings(rays=2000), seed=0)
>>> result.rir.shape[0], result.direct
(1, 'visible')

A scene comes from a mesh file (:meth:`Scene.from_file`, faces labelled by their object or
group names or a PLY face property, each label mapped to a material), a procedural room
(:meth:`Scene.shoebox`) or any :class:`~sonicspec.geometry.mesh.SceneMesh`
(:meth:`Scene.from_mesh`). :func:`compute_rir` simulates one source, :func:`compute_rirs` many
with one trace. The receiver is mono unless given as one of the spec's microphone models (or
its fields as a mapping): arrays, ambisonics, binaural.

Everything here calls what the pipeline's stages call (``geometry.io.load_mesh``,
``geometry.materials.assign_materials``, ``acoustics.engine``), with the spec's own defaults
(:class:`RirSettings` is the spec's ``acoustics`` section plus the sample rate and the speed
of sound). Nothing is repaired unless asked, nothing is written, and the only randomness is
the ``seed`` given.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, TypeAdapter

from sonicspec.acoustics.engine import (
    RirResult,
    SimulationSettings,
    acoustic_scene,
    check_inside,
    load_hrirs,
    rir_results,
)
from sonicspec.errors import GeometryError
from sonicspec.geometry.io import WELD_DISTANCE_M
from sonicspec.geometry.materials import MaterialLibrary, assign_materials, material_library
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.repair import LeakReport, WeldReport, weld_seams
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.load import did_you_mean
from sonicspec.spec.materials import CustomMaterialSpec, MaterialsSpec
from sonicspec.spec.microphone import MicrophoneSpec
from sonicspec.spec.scene import (
    MeshObstacleSpec,
    MeshSceneSpec,
    RepairSpec,
    SceneSpec,
    SurfaceMaterialsSpec,
)

__all__ = ["RirResult", "RirSettings", "Scene", "compute_rir", "compute_rirs"]


class RirSettings(AcousticsSpec):
    """Simulation settings: the spec's ``acoustics`` section (same fields, same defaults),
    the sample rate and the speed of sound (the spec's defaults: 16 kHz, 343 m/s)."""

    sample_rate_hz: int = DatasetSpec.model_fields["sample_rate_hz"]
    speed_of_sound_m_s: float = DatasetSpec.model_fields["speed_of_sound_m_s"]

    def simulation_settings(self) -> SimulationSettings:
        """The engine's settings (``bands_hz: auto`` resolved for the sample rate)."""
        return SimulationSettings.from_spec(self.model_dump(mode="json"), self.sample_rate_hz,
                                            self.speed_of_sound_m_s)


_MICROPHONE = TypeAdapter(MicrophoneSpec)
_CUSTOM = TypeAdapter(dict[str, CustomMaterialSpec])


def _library(name: str, custom: Mapping[str, Any] | None,
             scattering: Sequence[float] | None = None) -> MaterialLibrary:
    """A built-in library plus materials given like the spec's ``materials.custom`` (one
    value for all bands allowed; scattering 0.1 and transmission 0 by default), and every
    material's scattering replaced by ``scattering`` (the spec's
    ``materials.scattering_override``) when given."""
    dumped = {k: v.model_dump(mode="json") for k, v in _CUSTOM.validate_python(
        dict(custom or {})).items()}
    return material_library(name, dumped, scattering)


def _check_material(library: MaterialLibrary, name: str, where: str) -> None:
    if name not in library.materials:
        raise GeometryError(f"{where}: expected a material of library {library.name!r}, got "
                            f"{name!r}" + did_you_mean(name, list(library.materials)))


@dataclass(frozen=True, eq=False)
class Scene:
    """A scene mesh whose faces have materials, and the library the names resolve in.

    Build one with :meth:`from_file`, :meth:`shoebox` or :meth:`from_mesh`.

    Attributes
    ----------
    mesh : SceneMesh
        Metres, z up, normals into the air; ``mesh.materials`` are names in ``library``.
    library : MaterialLibrary
        A built-in library, with the user's own materials added.
    name : str
        What messages call the scene (the file name of a mesh file).
    weld : WeldReport or None
        What loading joined (:meth:`from_file`): vertices merged, T-junctions stitched, open
        edges before and after; None for scenes not read from a file.
    """

    mesh: SceneMesh
    library: MaterialLibrary
    name: str = "scene"
    weld: WeldReport | None = None

    def __post_init__(self) -> None:
        for material in self.mesh.materials:
            _check_material(self.library, material, f"scene {self.name!r}")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_file(cls, path: str | Path, materials: Mapping[str, str] | None = None, *,
                  default_material: str | None = None, library: str = "sonicspec",
                  custom_materials: Mapping[str, Any] | None = None, up_axis: str = "auto",
                  unit_scale: float = 1.0, repair: bool | RepairSpec = False,
                  weld_distance_m: float = WELD_DISTANCE_M) -> Scene:
        """A scene from a glb, gltf, ply or obj file, its labels mapped to materials.

        Parameters
        ----------
        path
            The mesh file. Labels: obj objects (``o name``; a lone object keeps its name) or,
            in a file without objects, groups (``g name``); glb/gltf mesh names; a PLY
            integer face property ``label``/``category``.
        materials : mapping, optional
            Label -> material name. Labels it does not name take the library's label rule
            (mpcat40 categories in ``sonicspec``, SonicSet's substring rule in
            ``sonicset``), else the library's default, with a warning.
        default_material : str, optional
            Material of faces without a label.
        library : {"sonicspec", "sonicset"}
            The built-in material library.
        custom_materials : mapping, optional
            Name -> ``{"absorption": ..., "scattering": ..., "transmission": ...}``, one
            value or seven (125 Hz–8 kHz) each, as the spec's ``materials.custom``.
        up_axis, unit_scale
            As :func:`sonicspec.geometry.io.load_mesh`.
        repair : bool or RepairSpec
            Run the geometry library's repair (:func:`~sonicspec.geometry.repair.repair_mesh`
            with the spec's ``repair`` settings, default or given); off by default.
        weld_distance_m : float
            Seams are joined on load whatever ``repair`` says: vertices of open edges closer
            than this (metres, default 0.1 mm), across objects, groups and meshes, and the
            T-junctions along them (:func:`~sonicspec.geometry.repair.weld_seams`; what was
            joined is :attr:`weld`). 0 keeps the file's vertices.

        Raises
        ------
        GeometryError
            An unreadable file; a label ``materials`` names that the mesh does not have; a
            material name that is not in the library (with a did-you-mean hint).

        Warns
        -----
        SonicspecWarning
            Faces fell back to the library's default material (labels and area share).
        """
        from sonicspec.geometry.io import load_mesh

        path = Path(path)
        lib = _library(library, custom_materials)
        mapping = dict(materials or {})
        for label, name in mapping.items():
            _check_material(lib, name, f"materials[{label!r}]")
        if default_material is not None:
            _check_material(lib, default_material, "default_material")
        mesh, weld = weld_seams(load_mesh(path, up_axis, unit_scale, obj_labels=True,
                                          weld_distance_m=0.0), weld_distance_m)
        _check_labels(mapping, mesh, path.name)
        mesh = assign_materials(mesh, lib, mapping, default_material, where=path.name)
        if repair is not False:
            mesh = _repaired(mesh, RepairSpec() if repair is True else repair)
        return cls(mesh, lib, path.name, weld)

    @classmethod
    def shoebox(cls, size_m: Sequence[float], materials: Mapping[str, str] | None = None, *,
                library: str = "sonicspec", custom_materials: Mapping[str, Any] | None = None
                ) -> Scene:
        """A closed box room ``[0, x] × [0, y] × [0, z]``, metres.

        Parameters
        ----------
        size_m : (3,) float
            Length, width and height, metres.
        materials : mapping, optional
            ``walls``, ``floor``, ``ceiling`` -> material name (the spec's defaults for the
            ones not given).
        library, custom_materials
            As :meth:`from_file`.
        """
        from sonicspec.geometry.procedural import shoebox

        lib = _library(library, custom_materials)
        given = dict(materials or {})
        surfaces = tuple(SurfaceMaterialsSpec.model_fields)
        for key in given:
            if key not in surfaces:
                raise GeometryError(f"materials: expected keys among {', '.join(surfaces)}, "
                                    f"got {key!r}" + did_you_mean(key, surfaces))
        room = SurfaceMaterialsSpec(**given)
        mesh = shoebox(size_m, wall_material=room.walls, floor_material=room.floor,
                       ceiling_material=room.ceiling)
        return cls(mesh, lib, "shoebox")

    @classmethod
    def from_mesh(cls, mesh: SceneMesh, materials: Mapping[str, str] | None = None, *,
                  default_material: str | None = None, library: str = "sonicspec",
                  custom_materials: Mapping[str, Any] | None = None, name: str = "scene"
                  ) -> Scene:
        """A scene of a :class:`SceneMesh` (e.g. from :mod:`sonicspec.geometry.procedural`).

        Without ``materials`` and ``default_material`` the mesh keeps its materials;
        with them, its labels are mapped as in :meth:`from_file`.
        """
        lib = _library(library, custom_materials)
        if materials is not None or default_material is not None:
            mapping = dict(materials or {})
            _check_labels(mapping, mesh, name)
            mesh = assign_materials(mesh, lib, mapping, default_material, where=name)
        return cls(mesh, lib, name)

    @classmethod
    def from_spec(cls, scene: SceneSpec, materials: MaterialsSpec | None = None, *,
                  base_dir: str | Path = ".", seed: int = 0) -> Scene:
        """A scene as a dataset spec (or a scene file) declares it, built as a build builds
        it: a procedural room with its obstacles, or a mesh file with its label map, repaired
        and leak-tested per the scene's ``repair`` settings.

        Parameters
        ----------
        scene
            One of the spec's scene models (``ShoeboxSceneSpec``, ``MeshSceneSpec``, ...).
            A mesh scene's ``path`` names one file (not a glob).
        materials
            The spec's ``materials`` section (library, custom materials, label map; a mesh
            scene's own ``label_materials`` win).
        base_dir
            What the scene's relative paths are relative to (the spec file's folder).
        seed
            Seeds the leak test of a mesh scene.
        """
        import glob

        from sonicspec.artifacts.scenes import build_scene_mesh
        from sonicspec.hashing import rng_for
        from sonicspec.plan.params import MeshParams

        materials = materials or MaterialsSpec()
        base = Path(base_dir)
        paths = {f"obstacle{j}": str(base / ob.path) for j, ob in enumerate(scene.obstacles)
                 if isinstance(ob, MeshObstacleSpec)}
        extra: dict[str, Any] = {}
        if isinstance(scene, MeshSceneSpec):
            if glob.has_magic(scene.path):
                raise GeometryError(f"scene {scene.id!r}: path {scene.path!r} is a glob; a "
                                    "single scene names one file")
            file = base / scene.path
            if not file.is_file():
                raise GeometryError(f"scene {scene.id!r}: mesh file {file} does not exist")
            paths["mesh"] = str(file)
            stem = file.with_suffix("")
            for role, beside in (("semantic", Path(f"{stem}_semantic.ply")),
                                 ("house", stem.with_suffix(".house"))):
                if scene.format != "plain" and beside.is_file():
                    paths[role] = str(beside)
            extra = {"library": materials.library, "obj_labels": True,
                     "label_materials": {**materials.label_materials, **scene.label_materials}}
        params = MeshParams.model_validate({
            "scene": scene.model_dump(mode="json", exclude={"id", "path"}), "files": {},
            "scene_id": scene.id, **extra})
        lib = _library(materials.library, materials.model_dump(mode="json")["custom"],
                       materials.scattering_override)
        mesh, _ = build_scene_mesh(params, paths, rng_for(seed, "mesh", scene.id))
        return cls(mesh, lib, scene.id)

    # ------------------------------------------------------------------ facts
    @property
    def labels(self) -> tuple[str, ...]:
        """The face labels (empty when the mesh has none)."""
        return self.mesh.labels

    def leak_test(self, rays: int = 10_000, *, points: Sequence[Sequence[float]] | None = None,
                  seed: int | np.random.Generator = 0) -> LeakReport:
        """Whether sound can leave the scene: rays from the air that sources and receivers
        reach (points 0.3–2 m above floors and other upward-facing surfaces, never inside a
        closed solid), or from ``points`` (e.g. your sources and microphones, metres); the
        share that escapes or meets a face from behind, and where
        (:func:`~sonicspec.geometry.repair.leak_test`; ``report.where()`` in words)."""
        from sonicspec.geometry.repair import leak_test

        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        interior = None if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return leak_test(self.mesh, rng, rays, interior_points=interior)

    def material_areas_m2(self) -> dict[str, float]:
        """Surface area per material, m², largest first."""
        areas = self.mesh.face_areas
        out = {name: float(areas[self.mesh.face_material == i].sum())
               for i, name in enumerate(self.mesh.materials)}
        return dict(sorted(out.items(), key=lambda kv: -kv[1]))

    def __repr__(self) -> str:
        lo, hi = self.mesh.bounds
        return (f"Scene({self.name!r}, {self.mesh.n_faces} faces, bounds {lo.round(2).tolist()}"
                f" .. {hi.round(2).tolist()} m, materials {list(self.mesh.materials)}, "
                f"library {self.library.name!r})")


def _check_labels(materials: Mapping[str, str], mesh: SceneMesh, where: str) -> None:
    for label in materials:
        if label in mesh.labels:
            continue
        if not mesh.labels:
            raise GeometryError(f"materials: expected labels of {where}, got {label!r}; the "
                                "mesh has no labels (name its objects or groups, or give "
                                "default_material)")
        raise GeometryError(f"materials: expected labels of {where} "
                            f"({', '.join(map(repr, mesh.labels))}), got {label!r}"
                            + did_you_mean(label, mesh.labels))


def _repaired(mesh: SceneMesh, repair: RepairSpec) -> SceneMesh:
    from sonicspec.geometry.repair import RepairSettings, repair_mesh

    repaired, _ = repair_mesh(mesh, RepairSettings.from_spec(repair.model_dump(mode="json")))
    return repaired


def _receiver(receiver: BaseModel | Mapping[str, Any] | None) -> dict[str, Any]:
    """The spec's microphone fields of a receiver given as a model or a mapping."""
    if receiver is None:
        receiver = {"kind": "mono"}
    if not isinstance(receiver, BaseModel):
        receiver = _MICROPHONE.validate_python(dict(receiver))
    return receiver.model_dump(mode="json")


def compute_rirs(scene: Scene, sources: Sequence[Sequence[float]] | np.ndarray,
                 mic: Sequence[float], settings: RirSettings | None = None, *,
                 receiver: BaseModel | Mapping[str, Any] | None = None,
                 seed: int | np.random.Generator = 0, hrirs=None,
                 n_threads: int = 1, directivity=None) -> list[RirResult]:
    """RIRs from several source positions to one microphone, from one trace.

    Parameters and results as :func:`compute_rir`, with ``sources`` of shape (N, 3).
    """
    sim = (settings or RirSettings()).simulation_settings()
    microphone = _receiver(receiver)
    if hrirs is None and microphone["kind"] == "binaural" and microphone["hrtf"]["kind"] == "sofa":
        hrirs = load_hrirs(microphone["hrtf"]["path"])
    points = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    mic_m = np.asarray(mic, dtype=np.float64).reshape(3)
    check_inside(scene.mesh.vertices, f"scene {scene.name!r}", mic=mic_m.tolist(),
                 **{f"sources[{k}]" if len(points) > 1 else "source": p.tolist()
                    for k, p in enumerate(points)})
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    traced = acoustic_scene(scene.mesh, scene.library, sim)
    return rir_results(traced, mic_m, points, sim, rng, microphone=microphone, hrirs=hrirs,
                       n_threads=n_threads, where=f"scene {scene.name!r}",
                       directivity=directivity)


def compute_rir(scene: Scene, source: Sequence[float], mic: Sequence[float],
                settings: RirSettings | None = None, *,
                receiver: BaseModel | Mapping[str, Any] | None = None,
                seed: int | np.random.Generator = 0, hrirs=None,
                n_threads: int = 1, directivity=None) -> RirResult:
    """The RIR from ``source`` to ``mic`` in ``scene``, with its figures.

    Parameters
    ----------
    scene : Scene
        The room and its materials.
    source, mic : (3,) float
        Positions in the scene, metres.
    settings : RirSettings, optional
        Rays, image-source order, RIR length, air, bands, sample rate (the spec's defaults
        when not given).
    receiver : microphone model or mapping, optional
        One of the spec's microphone models (``MonoMicSpec``, ``AmbisonicsMicSpec``, ...) or
        its fields as a mapping, e.g. ``{"kind": "ambisonics", "order": 1}`` or
        ``{"kind": "binaural"}`` (the rigid-sphere head; ``{"kind": "binaural", "hrtf":
        {"kind": "sofa", "path": "subject.sofa"}}`` reads a SOFA file), directional capsules
        (``{"kind": "mono", "capsule": {"pattern": "cardioid"}}``) or a device preset
        (``{"kind": "device", "device": "em32"}``). Default: mono.
    seed : int or numpy.random.Generator
        The simulation's only randomness (rays, the late noise): the same seed, settings and
        scene give the same bytes.
    hrirs : HrirSet, optional
        A measured HRIR set already loaded (instead of the receiver's SOFA path).
    n_threads : int
        Threads for the ray trace (the bytes do not depend on it).
    directivity : SourceDirectivity, optional
        A directional source: its pattern and where it faces
        (:class:`sonicspec.acoustics.directivity.SourceDirectivity`, e.g.
        ``SourceDirectivity(pattern_by_name("speech"), yaw_deg=90.0)``); default omni.

    Returns
    -------
    RirResult
        ``rir`` ``(channels, samples)`` float32 and ``sample_rate_hz``; ``t30_s``,
        ``edt_s``, ``c50_db`` per band of ``bands_hz`` and ``drr_db`` (first channel, ISO
        3382-1); ``arrivals`` (early arrivals), ``direct`` / ``direct_visible``;
        ``to_dict()`` for all of it as JSON.

    Raises
    ------
    AcousticsError
        A position outside the scene's bounds, or a receiver this version cannot render.
    """
    (result,) = compute_rirs(scene, [source], mic, settings, receiver=receiver, seed=seed,
                             hrirs=hrirs, n_threads=n_threads, directivity=directivity)
    return result
