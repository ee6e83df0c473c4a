"""Reading a built dataset folder: its groups, their tracks and mixtures, windows of audio.

A folder is what ``sonicspec build`` writes (docs/reference/dataset.md): ``dataset.json``
lists the groups; each group's ``metadata.json`` (SonicSet form) names its tracks
(``source1``…, ``noise``, ``music``, each with ``file`` and its position ``track`` in the
group's ``tracks.npz``), the stems beside them
(``source1_dry``…, found by name) and its ``mixtures`` (``name``, ``task``, ``components``,
``targets``, ``file``). A dataset built with ``outputs.scale: per_file`` also has
``audio_scales`` (file relative to the group's folder -> scale): its PCM files peak just under
full scale and the signal is the decoded samples times the scale, which every read here applies
(a dataset without the map reads as decoded: scale 1, or a file's own ``sonicspec_scale`` tag).
Nothing here writes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.errors import SonicspecError
from sonicspec.export.files import SCALE_TAG, check_scale, read_scale_tag, scale_from_comment
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
        ``(channels, samples)``, at the signal's level (the file's scale applied)."""
        path = self.path_of(name_or_path)
        return read_audio(path, start, stop, channels, scale=self.recorded_scale(path))

    def path_of(self, name_or_path: str | Path) -> Path:
        """The file of a track or stem name, or of a path relative to the folder."""
        return (self.track_path(name_or_path) if isinstance(name_or_path, str)
                and "/" not in name_or_path else self.root / name_or_path)

    def recorded_scale(self, path: Path) -> float | None:
        """The scale ``metadata.json``'s ``audio_scales`` records for a file of the group
        (``outputs.scale: per_file``); None when the dataset records none (built without
        scales, or before them: the files are at their level, or carry their own tag). A
        file the map lacks, or a value that is not a finite number > 0, is a
        :class:`DatasetError`."""
        scales = self.metadata.get("audio_scales")
        if scales is None:
            return None
        where = f"{self.root / self.id}/metadata.json: audio_scales"
        if not isinstance(scales, dict):
            raise DatasetError(f"{where}: expected a map of file -> scale, got {scales!r}")
        try:
            rel = Path(path).relative_to(self.root / self.id).as_posix()
        except ValueError:
            raise DatasetError(f"{path}: not a file of group {self.id}") from None
        if rel not in scales:
            raise DatasetError(f"{where}: no scale for {rel!r} (its samples are scaled to "
                               "full scale; without the scale its level is unknown); rebuild "
                               "the group or restore its metadata.json")
        try:
            return check_scale(scales[rel], f"{where}[{rel!r}]")
        except SonicspecError as exc:
            raise DatasetError(str(exc)) from None

    def scale(self, name_or_path: str | Path) -> float:
        """The factor that brings a file's decoded samples to the signal's level: the
        recorded scale, else the file's own tag (``sonicspec_scale=``), else 1."""
        path = self.path_of(name_or_path)
        recorded = self.recorded_scale(path)
        return recorded if recorded is not None else _tag_scale(path) or 1.0


def _tag_scale(path: Path) -> float | None:
    try:
        return read_scale_tag(path)
    except SonicspecError as exc:
        raise DatasetError(str(exc)) from None
    except (RuntimeError, OSError) as exc:
        raise DatasetError(f"{path}: cannot read audio ({exc})") from None


def read_audio(path: Path, start: int = 0, stop: int | None = None,
               channels: tuple[int, ...] | None = None, *, scale: float | None = None
               ) -> np.ndarray:
    """Samples ``[start, stop)`` of an audio file, float32 ``(channels, samples)``, at the
    signal's level.

    ``scale`` is the one the dataset records for the file; the file's own comment tag
    (``sonicspec_scale=``, :data:`sonicspec.export.files.SCALE_TAG`) must then agree with
    it. Without ``scale`` the tag's is used, and without a tag the samples are as decoded
    (float WAV, or files written without scales).
    """
    import soundfile as sf

    try:
        with sf.SoundFile(str(path)) as fh:
            tag = scale_from_comment(fh.comment, path)
            end = fh.frames if stop is None else min(stop, fh.frames)
            if start:
                fh.seek(start)
            want = np.float32 if (scale or tag or 1.0) == 1.0 else np.float64
            data = fh.read(max(0, end - start), dtype=want, always_2d=True)
    except SonicspecError as exc:
        raise DatasetError(str(exc)) from None
    except (sf.LibsndfileError, RuntimeError, OSError) as exc:
        raise DatasetError(f"{path}: cannot read audio ({exc})") from None
    if scale is not None and tag is not None and tag != scale:
        raise DatasetError(f"{path}: its tag {SCALE_TAG}={tag!r} differs from the scale the "
                           f"metadata records ({scale!r}); the file or metadata.json changed "
                           "after the build (sonicspec verify names which)")
    factor = scale if scale is not None else tag
    if factor is not None and factor != 1.0:
        # One rounding to float32, after the scale (the file's integers are exact in float64).
        data = (data * factor).astype(np.float32)
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
