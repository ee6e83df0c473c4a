"""The root of a spec file: one dataset."""

from __future__ import annotations

from typing import Literal

from pydantic import (
    Field,
    SerializationInfo,
    SerializerFunctionWrapHandler,
    field_validator,
    model_serializer,
)
from pydantic_core import PydanticCustomError

from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.spec.augmentation import AugmentationSpec
from sonicspec.spec.base import Identifier, SpecModel, SplitName
from sonicspec.spec.corpora import CorporaSpec
from sonicspec.spec.directivity import SourcesDirectivitySpec
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.spec.microphone import MicrophoneSpec, MonoMicSpec
from sonicspec.spec.mixture import MixtureSpec
from sonicspec.spec.outputs import OutputsSpec
from sonicspec.spec.placement import PlacementSpec
from sonicspec.spec.scene import SceneSpec
from sonicspec.spec.splits import MAX_GROUPS, SplitSpec
from sonicspec.spec.trajectory import ShortestPathTrajectorySpec, TrajectorySpec
from sonicspec.units import SPEED_OF_SOUND_M_S

SPEC_VERSION = 1


class DatasetSpec(SpecModel):
    """A whole dataset: scenes, acoustics, corpora, mixing recipe, splits and outputs."""

    sonicspec: Literal[1] = Field(description="Spec language version; this release reads 1.")
    name: Identifier = Field(description="Dataset name; used for folder names and manifests.")
    description: str = Field("", description="Free text shown in dataset.json.")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Root of every random draw.")
    sample_rate_hz: int = Field(16000, ge=8000, le=192000, description="Output sample rate, Hz.")
    speed_of_sound_m_s: float = Field(
        SPEED_OF_SOUND_M_S, ge=300, le=400, description="Speed of sound, m/s."
    )
    scenes: list[SceneSpec] = Field(min_length=1, description="Rooms and buildings to simulate.")
    materials: MaterialsSpec = Field(
        default_factory=MaterialsSpec, description="Material library and user materials."
    )
    microphone: MicrophoneSpec = Field(
        default_factory=lambda: MonoMicSpec(kind="mono"), description="The receiver."
    )
    placement: PlacementSpec = Field(
        default_factory=PlacementSpec, description="Placement rules for mic and sources."
    )
    trajectory: TrajectorySpec = Field(
        default_factory=lambda: ShortestPathTrajectorySpec(kind="shortest_path"),
        description="How speech sources move (noise and music are always static).",
    )
    directivity: SourcesDirectivitySpec = Field(
        default_factory=SourcesDirectivitySpec,
        description=("How each source role radiates (a pattern per octave band) and where it "
                     "faces; every source is omnidirectional by default."),
    )
    acoustics: AcousticsSpec = Field(default_factory=AcousticsSpec, description="Tracer settings.")
    corpora: CorporaSpec = Field(description="Speech, noise and music corpora.")
    mixture: MixtureSpec = Field(default_factory=MixtureSpec, description="Mixing recipe.")
    splits: dict[SplitName, SplitSpec] = Field(
        min_length=1,
        description="Splits by name (e.g. train, val, test); at most 1,000,000 groups in all.",
    )
    outputs: OutputsSpec = Field(
        default_factory=OutputsSpec, description="Output locations and formats."
    )
    augmentation: AugmentationSpec | None = Field(
        None, description="Device and channel effects on the mixtures (microphone response, "
        "self-noise, gain, clipping, resampling, codecs), drawn per group and recorded in "
        "metadata.json; null: none (the mixtures as mixed).")

    @model_serializer(mode="wrap")
    def _defaults_left_out(self, handler: SerializerFunctionWrapHandler,
                       info: SerializationInfo) -> dict:
        # Every source omnidirectional (the default): left out, so a spec written before
        # directivity existed serialises (and is keyed, and lands in dataset.json) as before.
        # No augmentation (null): left out the same way, for the same reason.
        data = handler(self)
        if self.directivity.is_omni and self.directivity == SourcesDirectivitySpec():
            data.pop("directivity", None)
        if isinstance(data, dict) and data.get("augmentation", 0) is None:
            del data["augmentation"]
        return data

    @field_validator("splits")
    @classmethod
    def _groups_bounded(cls, splits: dict[str, SplitSpec]) -> dict[str, SplitSpec]:
        # Splits composed per speaker and scene are counted when the plan is compiled.
        fixed = {k: s.groups for k, s in splits.items() if isinstance(s.groups, int)}
        total = sum(fixed.values())
        if total > MAX_GROUPS:
            raise PydanticCustomError(
                "groups_total",
                "expected at most {limit} groups in all splits together (got {total}: {each})",
                {"limit": f"{MAX_GROUPS:,}", "total": f"{total:,}",
                 "each": ", ".join(f"{k}: {n:,}" for k, n in fixed.items())},
            )
        return splits
