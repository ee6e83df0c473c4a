"""Mixing recipe: what a group contains, how loud each part is, which mixtures to export."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, model_serializer, model_validator
from pydantic_core import PydanticCustomError

from sonicspec.spec.base import SpecModel, value_range

Background = Literal["noise", "music", "both", "none"]
Rendering = Literal["paths", "sample_crossfade", "stft_crossfade", "segment_ola"]
"""How a build renders a moving source (``mixture.interpolation`` with ``auto`` resolved)."""
Interpolation = Literal["auto", "paths", "sample_crossfade", "stft_crossfade", "segment_ola"]


LOUDNESS_PRESETS: dict[str, dict[str, float]] = {
    # The SonicSim paper's text: fixed levels.
    "sonicsim_paper": {"speech_lufs": -17.0, "noise_lufs": -21.0, "music_lufs": -24.0,
                       "jitter_lu": 0.0},
    # The released SonicSet scripts: uniform in -17 ± 2, -24 ± 2, -29 ± 2 LUFS.
    "sonicset_release": {"speech_lufs": -17.0, "noise_lufs": -24.0, "music_lufs": -29.0,
                         "jitter_lu": 2.0},
}


class LoudnessSpec(SpecModel):
    """Target loudness of each component (ITU-R BS.1770), before mixing."""

    preset: Literal["sonicsim_paper", "sonicset_release"] | None = Field(
        None,
        description="Named levels: 'sonicsim_paper' (-17/-21/-24 LUFS, as the paper states) or "
        "'sonicset_release' (-17/-24/-29 LUFS ± 2 LU, as the released scripts draw them); sets "
        "the four level fields, which then must not disagree with it.",
    )

    @model_validator(mode="before")
    @classmethod
    def _apply_preset(cls, data: object) -> object:
        if not isinstance(data, dict) or data.get("preset") not in LOUDNESS_PRESETS:
            return data
        levels = LOUDNESS_PRESETS[data["preset"]]
        clash = sorted(k for k, v in levels.items() if k in data and data[k] != v)
        if clash:
            raise PydanticCustomError(
                "preset_conflict",
                "preset '{preset}' sets {fields}; remove {them} or the preset",
                {"preset": data["preset"], "fields": ", ".join(clash),
                 "them": "it" if len(clash) == 1 else "them"},
            )
        return {**data, **levels}

    speech_lufs: float = Field(-17.0, ge=-70, le=0, description="Each speech track, LUFS.")
    noise_lufs: float = Field(-21.0, ge=-70, le=0, description="The noise track, LUFS.")
    music_lufs: float = Field(-24.0, ge=-70, le=0, description="The music track, LUFS.")
    jitter_lu: float = Field(
        0.0,
        ge=0,
        le=20,
        description="Each target is drawn uniformly in target ± jitter, LU (SonicSet's "
        "released scripts: 2).",
    )
    stage: Literal["reverberant", "dry"] = Field(
        "reverberant",
        description="Which signal is normalised: the reverberant track at the microphone (the "
        "level heard) or the dry source before rendering (the gain then carries over).",
    )
    peak_limit_dbfs: float | None = Field(
        -1.0,
        le=0,
        description="If any written signal or mixture would peak above this, the whole group "
        "is scaled down by one gain (recorded as group_gain_db; the build warns when a shard's "
        "median cut exceeds 1 dB), dBFS. null keeps absolute levels (no guard; needs "
        "outputs.scale: per_file, or float WAV: outputs.audio_format wav, subtype FLOAT).",
    )


class SeparationTaskSpec(SpecModel):
    """Mixtures of several speakers (plus optional background) with each speaker as target."""

    kind: Literal["separation"] = Field(description="Task type.")
    speakers: int = Field(2, ge=2, le=10, description="Speakers in each mixture.")
    background: Background = Field("noise", description="Background added to each mixture.")


class EnhancementTaskSpec(SpecModel):
    """Mixtures of one speaker and background with the clean speaker as target."""

    kind: Literal["enhancement"] = Field(description="Task type.")
    background: Literal["noise", "music", "both"] = Field(
        "noise", description="Background added to the speaker."
    )


TaskSpec = Annotated[SeparationTaskSpec | EnhancementTaskSpec, Field(discriminator="kind")]

BackgroundField = Literal["point", "diffuse_spherical", "diffuse_cylindrical"]


class BackgroundFieldSpec(SpecModel):
    """How a static background track (noise or music) reaches the microphone."""

    field: BackgroundField = Field(
        "point",
        description="'point': from its static source placed in the room, through its RIR "
        "(SonicSet). 'diffuse_spherical': an isotropic field, uncorrelated plane waves from "
        "every direction alike (coherence sin(kd)/(kd) between omni capsules d metres "
        "apart); 'diffuse_cylindrical': from every horizontal direction alike (J0(kd)). A "
        "diffuse field is rendered at any receiver through the receiver's own per-direction "
        "response (arrays, ambisonics, binaural), its level set by mixture.loudness like a "
        "point source's.",
    )
    diffuse_fraction: float = Field(
        1.0,
        gt=0,
        le=1,
        description="Share of the track's power that is diffuse, the rest heard from its "
        "point source (both parts brought to equal power at the loudness-measured channels "
        "first), 0 < fraction <= 1. Only with a diffuse field.",
    )

    @model_validator(mode="after")
    def _fraction_needs_a_diffuse_field(self) -> BackgroundFieldSpec:
        if self.field == "point" and self.diffuse_fraction != 1.0:
            raise PydanticCustomError(
                "point_fraction",
                "diffuse_fraction {fraction} needs field diffuse_spherical or "
                "diffuse_cylindrical; a point field has no diffuse part",
                {"fraction": self.diffuse_fraction},
            )
        return self

    @property
    def diffuse(self) -> Literal["spherical", "cylindrical"] | None:
        """The isotropic field's kind, or None for a point source."""
        return None if self.field == "point" else self.field.removeprefix("diffuse_")  # type: ignore[return-value]


class MixtureSpec(SpecModel):
    """One group: a clip of ``duration_s`` in one scene (the SonicSet recipe by default)."""

    duration_s: float = Field(60.0, gt=0, le=3600, description="Length of a group's clip, seconds.")
    speakers: int = Field(3, ge=1, le=10, description="Speech tracks (one speaker each) per group.")
    utterances_per_speaker: value_range(ge=1, integer=True) = Field(  # type: ignore[valid-type]
        (3, 5), description="Whole utterances of the speaker in each speech track."
    )
    utterance_gap_s: value_range(ge=0) = Field(  # type: ignore[valid-type]
        (0.0, 8.0), description="Silence drawn before each utterance, seconds."
    )
    noise_clips: value_range(ge=0, integer=True) = Field(  # type: ignore[valid-type]
        (6, 8), description="Noise clips in the noise track (0: no noise track)."
    )
    noise_gap_s: value_range(ge=0) = Field(  # type: ignore[valid-type]
        (0.0, 4.0), description="Silence drawn before each noise clip, seconds."
    )
    music_clips: value_range(ge=0, integer=True) = Field(  # type: ignore[valid-type]
        (6, 8), description="Music clips in the music track (0: no music track)."
    )
    music_gap_s: value_range(ge=0) = Field(  # type: ignore[valid-type]
        (0.0, 4.0), description="Silence drawn before each music clip, seconds."
    )
    loudness: LoudnessSpec = Field(default_factory=LoudnessSpec, description="Target levels.")
    noise_field: BackgroundFieldSpec = Field(
        default_factory=BackgroundFieldSpec,
        description="How the noise track reaches the microphone: from its point source "
        "(default) or as a diffuse field.",
    )
    music_field: BackgroundFieldSpec = Field(
        default_factory=BackgroundFieldSpec,
        description="How the music track reaches the microphone: from its point source "
        "(default) or as a diffuse field.",
    )
    interpolation: Interpolation = Field(
        "auto",
        description="How a moving source is heard along its path. 'paths': the direct sound and "
        "every image-source reflection as a time-varying delay from where the source is at "
        "each emission (Doppler, level and delay exact; the ray-traced late part crossfaded "
        "between RIR points; edge-diffracted paths too; a moving microphone's images move "
        "with it; every receiver, SOFA HRIRs blended by direction). Or the RIRs along the "
        "path are blended: per-sample crossfade of neighbouring convolutions (SonicSet), "
        "STFT-domain interpolation (DCASE/SpatialScaper), or one RIR per segment with "
        "overlap-added tails (gpuRIR); blends comb-filter the direct sound "
        "(bench/bench_motion.py). 'auto': 'paths'.",
    )

    @model_serializer(mode="wrap")
    def _omit_point_backgrounds(self, handler: Any) -> Any:
        """``noise_field`` / ``music_field`` left out of a dump at their default (``point``),
        as older specs had no such fields: a point-background spec's copy in dataset.json,
        and the dataset step's key, stay as they were (issue 30)."""
        data = handler(self)
        if isinstance(data, dict):
            for name in ("noise_field", "music_field"):
                if getattr(self, name) == BackgroundFieldSpec():
                    data.pop(name, None)
        return data

    def rendering(self) -> Rendering:
        """The method a build uses: ``interpolation``, with ``auto`` resolved (``paths``,
        which this version renders for every receiver)."""
        return "paths" if self.interpolation == "auto" else self.interpolation

    targets: list[Literal["dry", "direct", "early"]] = Field(
        default_factory=list,
        description="Extra training targets exported per source besides the reverberant track.",
    )
    tasks: list[TaskSpec] = Field(
        default_factory=lambda: [
            SeparationTaskSpec(kind="separation"),
            EnhancementTaskSpec(kind="enhancement"),
        ],
        description="Mixtures exported for each group.",
    )
