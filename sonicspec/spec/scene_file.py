"""A scene on its own: one room and the settings to compute RIRs in it (``sonicspec rir``).

A dataset spec declares a whole dataset; a scene file declares one scene — a procedural room
or a mesh file with its label map — and, optionally, the materials, acoustics, receiver,
sample rate and seed of the RIRs computed in it. Every section is the dataset spec's own
model, with the same defaults::

    scene:
      kind: shoebox
      id: studio
      size_m: [5, 4, 2.8]
      materials: {walls: gypsum_board, floor: carpet_on_concrete, ceiling: acoustic_ceiling_tile}
    acoustics: {rays: 8000}
"""

from __future__ import annotations

from pydantic import Field

from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.spec.base import SpecModel
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.spec.microphone import MicrophoneSpec, MonoMicSpec
from sonicspec.spec.scene import SceneSpec

_DATASET = DatasetSpec.model_fields


class SceneFileSpec(SpecModel):
    """One scene and how to compute RIRs in it; see the module's docstring."""

    scene: SceneSpec = Field(description="The room: a procedural kind or a mesh file.")
    materials: MaterialsSpec = Field(
        default_factory=MaterialsSpec, description="Material library and user materials."
    )
    acoustics: AcousticsSpec = Field(default_factory=AcousticsSpec, description="Tracer settings.")
    microphone: MicrophoneSpec = Field(
        default_factory=lambda: MonoMicSpec(kind="mono"), description="The receiver."
    )
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Root of every random draw.")
    sample_rate_hz: int = Field(_DATASET["sample_rate_hz"].default, ge=8000, le=192000,
                                description="Output sample rate, Hz.")
    speed_of_sound_m_s: float = Field(_DATASET["speed_of_sound_m_s"].default, ge=300, le=400,
                                      description="Speed of sound, m/s.")


def is_scene_file(data: object) -> bool:
    """Whether parsed YAML is a scene file (a ``scene`` and no ``sonicspec`` version)."""
    return isinstance(data, dict) and "scene" in data and "sonicspec" not in data
