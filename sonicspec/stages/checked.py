"""What the last build found sound, so the next one re-reads only what changed since.

Verifying an artifact means reading and digesting all its arrays; checking a dataset file means
hashing it. Both are worth doing once, not at every build: this cache keeps, per artifact, the
fingerprint (file names, sizes, modification times) it had when it was last verified, and per
dataset file its size, modification time and checksum. A build stats everything (cheap) and
re-verifies only what moved. Damage that keeps a file's size and time (a disk's bit rot) is for
``sonicspec verify``, which reads everything.

Only the process holding the store's build lock writes the cache (atomically).
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

    def save(self) -> None:
        write_text(self.path, json.dumps({"artifacts": self._artifacts, "files": self._files},
                                         sort_keys=True, separators=(",", ":")))
