"""Manifests: Lhotse-compatible JSONL (recordings, supervisions) and a flat CSV.

Lhotse reads ``RecordingSet`` and ``SupervisionSet`` from JSONL files of dicts in the shape
its ``to_dict`` writes; sonicspec writes that shape without importing Lhotse:

* recording: ``{id, sources: [{type: "file", channels: [0..C-1], source: path}],
  sampling_rate, num_samples, duration, channel_ids}``, and for a source's own file
  ``custom: {track: {file, frames, hop_s, arrays, scale}}``: a reference to the source's
  position track in the group's ``tracks.npz`` (:mod:`sonicspec.export.tracks`; before
  metadata version 2 the lists themselves), and for
  a scaled file (``outputs.scale: per_file``) ``transforms: [{name: "Volume", kwargs:
  {factor: <scale>}}]``, which Lhotse applies on load
* supervision: ``{id, recording_id, start, duration, channel, text, speaker}``
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import IO, Any


@dataclass(frozen=True)
class RecordingEntry:
    """One audio file of the dataset, as a manifest sees it."""

    id: str
    path: str
    sample_rate_hz: int
    num_samples: int
    channels: int
    custom: Mapping[str, Any] | None = None
    """Extra fields (Lhotse's ``custom``): a source's position ``track``."""
    scale: float | None = None
    """The file's scale (``outputs.scale: per_file``): Lhotse applies it as the recording's
    ``Volume`` transform, so ``load_audio()`` gives the signal at its level."""

    def to_lhotse(self) -> dict[str, Any]:
        extra: dict[str, Any] = {"custom": dict(self.custom)} if self.custom else {}
        if self.scale is not None:
            extra["transforms"] = [{"name": "Volume", "kwargs": {"factor": self.scale}}]
        return {
            **extra,
            "id": self.id,
            "sources": [{"type": "file", "channels": list(range(self.channels)),
                         "source": self.path}],
            "sampling_rate": self.sample_rate_hz,
            "num_samples": self.num_samples,
            "duration": round(self.num_samples / self.sample_rate_hz, 6),
            "channel_ids": list(range(self.channels)),
        }


@dataclass(frozen=True)
class SupervisionEntry:
    """One utterance inside a recording: where it is, who says what."""

    id: str
    recording_id: str
    start_sample: int
    end_sample: int
    sample_rate_hz: int
    text: str
    speaker: str

    def to_lhotse(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "recording_id": self.recording_id,
            "start": round(self.start_sample / self.sample_rate_hz, 6),
            "duration": round((self.end_sample - self.start_sample) / self.sample_rate_hz, 6),
            "channel": 0,
            "text": self.text,
            "speaker": self.speaker,
        }


def jsonl_line(item: Mapping[str, Any]) -> str:
    """One JSON object on one line (keys sorted) and a newline."""
    return json.dumps(item, sort_keys=True, ensure_ascii=False) + "\n"


def jsonl(items: Iterable[Mapping[str, Any]]) -> str:
    """One compact JSON object per line, keys sorted."""
    return "".join(jsonl_line(item) for item in items)


def csv_writer(fh: IO[str], columns: Sequence[str]) -> csv.DictWriter:
    """A CSV writer on ``fh`` whose header is written; missing cells are empty
    (``restval``), cells it has no column for are left out."""
    writer = csv.DictWriter(fh, fieldnames=list(columns), lineterminator="\n", restval="",
                            extrasaction="ignore")
    writer.writeheader()
    return writer


def csv_text(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> str:
    """CSV with a header; missing cells are empty."""
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({c: row.get(c, "") for c in columns})
    return out.getvalue()
