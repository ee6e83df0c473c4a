"""Typed parameters of every step: one frozen model per step, built from the spec's own models.

A job's ``params`` are plain JSON data (they are hashed into its content key and stored with
its artifact); the model of its step says what that data is. The stage that runs the job reads
its parameters through the model (:meth:`sonicspec.stages.context.JobContext.params`), so a
misspelt or missing parameter fails when the job starts, naming the step and the field, and
stages reach settings as attributes (``params.acoustics.rays``), never by string.

Settings keep the spec's field names and the spec's defaults: a params model declares no
default of its own (a setting's default lives in the spec model, once). Where a job must not
depend on something the spec holds — where a file is (``root``, ``path``, ``dir``), what a
scene is called (``id``) — the portable variants below drop that field from the spec model,
so moving a corpus or renaming a scene keeps the content keys.

:func:`compile_spec <sonicspec.plan.compile.compile_spec>` writes params as plain data for
speed (10^6 groups); ``tests/test_plan_params.py`` checks that every job of every example spec
reads into its model and dumps back to the very same data.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    create_model,
    model_serializer,
)

from sonicspec.errors import StageError
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.spec.augmentation import AugmentationSpec
from sonicspec.spec.base import BandCoefficients
from sonicspec.spec.corpora import (
    FmaCorpusSpec,
    FolderCorpusSpec,
    Fsd50kCorpusSpec,
    GeneratedNoiseSpec,
    GeneratedSpeechSpec,
    LibriSpeechCorpusSpec,
)
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.directivity import SourcesDirectivitySpec
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.spec.microphone import MicrophoneSpec
from sonicspec.spec.mixture import (
    BackgroundFieldSpec,
    LoudnessSpec,
    MixtureSpec,
    Rendering,
    TaskSpec,
)
from sonicspec.spec.outputs import Manifest, OutputsSpec
from sonicspec.spec.placement import PlacementSpec
from sonicspec.spec.scene import (
    CylinderSceneSpec,
    LShapeSceneSpec,
    MeshSceneSpec,
    PolygonSceneSpec,
    ShoeboxSceneSpec,
)
from sonicspec.spec.trajectory import TrajectorySpec

_DROPPED = Field(None, exclude=True)
"""A spec field a job must not depend on: absent from its params (and from its key)."""


# ----------------------------------------------------------------- portable spec models
class LibriSpeechCorpusParams(LibriSpeechCorpusSpec):
    root: None = _DROPPED  # type: ignore[assignment]


class FolderCorpusParams(FolderCorpusSpec):
    root: None = _DROPPED  # type: ignore[assignment]


class Fsd50kCorpusParams(Fsd50kCorpusSpec):
    root: None = _DROPPED  # type: ignore[assignment]


class FmaCorpusParams(FmaCorpusSpec):
    root: None = _DROPPED  # type: ignore[assignment]


CorpusSpecParams = (LibriSpeechCorpusParams | FolderCorpusParams | GeneratedSpeechSpec
                    | Fsd50kCorpusParams | FmaCorpusParams | GeneratedNoiseSpec)
"""A corpus without its folder (the folder enters the key by its listing). The two
``generated`` kinds share a tag; their fields tell them apart."""


class ShoeboxSceneParams(ShoeboxSceneSpec):
    id: None = _DROPPED  # type: ignore[assignment]


class CylinderSceneParams(CylinderSceneSpec):
    id: None = _DROPPED  # type: ignore[assignment]


class LShapeSceneParams(LShapeSceneSpec):
    id: None = _DROPPED  # type: ignore[assignment]


class PolygonSceneParams(PolygonSceneSpec):
    id: None = _DROPPED  # type: ignore[assignment]


class MeshSceneParams(MeshSceneSpec):
    id: None = _DROPPED  # type: ignore[assignment]
    path: None = _DROPPED  # type: ignore[assignment]


SceneParams = Annotated[
    ShoeboxSceneParams | CylinderSceneParams | LShapeSceneParams | PolygonSceneParams
    | MeshSceneParams,
    Field(discriminator="kind"),
]
"""A scene without its id and file (the file enters the key by content)."""


class OutputsParams(OutputsSpec):
    """What an export writes, without where (``dir``, ``store_dir``), how finely the work
    is cut (``groups_per_shard``) and the report made after the build (``report``): no
    exported byte depends on them."""

    dir: None = _DROPPED  # type: ignore[assignment]
    report: None = _DROPPED  # type: ignore[assignment]
    store_dir: None = _DROPPED  # type: ignore[assignment]
    allow_outside_spec_folder: None = _DROPPED  # type: ignore[assignment]
    groups_per_shard: None = _DROPPED  # type: ignore[assignment]

    omitted_when: ClassVar[Mapping[str, Any]] = {"scale": "none", "bits": None}
    """Left out at their defaults (added in issue 27), so exports that do not use them keep
    their keys."""

    @model_serializer(mode="wrap")
    def _omit(self, handler: Any) -> Any:
        return without_omitted(handler(self), self.omitted_when)


def without_omitted(data: dict[str, Any], omitted_when: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` less the fields that hold their ``omitted_when`` value."""
    for name, value in omitted_when.items():
        if name in data and data[name] == value:
            del data[name]
    return data


# ----------------------------------------------------------------- the step models
class StepParams(BaseModel):
    """Base of every step's params: immutable, no unknown keys, no defaults of its own."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    omitted_when: ClassVar[Mapping[str, Any]] = {}
    """Fields left out of the data when they hold this value (a key only some jobs of a step
    carry, so adding the field did not change the others' keys)."""

    @model_serializer(mode="wrap")
    def _omit(self, handler: Any) -> Any:
        return without_omitted(handler(self), self.omitted_when)


class CorpusParams(StepParams):
    role: Literal["speech", "noise", "music"]
    corpus: CorpusSpecParams
    sample_rate_hz: int
    seed: int
    splits: tuple[str, ...]
    listing: str | None = None
    """Digest of the corpus folder's file names and sizes; None for a generated corpus."""

    omitted_when: ClassVar[Mapping[str, Any]] = {"listing": None}


class MeshParams(StepParams):
    scene: SceneParams
    files: dict[str, str]
    """SHA-256 of each input file by role (``mesh``, ``semantic``, ``house``, ``obstacle<j>``)."""
    scene_id: str
    library: Literal["sonicspec", "sonicset"] | None = None
    """Mesh scenes: the material library their labels resolve against."""
    label_materials: dict[str, str] | None = None
    """Mesh scenes: the spec's label map with the scene's own on top."""
    obj_labels: bool = False
    """Obj scenes: an obj file's lone object keeps its name (``geometry.io.load_mesh``)."""

    omitted_when: ClassVar[Mapping[str, Any]] = {
        "library": None, "label_materials": None, "obj_labels": False}


class NavigationParams(StepParams):
    walker_radius_m: float
    walker_height_m: float


class ShardParams(StepParams):
    """A shard of groups of one split: every per-group draw is seeded by ``seed`` and the
    group id, never by the shard."""

    groups: tuple[str, ...]
    split: str
    seed: int


class PlacementParams(ShardParams):
    scene_id: str
    placement: PlacementSpec
    trajectory: TrajectorySpec
    microphone: MicrophoneSpec
    speakers: int
    noise: bool
    music: bool


def _subset(model: type[BaseModel], names: tuple[str, ...], doc: str) -> type[StepParams]:
    """A params model of some of ``model``'s fields, with their types and checks, no defaults."""
    fields: dict[str, Any] = {}
    for name in names:
        info = model.model_fields[name]
        kind = (Annotated[(info.annotation, *info.metadata)] if info.metadata
                else info.annotation)
        fields[name] = (kind, ...)
    return create_model(f"{model.__name__.removesuffix('Spec')}Subset", __base__=StepParams,
                       __doc__=doc, __module__=__name__, **fields)


ARRANGEMENT_FIELDS = ("duration_s", "speakers", "utterances_per_speaker", "utterance_gap_s",
                      "noise_clips", "noise_gap_s", "music_clips", "music_gap_s")
Arrangement = _subset(MixtureSpec, ARRANGEMENT_FIELDS,
                      "The fields of ``mixture`` that decide which clips play when.")


class SpeakerComposition(StepParams):
    """A shard of a split composed per speaker and scene (``each_speaker_per_scene``)."""

    scene_id: str
    """The shard's scene: its speakers' shuffle is seeded by the split and this id."""
    slots: tuple[int, ...]
    """Per group of the shard, which ``mixture.speakers`` run of the shuffle it takes."""
    speakers: int
    """Speakers of the split when the plan was made (the index must have as many)."""


class ArrangeParams(ShardParams):
    mixture: Arrangement  # type: ignore[valid-type]
    sample_rate_hz: int
    composition: SpeakerComposition | None = None
    """Speakers per scene and slot; None: each group draws its speakers at random."""

    omitted_when: ClassVar[Mapping[str, Any]] = {"composition": None}


class MaterialTable(_subset(MaterialsSpec, ("library", "custom"), "")):  # type: ignore[misc]
    """The materials names resolve against (labels were resolved by the mesh job), and the
    scattering every surface gets in place of its material's (issue 30)."""

    scattering_override: BandCoefficients | None = None
    omitted_when: ClassVar[Mapping[str, Any]] = {"scattering_override": None}
    """Left out at its default (added in issue 30), so specs that do not set it keep their
    rir keys."""


class WalkParams(StepParams):
    """How a source walks (the trajectory's speed and span): the rir step of a moving
    microphone needs it to know where the source is when the microphone is where."""

    speed_m_s: float | None
    walk_span: Literal["speech", "clip"]


class RirParams(ShardParams):
    acoustics: AcousticsSpec
    materials: MaterialTable  # type: ignore[valid-type]
    microphone: MicrophoneSpec
    speed_of_sound_m_s: float
    sample_rate_hz: int
    files: dict[str, str]
    """SHA-256 of the SOFA file of a binaural microphone (``hrtf``), else empty."""
    early_paths: bool
    """Also store each source's exact early paths and late RIRs (``interpolation: paths``)."""
    walk: WalkParams | None = None
    """A moving microphone: how the sources walk (its RIRs are traced at pairs of source
    and microphone positions, :mod:`sonicspec.stages.motion`); None otherwise."""
    directivity: SourcesDirectivitySpec | None = None
    """The spec's ``directivity`` when some source is not omnidirectional (its SOFA files'
    digests in ``files`` as ``directivity_<role>``); None: every source omni. The render
    step reads it from here."""
    untraced: tuple[Literal["noise", "music"], ...] | None = None
    """Background roles heard only as a diffuse field (``mixture.noise_field`` /
    ``music_field`` with ``diffuse_fraction: 1``): their point source is not heard, so no RIR
    is traced for it. None: every placed source is traced (left out then, so the other specs'
    rir jobs keep their keys)."""

    omitted_when: ClassVar[Mapping[str, Any]] = {"walk": None, "directivity": None,
                                                 "untraced": None}


class RenderParams(ShardParams):
    interpolation: Rendering
    """``mixture.interpolation`` with ``auto`` resolved (:meth:`MixtureSpec.rendering`)."""
    targets: tuple[Literal["dry", "direct", "early"], ...]
    sample_rate_hz: int
    speed_m_s: float | None
    """The trajectory's walking speed (None: the walk spans ``walk_span``)."""
    walk_span: Literal["speech", "clip"]
    """What a moving source's walk spans: its speech or the whole clip."""
    speed_of_sound_m_s: float
    backgrounds: dict[Literal["noise", "music"], BackgroundFieldSpec] | None = None
    """The background roles heard as a diffuse field (``mixture.noise_field``,
    ``mixture.music_field`` when not ``point``); None: every background from its point
    source (left out then, so point-source renders keep their keys)."""

    omitted_when: ClassVar[Mapping[str, Any]] = {"backgrounds": None}


class MixParams(ShardParams):
    loudness: LoudnessSpec
    tasks: tuple[TaskSpec, ...]
    speakers: int
    sample_rate_hz: int
    binaural: bool
    targets: tuple[Literal["dry", "direct", "early"], ...]


class ExportParams(ShardParams):
    outputs: OutputsParams
    output_dir: str
    """``outputs.dir`` as written in the spec (no key depends on where it is)."""
    sample_rate_hz: int
    scene_id: str
    augmentation: AugmentationSpec | None = None
    """The spec's device and channel effects (issue 30)."""
    impulse_responses: dict[str, str] = Field(default_factory=dict)
    """Each impulse-response file of ``augmentation`` as written -> the SHA-256 of its bytes
    (files enter the key by content; the job's ``paths`` say where they are)."""

    omitted_when: ClassVar[Mapping[str, Any]] = {"augmentation": None, "impulse_responses": {}}
    """Left out when unused (added in issue 30), so exports without effects keep their keys."""


class DatasetParams(StepParams):
    spec: DatasetSpec
    output_dir: str
    manifests: tuple[Manifest, ...]
    splits: dict[str, int]
    """Groups per split."""


PARAMS: Mapping[str, type[StepParams]] = {
    "corpus": CorpusParams,
    "mesh": MeshParams,
    "navigation": NavigationParams,
    "placement": PlacementParams,
    "arrange": ArrangeParams,
    "rir": RirParams,
    "render": RenderParams,
    "mix": MixParams,
    "export": ExportParams,
    "dataset": DatasetParams,
}
"""Step name -> the model of its jobs' params."""


def read_params(step: str, data: Mapping[str, Any], label: str = "") -> StepParams:
    """``data`` (a job's params) as its step's model; a :class:`StageError` naming the job and
    the field when they do not fit (a plan made by another sonicspec version, or edited)."""
    try:
        return PARAMS[step].model_validate(dict(data))
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "(params)"
        raise StageError(f"{label or step}: parameter {where}: {first['msg']} "
                         f"({err.error_count()} problem{'s' * (err.error_count() != 1)}; "
                         "was the plan made by another sonicspec version? plan again)"
                         ) from None


def params_data(params: StepParams) -> dict[str, Any]:
    """The plain data of ``params``, as a job holds it."""
    return params.model_dump(mode="json")
