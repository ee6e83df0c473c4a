"""Atomic file writes: the one helper every writer of a single file uses.

A file is written under a temporary name beside its final place (the same folder, so the same
file system and a rename that is atomic) and renamed over it, so a reader, a resumed build or a
crash sees the old file or the new one, never half a file. The temporary name
``.<name>.tmp-<pid>-<random><suffix>`` is a dot-file (corpus readers skip it), keeps the file's
ending (soundfile picks a format from it) and contains ``.tmp-`` (how ``verify`` recognises a
leftover in a dataset folder).

The store's artifacts are Zarr folders, not files: they have their own rename into place
(:meth:`sonicspec.store.ArtifactStore.write`), which also settles two writers racing on a key.
"""

from __future__ import annotations

import errno
import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from sonicspec.errors import StoreError


def temp_beside(path: Path) -> Path:
    """A fresh temporary name in ``path``'s folder (see the module docstring)."""
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}{path.suffix}")


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one rename.

    Missing parent folders are made. On any failure the temporary file is removed and ``path``
    keeps its old content; an ``OSError`` becomes a :class:`StoreError` naming the file (and a
    full disk as such).
    """
    path = Path(path)
    tmp = temp_beside(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        hint = "; the disk is full" if exc.errno == errno.ENOSPC else ""
        raise StoreError(f"cannot write {path}: {exc.strerror or exc}{hint}") from exc
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 text to ``path``, atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


@contextmanager
def open_atomic(path: str | Path, mode: str = "w") -> Iterator[IO[Any]]:
    """An open file for a writer that streams: written under a temporary name beside ``path``
    and renamed over it when the ``with`` block ends without an error (a kill or an error
    leaves the old file, or none, and no half file under the final name).

    ``mode`` is ``"w"`` (UTF-8 text, ``\\n`` line ends) or ``"wb"``.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"open_atomic: mode must be 'w' or 'wb', got {mode!r}")
    with atomic_path(path) as tmp:
        fh = (open(tmp, "w", encoding="utf-8", newline="\n") if mode == "w"
              else open(tmp, "wb"))
        with fh:
            yield fh
