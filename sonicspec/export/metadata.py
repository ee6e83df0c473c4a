"""A group's ``metadata.json``: the typed record the export writes, and its JSON Schema.

The record is SonicSet's per-group metadata — ``source1..N: {audio, start_end_points, words}``,
``noise``, ``music`` — extended with what sonicspec knows: the speaker, the trajectory, the RIR
points, the acoustic figures, the gains, the mixtures and the content keys. Position tracks are
not in it: each ``track`` (and ``microphone_track``) is a reference to the group's
``tracks.npz`` (:mod:`sonicspec.export.tracks`).

The models below are the one definition of the record: the export step builds it through them
(so a field cannot be misspelled or mistyped) and :func:`metadata_schema` turns them into the
JSON Schema checked in as ``schema/sonicspec-metadata-v2.schema.json`` (``sonicspec schema
--metadata``), which other tools can validate a ``metadata.json`` against.

Version history (``version`` in the record): 1 had no ``version`` field and the tracks inline
(lists every 10 ms in ``track``/``microphone_track``, repeated in the Lhotse manifests); 2
references ``tracks.npz`` and is written as compact JSON.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from sonicspec.atomic import write_text

METADATA_VERSION = 2
METADATA_SCHEMA_FILENAME = f"sonicspec-metadata-v{METADATA_VERSION}.schema.json"
SPEECH_KEY_PATTERN = r"^source[1-9][0-9]*$"

Vector3 = tuple[float, float, float]


class _Record(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class TrackReference(_Record):
    """Where a track's numbers are: arrays of the group's ``tracks.npz``."""

    file: str = Field(description="The archive, relative to the dataset folder.")
    frames: int = Field(ge=0, description="Frames in each array (one every hop_s).")
    hop_s: float = Field(gt=0, description="Time between frames, seconds (0.01).")
    arrays: dict[str, str] = Field(description=(
        "Quantity (positions_m, azimuth_deg, elevation_deg, distance_m, and for a "
        "directional source yaw_deg: where it faces, degrees counter-clockwise from +x; the "
        "microphone: positions_m and, when it moves, yaw_deg) -> the array's name in the "
        "archive."))
    scale: dict[str, int] = Field(description=(
        "Quantity -> integers per unit: the value is the stored int32 array / scale "
        "(10000 per metre, 100 per degree)."))


class Loudness(_Record):
    """How a component was levelled (the mix step's record)."""

    role: Literal["speech", "noise", "music"] = Field(description="The component's role.")
    target_lufs: float = Field(description="Level asked for, LUFS.")
    measured_lufs: float = Field(description="Level measured before the gain, LUFS.")
    measured_on: Literal["reverberant", "dry"] = Field(
        description="The signal the level was measured on.")
    gain_db: float | None = Field(description="Gain applied, dB (null: silence).")
    output_lufs: float = Field(description="Level of the written file, LUFS.")


class RirTail(_Record):
    """How a RIR's length was chosen (the rir step's
    :class:`~sonicspec.acoustics.late.tails.TailFacts`, field by field): every band's decay
    60 dB down, at most a limit."""

    rule: Literal["auto", "fixed"] = Field(description=(
        "acoustics.max_rir_length_s: auto (the decay decides, at most max_rir_cap_s) or a "
        "number of seconds (fixed)."))
    limit_s: float = Field(description="The longest RIR allowed, seconds.")
    limit_field: str = Field(description=(
        "The spec field that sets the limit (max_rir_cap_s or max_rir_length_s)."))
    decay_end_s: float = Field(description="Where the last band's late decay ends, seconds.")
    decay_60db_s: list[float | None] = Field(description=(
        "Per band: when its decay is 60 dB below its early level, seconds (null: not "
        "within the limit)."))
    continued_from_s: list[float | None] = Field(description=(
        "Per band: where the rays ran out and a line fitted to the last 20 dB of the decay "
        "carries it on, seconds (null: traced to the end)."))
    level_at_limit_db: list[float | None] = Field(description=(
        "Per band: the level its decay reached where the limit cut it, dB re its early "
        "level (null: not cut)."))
    fitted_t60_s: list[float | None] = Field(description=(
        "Per band: the 60 dB time of the fitted line where it was used (a continuation, a "
        "cut), seconds (null: not used)."))


class ImageSourceOrder(_Record):
    """How far the exact early reflections went (issue 27): a scan's noise can make the
    candidate search stop below the order asked, the ray tracer covering the rest."""

    asked: int = Field(ge=0, description="acoustics.image_source_order.")
    reached: int = Field(ge=0, description="The order every RIR of the track completed.")
    stopped: str | None = Field(description="Why reached < asked (null: it is not).")


class _Track(_Record):
    audio: list[str] = Field(description="Corpus files of the clips, in time order.")
    start_end_points: list[tuple[int, int]] = Field(
        description="Each clip's [start, end) in the group, samples.")
    file: str | None = Field(description=(
        "The track's audio file, relative to the dataset folder (null: not written, "
        "outputs.sources / outputs.background off)."))
    rir_points_m: list[Vector3] = Field(description=(
        "Where the RIRs were computed, metres (empty for a background heard only as a "
        "diffuse field, diffuse_fraction 1: its point source is not traced)."))
    t30_s: float | None = Field(None, description=(
        "T30 of the first point's RIR, seconds (null: the decay is too short to fit; "
        "absent: no RIR, a background heard only as a diffuse field)."))
    drr_db: float | None = Field(None, description=(
        "Direct-to-reverberant ratio of the first point's RIR, dB (absent: no RIR)."))
    direct_path: str | None = Field(None, description=(
        "The direct path at the first point: visible, through walls or blocked (absent: no "
        "RIR)."))
    rir_tail: RirTail | None = Field(None, description=(
        "How the RIR's length was chosen at the first point (absent: no RIR, a background "
        "heard only as a diffuse field)."))
    loudness: Loudness = Field(description="How the track was levelled.")
    image_source_order: ImageSourceOrder | None = Field(None, description=(
        "The image-source order asked and reached by the track's RIRs (the lowest over its "
        "points), and why it is lower; absent in datasets built before it was recorded."))
    track: TrackReference = Field(description=(
        "Where the source is every hop_s (positions_m) and where it is heard from "
        "(azimuth_deg, elevation_deg, distance_m in the microphone's frame)."))


class SpeechTrack(_Track):
    """A moving talker: its utterances, what they say, and its walk."""

    words: list[str] = Field(description="The transcript of each clip.")
    speaker: str = Field(description="The corpus speaker id.")
    trajectory_m: list[Vector3] = Field(description="The walk's corner points, metres.")
    path_length_m: float = Field(ge=0, description="Length of the walk, metres.")


class BackgroundTrack(_Track):
    """A static noise or music source."""

    position_m: Vector3 = Field(description="Where the source stands, metres.")
    field: Literal["diffuse_spherical", "diffuse_cylindrical"] | None = Field(None, description=(
        "How the track reaches the microphone when not from its point source alone "
        "(mixture.noise_field / music_field): a spherically or cylindrically isotropic "
        "field. Absent: from the point source at position_m."))
    diffuse_fraction: float | None = Field(None, gt=0, le=1, description=(
        "With field: the share of the track's power that is diffuse (the rest from the "
        "point source at position_m)."))


class MixtureRecord(_Record):
    name: str = Field(description="The mixture's name (sep_s1s2_noise ...).")
    task: Literal["separation", "enhancement"] = Field(description="The task it is for.")
    components: list[str] = Field(description="Tracks summed into it.")
    targets: list[str] = Field(description="Tracks it is to be separated into.")
    file: str = Field(description="Its audio file, relative to the dataset folder.")
    augmentation: list[dict[str, Any] | None] | None = Field(None, description=(
        "With augmentation: what each effect of the group's draw measured on this mixture, "
        "in the chain's order (null: not applied): bitrate_kbps (encoded bytes x 8 / duration, "
        "per channel) and codec_rate_hz of a codec, clipped_share of clipping, noise_rms_db "
        "of self-noise; and full_scale_clipped_share, the share of samples cut at 0 dBFS when "
        "the file cannot hold more."))


class CapsuleRecord(BaseModel):
    """One capsule of the microphone, in its own frame (x where it faces, y its left, z up:
    turned into the scene by its yaw and pitch, ``microphone_track``'s ``yaw_deg`` when it
    moves)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    position_m: Vector3 = Field(description="Offset from the microphone's centre, metres.")
    pattern: str = Field(description=(
        "First-order pattern a + (1 - a) cos(theta): omni, subcardioid, cardioid, "
        "supercardioid, hypercardioid or figure_eight (ideal: the same at every frequency)."))
    axis: Vector3 = Field(description="Unit vector the capsule points to.")


class CapsulesRecord(BaseModel):
    """The microphone's capsules when they are not all omni in free field, or a device."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    device: str | None = Field(description="The device preset, if the spec named one.")
    sphere_radius_m: float | None = Field(description=(
        "Radius of the rigid sphere the capsules sit on (rendered with the sphere head's "
        "model), metres; null in free field."))
    capsules: list[CapsuleRecord] = Field(description="Per channel, in channel order.")


class GroupMetadata(BaseModel):
    """One group's ``metadata.json``. Speech tracks are the keys ``source1`` … ``sourceN``."""

    model_config = ConfigDict(frozen=True, extra="allow", json_schema_extra={
        "propertyNames": {"anyOf": [{"pattern": SPEECH_KEY_PATTERN},
                                    {"enum": ["version", "group", "split", "scene_id",
                                              "mic_m", "floor", "sample_rate_hz",
                                              "num_samples", "mixtures", "group_gain_db",
                                              "keys", "microphone_track", "noise", "music",
                                              "audio_scales", "capsules", "augmentation"]}]}})
    __pydantic_extra__: dict[str, SpeechTrack] = Field(init=False)  # type: ignore[assignment]

    version: Literal[2] = Field(METADATA_VERSION, description="Version of this record's form.")
    group: str = Field(description="The group id, <split>/<index>.")
    split: str = Field(description="The split.")
    scene_id: str = Field(description="The scene the group is in.")
    mic_m: Vector3 = Field(description="Where the microphone starts, metres.")
    floor: int = Field(description="The floor of the scene the group is on.")
    sample_rate_hz: int = Field(gt=0, description="Sample rate of every file, Hz.")
    num_samples: int = Field(ge=0, description="Length of every track, samples.")
    mixtures: list[MixtureRecord] = Field(description="The task mixtures written.")
    group_gain_db: float | None = Field(description=(
        "Gain applied to the whole group to keep its peaks under the limit, dB."))
    keys: dict[str, str] = Field(description="Step -> content key of the job that made it.")
    microphone_track: TrackReference = Field(description=(
        "Where the microphone is every hop_s (positions_m), and where it faces (yaw_deg) "
        "when it moves."))
    noise: BackgroundTrack | None = Field(None, description="The noise track, if any.")
    music: BackgroundTrack | None = Field(None, description="The music track, if any.")
    capsules: CapsulesRecord | None = Field(None, description=(
        "The microphone's capsules (patterns, axes, positions) when any is directional, on a "
        "rigid sphere, or from a device preset; absent for omni capsules in free field."))
    audio_scales: dict[str, float] | None = Field(None, description=(
        "With outputs.scale: per_file, each audio file (relative to the group's folder) -> "
        "its scale: the signal is the decoded samples times it (the file's sonicspec_scale "
        "tag says the same)."))

    augmentation: list[dict[str, Any]] | None = Field(None, description=(
        "The group's draw of the spec's augmentation chain, in order: each effect's kind, "
        "applied (drawn with its probability), targets (also applied to the clean tracks) and "
        "its drawn parameters (preset or points, file, snr_db, color and seed, gain_db, "
        "threshold_dbfs, rate_hz, bitrate_kbps; one_of: choice and the chosen effect's draw). "
        "Absent without augmentation."))

    def to_json(self) -> str:
        """Compact JSON, keys sorted, final newline; absent backgrounds, scales, capsules and
        augmentation, a point background's field and the RIR facts of a background without
        RIRs (heard only as a diffuse field), left out."""
        data = self.model_dump(mode="json")
        for name in ("noise", "music", "audio_scales", "capsules", "augmentation"):
            if data[name] is None:
                del data[name]
            elif name in ("noise", "music"):  # a point background: no field recorded
                for key in ("field", "diffuse_fraction"):
                    if data[name][key] is None:
                        del data[name][key]
                if data[name]["rir_tail"] is None:  # diffuse only: no RIR, no RIR facts
                    for key in ("t30_s", "drr_db", "direct_path", "rir_tail",
                                "image_source_order"):
                        del data[name][key]
        for m in data["mixtures"]:
            if m.get("augmentation", 0) is None:
                del m["augmentation"]
        return json.dumps(data, sort_keys=True, separators=(",", ":"),
                          ensure_ascii=False) + "\n"

    def write(self, path: Path) -> Path:
        return write_text(path, self.to_json())


def metadata_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``metadata.json``."""
    schema = GroupMetadata.model_json_schema(mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["$id"] = f"https://sonicspec.dev/schema/{METADATA_SCHEMA_FILENAME}"
    schema["title"] = f"sonicspec group metadata.json, version {METADATA_VERSION}"
    return schema


def metadata_schema_text() -> str:
    """The schema as stable text: sorted keys, two-space indent, final newline."""
    return json.dumps(metadata_schema(), indent=2, sort_keys=True, ensure_ascii=False) + "\n"
