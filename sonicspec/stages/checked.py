"""What the last build found sound, so the next one re-reads only what changed since.

Verifying an artifact means reading and digesting all its arrays; checking a dataset file means
hashing it. Both are worth doing once, not at every build: this cache keeps, per artifact, the
fingerprint (file names, sizes, modification times) it had when it was last verified, and per
dataset file its size, modification time and checksum. A build stats everything (cheap) and
re-verifies only what moved. Damage that keeps a file's size and time (a disk's bit rot) is for
``sonicspec verify``, which reads everything, and which forgets here what it found damaged, so
the next build re-checks exactly those and repairs them.

Only the process holding the store's lock (a build, or a verify) writes the cache (atomically).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from sonicspec.atomic import write_text

CACHE_NAME = "checked.json"


class CheckCache:
    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            data = json.loads(path.read_text())
            self._artifacts: dict[str, str] = dict(data["artifacts"])
            self._files: dict[str, list] = dict(data["files"])
        except (OSError, ValueError, KeyError, TypeError):
            self._artifacts, self._files = {}, {}

    @classmethod
    def of_store(cls, store_dir: str | Path) -> CheckCache:
        return cls(Path(store_dir) / "cache" / CACHE_NAME)

    def artifact_ok(self, key: str, fingerprint: str) -> bool:
        return self._artifacts.get(key) == fingerprint

    def mark_artifact(self, key: str, fingerprint: str) -> None:
        self._artifacts[key] = fingerprint

    @staticmethod
    def _file_token(st: os.stat_result, sha256: str) -> list:
        return [st.st_size, st.st_mtime_ns, sha256]

    def file_ok(self, path: Path, st: os.stat_result, sha256: str) -> bool:
        return self._files.get(str(path)) == self._file_token(st, sha256)

    def mark_file(self, path: Path, st: os.stat_result, sha256: str) -> None:
        self._files[str(path)] = self._file_token(st, sha256)

    def forget_file(self, path: Path) -> None:
        self._files.pop(str(path), None)

    def forget_artifact(self, key: str) -> None:
        self._artifacts.pop(key, None)

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
        return gone

    def save(self) -> None:
        write_text(self.path, json.dumps({"artifacts": self._artifacts, "files": self._files},
                                         sort_keys=True, separators=(",", ":")))
