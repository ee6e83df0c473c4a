"""The content-hashed artifact store: one Zarr v3 group per job, written atomically.

Layout: ``<root>/<stage>/<key[:2]>/<key>.zarr``. An artifact is written into a temporary
folder beside its final place and renamed into place, so a reader (or a build resumed after a
crash) sees either the whole artifact or none. Its attributes hold provenance under
``"sonicspec"`` (stage, key, parameters, input keys, package version, the digest of its arrays
and the digest of its data) and the stage's own JSON-able result under ``"data"``, written as
compact JSON (zarr's default indents it: 4.5x the bytes). Because the key is the content hash
of what the job computes, two writers racing on one key write the same thing, and the loser
discards its copy.

Store format (``"format"`` in the provenance): 2 since the data digest (``data_digest``, the
SHA-256 of the data's canonical JSON) came in, so that ``verify`` finds an edit inside the
data as it finds one in an array. An artifact of format 1 (no data digest) is still read, but
``verify`` reports it as not checkable and a build makes it again.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import socket
import time
import uuid
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec import __version__
from sonicspec.atomic import os_error_cause
from sonicspec.errors import CompileError, StoreError
from sonicspec.hashing import KEY_LENGTH, array_digest, canonical_json, sha256_hex

TEMP_PREFIX = ".tmp-"
STORE_FORMAT = 2
"""The layout of an artifact's attributes (see the module docstring)."""
_ONE_CHUNK_BYTES = 64 * 2**20


@dataclass(frozen=True)
class Artifact:
    """A stored job result: its arrays, its stage data and its provenance."""

    stage: str
    key: str
    arrays: Mapping[str, np.ndarray]
    data: Any
    provenance: Mapping[str, Any]


@dataclass(frozen=True)
class VerifyProblem:
    stage: str
    key: str
    problem: str

    def format(self) -> str:
        return f"{self.stage} {self.key}: {self.problem}"


def _write_group(path: Path, arrays: Mapping[str, np.ndarray], attrs: dict[str, Any]) -> None:
    """A Zarr v3 group at ``path`` with ``arrays`` (zstd) and ``attrs``, written once each."""
    import zarr

    group = zarr.create_group(store=str(path), zarr_format=3, attributes=attrs, overwrite=True)
    for name in sorted(arrays):
        a = arrays[name]
        chunks = a.shape if a.nbytes <= _ONE_CHUNK_BYTES and a.size else "auto"
        if a.size == 0:
            chunks = tuple(max(1, s) for s in a.shape) or ()
        arr = group.create_array(
            name,
            shape=a.shape,
            dtype=a.dtype,
            chunks=chunks,
            compressors=zarr.codecs.ZstdCodec(level=3),
            fill_value=0,
        )
        if a.size:
            arr[...] = a


def _check_key(key: str) -> None:
    if len(key) != KEY_LENGTH or any(c not in "0123456789abcdef" for c in key):
        raise StoreError(f"artifact key: expected {KEY_LENGTH} lowercase hex digits, got {key!r}")


class ArtifactStore:
    """Content-addressed Zarr artifacts under ``root`` (see the module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def path(self, stage: str, key: str) -> Path:
        _check_key(key)
        return self.root / stage / key[:2] / f"{key}.zarr"

    def exists(self, stage: str, key: str) -> bool:
        return (self.path(stage, key) / "zarr.json").is_file()

    def fingerprint(self, stage: str, key: str) -> str:
        """Names, sizes and modification times of an artifact's files, hashed.

        It changes whenever a file of the artifact is written, truncated, added or removed,
        and costs one ``stat`` per file, so a build can re-verify (read and digest) only the
        artifacts whose fingerprint moved since they were last found sound.
        """
        root = self.path(stage, key)
        entries = []
        for dirpath, dirs, files in os.walk(root):
            dirs.sort()
            for name in sorted(files):
                full = os.path.join(dirpath, name)
                st = os.stat(full)
                entries.append(f"{os.path.relpath(full, root)}|{st.st_size}|{st.st_mtime_ns}")
        return sha256_hex("\n".join(entries))

    def remove(self, stage: str, key: str) -> None:
        """Delete an artifact (a damaged one, so that the build makes it again)."""
        path = self.path(stage, key)
        if path.exists():
            # Renamed aside first: readers never see a half-deleted group.
            doomed = path.parent / f"{TEMP_PREFIX}{key}-removed-{uuid.uuid4().hex[:8]}.zarr"
            os.rename(path, doomed)
            shutil.rmtree(doomed, ignore_errors=True)
    def present(self, stage: str, keys: Iterable[str]) -> set[str]:
        """Those of ``keys`` whose artifact exists (as :meth:`exists` says).

        Lists each prefix folder once instead of a ``stat`` per key: a plan of 10^6 groups
        has 1.5 million jobs, and most of them are usually not built.
        """
        wanted = set(keys)
        found: set[str] = set()
        folder = self.root / stage
        try:
            prefixes = os.listdir(folder)
        except (FileNotFoundError, NotADirectoryError):
            return found
        for prefix in prefixes:
            try:
                names = os.listdir(folder / prefix)
            except (FileNotFoundError, NotADirectoryError):
                continue
            for name in names:
                key = name[: -len(".zarr")]
                if name.endswith(".zarr") and key in wanted and self.exists(stage, key):
                    found.add(key)
        return found

    def write(
        self,
        stage: str,
        key: str,
        arrays: Mapping[str, np.ndarray],
        *,
        data: Any = None,
        params: Mapping[str, Any] | None = None,
        input_keys: tuple[str, ...] = (),
        stage_version: int = 1,
    ) -> Path:
        """Write an artifact atomically; a no-op if it already exists (same key, same bytes)."""
        import zarr

        final = self.path(stage, key)
        if self.exists(stage, key):
            return final
        arrays = {name: np.asarray(a) for name, a in arrays.items()}
        for name, a in arrays.items():
            if a.dtype == object or a.dtype.kind in "USV":
                raise StoreError(
                    f"{stage} {key[:12]}: array {name!r} has dtype {a.dtype}; "
                    "store text in data, numbers in arrays"
                )
        data_text = canonical_json(data)
        provenance = {
            "format": STORE_FORMAT,
            "stage": stage,
            "key": key,
            "stage_version": stage_version,
            "params": params or {},
            "input_keys": list(input_keys),
            "package_version": __version__,
            "digest": array_digest(arrays),
            "data_digest": sha256_hex(data_text),
            "arrays": {
                n: {"dtype": a.dtype.str, "shape": list(a.shape)} for n, a in sorted(arrays.items())
            },
        }
        attrs = {"sonicspec": json.loads(canonical_json(provenance)), "data": json.loads(data_text)}
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = final.parent / (
            f"{TEMP_PREFIX}{key}-{os.getpid()}-{uuid.uuid4().hex[:8]}@{socket.gethostname()}.zarr"
        )
        try:
            with zarr.config.set({"json_indent": None}):  # compact zarr.json: bytes are data
                _write_group(tmp, arrays, attrs)
            if final.exists() and not self.exists(stage, key):
                shutil.rmtree(final)  # a damaged leftover (e.g. its zarr.json was deleted)
            try:
                os.rename(tmp, final)
            except OSError as exc:
                if exc.errno in (errno.ENOTEMPTY, errno.EEXIST) and self.exists(stage, key):
                    shutil.rmtree(tmp, ignore_errors=True)  # another writer won the race
                else:
                    raise
        except OSError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            raise StoreError(f"{stage} {key[:12]}: cannot write {final}: "
                             f"{os_error_cause(exc, self.root)}") from exc
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return final

    def read(self, stage: str, key: str) -> Artifact:
        """Read a whole artifact; :class:`StoreError` if missing or unreadable."""
        import zarr

        path = self.path(stage, key)
        if not self.exists(stage, key):
            raise StoreError(f"{stage} {key[:12]}: no artifact at {path}")
        try:
            group = zarr.open_group(store=str(path), mode="r")
            attrs = dict(group.attrs)
            arrays = {name: np.asarray(group[name][...]) for name in sorted(group.array_keys())}
        except Exception as exc:  # zarr raises many kinds on damaged files
            raise StoreError(f"{stage} {key[:12]}: unreadable artifact at {path}: {exc}") from exc
        if "sonicspec" not in attrs:
            raise StoreError(f"{stage} {key[:12]}: {path} has no provenance attributes")
        return Artifact(stage, key, arrays, attrs.get("data"), attrs["sonicspec"])

    def read_array(self, stage: str, key: str, name: str, index: int) -> np.ndarray:
        """Row ``index`` of one array of an artifact, reading only the chunks it lies in
        (the report reads one RIR of a shard's stack this way)."""
        import zarr

        path = self.path(stage, key)
        if not self.exists(stage, key):
            raise StoreError(f"{stage} {key[:12]}: no artifact at {path}")
        try:
            return np.asarray(zarr.open_group(store=str(path), mode="r")[name][index])
        except Exception as exc:  # zarr raises many kinds on damaged files
            raise StoreError(f"{stage} {key[:12]}: cannot read array {name!r} row {index} "
                             f"at {path}: {exc}") from exc

    def read_data(self, stage: str, key: str) -> Any:
        """Only the stage's JSON data (cheap: no arrays are read)."""
        path = self.path(stage, key) / "zarr.json"
        try:
            return json.loads(path.read_text())["attributes"]["data"]
        except FileNotFoundError:
            raise StoreError(f"{stage} {key[:12]}: no artifact at {path.parent}") from None
        except (KeyError, ValueError) as exc:
            raise StoreError(f"{stage} {key[:12]}: unreadable metadata in {path}") from exc

    def artifacts(self) -> Iterator[tuple[str, str]]:
        """Every (stage, key) present, in a stable order."""
        if not self.root.is_dir():
            return
        for stage_dir in sorted(p for p in self.root.iterdir() if p.is_dir()):
            for prefix in sorted(p for p in stage_dir.iterdir() if p.is_dir()):
                for item in sorted(prefix.glob("*.zarr")):
                    if not item.name.startswith(TEMP_PREFIX):
                        yield stage_dir.name, item.name[: -len(".zarr")]

    def temp_folders(self) -> list[Path]:
        """Leftovers of writers that died before their rename."""
        if not self.root.is_dir():
            return []
        return sorted(self.root.glob(f"*/*/{TEMP_PREFIX}*"))

    def clean_stale_temp(self, max_age_s: float = 86400.0) -> int:
        """Delete temporary folders of writers that are gone; returns how many.

        A writer on this host is gone when its process no longer exists; one on another host
        (a cluster node) when its folder is older than ``max_age_s``.
        """
        removed = 0
        host = socket.gethostname()
        for tmp in self.temp_folders():
            name = tmp.name[len(TEMP_PREFIX) : -len(".zarr")]
            stem, _, owner = name.rpartition("@")
            try:
                pid = int(stem.split("-")[1])
            except (IndexError, ValueError):
                pid = -1
            if owner == host and pid > 0:
                if _writer_alive(pid, tmp):
                    continue  # still writing
            elif time.time() - tmp.stat().st_mtime < max_age_s:
                continue
            shutil.rmtree(tmp, ignore_errors=True)
            removed += 1
        return removed

    def verify_one(self, stage: str, key: str) -> VerifyProblem | None:
        """Re-read an artifact and recompute its digest."""
        try:
            art = self.read(stage, key)
        except StoreError as exc:
            return VerifyProblem(stage, key, str(exc).split(": ", 1)[-1])
        prov = art.provenance
        if prov.get("key") != key or prov.get("stage") != stage:
            return VerifyProblem(
                stage,
                key,
                "provenance names another artifact "
                f"({prov.get('stage')} {str(prov.get('key'))[:12]})",
            )
        expected = {n: (m["dtype"], tuple(m["shape"])) for n, m in prov.get("arrays", {}).items()}
        found = {n: (a.dtype.str, a.shape) for n, a in art.arrays.items()}
        if expected != found:
            return VerifyProblem(
                stage,
                key,
                f"arrays differ from provenance: expected "
                f"{sorted(expected)}, found {sorted(found)}",
            )
        if array_digest(art.arrays) != prov.get("digest"):
            return VerifyProblem(stage, key, "array contents do not match the recorded digest")
        if "data_digest" not in prov:
            return VerifyProblem(stage, key, f"written by an older sonicspec (store format "
                                 f"{prov.get('format', 1)}, before {STORE_FORMAT}): its data "
                                 "has no digest to check; `sonicspec build` makes it again")
        try:
            data_text = canonical_json(art.data)
        except CompileError:  # a non-finite number or a non-text key: edited by hand
            data_text = ""
        if sha256_hex(data_text) != prov["data_digest"]:
            return VerifyProblem(stage, key, "data (the JSON in zarr.json's attributes) does "
                                 "not match the recorded digest")
        return None

    def verify(self, expected: Mapping[str, str] | None = None) -> list[VerifyProblem]:
        """Check every artifact; with ``expected`` (key -> stage), also report missing ones."""
        problems = []
        present = set()
        for stage, key in self.artifacts():
            path = self.path(stage, key)
            if not self.exists(stage, key) and not any(path.iterdir()):
                continue  # made empty by Snakemake for a job that never wrote: no artifact
            present.add(key)
            problem = self.verify_one(stage, key)
            if problem is not None:
                problems.append(problem)
        for key, stage in sorted((expected or {}).items()):
            if key not in present:
                problems.append(VerifyProblem(stage, key, "missing"))
        for tmp in self.temp_folders():
            problems.append(
                VerifyProblem(
                    tmp.parent.parent.name,
                    tmp.name,
                    "unfinished temporary folder (a writer died); safe to delete",
                )
            )
        return problems


def _writer_alive(pid: int, folder: Path) -> bool:
    """Whether process ``pid`` on this host may still be writing ``folder``.

    A process killed while its parent died too stays a zombie until someone reaps it (in a
    container whose first process does not reap, for ever): ``os.kill(pid, 0)`` still succeeds,
    so on Linux its state is read from ``/proc``. A pid started after the folder was last
    changed is another process that reused the number.
    """
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        boot = next(float(line.split()[1]) for line in Path("/proc/stat").read_text().splitlines()
                    if line.startswith("btime "))
    except (OSError, StopIteration, ValueError, IndexError):
        return True  # no /proc: trust os.kill
    fields = stat.rpartition(")")[2].split()  # after "pid (comm)": state is first, starttime 20th
    if fields[0] in ("Z", "X"):
        return False
    try:
        started = boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")
        changed = folder.stat().st_mtime
    except (IndexError, ValueError, OSError):
        return True
    return started <= changed + 2.0
