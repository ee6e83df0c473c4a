"""What the ``export`` and ``dataset`` steps record of the files they write, and the check cache.

The ``export`` artifact's data is :class:`ExportData` (one :class:`ExportGroup` per group of
its shard), the ``dataset`` artifact's :class:`DatasetData`; each lists the dataset-folder
files it wrote as :class:`FileRecord` (path, size, SHA-256, and for audio what the manifests
say of it). ``checked.json`` in the store's cache (:mod:`sonicspec.stages.checked`) is
:class:`CheckedContent`. A field a record does not carry is absent from its JSON, not null
(:class:`FileRecord` leaves its unset fields out), so the stored bytes are those the steps wrote
as plain dicts before these models.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_serializer


class _Record(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class FileRecord(_Record):
    """One file a build wrote into the dataset folder (``checksums.sha256`` lists it).

    ``path``, ``bytes`` and ``sha256`` are those of every file; an export group's files also
    carry ``kind`` and ``name``, and its audio files ``channels``, ``num_samples``,
    ``sample_rate_hz`` and, with ``outputs.scale: per_file``, ``scale``. The dataset step's
    own files (manifests, ``dataset.json``, the checksum list) carry the first three only.
    """

    path: str = Field(description="Relative to the dataset folder, with '/' separators.")
    sha256: str | None = Field(None, description="SHA-256 (hex) of the bytes written; a "
                               "record without one is not checked.")
    bytes: int | None = Field(None, ge=0, description="Size in bytes when written.")
    kind: str | None = Field(None, description="What the file is: speech, noise, music, "
                             "speech_direct ..., rir, mixture, tracks, metadata.")
    name: str | None = Field(None, description="Its name in the group, e.g. source1, "
                             "mixtures/sep_s1s2_noise, rirs/source1/000.")
    channels: int | None = Field(None, ge=1, description="Audio channels.")
    num_samples: int | None = Field(None, ge=0, description="Audio samples per channel.")
    sample_rate_hz: int | None = Field(None, gt=0, description="Audio sample rate (Hz).")
    scale: float | None = Field(None, gt=0, description="outputs.scale per_file: the signal "
                                "is the decoded samples times this.")

    @model_serializer(mode="wrap")
    def _present_only(self, handler: Any) -> Any:
        return {k: v for k, v in handler(self).items() if v is not None}


class MetadataRef(_Record):
    path: str | None = Field(description="The group's metadata.json, relative to the "
                             "dataset folder; null with outputs.metadata off.")


class ExportGroup(_Record):
    """One group's record in an ``export`` artifact, copied by the ``dataset`` step into
    ``dataset.json``, the manifests and ``checksums.sha256``."""

    group: str = Field(description="Group id, '<split>/<index>'.")
    split: str
    scene_id: str
    metadata: MetadataRef
    files: list[FileRecord]
    recordings: list[dict[str, Any]] = Field(description="Lhotse recording entries.")
    supervisions: list[dict[str, Any]] = Field(description="Lhotse supervision entries.")
    duration_s: float = Field(ge=0, description="Clip length (s).")


class ExportData(_Record):
    groups: list[ExportGroup]


class SplitCount(_Record):
    groups: int
    files: int
    audio_hours: float


class DatasetData(_Record):
    dataset_json: str
    manifests: list[str]
    splits: dict[str, SplitCount]
    files: list[FileRecord]


class CheckedContent(_Record):
    """``checked.json``: per artifact key the fingerprint it had when last verified; per
    dataset file (its path as the build named it) ``[size, mtime_ns, sha256]``; per
    ``export``/``dataset`` artifact key ``[fingerprint, [[path, bytes, sha256], ...]]``."""

    artifacts: dict[str, str]
    files: dict[str, tuple[int, int, str]]
    written: dict[str, tuple[str, list[tuple[str, int | None, str]]]] = {}

    def written_records(self) -> dict[str, tuple[str, list[FileRecord]]]:
        return {k: (fp, [FileRecord(path=p, bytes=b, sha256=h) for p, b, h in rows])
                for k, (fp, rows) in self.written.items()}
