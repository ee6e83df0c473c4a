"""Source directivity: how talkers, noise and music sources radiate and where they face."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator
from pydantic_core import PydanticCustomError

from sonicspec.spec.base import SpecModel

Pattern = Literal["omni", "subcardioid", "cardioid", "supercardioid", "hypercardioid",
                  "speech", "sofa"]


class HeadTurnSpec(SpecModel):
    """Small random turns of the head around the facing direction: an Ornstein–Uhlenbeck
    process of the yaw deviation, drawn per group and track from the spec's seed."""

    std_deg: float = Field(
        15.0, gt=0, le=90,
        description="Standard deviation of the head's yaw around the facing direction, degrees.")
    time_constant_s: float = Field(
        1.5, gt=0, le=60,
        description=("How long a turn lasts: the correlation time of the yaw deviation "
                     "(it decorrelates by 1/e over this time), seconds."))


class DirectivitySpec(SpecModel):
    """How one role's sources radiate (a pattern per octave band) and where they face."""

    pattern: Pattern = Field(
        "omni",
        description=(
            "Radiation pattern, gain 1 straight ahead in every octave band: omni; the "
            "first-order family α + (1 − α) cos θ (subcardioid α 0.7, cardioid 0.5, "
            "supercardioid 0.366, hypercardioid 0.25), the same in every band; speech, a human "
            "talker per octave band (after Chu & Warnock 2002 and Monson et al. 2012: about "
            "1.5 dB down behind at 125 Hz, 10 dB at 4 kHz); sofa, a measured set (sofa_path). "
            "Applied to every path by the direction it leaves the source in, and to the "
            "late reverberation by the pattern's diffuse-field power per band."))
    sofa_path: str | None = Field(
        None, min_length=1,
        description=("With pattern sofa: a SOFA file of the FreeFieldDirectivityTF convention, "
                     "relative to the spec file (its magnitude averaged per octave band, "
                     "normalised on-axis: azimuth 0, elevation 0)."))
    facing: Literal["walk", "toward_mic", "fixed"] = Field(
        "walk",
        description=(
            "Where the source's front points: walk (the direction of travel, smoothed over "
            "facing_smoothing_s; a source that does not move faces the microphone), "
            "toward_mic (a moving microphone: where it is at each moment), or fixed "
            "(yaw_deg)."))
    yaw_deg: float = Field(
        0.0,
        description=("With facing fixed: the yaw of the front, degrees counter-clockwise from "
                     "+x seen from above."))
    facing_smoothing_s: float = Field(
        0.5, ge=0, le=10,
        description=("With facing walk: the time over which the direction of travel is "
                     "averaged (a Gaussian of this standard deviation), seconds; 0: none."))
    pitch_deg: float = Field(
        0.0, ge=-90, le=90, description="Elevation of the front above horizontal, degrees.")
    head_turn: HeadTurnSpec | None = Field(
        None,
        description=("Seeded random head turns around the facing direction, drawn per group "
                     "and track; none by default. Heard along the exact paths only: needs "
                     "mixture.interpolation paths (or auto) — with a crossfade of RIRs at "
                     "points validate refuses it, as those RIRs cannot follow a turn."))

    @model_validator(mode="after")
    def _sofa_needs_a_file(self) -> DirectivitySpec:
        if (self.pattern == "sofa") != (self.sofa_path is not None):
            raise PydanticCustomError(
                "sofa_path",
                "sofa_path: expected a SOFA file exactly when pattern is 'sofa' (got pattern "
                "'{pattern}', sofa_path {path})",
                {"pattern": self.pattern, "path": repr(self.sofa_path)})
        return self

    @property
    def is_omni(self) -> bool:
        """Radiates the same everywhere (then where it faces does not matter)."""
        return self.pattern == "omni"

    @property
    def facing_rule(self) -> str | float:
        """``walk``, ``toward_mic`` or the fixed yaw (degrees), as
        :func:`sonicspec.acoustics.directivity.facing_yaw_deg` takes it."""
        return self.yaw_deg if self.facing == "fixed" else self.facing


class SourcesDirectivitySpec(SpecModel):
    """The directivity of each source role; every source is omnidirectional by default."""

    speech: DirectivitySpec = Field(
        default_factory=DirectivitySpec,
        description="The talkers (e.g. pattern speech, facing walk).")
    noise: DirectivitySpec = Field(
        default_factory=DirectivitySpec, description="The noise source (static).")
    music: DirectivitySpec = Field(
        default_factory=DirectivitySpec, description="The music source (static).")

    def role(self, role: str) -> DirectivitySpec:
        return getattr(self, role)

    @property
    def is_omni(self) -> bool:
        return all(getattr(self, r).is_omni for r in ("speech", "noise", "music"))
