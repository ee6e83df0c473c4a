"""Checksums of the dataset folder, and the markers that say what a folder is.

Every file a build writes into the dataset folder has its SHA-256 recorded when it is written
(in the export and dataset artifacts) and listed in ``checksums.sha256`` at the folder's top, in
the format of coreutils' ``sha256sum`` (``sha256sum -c checksums.sha256`` checks a copy without
sonicspec). ``sonicspec verify DATASET`` checks every listed file.

Marker files tell what a folder is, so that a build never writes into a folder that is not its
own and ``verify`` knows what it is pointed at: ``.sonicspec-dataset.json`` in a dataset folder
(with the store's location relative to it) and ``sonicspec-store.json`` in a store.
"""

from __future__ import annotations

import contextlib
import heapq
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sonicspec.artifacts.records import FileRecord
from sonicspec.atomic import open_atomic, write_text
from sonicspec.errors import SpecError, StoreError
from sonicspec.export.files import write_json
from sonicspec.hashing import file_sha256

CHECKSUMS_NAME = "checksums.sha256"
DATASET_MARKER = ".sonicspec-dataset.json"
STORE_MARKER = "sonicspec-store.json"
# The report a build writes at the dataset's top (outputs.report), and its group pages.
REPORT_NAME = "report.html"
REPORT_FILES = "report_files"
STORE_STEP_FOLDERS = ("plans", "corpus", "mesh")  # what a store made before markers has


def file_record(out: Path, path: Path, **facts: Any) -> FileRecord:
    """The :class:`~sonicspec.artifacts.records.FileRecord` (path, SHA-256, bytes and
    ``facts``: kind, name, channels ...) of a file just written under the dataset folder."""
    return FileRecord(path=path.relative_to(out).as_posix(), sha256=file_sha256(path),
                      bytes=path.stat().st_size, **facts)


def checksum_line(record: FileRecord) -> str:
    """One line of ``checksums.sha256`` (``<sha256>  <path>`` and a newline)."""
    return f"{record.sha256}  {record.path}\n"


def checksums_text(records: Iterable[FileRecord]) -> str:
    return "".join(checksum_line(r) for r in sorted(records, key=lambda r: r.path))


def write_checksums(out: Path, records: Iterable[FileRecord]) -> Path:
    return write_text(out / CHECKSUMS_NAME, checksums_text(records))


def write_checksums_merged(out: Path, lines: Iterable[str], records: Iterable[FileRecord]
                           ) -> Path:
    """``checksums.sha256`` from ``lines`` already sorted by path (streamed, e.g. from a
    spool file) and a few more ``records``, merged in path order without holding the lines.
    """
    def path_of(line: str) -> str:
        return line[66:-1]

    extra = [checksum_line(r) for r in sorted(records, key=lambda r: r.path)]
    with open_atomic(out / CHECKSUMS_NAME) as fh:
        fh.writelines(heapq.merge(lines, extra, key=path_of))
    return out / CHECKSUMS_NAME


def read_checksums(out: Path) -> dict[str, str]:
    """``path -> sha256`` from the folder's checksum file."""
    path = out / CHECKSUMS_NAME
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StoreError(f"{path}: missing; the dataset folder's checksums were never "
                         "written (an unfinished build?)") from None
    out_map = {}
    for n, line in enumerate(text.splitlines(), 1):
        digest, sep, rel = line.partition("  ")
        if not sep or len(digest) != 64:
            raise StoreError(f"{path}:{n}: expected '<sha256>  <path>', got {line[:80]!r}")
        out_map[rel] = digest
    return out_map


@dataclass(frozen=True)
class FileProblem:
    path: str
    problem: str

    def format(self) -> str:
        return f"{self.path}: {self.problem}"


def verify_dataset(out: Path) -> tuple[int, list[FileProblem]]:
    """Check every file listed in ``checksums.sha256``; (files checked, problems).

    Files in the folder that the list does not name are reported too (left by hand, or by
    another tool): they are not part of what the build made.
    """
    try:
        listed = read_checksums(out)
    except StoreError as exc:
        return 0, [FileProblem(CHECKSUMS_NAME, str(exc).split(": ", 1)[-1])]
    problems = []
    for rel, digest in sorted(listed.items()):
        full = out / rel
        if not full.is_file():
            problems.append(FileProblem(rel, "missing"))
        elif file_sha256(full) != digest:
            problems.append(FileProblem(rel, "contents differ from the checksum recorded "
                                             "when it was written"))
    for rel in unlisted_files(out, listed):
        what = ("unfinished temporary file (a writer died); safe to delete"
                if ".tmp-" in rel.rsplit("/", 1)[-1] else "not written by the build")
        problems.append(FileProblem(rel, what))
    return len(listed), problems


def unlisted_files(out: Path, listed: dict[str, str]) -> list[str]:
    """Files under ``out`` that the checksum list does not name (nor the list, the marker and
    the report)."""
    known = set(listed) | {CHECKSUMS_NAME, DATASET_MARKER, REPORT_NAME}
    found = []
    for dirpath, dirs, files in os.walk(out):
        if Path(dirpath) == out and REPORT_FILES in dirs:
            dirs.remove(REPORT_FILES)  # the report's group pages: not part of the dataset
        dirs.sort()
        for name in sorted(files):
            rel = Path(dirpath, name).relative_to(out).as_posix()
            if rel not in known:
                found.append(rel)
    return found


class UnsafeOutputError(SpecError):
    """An output folder that a build must not write into (exit code 2, like a bad spec)."""


# --- markers ----------------------------------------------------------------------------------


def folder_kind(path: Path) -> str | None:
    """``"dataset"``, ``"store"`` or None: what a folder is, by its marker.

    Folders made before markers existed are recognised by their contents (a dataset by its
    ``dataset.json`` from sonicspec, a store by its ``plans`` and step folders).
    """
    if (path / DATASET_MARKER).is_file():
        return "dataset"
    if (path / STORE_MARKER).is_file():
        return "store"
    with contextlib.suppress(OSError, ValueError):  # no (readable) dataset.json: not one
        legacy = json.loads((path / "dataset.json").read_text())
        if isinstance(legacy, dict) and "sonicspec_version" in legacy:
            return "dataset"
    if (path / "plans").is_dir() and any((path / s).is_dir() for s in STORE_STEP_FOLDERS[1:]):
        return "store"
    return None


def claim_folder(path: Path, kind: str, where: str, info: dict[str, Any] | None = None, *,
                 write: bool = True) -> None:
    """Make ``path`` a ``kind`` folder, refusing a non-empty folder that is something else.

    ``where`` names the setting in messages (``outputs.dir``); ``write=False`` only checks.
    """
    marker = path / (DATASET_MARKER if kind == "dataset" else STORE_MARKER)
    if path.exists() and not path.is_dir():
        raise UnsafeOutputError(f"{where}: {path} is a file, not a folder")
    found = folder_kind(path) if path.is_dir() else None
    if found is None and path.is_dir() and any(path.iterdir()) and not (
            kind == "store" and _only_digest_cache(path)):
        raise UnsafeOutputError(
            f"{where}: {path} is not empty and is not a sonicspec {kind} (no {marker.name}); "
            "sonicspec writes only into empty folders or its own: choose another folder")
    if found is not None and found != kind:
        raise UnsafeOutputError(f"{where}: {path} is a sonicspec {found}, not a {kind}; "
                                "the dataset folder and the store must be different folders")
    if not write:
        return
    content = {"format": f"sonicspec-{kind}", "version": 1, **(info or {})}
    try:
        current = json.loads(marker.read_text())
    except (OSError, ValueError):
        current = None
    if current != content:
        write_json(marker, content)


def _only_digest_cache(path: Path) -> bool:
    """Whether a folder holds nothing but the file-digest cache that planning a spec writes
    (``cache/file-digests.json``, made before the build claims its store)."""
    entries = list(path.iterdir())
    cache = path / "cache"
    return (all(e == cache for e in entries) and cache.is_dir()
            and all(f.name == "file-digests.json" for f in cache.iterdir()))


def read_marker(path: Path) -> dict[str, Any]:
    """The dataset marker's content (empty for a folder made before markers)."""
    try:
        data = json.loads((path / DATASET_MARKER).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}
