"""Microphones: mono, binaural, ambisonics, arrays, and real devices.

Capsules of mono microphones and arrays have a first-order pattern and an orientation in the
array's frame (x where the array looks, y its left, z up; the frame turns with ``yaw_deg`` and
``pitch_deg``). Device presets are data (``sonicspec/data/microphones/``, one JSON file per
device with the source of its geometry), the same files the acoustics library renders from,
so validating a spec imports no acoustics.
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Annotated, Any, Literal

from pydantic import Field, model_serializer, model_validator
from pydantic_core import PydanticCustomError

from sonicspec.spec.base import SpecModel, vector
from sonicspec.spec.trajectory import MicrophoneTrajectorySpec, StaticTrajectorySpec

CapsulePattern = Literal["omni", "subcardioid", "cardioid", "supercardioid", "hypercardioid",
                         "figure_eight"]


class CapsuleSpec(SpecModel):
    """One capsule's first-order pattern ``a + (1 - a) cos(theta)`` and where it points.

    The patterns are those of ideal capsules, the same at every frequency: omni (a = 1),
    subcardioid (0.7), cardioid (0.5), supercardioid (0.366), hypercardioid (0.25),
    figure_eight (0). The axis is given in the array's frame (x: where the array looks, y: its
    left, z: up) by azimuth and elevation, or as a vector; the capsules turn with the array.
    """

    pattern: CapsulePattern = Field(
        "omni", description="First-order pattern: omni, subcardioid, cardioid, supercardioid, "
        "hypercardioid or figure_eight (ideal capsules: the same at every frequency).")
    azimuth_deg: float = Field(
        0.0, ge=-360, le=360, description="Axis azimuth in the array's frame, from its front "
        "(+x) towards its left (+y), degrees; with facing: outward, from the capsule's "
        "outward direction.")
    elevation_deg: float = Field(
        0.0, ge=-90, le=90, description="Axis elevation above the array's horizontal plane, "
        "degrees.")
    axis: vector(3) | None = Field(  # type: ignore[valid-type]
        None, description="Axis as a vector [x, y, z] in the array's frame (any length > 0; "
        "instead of azimuth_deg and elevation_deg).")
    facing: Literal["front", "outward"] = Field(
        "front", description="front: azimuth_deg counts from the array's front; outward: from "
        "the horizontal direction from the array's centre to the capsule (a capsule at the "
        "centre: the front), so capsules on a circle can all face out.")

    @model_validator(mode="after")
    def _one_orientation(self) -> CapsuleSpec:
        if self.axis is not None:
            if self.azimuth_deg or self.elevation_deg or self.facing != "front":
                raise PydanticCustomError(
                    "capsule_axis", "give the axis or azimuth_deg/elevation_deg/facing, not "
                    "both (got axis {axis})", {"axis": list(self.axis)})
            if sum(v * v for v in self.axis) < 1e-18:
                raise PydanticCustomError("capsule_axis", "the axis needs a direction, got "
                                          "[0, 0, 0]", {})
        return self


def _default_capsule() -> CapsuleSpec:
    return CapsuleSpec()


class _CapsuleMixin(SpecModel):
    """``capsule`` left out of the data at its default (omni), so microphones written before
    capsules had patterns keep their content keys."""

    capsule: CapsuleSpec = Field(
        default_factory=_default_capsule,
        description="Pattern and orientation of every capsule (default: omni).")

    @model_serializer(mode="wrap")
    def _omit_default_capsule(self, handler: Any) -> Any:
        data = handler(self)
        if isinstance(data, dict):
            if self.capsule == CapsuleSpec():
                data.pop("capsule", None)
            if "capsules" in data and data["capsules"] is None:
                data.pop("capsules")
        return data


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


class MonoMicSpec(_MicBase, _CapsuleMixin):
    """One capsule (omnidirectional unless ``capsule`` says otherwise)."""

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


class LinearArrayMicSpec(_MicBase, _CapsuleMixin):
    """Capsules on a line through the centre, along the left axis."""

    kind: Literal["linear_array"] = Field(description="Microphone type.")
    n: int = Field(ge=2, le=64, description="Number of capsules.")
    spacing_m: float = Field(gt=0, le=1.0, description="Distance between neighbours, metres.")


class CircularArrayMicSpec(_MicBase, _CapsuleMixin):
    """Capsules evenly spaced on a horizontal circle, the first on the array's front."""

    kind: Literal["circular_array"] = Field(description="Microphone type.")
    n: int = Field(ge=2, le=64, description="Number of capsules.")
    radius_m: float = Field(gt=0, le=1.0, description="Circle radius, metres.")


class CustomArrayMicSpec(_MicBase, _CapsuleMixin):
    """Capsules at positions relative to the array centre (before rotation)."""

    kind: Literal["custom"] = Field(description="Microphone type.")
    positions_m: list[vector(3)] = Field(  # type: ignore[valid-type]
        min_length=1,
        max_length=64,
        description="Capsule offsets [x, y, z] from the centre, metres.",
    )
    capsules: list[CapsuleSpec] | None = Field(
        None, description="One pattern and orientation per position, in order (instead of "
        "capsule, which gives all of them the same).")

    @model_validator(mode="after")
    def _capsules_match(self) -> CustomArrayMicSpec:
        if self.capsules is not None:
            if len(self.capsules) != len(self.positions_m):
                raise PydanticCustomError(
                    "capsules_length", "expected one capsule per position ({n}), got {k}",
                    {"n": len(self.positions_m), "k": len(self.capsules)})
            if self.capsule != CapsuleSpec():
                raise PydanticCustomError(
                    "capsules_both", "give capsule (the same for all) or capsules (one per "
                    "position), not both", {})
        return self


DEVICE_NAMES = ("respeaker_4mic", "respeaker_6mic", "minidsp_uma8", "smart_speaker_7mic",
                "phone_2mic", "phone_3mic", "em32")
"""The device presets shipped as data (``sonicspec/data/microphones/<name>.json``)."""


@cache
def device_preset(name: str) -> dict[str, Any]:
    """The data of a device preset: ``name``, ``title``, ``source`` (where its geometry comes
    from), ``body`` (``{"kind": "free"}`` or ``{"kind": "rigid_sphere", "radius_m": ...}``)
    and ``capsules`` (each a ``position_m`` in the device's frame, metres, and optionally a
    ``pattern`` and an ``axis``)."""
    if name not in DEVICE_NAMES:
        raise KeyError(name)
    text = (resources.files("sonicspec").joinpath("data", "microphones", f"{name}.json")
            .read_text("utf-8"))
    return json.loads(text)


class DeviceMicSpec(_MicBase):
    """A real device from the presets (``sonicspec microphones`` lists them with the source
    of each geometry): its capsules' positions, patterns and body as the preset gives them,
    placed and turned like any array."""

    kind: Literal["device"] = Field(description="Microphone type.")
    device: Literal[DEVICE_NAMES] = Field(  # type: ignore[valid-type]
        description="The device preset: respeaker_4mic, respeaker_6mic, minidsp_uma8, "
        "smart_speaker_7mic, phone_2mic, phone_3mic or em32 (32 capsules on a rigid "
        "sphere).")


MicrophoneSpec = Annotated[
    MonoMicSpec
    | BinauralMicSpec
    | AmbisonicsMicSpec
    | LinearArrayMicSpec
    | CircularArrayMicSpec
    | CustomArrayMicSpec
    | DeviceMicSpec,
    Field(discriminator="kind"),
]


def channel_count(
    mic: MonoMicSpec
    | BinauralMicSpec
    | AmbisonicsMicSpec
    | LinearArrayMicSpec
    | CircularArrayMicSpec
    | CustomArrayMicSpec
    | DeviceMicSpec,
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
    if isinstance(mic, DeviceMicSpec):
        return len(device_preset(mic.device)["capsules"])
    return mic.n
