"""One build at a time per store: a lock file made with ``O_CREAT | O_EXCL``.

Exclusive creation is atomic on local file systems and on NFS (v3 and later), which is where a
cluster's store lives; ``flock`` is not reliable there. The file names its holder: the head's
pid, host and start time, and once Snakemake runs, the process group (``pgid``) it was started
in: Snakemake and every job it starts live in that group, so the lock covers the whole build,
not one pid.

When a lock is stale: its holder is on this host, the head's process is gone and no process
of its group lives (zombies do not count). A head that died (``kill -9``) while its jobs still
run leaves a lock that is *not* stale: a second build would run beside those jobs on the same
store. A build that finds such a group, every process of which names this store on its
command line (Snakemake's ``--directory``, the jobs' plan path), stops it (SIGTERM, then
SIGKILL) and says so: what it was making is remade, with the same bytes. A group it cannot
recognise is left alone and the error names it and how to stop it. A holder on another host
is never guessed dead; the error says which file to delete if that build is known to be over.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import time
from pathlib import Path
from types import TracebackType

from sonicspec.atomic import os_error_cause, write_text
from sonicspec.errors import StoreError

LOCK_NAME = "build.lock"


class StoreLockedError(StoreError):
    """Another build holds the store's lock."""


def _proc_state(pid: int) -> tuple[str, int] | None:
    """(state letter, process group) of a process from ``/proc``, or None if it is gone
    (or there is no ``/proc``: see :func:`_alive`)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    except OSError:
        return ("?", -1)
    fields = text.rsplit(")", 1)[-1].split()  # after the command name, which may hold spaces
    return fields[0], int(fields[2])


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (a dead process not yet reaped)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # exists, owned by someone else
    if Path("/proc/self/stat").is_file():
        state = _proc_state(pid)
        return state is not None and state[0] != "Z"
    return True


def group_members(pgid: int) -> list[int]:
    """Live (non-zombie) processes of process group ``pgid``."""
    if Path("/proc/self/stat").is_file():
        out = []
        for entry in os.scandir("/proc"):
            if entry.name.isdigit():
                state = _proc_state(int(entry.name))
                if state is not None and state[1] == pgid and state[0] != "Z":
                    out.append(int(entry.name))
        return sorted(out)
    try:  # no /proc (macOS): a signal 0 to the group tells whether any member exists
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return []
    except PermissionError:
        pass  # the group exists, owned by someone else
    return [pgid]


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(
            errors="replace")
    except OSError:
        return ""


def stop_orphans(pgid: int, store_dir: Path, grace_s: float = 10.0) -> int:
    """Stop process group ``pgid`` if every live process of it names ``store_dir`` on its
    command line (a dead build's Snakemake and jobs); how many processes it had (0 if it is
    not recognised, or already gone)."""
    if not Path("/proc/self/stat").is_file():
        return 0
    names = {str(store_dir.absolute()), os.path.realpath(store_dir)}

    def names_store(pid: int) -> bool:
        line = _cmdline(pid)  # ends with a space: the folder, or a path inside it
        return any(f"{n} " in line or f"{n}/" in line for n in names)

    members = group_members(pgid)
    if not members or not all(names_store(p) for p in members):
        return 0
    for sig, wait_s in ((signal.SIGTERM, grace_s), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            break
        deadline = time.monotonic() + wait_s
        while group_members(pgid) and time.monotonic() < deadline:
            time.sleep(0.05)
        if not group_members(pgid):
            break
    return len(members)


class StoreLock:
    """Hold ``<store>/build.lock`` for the duration of a ``with`` block."""

    def __init__(self, store_dir: str | Path, purpose: str = "build") -> None:
        self.path = Path(store_dir) / LOCK_NAME
        self.purpose = purpose
        self._held = False
        self._me: dict = {}
        self.stopped = ""
        """What :meth:`acquire` stopped to take the lock (a dead build's jobs), or ""."""

    def holder(self) -> dict | None:
        """Who holds the lock (pid, host, since, purpose, pgid), or None if nobody does."""
        try:
            return json.loads(self.path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return {}  # being written, or damaged: someone made it

    def running(self) -> dict | None:
        """The holder if its build (head or jobs) is still running, else None."""
        holder = self.holder()
        if holder is None or self._stale(holder):
            return None
        return holder

    @staticmethod
    def _stale(holder: dict) -> bool:
        if holder.get("host") != socket.gethostname() or not isinstance(holder.get("pid"), int):
            return False
        if _alive(holder["pid"]):
            return False
        pgid = holder.get("pgid")
        return not (isinstance(pgid, int) and group_members(pgid))

    @staticmethod
    def _orphaned(holder: dict) -> bool:
        """A dead head on this host whose process group still lives."""
        return (holder.get("host") == socket.gethostname() and isinstance(holder.get("pid"), int)
                and isinstance(holder.get("pgid"), int) and not _alive(holder["pid"])
                and bool(group_members(holder["pgid"])))

    def acquire(self) -> None:
        me = {"pid": os.getpid(), "host": socket.gethostname(),
              "since": time.strftime("%Y-%m-%d %H:%M:%S"), "purpose": self.purpose}
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(self._io_message(exc)) from exc
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self.holder()
                if holder is None:
                    continue  # released meanwhile: try again
                if self.purpose == "build" and self._orphaned(holder):
                    pgid = holder["pgid"]
                    n = stop_orphans(pgid, self.path.parent)
                    if n and not group_members(pgid):
                        self.stopped = (
                            f"stopped {n} process(es) of a build of this store that died (pid "
                            f"{holder['pid']}, process group {pgid}): Snakemake and the jobs "
                            "it had running; what they were making is made again")
                if self._stale(holder):
                    try:
                        self.path.unlink(missing_ok=True)  # its build died without releasing it
                    except OSError as exc:
                        raise StoreError(self._io_message(exc)) from exc
                    continue
                raise StoreLockedError(self._busy_message(holder)) from None
            except OSError as exc:
                raise StoreError(self._io_message(exc)) from exc
            try:
                with os.fdopen(fd, "w") as fh:
                    fh.write(json.dumps(me))
            except OSError as exc:
                self.path.unlink(missing_ok=True)
                raise StoreError(self._io_message(exc)) from exc
            self._held, self._me = True, me
            return
        raise StoreLockedError(self._busy_message(self.holder() or {}))

    def set_group(self, pgid: int) -> None:
        """Record the process group the build's Snakemake and jobs run in (replacing the
        lock file in one rename: it exists throughout)."""
        if self._held:
            self._me = {**self._me, "pgid": pgid}
            write_text(self.path, json.dumps(self._me))

    def _io_message(self, exc: OSError) -> str:
        return (f"cannot take the store's lock {self.path}: {os_error_cause(exc, self.path.parent)}"
                f"; a {self.purpose} needs a store it can write")

    def _busy_message(self, holder: dict) -> str:
        purpose = holder.get("purpose", "build")
        what = "another build" if purpose == "build" else f"a {purpose}"
        who = (f"pid {holder.get('pid', '?')}, host {holder.get('host', '?')}, "
               f"since {holder.get('since', '?')}")
        pgid = holder.get("pgid")
        if (isinstance(pgid, int) and holder.get("host") == socket.gethostname()
                and isinstance(holder.get("pid"), int) and not _alive(holder["pid"])):
            members = group_members(pgid)
            return (f"a {purpose} of this store died ({who}) but {len(members)} process(es) of its "
                    f"Snakemake and jobs (process group {pgid}) are still running and writing "
                    f"the store; wait for them to end, or stop them: kill -- -{pgid}")
        return (f"{what} of this store is running ({who}); wait for it to finish. "
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
