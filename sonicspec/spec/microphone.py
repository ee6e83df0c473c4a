"""Microphones: mono, binaural, ambisonics and arrays."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel, vector
from sonicspec.spec.trajectory import MicrophoneTrajectorySpec, StaticTrajectorySpec


class _MicBase(SpecModel):
    height_m: float = Field(
        1.5, gt=0, description="Height of the array centre above the floor, metres."
    )
    yaw_deg: float = Field(
        0.0, description="Orientation about the vertical axis (0: facing +x), degrees."
    )
    pitch_deg: float = Field(
        0.0, ge=-90, le=90, description="Elevation of the look direction, degrees."
    )
    trajectory: MicrophoneTrajectorySpec = Field(
        default_factory=lambda: StaticTrajectorySpec(kind="static"),
        description="How the microphone moves (default: it stays where placement puts it).",
    )


class MonoMicSpec(_MicBase):
    """One omnidirectional capsule."""

    kind: Literal["mono"] = Field(description="Microphone type.")


class SphereHeadSpec(SpecModel):
    """The built-in analytic rigid-sphere head model (works offline)."""

    kind: Literal["sphere"] = Field(description="HRTF source.")
    head_radius_m: float = Field(0.0875, gt=0.03, le=0.2, description="Sphere radius, metres.")
    ear_angle_deg: float = Field(
        100.0, ge=0, le=180, description="Azimuth of each ear from the front, degrees."
    )


class SofaHrtfSpec(SpecModel):
    """A measured HRTF set in a SOFA file (SimpleFreeFieldHRIR)."""

    kind: Literal["sofa"] = Field(description="HRTF source.")
    path: str = Field(min_length=1, description="SOFA file, relative to the spec file.")


HrtfSpec = Annotated[SphereHeadSpec | SofaHrtfSpec, Field(discriminator="kind")]


class BinauralMicSpec(_MicBase):
    """Two ears rendered through an HRTF."""

    kind: Literal["binaural"] = Field(description="Microphone type.")
    hrtf: HrtfSpec = Field(
        default_factory=lambda: SphereHeadSpec(kind="sphere"),
        description="HRTF: the built-in sphere head model or a SOFA file.",
    )


class AmbisonicsMicSpec(_MicBase):
    """Higher-order ambisonics, ACN channel order, SN3D normalisation."""

    kind: Literal["ambisonics"] = Field(description="Microphone type.")
    order: int = Field(1, ge=1, le=3, description="Ambisonic order: (order + 1)^2 channels.")


class LinearArrayMicSpec(_MicBase):
    """Omnidirectional capsules on a line through the centre, along the left axis."""

    kind: Literal["linear_array"] = Field(description="Microphone type.")
    n: int = Field(ge=2, le=64, description="Number of capsules.")
    spacing_m: float = Field(gt=0, le=1.0, description="Distance between neighbours, metres.")


class CircularArrayMicSpec(_MicBase):
    """Omnidirectional capsules evenly spaced on a horizontal circle."""

    kind: Literal["circular_array"] = Field(description="Microphone type.")
    n: int = Field(ge=2, le=64, description="Number of capsules.")
    radius_m: float = Field(gt=0, le=1.0, description="Circle radius, metres.")


class CustomArrayMicSpec(_MicBase):
    """Omnidirectional capsules at positions relative to the array centre (before rotation)."""

    kind: Literal["custom"] = Field(description="Microphone type.")
    positions_m: list[vector(3)] = Field(  # type: ignore[valid-type]
        min_length=1,
        max_length=64,
        description="Capsule offsets [x, y, z] from the centre, metres.",
    )


MicrophoneSpec = Annotated[
    MonoMicSpec
    | BinauralMicSpec
    | AmbisonicsMicSpec
    | LinearArrayMicSpec
    | CircularArrayMicSpec
    | CustomArrayMicSpec,
    Field(discriminator="kind"),
]


def channel_count(
    mic: MonoMicSpec
    | BinauralMicSpec
    | AmbisonicsMicSpec
    | LinearArrayMicSpec
    | CircularArrayMicSpec
    | CustomArrayMicSpec,
) -> int:
    """Number of output channels the microphone renders."""
    if isinstance(mic, MonoMicSpec):
        return 1
    if isinstance(mic, BinauralMicSpec):
        return 2
    if isinstance(mic, AmbisonicsMicSpec):
        return (mic.order + 1) ** 2
    if isinstance(mic, CustomArrayMicSpec):
        return len(mic.positions_m)
    return mic.n
