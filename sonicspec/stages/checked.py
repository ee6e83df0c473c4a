"""What the last build found sound, so the next one re-reads only what changed since.

Verifying an artifact means reading and digesting all its arrays; checking a dataset file means
hashing it; knowing which dataset files an ``export`` or ``dataset`` artifact wrote means reading
its JSON (megabytes per group). All are worth doing once, not at every build: this cache keeps, per
artifact, the fingerprint (file names, sizes, modification times) it had when it was last verified;
per ``export``/``dataset`` artifact the list of files it records (path, bytes, SHA-256), valid
while the artifact keeps that fingerprint; and per dataset file its size, modification time and
checksum. A build stats everything (cheap) and reads only what moved. Damage that keeps a file's
size and time (a disk's bit rot) is for ``sonicspec verify``, which reads everything, and which
forgets here what it found damaged, so the next build re-checks exactly those and repairs them.

Only the process holding the store's lock (a build, or a verify) writes the cache (atomically).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path

from sonicspec.artifacts.records import CheckedContent, FileRecord
from sonicspec.atomic import write_text

CACHE_NAME = "checked.json"


class CheckCache:
    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            content = CheckedContent.model_validate_json(path.read_bytes())
        except (OSError, ValueError):  # missing, or not what this version writes: start over
            content = CheckedContent(artifacts={}, files={})
        self._artifacts = dict(content.artifacts)
        self._files = dict(content.files)
        self._written = content.written_records()
        self._dirty = False

    @classmethod
    def of_store(cls, store_dir: str | Path) -> CheckCache:
        return cls(Path(store_dir) / "cache" / CACHE_NAME)

    def artifact_ok(self, key: str, fingerprint: str) -> bool:
        return self._artifacts.get(key) == fingerprint

    def mark_artifact(self, key: str, fingerprint: str) -> None:
        if self._artifacts.get(key) != fingerprint:
            self._artifacts[key] = fingerprint
            self._dirty = True

    def written(self, key: str, fingerprint: str) -> list[FileRecord] | None:
        """The dataset files artifact ``key`` records (``path``, ``bytes``, ``sha256``), if
        they were read from it while it had ``fingerprint``; else None (read them again)."""
        entry = self._written.get(key)
        if entry is None or entry[0] != fingerprint:
            return None
        return list(entry[1])

    def mark_written(self, key: str, fingerprint: str,
                     records: Iterable[FileRecord]) -> list[FileRecord]:
        """Remember the files artifact ``key`` (with ``fingerprint``) records; returns those
        that carry a checksum (the others are not checked)."""
        kept = [FileRecord(path=r.path, bytes=r.bytes, sha256=r.sha256)
                for r in records if r.sha256 is not None]
        self._written[key] = (fingerprint, kept)
        self._dirty = True
        return kept

    @staticmethod
    def _file_token(st: os.stat_result, sha256: str) -> tuple[int, int, str]:
        return (st.st_size, st.st_mtime_ns, sha256)

    def file_ok(self, path: Path, st: os.stat_result, sha256: str) -> bool:
        return self._files.get(str(path)) == self._file_token(st, sha256)

    def mark_file(self, path: Path, st: os.stat_result, sha256: str) -> None:
        token = self._file_token(st, sha256)
        if self._files.get(str(path)) != token:
            self._files[str(path)] = token
            self._dirty = True

    def forget_file(self, path: Path) -> None:
        if self._files.pop(str(path), None) is not None:
            self._dirty = True

    def forget_artifact(self, key: str) -> None:
        if self._artifacts.pop(key, None) is not None:
            self._dirty = True

    def forget_files(self, paths: list[Path]) -> int:
        """Forget ``paths`` however they were named when recorded (through a symlink, a
        relative folder): entries are matched by real path. Returns how many were forgotten."""
        wanted = {os.path.realpath(p) for p in paths}
        real_dirs: dict[str, str] = {}
        gone = 0
        for name in list(self._files):
            folder, base = os.path.split(name)
            if folder not in real_dirs:
                real_dirs[folder] = os.path.realpath(folder)
            if os.path.join(real_dirs[folder], base) in wanted:
                del self._files[name]
                gone += 1
        self._dirty = self._dirty or gone > 0
        return gone

    def save(self) -> None:
        """Write the cache if anything changed since it was read (a no-op build writes
        nothing)."""
        if not self._dirty and self.path.is_file():
            return
        content = CheckedContent(
            artifacts=self._artifacts, files=self._files,
            written={k: (fp, [(r.path, r.bytes, r.sha256) for r in records])
                     for k, (fp, records) in self._written.items()})
        write_text(self.path, json.dumps(content.model_dump(mode="json"),
                                         sort_keys=True, separators=(",", ":")))
        self._dirty = False
