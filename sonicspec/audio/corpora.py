"""Corpora: index speech, noise and music collections once, then load and resample their files.

An index (:class:`CorpusIndex`) lists every usable file of a corpus with its split, speaker,
length, transcript and labels, so arranging a group never has to open a file just to learn how
long it is. Reading a corpus of 100 000 files takes minutes, so the pipeline builds the index
once and keeps it as JSON (:func:`cached_index`).

Readers follow the real layouts:

- LibriSpeech: ``<root>/<subset>/<speaker>/<chapter>/<speaker>-<chapter>-<nnnn>.flac`` and
  ``<speaker>-<chapter>.trans.txt`` (lines ``<utterance id> <WORDS>``); each split is fed by
  whole subsets, so speakers never cross splits.
- FSD50K: ``FSD50K.dev_audio/<fname>.wav``, ``FSD50K.eval_audio/<fname>.wav`` and
  ``FSD50K.ground_truth/{dev,eval}.csv`` (``fname,labels,mids[,split]``, labels comma-joined).
  The official dev/eval partition is pooled and re-split by ratio (SonicSet's 7:2:1).
- FMA: ``fma_<size>/<nnn>/<track id:06d>.mp3`` and ``fma_metadata/tracks.csv`` (three header
  rows: column group, field, then ``track_id``); ``genres_all`` lists genre ids, 1235 is
  Instrumental. ``fma_metadata/genres.csv``, when present, turns ids into genre names.
- A plain folder: every file with a chosen ending; with ``by_speaker`` the first-level
  sub-folders are the speakers.

A file that cannot be used (unreadable, missing from its transcript, listed but absent) is
skipped and reported by name in :attr:`CorpusIndex.problems`; a missing root or metadata file,
or a split left without any usable file, is a :class:`~sonicspec.errors.CorpusError`.

Ratio splits are a permutation, drawn from the caller's generator, of the sorted ids (or
speakers), cut into consecutive runs whose lengths are the ratios rounded by largest remainder:
the same seed and the same listing give the same split on every machine.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import soundfile as sf

from sonicspec.atomic import write_text
from sonicspec.errors import AudioError, CorpusError, SonicspecError
from sonicspec.shares import split_shares

INDEX_FORMAT = 2
"""Version of the JSON an index is stored as; a cache in another format is rebuilt."""

FMA_SIZES = ("small", "medium", "large", "full")
FMA_INSTRUMENTAL_GENRE_ID = 1235
"""FMA's top-level genre "Instrumental" (no vocals): the music SonicSet mixes in."""

RESAMPLE_PASSBAND = 0.9
"""Resampling keeps 0 … 0.9 × the lower Nyquist frequency flat (ripple < 0.001 dB)."""
RESAMPLE_STOPBAND_DB = 90.0
"""… and attenuates everything at and above the lower Nyquist frequency by this much (the
Kaiser design target; 89.7 dB measured for 44.1 → 16 kHz)."""


# --------------------------------------------------------------------------------------------
# Index objects


@dataclass(frozen=True)
class CorpusItem:
    """One usable audio file of a corpus, as the index records it."""

    id: str
    """Unique in the corpus: LibriSpeech ``84-121123-0000``, FSD50K ``64760``, FMA ``000002``,
    a folder corpus the path below the root without its ending (``spk1/take03``)."""
    path: str
    """Absolute path of the audio file."""
    split: str
    """The split the file feeds (``train``, ``val``, ``test`` …)."""
    speaker: str
    """Speaker id for speech; ``""`` for noise and music."""
    num_samples: int
    """Length in frames at the file's own rate."""
    sample_rate_hz: int
    """The file's own sample rate."""
    text: str = ""
    """Transcript (speech), as the corpus writes it."""
    labels: tuple[str, ...] = ()
    """FSD50K sound-event labels or FMA genres."""

    @property
    def duration_s(self) -> float:
        """Length in seconds."""
        return self.num_samples / self.sample_rate_hz

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (labels as a list)."""
        return {
            "id": self.id, "path": self.path, "split": self.split, "speaker": self.speaker,
            "num_samples": self.num_samples, "sample_rate_hz": self.sample_rate_hz,
            "text": self.text, "labels": list(self.labels),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CorpusItem:
        """Inverse of :meth:`to_dict`."""
        return cls(
            id=str(d["id"]), path=str(d["path"]), split=str(d["split"]),
            speaker=str(d["speaker"]), num_samples=int(d["num_samples"]),
            sample_rate_hz=int(d["sample_rate_hz"]), text=str(d.get("text", "")),
            labels=tuple(str(label) for label in d.get("labels", ())),
        )


@dataclass(frozen=True)
class CorpusIndex:
    """Every usable file of a corpus, sorted by (split, id), and what was skipped and why."""

    kind: str
    """``librispeech``, ``fsd50k``, ``fma`` or ``folder``."""
    items: tuple[CorpusItem, ...]
    """Sorted by (split, id) on construction."""
    problems: tuple[str, ...] = ()
    """One message per problem met (mostly a skipped file), naming the file and the reason."""
    skipped: tuple[tuple[str, str], ...] = ()
    """(path, reason) of every file left out: unreadable, unlisted, duplicated, listed but
    missing. Paths as the reader saw them (the corpus stage stores them relative to the
    root)."""

    def __post_init__(self) -> None:
        items = tuple(sorted(self.items, key=lambda it: (it.split, it.id)))
        seen: set[str] = set()
        for item in items:
            if item.id in seen:
                raise CorpusError(f"{self.kind} corpus: expected unique item ids, got "
                                  f"{item.id!r} more than once")
            seen.add(item.id)
        object.__setattr__(self, "items", items)
        object.__setattr__(self, "problems", tuple(self.problems))
        object.__setattr__(self, "skipped", tuple((str(p), str(r)) for p, r in self.skipped))

    @property
    def splits(self) -> list[str]:
        """The splits that hold at least one item, sorted."""
        return sorted({item.split for item in self.items})

    def split(self, name: str) -> list[CorpusItem]:
        """Items of one split, sorted by id."""
        return [item for item in self.items if item.split == name]

    def speakers(self, split: str) -> dict[str, list[CorpusItem]]:
        """Speaker -> that speaker's items (sorted by id) in one split; speakers sorted."""
        out: dict[str, list[CorpusItem]] = {}
        for item in self.split(split):
            out.setdefault(item.speaker, []).append(item)
        return dict(sorted(out.items()))

    def require_speakers(self, split: str, needed: int, where: str) -> None:
        """Raise :class:`CorpusError` unless ``split`` has at least ``needed`` speakers."""
        have = len(self.speakers(split))
        if have < needed:
            raise CorpusError(
                f"{where}: split '{split}' has {have} speaker{'' if have == 1 else 's'}, the "
                f"mixture needs {needed}; add speakers to the corpus or lower the number of "
                f"speakers per mixture{self._skipped_hint()}")

    def require_items(self, split: str, needed: int, where: str) -> None:
        """Raise :class:`CorpusError` unless ``split`` has at least ``needed`` files."""
        have = len(self.split(split))
        if have < needed:
            raise CorpusError(
                f"{where}: split '{split}' has {have} usable file{'' if have == 1 else 's'}, "
                f"{needed} are needed; add files to the corpus or ask for fewer"
                f"{self._skipped_hint()}")

    def _skipped_hint(self) -> str:
        if not self.problems:
            return ""
        return f" ({len(self.problems)} files were skipped, e.g. {self.problems[0]})"

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict, with the index format version."""
        return {"format": INDEX_FORMAT, "kind": self.kind,
                "items": [item.to_dict() for item in self.items],
                "problems": list(self.problems),
                "skipped": [{"path": p, "reason": r} for p, r in self.skipped]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CorpusIndex:
        """Inverse of :meth:`to_dict`; a dict in another format is a :class:`CorpusError`."""
        if d.get("format") != INDEX_FORMAT:
            raise CorpusError(f"corpus index: expected format {INDEX_FORMAT}, got "
                              f"{d.get('format')!r}")
        return cls(kind=str(d["kind"]),
                   items=tuple(CorpusItem.from_dict(item) for item in d["items"]),
                   problems=tuple(str(p) for p in d.get("problems", ())),
                   skipped=tuple((s["path"], s["reason"]) for s in d.get("skipped", ())))


# --------------------------------------------------------------------------------------------
# Shared helpers


def _require_dir(path: Path, what: str) -> None:
    if not path.is_dir():
        raise CorpusError(f"{what}: expected a folder at {path}, got nothing there"
                          if not path.exists() else
                          f"{what}: expected a folder at {path}, got a file")


def _require_file(path: Path, what: str) -> None:
    if not path.is_file():
        raise CorpusError(f"{what}: expected the file {path}, got nothing there")


def _hidden(path: Path) -> bool:
    """Dot-files are temporaries of interrupted writes (and OS litter), never corpus files."""
    return path.name.startswith(".")


def _subdirs(path: Path) -> list[Path]:
    return sorted(p for p in path.iterdir() if p.is_dir() and not _hidden(p))


def probe_audio(path: Path) -> tuple[int, int] | str:
    """(frames, sample rate) of an audio file, or why it is unusable.

    The one test of whether a corpus file is usable: the readers and ``validate
    --check-files`` both ask it.
    """
    try:
        info = sf.info(str(path))
    except (RuntimeError, OSError, ValueError) as err:  # LibsndfileError is a RuntimeError
        return f"unreadable audio ({err})"
    if info.frames <= 0 or info.samplerate <= 0:
        return "no audio samples"
    truncated = _truncated(info.extra_info)
    if truncated is not None:
        return truncated
    return int(info.frames), int(info.samplerate)


# libsndfile's parse log: ``data : 2000000000 (should be 100)`` when a WAV (``data``), AIFF
# (``SSND``) or similar chunk claims more bytes than the file holds; it then reads what is
# there without a word.
_CHUNK_CLAIM = re.compile(r"^\s*(data|SSND)\s*:\s*(\d+)\s*\(should be (\d+)\)", re.M)
_UNKNOWN_LENGTH = (0, 0xFFFFFFFF, 0xFFFFFFFF - 1)
"""Chunk sizes streaming writers leave when they do not know the length: not a claim."""


def _truncated(parse_log: str) -> str | None:
    """Why a file whose header claims more audio than it holds is unusable (a cut copy or
    download: what is there is a fragment of the recording), or None."""
    for chunk, claimed, held in _CHUNK_CLAIM.findall(parse_log or ""):
        claimed_n, held_n = int(claimed), int(held)
        if held_n < claimed_n and claimed_n not in _UNKNOWN_LENGTH:
            return (f"truncated: its header's {chunk} chunk claims {claimed_n:,} bytes of audio "
                    f"but the file holds {held_n:,} (an interrupted copy or download?)")
    return None


def _check_ratios(ratios: Mapping[str, float], where: str) -> dict[str, float]:
    """The positive shares, by split name; they must sum to 1 (:func:`split_shares`)."""
    try:
        return split_shares(ratios, list(ratios))
    except SonicspecError as err:
        raise CorpusError(f"{where}: {err}") from None


def _ratio_counts(n: int, ratios: Mapping[str, float]) -> dict[str, int]:
    """Split ``n`` by largest remainder; every split gets one when there are enough."""
    names = sorted(ratios)
    exact = [ratios[name] * n for name in names]
    counts = [math.floor(e) for e in exact]
    # Largest remainder first; a tie (up to float noise) goes to the larger share.
    order = sorted(range(len(names)),
                   key=lambda i: (round(counts[i] - exact[i], 9), -ratios[names[i]], i))
    for i in order[: n - sum(counts)]:
        counts[i] += 1
    for i in sorted(range(len(names)), key=lambda i: (-ratios[names[i]], i)):
        if counts[i] == 0:
            j = max(range(len(names)), key=lambda m: (counts[m], -m))
            if counts[j] > 1:
                counts[j] -= 1
                counts[i] += 1
    return dict(zip(names, counts, strict=True))


def _assign_by_ratio(keys: Sequence[str], ratios: Mapping[str, float],
                     rng: np.random.Generator) -> dict[str, str]:
    """Key -> split: a permutation of the sorted keys cut into runs of the ratio counts."""
    ordered = sorted(keys)
    perm = rng.permutation(len(ordered))
    out: dict[str, str] = {}
    start = 0
    for name, count in _ratio_counts(len(ordered), ratios).items():
        for i in perm[start: start + count]:
            out[ordered[i]] = name
        start += count
    return out


class _Findings(list):
    """The problem messages of an indexing run (a list of str), and which files it skipped."""

    def __init__(self) -> None:
        super().__init__()
        self.skipped: list[tuple[str, str]] = []

    def skip(self, path: Path, reason: str, message: str | None = None) -> None:
        """Record ``path`` as skipped for ``reason`` and report it (by default
        ``<path>: <reason>; skipped``; ``message=""`` records without a message)."""
        self.skipped.append((str(path), reason))
        if message != "":
            self.append(message or f"{path}: {reason}; skipped")


def _finish(kind: str, items: list[CorpusItem], problems: _Findings, splits: Sequence[str],
            where: str) -> CorpusIndex:
    index = CorpusIndex(kind=kind, items=tuple(items), problems=tuple(problems),
                        skipped=tuple(problems.skipped))
    for name in sorted(splits):
        if not index.split(name):
            hint = f"; skipped files: {'; '.join(problems[:3])}" if problems else ""
            raise CorpusError(f"{where}: split '{name}' has no usable files{hint}")
    return index


# --------------------------------------------------------------------------------------------
# LibriSpeech


def index_librispeech(root: Path, subsets: Mapping[str, Sequence[str]]) -> CorpusIndex:
    """Index a LibriSpeech-layout corpus; ``subsets`` maps each split to its subset folders.

    A chapter without its ``<speaker>-<chapter>.trans.txt``, an utterance its transcript does
    not list and an unreadable file are skipped and reported; a subset given to two splits, a
    speaker found in subsets of two splits, or a missing subset folder is an error.
    """
    root = Path(root)
    _require_dir(root, "LibriSpeech root")
    if not subsets:
        raise CorpusError("LibriSpeech subsets: expected at least one split, got none")
    split_of_subset: dict[str, str] = {}
    for split, names in subsets.items():
        if not names:
            raise CorpusError(f"LibriSpeech subsets of split '{split}': expected at least "
                              "one subset folder, got none")
        for name in names:
            other = split_of_subset.setdefault(name, split)
            if other != split:
                raise CorpusError(f"LibriSpeech subset '{name}': expected in one split, got "
                                  f"in '{other}' and '{split}'; speakers would cross splits")
            _require_dir(root / name, f"LibriSpeech subset '{name}'")
    items: list[CorpusItem] = []
    problems = _Findings()
    split_of_speaker: dict[str, str] = {}
    for subset, split in sorted(split_of_subset.items()):
        for speaker_dir in _subdirs(root / subset):
            speaker = speaker_dir.name
            other = split_of_speaker.setdefault(speaker, split)
            if other != split:
                raise CorpusError(
                    f"LibriSpeech speaker {speaker} ({speaker_dir}): expected in the subsets "
                    f"of one split, got in '{other}' and '{split}'; speakers must not cross "
                    "splits")
            for chapter_dir in _subdirs(speaker_dir):
                _index_chapter(chapter_dir, speaker, split, items, problems)
    return _finish("librispeech", items, problems, list(subsets), "LibriSpeech")


def librispeech_speakers(root: Path, subsets: Mapping[str, Sequence[str]]
                         ) -> dict[str, list[str]]:
    """Split -> its speakers (sorted folder names) in a LibriSpeech-layout corpus, read from
    the folder names alone (no audio file is opened): what a plan counts before the corpus is
    indexed. A missing subset folder is an error; a speaker in two splits is one too."""
    root = Path(root)
    _require_dir(root, "LibriSpeech root")
    out: dict[str, list[str]] = {}
    split_of_speaker: dict[str, str] = {}
    for split, names in subsets.items():
        found: set[str] = set()
        for name in names:
            _require_dir(root / name, f"LibriSpeech subset '{name}'")
            for speaker_dir in _subdirs(root / name):
                other = split_of_speaker.setdefault(speaker_dir.name, split)
                if other != split:
                    raise CorpusError(
                        f"LibriSpeech speaker {speaker_dir.name} ({speaker_dir}): expected in "
                        f"the subsets of one split, got in '{other}' and '{split}'; speakers "
                        "must not cross splits")
                found.add(speaker_dir.name)
        out[split] = sorted(found)
    return out


def _read_transcript(path: Path, problems: _Findings) -> dict[str, str] | None:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        problems.append(f"{path}: unreadable transcript ({err}); its chapter skipped")
        return None
    out: dict[str, str] = {}
    for line in lines:
        parts = line.strip().split(maxsplit=1)
        if parts:
            out[parts[0]] = parts[1] if len(parts) > 1 else ""
    return out


def _index_chapter(chapter_dir: Path, speaker: str, split: str, items: list[CorpusItem],
                   problems: _Findings) -> None:
    flacs = sorted(p for p in chapter_dir.glob("*.flac") if p.is_file() and not _hidden(p))
    if not flacs:
        return
    trans = chapter_dir / f"{speaker}-{chapter_dir.name}.trans.txt"
    if not trans.is_file():
        problems.append(f"{trans}: transcript file missing; skipped the {len(flacs)} "
                        f"utterances of {chapter_dir}")
        for flac in flacs:
            problems.skip(flac, f"transcript file {trans.name} missing", "")
        return
    words = _read_transcript(trans, problems)
    if words is None:
        for flac in flacs:
            problems.skip(flac, f"transcript file {trans.name} unreadable", "")
        return
    for flac in flacs:
        uid = flac.stem
        if uid not in words:
            problems.skip(flac, f"utterance missing from its transcript {trans.name}",
                          f"{flac}: utterance {uid} missing from its transcript {trans}; "
                          "skipped")
            continue
        probe = probe_audio(flac)
        if isinstance(probe, str):
            problems.skip(flac, probe)
            continue
        items.append(CorpusItem(id=uid, path=str(flac.resolve()), split=split,
                                speaker=speaker, num_samples=probe[0],
                                sample_rate_hz=probe[1], text=words[uid]))
    present = {flac.stem for flac in flacs}
    for uid in sorted(set(words) - present):
        problems.append(f"{trans}: lists {uid} but {chapter_dir / (uid + '.flac')} does not "
                        "exist")


# --------------------------------------------------------------------------------------------
# FSD50K


def _read_csv_dicts(path: Path, required: Sequence[str], what: str) -> list[dict[str, str]]:
    _require_file(path, what)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            missing = [c for c in required if c not in (reader.fieldnames or ())]
            if missing:
                raise CorpusError(f"{path}: expected columns {', '.join(required)}, got "
                                  f"{', '.join(reader.fieldnames or ()) or 'no header'}")
            return list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise CorpusError(f"{path}: expected a readable CSV file, got {err}") from err


def index_fsd50k(root: Path, split_ratios: Mapping[str, float], exclude_labels: Sequence[str],
                 rng: np.random.Generator) -> CorpusIndex:
    """Index FSD50K: dev and eval pooled, clips with an excluded label left out, split by ratio.

    The split is drawn over the listed clips that survive the label filter, before their files
    are opened, so a broken file never moves another clip to a different split.
    """
    root = Path(root)
    _require_dir(root, "FSD50K root")
    ratios = _check_ratios(split_ratios, "FSD50K split_ratios")
    excluded = set(exclude_labels)
    listed: dict[str, tuple[Path, tuple[str, ...]]] = {}
    problems = _Findings()
    for part, folder in (("dev", "FSD50K.dev_audio"), ("eval", "FSD50K.eval_audio")):
        gt = root / "FSD50K.ground_truth" / f"{part}.csv"
        rows = _read_csv_dicts(gt, ("fname", "labels"), f"FSD50K {part} ground truth")
        audio_dir = root / folder
        _require_dir(audio_dir, f"FSD50K {part} audio")
        for row in rows:
            fname = (row["fname"] or "").strip()
            labels = tuple(x.strip() for x in (row["labels"] or "").split(",") if x.strip())
            if not fname:
                problems.append(f"{gt}: row without fname; skipped")
                continue
            if excluded.intersection(labels):
                continue
            if fname in listed:
                problems.append(f"{gt}: clip {fname} listed again; the first listing kept")
                continue
            listed[fname] = (audio_dir / f"{fname}.wav", labels)
    split_of = _assign_by_ratio(list(listed), ratios, rng)
    items: list[CorpusItem] = []
    for fname in sorted(listed):
        path, labels = listed[fname]
        if not path.is_file():
            problems.skip(path, "listed in the ground truth but missing")
            continue
        probe = probe_audio(path)
        if isinstance(probe, str):
            problems.skip(path, probe)
            continue
        items.append(CorpusItem(id=fname, path=str(path.resolve()), split=split_of[fname],
                                speaker="", num_samples=probe[0], sample_rate_hz=probe[1],
                                labels=labels))
    return _finish("fsd50k", items, problems, list(ratios), "FSD50K")


# --------------------------------------------------------------------------------------------
# FMA


def _parse_genre_ids(text: str) -> tuple[int, ...]:
    """``"[1235, 10]"`` -> (1235, 10); ``"[]"`` or ``""`` -> ()."""
    body = text.strip()
    if body.startswith("[") and body.endswith("]"):
        body = body[1:-1]
    return tuple(int(x) for x in body.split(",") if x.strip())


class _CsvFieldLimit:
    """Raise csv's per-field size limit while reading (FMA's artist bios are long)."""

    def __enter__(self) -> None:
        self._old = csv.field_size_limit(min(sys.maxsize, 2**31 - 1))

    def __exit__(self, *exc: object) -> None:
        csv.field_size_limit(self._old)


def _read_fma_tracks(path: Path, problems: _Findings
                     ) -> dict[int, tuple[str, tuple[int, ...]]]:
    """track id -> (genre_top, genres_all) from FMA's three-header-row tracks.csv."""
    _require_file(path, "FMA track metadata")
    out: dict[int, tuple[str, tuple[int, ...]]] = {}
    try:
        with _CsvFieldLimit(), open(path, newline="", encoding="utf-8") as f:
            reader = csv.reader(f)
            header = [next(reader, None) for _ in range(3)]
            if any(row is None for row in header) or not header[2] or \
                    header[2][0].strip() != "track_id":
                raise CorpusError(f"{path}: expected FMA's three header rows (column groups, "
                                  "fields, then 'track_id'), got another layout")
            columns = {(a.strip(), b.strip()): i for i, (a, b) in
                       enumerate(zip(header[0], header[1], strict=False))}
            try:
                top_col = columns["track", "genre_top"]
                all_col = columns["track", "genres_all"]
            except KeyError:
                raise CorpusError(f"{path}: expected the columns track/genre_top and "
                                  "track/genres_all, got none of that name") from None
            for row in reader:
                if not row or not row[0].strip():
                    continue
                try:
                    track = int(row[0])
                    genres = _parse_genre_ids(row[all_col])
                except (ValueError, IndexError):
                    problems.append(f"{path}: line {reader.line_num}: unreadable track id or "
                                    "genres_all; row skipped")
                    continue
                out[track] = (row[top_col].strip() if top_col < len(row) else "", genres)
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise CorpusError(f"{path}: expected a readable CSV file, got {err}") from err
    return out


def _read_fma_genres(path: Path) -> dict[int, str]:
    """genre id -> title from the optional genres.csv (empty if absent)."""
    if not path.is_file():
        return {}
    out: dict[int, str] = {}
    for row in _read_csv_dicts(path, ("genre_id", "title"), "FMA genres"):
        try:
            out[int(row["genre_id"])] = row["title"].strip()
        except (ValueError, AttributeError):
            continue
    return out


def index_fma(root: Path, size: str, split_ratios: Mapping[str, float],
              instrumental_only: bool, rng: np.random.Generator) -> CorpusIndex:
    """Index FMA audio in ``fma_<size>`` against ``fma_metadata/tracks.csv``, split by ratio.

    With ``instrumental_only`` only tracks whose ``genres_all`` holds Instrumental (1235) or
    whose ``genre_top`` is Instrumental are kept (SonicSet mixes music without vocals). Labels
    are the names of ``genres_all`` (ids when ``genres.csv`` is absent).
    """
    root = Path(root)
    _require_dir(root, "FMA root")
    if size not in FMA_SIZES:
        raise CorpusError(f"FMA size: expected one of {', '.join(FMA_SIZES)}, got {size!r}")
    ratios = _check_ratios(split_ratios, "FMA split_ratios")
    audio_dir = root / f"fma_{size}"
    _require_dir(audio_dir, f"FMA audio (fma_{size})")
    problems = _Findings()
    tracks_csv = root / "fma_metadata" / "tracks.csv"
    tracks = _read_fma_tracks(tracks_csv, problems)
    names = _read_fma_genres(root / "fma_metadata" / "genres.csv")
    listed: dict[str, tuple[Path, tuple[str, ...]]] = {}
    for mp3 in sorted(p for p in audio_dir.glob("*/*.mp3") if p.is_file() and not _hidden(p)):
        stem = mp3.stem
        if not stem.isdigit():
            problems.skip(mp3, "expected an FMA file name <track id>.mp3")
            continue
        meta = tracks.get(int(stem))
        if meta is None:
            problems.skip(mp3, f"track {int(stem)} is not in {tracks_csv.name}",
                          f"{mp3}: track {int(stem)} is not in {tracks_csv}; skipped")
            continue
        genre_top, genres = meta
        if instrumental_only and not (FMA_INSTRUMENTAL_GENRE_ID in genres
                                      or genre_top == "Instrumental"):
            continue
        labels = tuple(names.get(g, str(g)) for g in genres) or \
            ((genre_top,) if genre_top else ())
        if stem in listed:
            problems.skip(mp3, f"track {stem} found twice; the first kept",
                          f"{mp3}: track {stem} found twice; the first kept")
            continue
        listed[stem] = (mp3, labels)
    split_of = _assign_by_ratio(list(listed), ratios, rng)
    items: list[CorpusItem] = []
    for stem in sorted(listed):
        path, labels = listed[stem]
        probe = probe_audio(path)
        if isinstance(probe, str):
            problems.skip(path, probe)
            continue
        items.append(CorpusItem(id=stem, path=str(path.resolve()), split=split_of[stem],
                                speaker="", num_samples=probe[0], sample_rate_hz=probe[1],
                                labels=labels))
    return _finish("fma", items, problems, list(ratios), "FMA")


# --------------------------------------------------------------------------------------------
# Plain folders


def normalise_extensions(extensions: Sequence[str]) -> set[str]:
    """File endings as the readers match them: lower case with the dot (``WAV`` -> ``.wav``)."""
    exts = {e.lower() if e.startswith(".") else f".{e.lower()}" for e in extensions if e}
    if not exts:
        raise CorpusError("folder corpus extensions: expected at least one file ending, "
                          "got none")
    return exts


def audio_files(root: Path, exts: set[str]) -> Iterator[Path]:
    """Files below ``root`` with one of the endings ``exts`` (lower case, with the dot), in
    sorted walking order; dot-files and dot-folders are left out."""
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        for name in sorted(filenames):
            path = Path(dirpath) / name
            if not name.startswith(".") and path.suffix.lower() in exts:
                yield path


def index_folder(root: Path, extensions: Sequence[str], split_ratios: Mapping[str, float],
                 rng: np.random.Generator, *, by_speaker: bool) -> CorpusIndex:
    """Index every audio file below ``root``; ids are paths below it without the ending.

    With ``by_speaker`` the first-level sub-folders are speakers and whole speakers are split
    by ratio (speakers never cross splits; files directly in ``root`` are skipped); otherwise
    files are split by ratio.
    """
    root = Path(root)
    _require_dir(root, "folder corpus root")
    exts = normalise_extensions(extensions)
    ratios = _check_ratios(split_ratios, "folder corpus split_ratios")
    problems = _Findings()
    listed: dict[str, tuple[Path, str]] = {}
    for path in audio_files(root, exts):
        rel = path.relative_to(root)
        uid = rel.with_suffix("").as_posix()
        speaker = rel.parts[0] if len(rel.parts) > 1 else ""
        if by_speaker and not speaker:
            problems.skip(path, "not inside a speaker folder")
            continue
        if uid in listed:
            problems.skip(path, f"same id {uid!r} as {listed[uid][0].name}",
                          f"{path}: same id {uid!r} as {listed[uid][0]}; skipped")
            continue
        listed[uid] = (path, speaker if by_speaker else "")
    if by_speaker:
        split_of_speaker = _assign_by_ratio(sorted({s for _, s in listed.values()}), ratios, rng)
        split_of = {uid: split_of_speaker[s] for uid, (_, s) in listed.items()}
    else:
        split_of = _assign_by_ratio(list(listed), ratios, rng)
    items = _probe_listed(listed, split_of, problems)
    return _finish("folder", items, problems, list(ratios), f"folder corpus {root}")


def folder_speakers(root: Path, extensions: Sequence[str], split_ratios: Mapping[str, float],
                    rng: np.random.Generator) -> dict[str, list[str]]:
    """Split -> its speakers (sorted) in a folder speech corpus, from the file names alone:
    the speakers :func:`index_folder` with ``by_speaker`` assigns when given the same ``rng``
    and every file is readable."""
    root = Path(root)
    _require_dir(root, "folder corpus root")
    ratios = _check_ratios(split_ratios, "folder corpus split_ratios")
    speakers = {p.relative_to(root).parts[0] for p in audio_files(root,
                                                                   normalise_extensions(extensions))
                if len(p.relative_to(root).parts) > 1}
    out: dict[str, list[str]] = {name: [] for name in ratios}
    for speaker, split in _assign_by_ratio(sorted(speakers), ratios, rng).items():
        out[split].append(speaker)
    return {name: sorted(v) for name, v in out.items()}


def _probe_listed(listed: Mapping[str, tuple[Path, str]], split_of: Mapping[str, str],
                  problems: _Findings) -> list[CorpusItem]:
    items: list[CorpusItem] = []
    for uid in sorted(listed):
        path, speaker = listed[uid]
        probe = probe_audio(path)
        if isinstance(probe, str):
            problems.skip(path, probe)
            continue
        items.append(CorpusItem(id=uid, path=str(path.resolve()), split=split_of[uid],
                                speaker=speaker, num_samples=probe[0],
                                sample_rate_hz=probe[1]))
    return items


def index_split_folders(root: Path, splits: Sequence[str],
                        extensions: Sequence[str] = (".flac", ".wav")) -> CorpusIndex:
    """Index a folder already divided by split: ``<root>/<split>/**/<file>``.

    The layout :func:`sonicspec.audio.generated.generate_background_corpus` writes. Ids are
    paths below ``root`` without the ending (``train/noise-0003``); no speakers.
    """
    root = Path(root)
    _require_dir(root, "split folder corpus root")
    exts = normalise_extensions(extensions)
    problems = _Findings()
    listed: dict[str, tuple[Path, str]] = {}
    split_of: dict[str, str] = {}
    for split in splits:
        _require_dir(root / split, f"split folder corpus, split '{split}'")
        for path in audio_files(root / split, exts):
            uid = path.relative_to(root).with_suffix("").as_posix()
            if uid in listed:
                problems.skip(path, f"same id {uid!r} as {listed[uid][0].name}",
                          f"{path}: same id {uid!r} as {listed[uid][0]}; skipped")
                continue
            listed[uid] = (path, "")
            split_of[uid] = split
    items = _probe_listed(listed, split_of, problems)
    return _finish("folder", items, problems, list(splits), f"split folder corpus {root}")


# --------------------------------------------------------------------------------------------
# Cache


def cached_index(cache_file: Path, build: Callable[[], CorpusIndex]) -> CorpusIndex:
    """The index stored in ``cache_file``, or ``build()`` stored there (atomically) first.

    A cache that cannot be read or parsed, or is in another format, is rebuilt. The caller
    names the cache file after what determines the index (corpus kind, root listing, ratios,
    seed), so a changed corpus gets a new file instead of a stale index.
    """
    cache_file = Path(cache_file)
    try:
        return CorpusIndex.from_dict(json.loads(cache_file.read_text(encoding="utf-8")))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass  # absent, unreadable, corrupt or stale: rebuild
    index = build()
    text = json.dumps(index.to_dict(), separators=(",", ":"), sort_keys=True)
    write_text(cache_file, text)
    return index


# --------------------------------------------------------------------------------------------
# Resampling and loading


@lru_cache(maxsize=32)
def _antialias_filter(from_hz: int, to_hz: int) -> np.ndarray:
    """Kaiser-window low-pass at the upsampled rate for :func:`resample`.

    Flat to ``RESAMPLE_PASSBAND`` × the lower Nyquist, about ``RESAMPLE_STOPBAND_DB`` down
    from the lower Nyquist on, so nothing above the output's Nyquist aliases back (scipy's
    default filter is centred on Nyquist and lets a tone 2 kHz above it alias at −57 dB).
    """
    g = math.gcd(from_hz, to_hz)
    up = to_hz // g
    fs_up = from_hz * up
    nyquist = min(from_hz, to_hz) / 2
    width = (1 - RESAMPLE_PASSBAND) * nyquist
    from scipy.signal import firwin, kaiserord  # scipy.signal takes 1 s to import

    numtaps, beta = kaiserord(RESAMPLE_STOPBAND_DB, width / (fs_up / 2))
    numtaps |= 1  # odd length: resample_poly compensates a whole-sample delay
    return firwin(numtaps, (1 + RESAMPLE_PASSBAND) / 2 * nyquist, window=("kaiser", beta),
                  fs=fs_up)


def resample(x: np.ndarray, from_hz: int, to_hz: int) -> np.ndarray:
    """Resample along the last axis by the reduced ratio ``to/from`` (polyphase FIR).

    Parameters
    ----------
    x : array (..., T)
        Signal at ``from_hz``.
    from_hz, to_hz : int
        Sample rates in Hz (positive integers).

    Returns
    -------
    array (..., ceil(T * to / from)), float64
        The band below 0.9 × the lower Nyquist frequency is kept (ripple < 0.001 dB);
        everything at or above the lower Nyquist is attenuated by about 90 dB; no delay.
    """
    for name, rate in (("from_hz", from_hz), ("to_hz", to_hz)):
        if isinstance(rate, bool) or not float(rate).is_integer() or rate <= 0:
            raise AudioError(f"resample {name}: expected a positive whole number of Hz, got "
                             f"{rate!r}")
    from_hz, to_hz = int(from_hz), int(to_hz)
    x = np.asarray(x, dtype=np.float64)
    if from_hz == to_hz:
        return x.copy()
    g = math.gcd(from_hz, to_hz)
    from scipy.signal import resample_poly

    return resample_poly(x, to_hz // g, from_hz // g, axis=-1,
                         window=_antialias_filter(from_hz, to_hz))


def load_audio(item_or_path: CorpusItem | str | os.PathLike[str], sample_rate_hz: int
               ) -> np.ndarray:
    """A corpus file as mono float64 at ``sample_rate_hz`` (channels averaged, resampled).

    An unreadable or empty file is a :class:`CorpusError` naming it.
    """
    path = item_or_path.path if isinstance(item_or_path, CorpusItem) else os.fspath(item_or_path)
    try:
        data, rate = sf.read(path, dtype="float64", always_2d=True)
    except (RuntimeError, OSError, ValueError) as err:
        raise CorpusError(f"{path}: expected a readable audio file, got {err}") from err
    if data.shape[0] == 0:
        raise CorpusError(f"{path}: expected audio samples, got an empty file")
    return resample(data.mean(axis=1), int(rate), sample_rate_hz)
