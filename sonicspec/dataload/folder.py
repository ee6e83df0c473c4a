"""Reading a built dataset folder: its groups, their tracks and mixtures, windows of audio.

A folder is what ``sonicspec build`` writes (README, "What a build writes"): ``dataset.json``
lists the groups; each group's ``metadata.json`` (SonicSet form) names its tracks
(``source1``…, ``noise``, ``music``, each with ``file`` and its position ``track`` in the
group's ``tracks.npz``), the stems beside them
(``source1_dry``…, found by name) and its ``mixtures`` (``name``, ``task``, ``components``,
``targets``, ``file``). Nothing here writes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.errors import SonicspecError
from sonicspec.export.tracks import TrackError, read_track

STEMS = ("dry", "direct", "early")
BACKGROUNDS = {"noise": ("noise",), "music": ("music",), "both": ("noise", "music"), "none": ()}


class DatasetError(SonicspecError):
    """A dataset folder, an estimates folder or a loader setting is not usable as asked."""


@dataclass(frozen=True)
class Group:
    """One group of a built dataset: its id (``train/000000``), folder and metadata."""

    root: Path
    id: str
    metadata: dict[str, Any] = field(repr=False)

    @property
    def split(self) -> str:
        return self.id.split("/")[0]

    @property
    def sample_rate_hz(self) -> int:
        return int(self.metadata["sample_rate_hz"])

    @property
    def num_samples(self) -> int:
        return int(self.metadata["num_samples"])

    @cached_property
    def speakers(self) -> tuple[str, ...]:
        """The speech tracks, ``source1``… in order."""
        names = [k for k in self.metadata if k.startswith("source") and k[6:].isdigit()]
        return tuple(sorted(names, key=lambda k: int(k[6:])))

    @cached_property
    def backgrounds(self) -> tuple[str, ...]:
        return tuple(b for b in ("noise", "music") if b in self.metadata)

    def mixtures(self, task: str | None = None) -> list[dict[str, Any]]:
        return [m for m in self.metadata.get("mixtures", []) if task in (None, m["task"])]

    def track_path(self, name: str) -> Path:
        """The audio file of a track (``source1``, ``noise``) or a stem (``source1_dry``)."""
        entry = self.metadata.get(name)
        if entry is not None and entry.get("file"):
            return self.root / entry["file"]
        base, _, stem = name.rpartition("_")
        if stem in STEMS and base in self.metadata:
            own = self.metadata[base].get("file")
            suffix = Path(own).suffix if own else ".flac"
            for ext in dict.fromkeys((suffix, ".flac", ".wav")):
                path = self.root / self.id / f"{name}{ext}"
                if path.is_file():
                    return path
            raise DatasetError(f"{self.root / self.id}: no {name} file; the dataset was built "
                               f"without mixture.targets: [{stem}]")
        raise DatasetError(f"{self.root / self.id}/metadata.json: no audio file for {name!r} "
                           "(outputs.sources / outputs.background off?)")

    def track(self, name: str) -> dict[str, Any]:
        """The position track of ``name`` (a source, or ``microphone``) as
        ``{"hop_s", "positions_m", ...}`` float64 arrays, read from the group's
        ``tracks.npz`` (or from the lists of a dataset built before it)."""
        return self.tracks((name,))[name]

    def tracks(self, names: tuple[str, ...] | list[str]) -> dict[str, dict[str, Any]]:
        """:meth:`track` of several names, opening the group's ``tracks.npz`` once (nothing
        is kept after: a loader visits every group)."""
        archives: dict[str, Any] = {}
        out = {}
        for name in names:
            entry = (self.metadata.get("microphone_track") if name == "microphone"
                     else (self.metadata.get(name) or {}).get("track"))
            if entry is None:
                raise DatasetError(f"{self.root / self.id}/metadata.json: no track for "
                                   f"{name!r}")
            try:
                out[name] = read_track(self.root, entry, archives)
            except TrackError as exc:
                raise DatasetError(str(exc)) from None
        return out

    def read(self, name_or_path: str | Path, start: int = 0, stop: int | None = None,
             channels: tuple[int, ...] | None = None) -> np.ndarray:
        """Samples ``[start, stop)`` of a track (or a file under the folder) as float32
        ``(channels, samples)``."""
        path = (self.track_path(name_or_path) if isinstance(name_or_path, str)
                and "/" not in name_or_path else self.root / name_or_path)
        return read_audio(path, start, stop, channels)


def read_audio(path: Path, start: int = 0, stop: int | None = None,
               channels: tuple[int, ...] | None = None) -> np.ndarray:
    """Samples ``[start, stop)`` of an audio file, float32 ``(channels, samples)``."""
    import soundfile as sf

    try:
        data, _ = sf.read(str(path), start=start, stop=stop, dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, OSError) as exc:
        raise DatasetError(f"{path}: cannot read audio ({exc})") from None
    out = data.T
    if channels is not None:
        if max(channels) >= out.shape[0]:
            raise DatasetError(f"{path}: channel {max(channels)} asked for, the file has "
                               f"{out.shape[0]}")
        out = out[list(channels)]
    return np.ascontiguousarray(out)


class DatasetFolder:
    """A built dataset folder: ``dataset.json`` and every group's ``metadata.json``."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        summary = self.root / "dataset.json"
        try:
            self.summary = json.loads(summary.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise DatasetError(f"{summary}: missing; expected a dataset folder built by "
                               "`sonicspec build` (its outputs.dir)") from None
        except json.JSONDecodeError as exc:
            raise DatasetError(f"{summary}: not JSON ({exc})") from None
        self._groups: dict[str, Group] = {}

    @property
    def splits(self) -> list[str]:
        return sorted(self.summary.get("splits", {}))

    def group_ids(self, split: str) -> list[str]:
        if split not in self.summary.get("splits", {}):
            raise DatasetError(f"{self.root}: split {split!r} not in the dataset; it has "
                               f"{self.splits}")
        return sorted(g["group"] for g in self.summary["groups"] if g["split"] == split)

    def group(self, group_id: str) -> Group:
        if group_id not in self._groups:
            entry = next((g for g in self.summary["groups"] if g["group"] == group_id), None)
            if entry is None:
                raise DatasetError(f"{self.root}: no group {group_id!r}")
            rel = (entry.get("metadata") or {}).get("path")
            if rel is None:
                raise DatasetError(f"{self.root}: group {group_id} has no metadata.json (built "
                                   "with outputs.metadata: false); the loader needs it")
            try:
                meta = json.loads((self.root / rel).read_text(encoding="utf-8"))
            except (OSError, json.JSONDecodeError) as exc:
                raise DatasetError(f"{self.root / rel}: unreadable ({exc})") from None
            self._groups[group_id] = Group(self.root, group_id, meta)
        return self._groups[group_id]

    def groups(self, split: str) -> list[Group]:
        return [self.group(g) for g in self.group_ids(split)]
