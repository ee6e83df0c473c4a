"""Device and channel effects on the mixtures (``augmentation:``).

A chain of effects, applied in order to every mixture a group writes: a microphone's
frequency response, its self-noise, gain and clipping, resampling, codecs. Each effect is drawn
per group (from the spec seed and the group) with its ``probability``, and its parameters
uniformly in their ranges (or one of a list); the draws go in ``metadata.json``. The targets
stay clean unless an effect says ``targets: true``. The loader applies the same block on the
fly (``SonicspecDataset(..., augmentation=...)``).

The library :mod:`sonicspec.audio.augment` holds the effects and checks the same block as plain
data (the loader's argument); ``tests/test_augment.py`` keeps the two in step.
"""

from __future__ import annotations

import itertools
from typing import Annotated, Any, Literal

from pydantic import (
    BeforeValidator,
    Field,
    StrictBool,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from sonicspec.spec.base import SpecModel, _fmt, value_range

ResponsePreset = Literal["smartphone", "laptop", "headset", "telephone"]
"""The presets of :data:`sonicspec.audio.augment.RESPONSE_PRESETS` (parametric device-class
shapes, each with where it comes from)."""
Mp3Bitrate = Literal[8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160, 192, 224, 256,
                     320]


def _got(v: Any) -> str:
    """A value as the user wrote it, for a message."""
    if isinstance(v, dict):
        return "a mapping"
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_got(x) for x in v) + "]"
    return _fmt([v])[1:-1]


def _listed(what: str, example: str, min_length: int = 1) -> Any:
    """Before-validator of a list field: a single value, or too few, gets a message naming
    what the list holds and an example (not pydantic's "must be a valid list")."""

    def check(v: Any) -> Any:
        if v is None:
            return v
        if not isinstance(v, (list, tuple)):
            raise PydanticCustomError("list_of", "expected a list of {what}, e.g. {example} "
                                      "(got {got})",
                                      {"what": what, "example": example, "got": _got(v)})
        if len(v) < min_length:
            least = "a non-empty list" if min_length == 1 else f"at least {min_length}"
            raise PydanticCustomError("list_length", "expected {least} of {what}, e.g. "
                                      "{example} (got {got})",
                                      {"least": least, "what": what, "example": example,
                                       "got": _got(v)})
        return v

    return BeforeValidator(check)


def _pair(v: Any) -> Any:
    """Before-validator of one response point: a [frequency Hz, gain dB] pair."""
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise PydanticCustomError("response_pair", "expected a [frequency Hz, gain dB] pair, "
                                  "e.g. [1000, -3] (got {got})", {"got": _got(v)})
    return v


MP3_RATES_HZ = (8000, 11025, 12000, 16000, 22050, 24000, 32000, 44100, 48000)


def mp3_bitrates_at(sample_rate_hz: int) -> tuple[int, ...]:
    """The MP3 bit rates (kbit/s) a dataset at ``sample_rate_hz`` can be coded at: MPEG-1's
    from 32 kHz on, MPEG-2's at 16-24 kHz, MPEG-2.5's (up to 64) below; a rate MP3 does not
    take is coded at the next it takes (the library's rule, checked against it in the tests)."""
    higher = [r for r in MP3_RATES_HZ if r >= sample_rate_hz]
    rate = min(higher) if higher else max(MP3_RATES_HZ)
    if rate >= 32000:
        return (32, 40, 48, 56, 64, 80, 96, 112, 128, 160, 192, 224, 256, 320)
    mpeg2 = (8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160)
    return mpeg2 if rate >= 16000 else tuple(b for b in mpeg2 if b <= 64)


class _EffectSpec(SpecModel):
    probability: float = Field(
        1.0, ge=0, le=1, description="Chance the effect is applied to a group (drawn per "
        "group), 0-1.")
    targets: StrictBool = Field(
        False, description="Also apply the effect (the same draw) to the group's clean "
        "tracks and training targets; false: the targets stay clean.")


class ResponseEffectSpec(_EffectSpec):
    """A microphone's frequency response, as a minimum-phase filter (no bulk delay)."""

    kind: Literal["response"] = Field(description="Effect type.")
    preset: Annotated[list[ResponsePreset] | None, _listed(
        "device-class presets ('smartphone', 'laptop', 'headset', 'telephone'), one drawn "
        "per group", "[smartphone, laptop]")] = Field(
        None, min_length=1, description="Device-class responses, one drawn per group: "
        "'smartphone', 'laptop', 'headset', 'telephone' (300-3400 Hz); parametric shapes, "
        "their sources listed in sonicspec.audio.augment.RESPONSE_PRESETS.")
    points: Annotated[list[Annotated[tuple[float, float], BeforeValidator(_pair)]] | None,
                      _listed("[frequency Hz, gain dB] pairs in increasing frequency",
                              "[[100, -6], [1000, 0], [8000, -3]]", 2)] = Field(
        None, min_length=2, description="A response of your own: [frequency Hz, gain dB] "
        "pairs in increasing frequency (1 Hz-100 kHz, -60 to +30 dB), linear in dB over log "
        "frequency between them, flat beyond the ends.")

    @model_validator(mode="after")
    def _one_source(self) -> ResponseEffectSpec:
        if (self.preset is None) == (self.points is None):
            raise PydanticCustomError("response_source", "expected either preset or points, "
                                      "one of the two (got {what})",
                                      {"what": "neither" if self.preset is None else "both"})
        return self

    @field_validator("points")
    @classmethod
    def _points(cls, v: list[tuple[float, float]] | None) -> list[tuple[float, float]] | None:
        if v is None:
            return v
        bad = [i for i, p in enumerate(v) if not (1 <= p[0] <= 1e5 and -60 <= p[1] <= 30)]
        if bad:
            raise PydanticCustomError("response_points", "expected [Hz, dB] with 1 <= Hz <= "
                                      "100000 and -60 <= dB <= 30 (got {p} as point {i})",
                                      {"p": _got(v[bad[0]]), "i": bad[0]})
        if any(b[0] <= a[0] for a, b in itertools.pairwise(v)):
            raise PydanticCustomError("response_order", "expected points in increasing "
                                      "frequency (got {got})", {"got": _got(v)})
        return v


class ImpulseResponseEffectSpec(_EffectSpec):
    """A measured device impulse response from a file (WAV/FLAC; the first channel)."""

    kind: Literal["impulse_response"] = Field(description="Effect type.")
    files: Annotated[list[str], _listed(
        "impulse-response files (relative to the spec), one drawn per group",
        "[device_ir.wav]")] = Field(
        min_length=1, description="Impulse-response files relative to the spec, one drawn "
        "per group; scaled to unit energy and advanced by their peak, so they colour the "
        "mixture without moving or re-levelling it; resampled to sample_rate_hz if needed.")


class SelfNoiseEffectSpec(_EffectSpec):
    """The device's own noise, independent per channel."""

    kind: Literal["self_noise"] = Field(description="Effect type.")
    snr_db: value_range(ge=-20, le=100) = Field(  # type: ignore[valid-type]
        description="Signal-to-noise ratio drawn per group, dB: the mixture's mean power "
        "(over the clip and the channels) over the noise's.")
    color: Literal["white", "pink"] = Field("white", description="Noise spectrum: flat, or "
                                            "1/f power.")


class GainEffectSpec(_EffectSpec):
    """A gain (the device's input level)."""

    kind: Literal["gain"] = Field(description="Effect type.")
    gain_db: value_range(ge=-60, le=40) = Field(  # type: ignore[valid-type]
        description="Gain drawn per group, dB.")


class ClippingEffectSpec(_EffectSpec):
    """Hard clipping (an overdriven converter)."""

    kind: Literal["clipping"] = Field(description="Effect type.")
    threshold_dbfs: value_range(ge=-60, le=0) = Field(  # type: ignore[valid-type]
        description="Clipping level drawn per group, dBFS: samples beyond ± it are cut to it.")


class ResampleEffectSpec(_EffectSpec):
    """Down to a lower rate and back (a narrow-band link)."""

    kind: Literal["resample"] = Field(description="Effect type.")
    rate_hz: Annotated[list[Annotated[int, Field(ge=1000, le=192000)]], _listed(
        "sample rates in Hz (1000-192000), one drawn per group", "[8000, 11025]")] = Field(
        min_length=1, description="Rates, one drawn per group, Hz: the signal is resampled "
        "to it and back with sonicspec's resampler (flat to 0.9 × its Nyquist frequency, "
        "about 90 dB down above it); a rate at or above the dataset's does nothing.")


class Mp3EffectSpec(_EffectSpec):
    """MP3 at a constant bit rate (LAME through libsndfile)."""

    kind: Literal["mp3"] = Field(description="Effect type.")
    bitrate_kbps: Annotated[list[Mp3Bitrate], _listed(
        "MP3 bit rates in kbit/s (8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160, "
        "192, 224, 256 or 320), one drawn per group", "[64, 128]")] = Field(
        min_length=1, description="Bit rates per channel, one drawn per group, kbit/s "
        "(32-320 at 32 kHz and above; 8-160 at 16-24 kHz; 8-64 below).")


class OpusEffectSpec(_EffectSpec):
    """Opus (libopus through libsndfile; variable bit rate around the asked one)."""

    kind: Literal["opus"] = Field(description="Effect type.")
    bitrate_kbps: value_range(ge=6, le=256) = Field(  # type: ignore[valid-type]
        description="Bit rate per channel drawn per group (rounded to 1 kbit/s), kbit/s.")


class GsmEffectSpec(_EffectSpec):
    """GSM 06.10 full rate: the narrow-band phone codec, 13 kbit/s at 8 kHz (the signal is
    resampled to 8 kHz and back)."""

    kind: Literal["gsm"] = Field(description="Effect type.")


SingleEffectSpec = Annotated[
    ResponseEffectSpec | ImpulseResponseEffectSpec | SelfNoiseEffectSpec | GainEffectSpec
    | ClippingEffectSpec | ResampleEffectSpec | Mp3EffectSpec | OpusEffectSpec | GsmEffectSpec,
    Field(discriminator="kind"),
]


class OneOfEffectSpec(_EffectSpec):
    """One of several effects, drawn per group (e.g. one codec of three)."""

    kind: Literal["one_of"] = Field(description="Effect type.")
    effects: Annotated[list[SingleEffectSpec], _listed(
        "effects to choose from (each a mapping with its kind; not one_of)",
        "[{kind: opus, bitrate_kbps: [16, 32]}, {kind: gsm}]")] = Field(
        min_length=1, description="The effects to choose from (their own probability and "
        "targets are ignored: this effect's apply).")
    weights: Annotated[list[Annotated[float, Field(ge=0)]] | None, _listed(
        "relative weights >= 0, one per effect", "[2, 1]")] = Field(
        None, description="Relative weight of each effect (null: equal).")

    @field_validator("weights")
    @classmethod
    def _weights(cls, v: list[float] | None, info: ValidationInfo) -> list[float] | None:
        effects = info.data.get("effects")
        if v is None or effects is None:  # (bad effects are reported on their own)
            return v
        if len(v) != len(effects) or sum(v) <= 0:
            raise PydanticCustomError(
                "weights", "expected {n} weights >= 0 (one per effect) with a positive sum "
                "(got {w})", {"n": len(effects), "w": _got(v)})
        return v


EffectSpec = Annotated[SingleEffectSpec | OneOfEffectSpec, Field(discriminator="kind")]


class AugmentationSpec(SpecModel):
    """Device and channel effects applied to each group's mixtures, in order."""

    effects: Annotated[list[EffectSpec], _listed(
        "effects, each a mapping with its kind, applied in order",
        "[{kind: self_noise, snr_db: [30, 50]}, {kind: mp3, bitrate_kbps: [64]}]", 0)] = Field(
        default_factory=list, description="The chain, applied in this order (a device's "
        "order: response, self_noise, gain, clipping, then resample and a codec).")
