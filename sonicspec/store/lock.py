"""One build at a time per store: a lock file made with ``O_CREAT | O_EXCL``.

Exclusive creation is atomic on local file systems and on NFS (v3 and later), which is where a
cluster's store lives; ``flock`` is not reliable there. The file names its holder (pid, host,
start time). A lock left by a build that died is taken over when its holder is provably gone:
same host and no such process. A holder on another host is never guessed dead; the error says
which file to delete if that build is known to be over.
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path
from types import TracebackType

from sonicspec.errors import StoreError

LOCK_NAME = "build.lock"


class StoreLockedError(StoreError):
    """Another build holds the store's lock."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, owned by someone else
    return True


class StoreLock:
    """Hold ``<store>/build.lock`` for the duration of a ``with`` block."""

    def __init__(self, store_dir: str | Path, purpose: str = "build") -> None:
        self.path = Path(store_dir) / LOCK_NAME
        self.purpose = purpose
        self._held = False

    def holder(self) -> dict | None:
        """Who holds the lock (pid, host, since, purpose), or None if nobody does."""
        try:
            return json.loads(self.path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return {}  # being written, or damaged: someone made it

    def acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        me = {"pid": os.getpid(), "host": socket.gethostname(),
              "since": time.strftime("%Y-%m-%d %H:%M:%S"), "purpose": self.purpose}
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self.holder()
                if holder is None:
                    continue  # released meanwhile: try again
                if (holder.get("host") == me["host"] and isinstance(holder.get("pid"), int)
                        and not _alive(holder["pid"])):
                    self.path.unlink(missing_ok=True)  # its build died without releasing it
                    continue
                raise StoreLockedError(self._busy_message(holder)) from None
            with os.fdopen(fd, "w") as fh:
                fh.write(json.dumps(me))
            self._held = True
            return
        raise StoreLockedError(self._busy_message(self.holder() or {}))

    def _busy_message(self, holder: dict) -> str:
        who = (f"pid {holder.get('pid', '?')}, host {holder.get('host', '?')}, "
               f"since {holder.get('since', '?')}")
        return (f"another build of this store is running ({who}); wait for it to finish. "
                f"If that build is known to be over (e.g. its cluster node died), delete "
                f"{self.path}")

    def release(self) -> None:
        if self._held:
            self._held = False
            self.path.unlink(missing_ok=True)

    def __enter__(self) -> StoreLock:
        self.acquire()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()
