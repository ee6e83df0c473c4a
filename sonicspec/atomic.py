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

_CAUSES = {
    errno.ENOSPC: "no space left: the disk is full",
    errno.EDQUOT: "no space left: the disk quota is exceeded",
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
}


_NEARLY_FULL_BYTES = 1 << 20
"""Free space below which a write that failed without saying why is put down to a full disk."""


def folder_problem(folder: str | Path) -> str | None:
    """Why nothing can be written in ``folder`` (read-only file system, no permission, no
    space), or None if it looks writable. For failures that do not say why (libsndfile's
    "System error")."""
    folder = Path(folder)
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent  # a folder about to be made: ask where it would be made
    try:
        st = os.statvfs(folder)
    except OSError as exc:
        return os_error_cause(exc, folder)
    if st.f_flag & os.ST_RDONLY:
        return f"the file system is read-only ({folder})"
    if not os.access(folder, os.W_OK):
        return f"permission denied: this user may not write in {folder}"
    # Blocks this user may still use (root may use the reserved ones too); checked right after
    # a failed write, while its temporary file still holds what it managed to write.
    blocks = st.f_bfree if hasattr(os, "geteuid") and os.geteuid() == 0 else st.f_bavail
    if blocks * st.f_frsize < _NEARLY_FULL_BYTES or (st.f_favail == 0 and st.f_files > 0):
        return f"no space left: the disk is full ({folder})"
    return None


def os_error_cause(exc: OSError, folder: str | Path | None = None) -> str:
    """The cause of an I/O error in words a user acts on: read-only, no space, permission
    (with the folder when given), else the system's own message."""
    cause = _CAUSES.get(exc.errno or 0)
    if cause is None:
        return exc.strerror or str(exc)
    if exc.errno in (errno.EACCES, errno.EPERM) and folder is not None:
        found = folder_problem(folder)
        if found is not None and not found.startswith("permission"):
            return found  # root gets EACCES-like errors from read-only mounts too
        return f"permission denied: this user may not write in {folder}"
    return cause if folder is None else f"{cause} ({folder})"


def temp_beside(path: Path) -> Path:
    """A fresh temporary name in ``path``'s folder (see the module docstring)."""
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}{path.suffix}")


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one rename.

    Missing parent folders are made. On any failure the temporary file is removed and ``path``
    keeps its old content; an ``OSError``, or any failure while the folder is read-only, full or
    not writable, becomes a :class:`StoreError` naming the file and the cause.
    """
    path = Path(path)
    tmp = temp_beside(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        raise StoreError(f"cannot write {path}: {os_error_cause(exc, path.parent)}") from exc
    except Exception as exc:
        # A writer that hides the cause (libsndfile says "System error"): ask the folder.
        cause = folder_problem(path.parent)
        if cause is None:
            raise
        raise StoreError(f"cannot write {path}: {cause}") from exc
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
