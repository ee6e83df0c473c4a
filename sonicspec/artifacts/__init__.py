"""What stages hand each other: one model per artifact's data, read and written here only.

A floor below both the stages and the export (docs/architecture.md): the steps encode and
decode through it, the report decodes through it and the Python API builds scenes with it
(:mod:`.scenes`: a spec's scene built into the mesh a mesh job stores), so nothing outside
the stages and the command line imports :mod:`sonicspec.stages`.

An artifact in the store (:mod:`sonicspec.store`) is a set of arrays plus JSON data. The data
of the shard steps is described below, field by field; a stage writes it through
:func:`encode` and reads another stage's through :func:`read`, both validating against the
model, so a stage never decodes another stage's JSON by hand and a change to an encoding is a
change here (with the producing step's version bumped).

Track names are made and parsed here only: a group's speech tracks are ``source1`` …
``sourceN`` (SonicSet's names), its background tracks ``noise`` and ``music``.

============  =====================================================================
step          data (arrays)
============  =====================================================================
corpus        role, kind, counts per split, problems, skipped files (``index_json``:
              the :class:`~sonicspec.audio.corpora.CorpusIndex` as compact JSON bytes;
              :func:`corpus_index_arrays`, :func:`read_corpus_index`)
mesh          :class:`~.mesh_report.MeshData`: the mesh stage's report (weld, repair,
              leak: only what ran) and the mesh's facts (the
              :class:`~sonicspec.geometry.mesh.SceneMesh` arrays; :func:`mesh_arrays`,
              :func:`read_mesh`)
navigation    scene id and each floor's grid facts (each floor's grids;
              :func:`navigation_arrays`, :func:`read_navigation`)
placement     :class:`PlacementData` (``group_count``)
arrange       :class:`ArrangeData` (``group_count``)
rir           :class:`RirData` (one ``(points, channels, samples)`` float32 stack per
              source, named by :attr:`RirSource.array`)
render        :class:`RenderData` (one ``(channels, clip samples)`` float32 array per track
              and kind, named in :attr:`RenderedTrack.arrays`)
mix           :class:`MixData` (``gains``: groups x :attr:`MixData.gain_columns`)
export        :class:`~.records.ExportData`: per group its files
              (:class:`~.records.FileRecord`), Lhotse entries and metadata path
              (``file_count``)
dataset       :class:`~.records.DatasetData`: the dataset's own files, manifests and
              counts per split (``group_count``)
============  =====================================================================
"""

from __future__ import annotations

import json
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError, model_serializer

from sonicspec.acoustics.late.tails import TailFacts
from sonicspec.acoustics.moving.delays import PathSet
from sonicspec.acoustics.paths.edges import EdgeChoice
from sonicspec.artifacts.mesh_report import MeshData
from sonicspec.artifacts.records import DatasetData, ExportData
from sonicspec.audio.arrange import Segment
from sonicspec.audio.corpora import CorpusIndex
from sonicspec.errors import StageError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.navigation import Floor, Navigation, WalkableGrid

SPEECH_PREFIX = "source"


def speech_track_name(k: int) -> str:
    """The name of a group's ``k``-th speech track (0-based): ``source1``, ``source2`` …"""
    return f"{SPEECH_PREFIX}{k + 1}"


def speech_track_index(name: str) -> int | None:
    """0-based index of a speech track's name, None for a background track."""
    if name.startswith(SPEECH_PREFIX) and name[len(SPEECH_PREFIX):].isdigit():
        return int(name[len(SPEECH_PREFIX):]) - 1
    return None


# ------------------------------------------------------------------------------ corpus
def corpus_index_arrays(index: CorpusIndex) -> dict[str, np.ndarray]:
    """A corpus index as the corpus artifact's array: one compressed JSON text, so a 100 000
    utterance corpus does not bloat the artifact's metadata."""
    blob = json.dumps(index.to_dict(), sort_keys=True, separators=(",", ":")).encode("utf-8")
    return {"index_json": np.frombuffer(blob, dtype=np.uint8)}


def read_corpus_index(arrays: dict[str, np.ndarray]) -> CorpusIndex:
    """The index :func:`corpus_index_arrays` stored."""
    return CorpusIndex.from_dict(json.loads(arrays["index_json"].tobytes().decode("utf-8")))


# ------------------------------------------------------------------------------ mesh
def mesh_arrays(mesh: SceneMesh) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A scene mesh as arrays and the facts :func:`read_mesh` needs with them."""
    arrays = {"vertices": mesh.vertices, "faces": mesh.faces, "face_material": mesh.face_material}
    if mesh.face_label is not None:
        arrays["face_label"] = mesh.face_label
    if mesh.face_object is not None:
        arrays["face_object"] = mesh.face_object
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    return arrays, {"materials": list(mesh.materials), "labels": list(mesh.labels),
                    "bounds_m": [lo.tolist(), hi.tolist()], "faces": int(mesh.faces.shape[0])}


def read_mesh(arrays: dict[str, np.ndarray], data: dict[str, Any]) -> SceneMesh:
    """The :class:`SceneMesh` a mesh artifact holds."""
    return SceneMesh(
        vertices=arrays["vertices"],
        faces=arrays["faces"],
        face_material=arrays["face_material"],
        materials=tuple(data["materials"]),
        face_label=arrays.get("face_label"),
        labels=tuple(data["labels"]),
        face_object=arrays.get("face_object"),
    )


# ------------------------------------------------------------------------------ navigation
GRID_ARRAYS = ("floor_z_m", "wall_distance_m", "obstacle_distance_m", "walkable", "component")


def navigation_arrays(nav: Navigation, scene_id: str
                      ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A navigation as arrays (``floor<k>_<grid>``) and the facts of each floor."""
    arrays: dict[str, np.ndarray] = {}
    floors = []
    for k, grid in enumerate(nav.grids):
        for name in GRID_ARRAYS:
            arrays[f"floor{k}_{name}"] = np.asarray(getattr(grid, name))
        floors.append({**grid.to_dict(), "distance_limit_m": grid.distance_limit_m})
    return arrays, {"scene_id": scene_id, "floors": floors}


def read_navigation(arrays: dict[str, np.ndarray], data: dict[str, Any]) -> Navigation:
    """The :class:`Navigation` a navigation artifact holds."""
    floors, grids = [], []
    for k, f in enumerate(data["floors"]):
        floor = Floor(**f["floor"])
        floors.append(floor)
        grids.append(WalkableGrid(
            floor=floor, cell_m=f["cell_m"], origin_xy_m=np.asarray(f["origin_xy_m"]),
            walker_radius_m=f["walker_radius_m"], walker_height_m=f["walker_height_m"],
            distance_limit_m=f["distance_limit_m"],
            **{name: arrays[f"floor{k}_{name}"] for name in GRID_ARRAYS},
        ))
    return Navigation(floors=tuple(floors), grids=tuple(grids))


class _Data(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


Vec3 = tuple[float, float, float]


# ------------------------------------------------------------------------------ placement
class SourcePlacement(_Data):
    """Where one source is and how it moves (``geometry.placement.SourcePlacement``), with
    the points its RIRs are computed at."""

    motion: Literal["static", "line", "shortest_path", "waypoints"]
    start_m: Vec3
    end_m: Vec3
    path_m: list[Vec3]
    path_length_m: float
    floor_index: int
    height_m: float
    rir_points_m: list[Vec3]
    """The path resampled every ``trajectory.rir_spacing_m`` (one point if static)."""
    rir_points_distance_m: list[float]
    """Distance along the path of each RIR point."""


class GroupPlacement(_Data):
    group: str
    scene_id: str
    floor_index: int
    mic_m: Vec3
    mic_path_m: list[Vec3]
    """The microphone's RIR points (one if it does not move)."""
    speech: list[SourcePlacement]
    noise: SourcePlacement | None
    music: SourcePlacement | None
    tries: int
    restarts: int

    def source(self, track: str) -> SourcePlacement:
        """The placement of the source a track plays from."""
        k = speech_track_index(track)
        found = self.speech[k] if k is not None and k < len(self.speech) else (
            getattr(self, track, None) if track in ("noise", "music") else None)
        if found is None:
            raise StageError(f"group {self.group}: no placed source for track {track!r}")
        return found


class PlacementData(_Data):
    groups: list[GroupPlacement]


# ------------------------------------------------------------------------------ arrange
class TrackFile(_Data):
    path: str
    """Below the corpus root of the track's role."""
    sample_rate_hz: int
    speaker: str


class ArrangedTrack(_Data):
    name: str
    role: Literal["speech", "noise", "music"]
    speaker: str
    segments: list[dict[str, Any]]
    """:meth:`sonicspec.audio.arrange.Segment.to_dict` of each clip, in time order."""
    files: dict[str, TrackFile]
    """Segment id -> its file."""

    def segment_list(self) -> list[Segment]:
        return [Segment.from_dict(s) for s in self.segments]


class ArrangedGroup(_Data):
    group: str
    clip_samples: int
    tracks: list[ArrangedTrack]


class ArrangeData(_Data):
    groups: list[ArrangedGroup]


# ------------------------------------------------------------------------------ rir
class RirSource(_Data):
    name: str
    """The track the RIRs are for."""
    array: str
    points: int
    t30_s: float | None
    """Broadband T30 of the first point's RIR (None where the decay is too short to fit)."""
    drr_db: float | None
    direct: str
    """The direct path at the first point: ``visible``, ``through walls`` or ``blocked``."""
    escaped_ray_fraction: float
    tail: TailFacts
    """How the RIR's length was chosen (first point;
    :class:`sonicspec.acoustics.late.tails.TailFacts`, stored field by field)."""
    image_source_order: int | None = None
    """The image-source order reached at every point of the source (the lowest over its
    points; None in artifacts written before it was recorded)."""
    image_source_order_asked: int | None = None
    """The order ``acoustics.image_source_order`` asked."""
    image_source_order_stopped: str | None = None
    """Why the order reached is lower than asked (``"order 3 needs more than 2,000,000
    candidates"``: the ray tracer covers the rest), None when it is not."""
    facing_yaw_deg: list[float] | None = None
    """A directional source: where it faced at each RIR point (degrees counter-clockwise
    from +x), as its RIRs were computed (a moving microphone: at each pair of source and
    microphone positions, at that pair's time); left out (None) for an omnidirectional one."""
    paths: str | None = None
    """With ``interpolation: paths``: the prefix of the source's exact early paths (arrays
    ``<paths>_images``, ``_weights``, ``_order``, ``_isometries`` for a moving
    microphone, ``_lengths`` for paths bent round edges and ``_at_index`` where points were
    added between the RIR points: a
    :class:`~sonicspec.acoustics.moving.delays.PathSet`) and late RIRs (``<paths>_late``, shaped
    like the RIRs: the RIRs less their early paths)."""


    @model_serializer(mode="wrap")
    def _omni_left_out(self, handler):
        data = handler(self)
        if self.facing_yaw_deg is None:  # an omni source's record as before directivity
            data.pop("facing_yaw_deg", None)
        return data


class RirGroup(_Data):
    group: str
    sources: list[RirSource]
    diffraction_edges: EdgeChoice | None = None
    """With ``acoustics.diffraction``: how the group's diffracting edges were chosen, one set
    for all of its RIRs (:class:`sonicspec.acoustics.paths.edges.EdgeChoice`: found, kept,
    the rule, the seam edges left out)."""

    def source(self, track: str) -> RirSource:
        for s in self.sources:
            if s.name == track:
                return s
        raise StageError(f"group {self.group} has no RIRs for track {track}")


class RirData(_Data):
    groups: list[RirGroup]
    bands_hz: list[float]
    sample_rate_hz: int
    capsules: dict[str, Any] | None = None
    """The microphone's capsules (:func:`sonicspec.acoustics.engine.capsule_facts`: device,
    sphere radius, per channel position, pattern and axis in the microphone's frame) when
    any is directional, on a sphere or from a device; left out of the data when None, so
    omni arrays keep their bytes."""

    @model_serializer(mode="wrap")
    def _omit_capsules(self, handler: Any) -> Any:
        data = handler(self)
        if isinstance(data, dict) and data.get("capsules", 0) is None:
            del data["capsules"]
        return data


# ------------------------------------------------------------------------------ render
class RenderedTrack(_Data):
    name: str
    role: Literal["speech", "noise", "music"]
    arrays: dict[str, str]
    """Kind (``reverberant``, ``dry``, ``direct``, ``early``) -> array name."""
    channels: int


class RenderGroup(_Data):
    group: str
    clip_samples: int
    tracks: list[RenderedTrack]


class RenderData(_Data):
    groups: list[RenderGroup]
    sample_rate_hz: int


# ------------------------------------------------------------------------------ mix
class ComponentLevel(_Data):
    role: Literal["speech", "noise", "music"]
    target_lufs: float
    measured_lufs: float
    measured_on: Literal["reverberant", "dry"]
    gain_db: float | None
    """None: silence."""
    output_lufs: float


class Mixture(_Data):
    """``sonicspec.audio.mix.Mixture.to_dict``."""

    name: str
    task: Literal["separation", "enhancement"]
    components: list[str]
    targets: list[str]


class MixGroup(_Data):
    group: str
    gains: dict[str, float]
    """Linear gain of every written signal: tracks, ``<track>_direct`` / ``_early`` /
    ``_dry`` targets; the group gain is applied."""
    group_gain_db: float | None
    peak_before_guard_dbfs: float | None
    components: dict[str, ComponentLevel]
    mixtures: list[Mixture]


class MixData(_Data):
    groups: list[MixGroup]
    gain_columns: list[str]
    sample_rate_hz: int


def path_set_arrays(prefix: str, paths: PathSet) -> dict[str, np.ndarray]:
    """A source's :class:`~sonicspec.acoustics.moving.delays.PathSet` as arrays ``<prefix>_images``,
    ``_weights``, ``_order`` and, for directional receivers, ``_directions``; for a
    directional source with edge paths, ``_departures``."""
    out = {f"{prefix}_images": paths.images_m, f"{prefix}_weights": paths.weights,
           f"{prefix}_order": paths.order}
    if paths.directions is not None:
        out[f"{prefix}_directions"] = paths.directions
    if paths.isometries is not None:
        out[f"{prefix}_isometries"] = paths.isometries
    if paths.lengths_m is not None:
        out[f"{prefix}_lengths"] = paths.lengths_m
    if paths.at_index is not None:
        out[f"{prefix}_at_index"] = paths.at_index
    if paths.departures is not None:  # a directional source's edge paths
        out[f"{prefix}_departures"] = paths.departures
    return out


def read_path_set(arrays, prefix: str) -> PathSet:
    """The :class:`~sonicspec.acoustics.moving.delays.PathSet` :func:`path_set_arrays` stored."""
    directions = arrays.get(f"{prefix}_directions")
    isometries = arrays.get(f"{prefix}_isometries")
    lengths = arrays.get(f"{prefix}_lengths")
    return PathSet(np.asarray(arrays[f"{prefix}_images"], dtype=np.float64),
                   np.asarray(arrays[f"{prefix}_weights"], dtype=np.float64),
                   np.asarray(arrays[f"{prefix}_order"], dtype=np.int64),
                   None if directions is None else np.asarray(directions, dtype=np.float64),
                   None if isometries is None else np.asarray(isometries, dtype=np.float64),
                   None if lengths is None else np.asarray(lengths, dtype=np.float64),
                   None if f"{prefix}_at_index" not in arrays else
                   np.asarray(arrays[f"{prefix}_at_index"], dtype=np.float64),
                   None if f"{prefix}_departures" not in arrays else
                   np.asarray(arrays[f"{prefix}_departures"], dtype=np.float64))


MODELS: dict[str, type[BaseModel]] = {
    "placement": PlacementData,
    "arrange": ArrangeData,
    "rir": RirData,
    "render": RenderData,
    "mix": MixData,
    "mesh": MeshData,
    "export": ExportData,
    "dataset": DatasetData,
}


def encode(step: str, data: Any) -> dict[str, Any]:
    """``data`` (a model or plain data) checked against ``step``'s model, as plain JSON data."""
    model = MODELS[step]
    try:
        typed = data if isinstance(data, model) else model.model_validate(data)
    except ValidationError as err:
        raise StageError(f"{step} artifact: {_first(err)}") from None
    return typed.model_dump(mode="json")


def decode(step: str, data: Any, where: str = "") -> Any:
    """The data of a ``step`` artifact as its model."""
    try:
        return MODELS[step].model_validate(data)
    except ValidationError as err:
        raise StageError(f"{where or step}: {step} artifact does not read ({_first(err)}); "
                         "was it made by another sonicspec version?") from None


def read(ctx, step: str) -> Any:
    """The data of this job's single ``step`` input, as its model."""
    keys = ctx.input_keys(step)
    if len(keys) != 1:
        raise StageError(f"{ctx.job.label}: expected one {step} input, found {len(keys)}")
    return decode(step, ctx.store.read_data(step, keys[0]), ctx.job.label)


def first_error(err: ValidationError) -> str:
    """A validation error's first problem, ``field.path: message``."""
    return _first(err)


def _first(err: ValidationError) -> str:
    e = err.errors()[0]
    return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
