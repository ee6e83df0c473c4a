"""Content keys, seeds and digests: the one place sonicspec hashes.

A ground-floor module: the plan (keys, seeds), the store (key length, canonical attributes,
array digests) and the export (file checksums) all hash through it, and it imports nothing of
sonicspec but the errors.

A job's key is the SHA-256 of the canonical JSON of ``{stage, stage_version, params,
input_keys}``: keys sorted, no whitespace, ASCII only, floats as their shortest round-trip
``repr``, tuples as lists. The same parameters always give the same key, on any machine.

Random draws come from :func:`rng_for`, a ``numpy.random.Generator`` on PCG64 seeded from the
spec seed and words of a key or name, never from global state (DESIGN.md §3).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.errors import CompileError

KEY_LENGTH = 64


def _canonical(value: Any, where: str = "params") -> Any:
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise CompileError(f"{where}: cannot hash a non-finite number ({value})")
        return value
    if isinstance(value, np.generic):
        return _canonical(value.item(), where)
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise CompileError(f"{where}: keys must be text to hash, got {k!r}")
            out[k] = _canonical(v, f"{where}.{k}")
        return out
    if isinstance(value, Sequence) and not isinstance(value, (bytes, bytearray)):
        return [_canonical(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise CompileError(f"{where}: cannot hash a value of type {type(value).__name__}")


def canonical_json(value: Any) -> str:
    """Stable JSON text of plain data (the input of every content key)."""
    return json.dumps(
        _canonical(value), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    )


# --- the fast path: the same text, without re-encoding what many jobs share -----------------
#
# A plan of 10^6 groups has 1.5 million jobs whose params repeat the same sub-dicts (acoustics,
# materials, microphone, ...). Encoding those once and splicing their text into every job's
# canonical JSON gives byte-identical text (hence identical keys) at a fraction of the cost.
# The text below is what ``json.dumps(sort_keys=True, separators=(",", ":"),
# ensure_ascii=True)`` writes: keys in sorted order, strings by the same C escaper, ints and
# floats by their ``repr``; anything else takes the reference path (:func:`canonical_json`).

_encode_str = json.encoder.encode_basestring_ascii  # type: ignore[attr-defined]


class _NotPlain(Exception):
    """A value the fast path does not handle; the caller falls back to :func:`canonical_json`."""


class SharedDict(dict):
    """A params sub-dict many jobs share, normalised once and holding its canonical JSON.

    Made by :func:`shared`; jobs keep the same object (no copy per job) and their keys splice
    its text. Treat it as read-only: its text is not recomputed.
    """

    __slots__ = ("canonical",)


class SharedList(list):
    """The list counterpart of :class:`SharedDict`."""

    __slots__ = ("canonical",)


def shared(value: Any) -> SharedDict | SharedList:
    """``value`` (a mapping or a sequence) as plain JSON data carrying its canonical text."""
    try:
        plain, text = _fast(value)
    except _NotPlain:
        text = canonical_json(value)
        plain = json.loads(text)
    out = SharedDict(plain) if isinstance(plain, dict) else SharedList(plain)
    out.canonical = text
    return out


def _fast(value: Any) -> tuple[Any, str]:
    """(plain copy, canonical JSON) of exact JSON types and shared values; else _NotPlain."""
    t = type(value)
    if t is str:
        return value, _encode_str(value)
    if t is SharedDict or t is SharedList:
        return value, value.canonical
    if t is dict:
        plain = {}
        parts = []
        for k in sorted(value):
            if type(k) is not str:
                raise _NotPlain
            v, text = _fast(value[k])
            plain[k] = v
            parts.append(f"{_encode_str(k)}:{text}")
        return plain, "{" + ",".join(parts) + "}"
    if t is list or t is tuple:
        items = [_fast(v) for v in value]
        return [v for v, _ in items], "[" + ",".join(text for _, text in items) + "]"
    if t is int:
        return value, int.__repr__(value)
    if t is float:
        if not math.isfinite(value):
            raise _NotPlain
        return value, float.__repr__(value)
    if value is None:
        return None, "null"
    if t is bool:
        return value, "true" if value else "false"
    raise _NotPlain


def normalised_params_and_key(
    stage: str, stage_version: int, params: Mapping[str, Any], input_keys: Sequence[str] = ()
) -> tuple[dict[str, Any], str]:
    """Params as plain JSON data (shared values kept) and the job's :func:`content_key`.

    The same key as ``content_key(stage, stage_version, params, input_keys)``, byte for byte
    (tested on whole plans), without re-encoding :func:`shared` sub-dicts for every job.
    """
    try:
        if type(params) is not dict or type(stage) is not str or type(stage_version) is not int:
            raise _NotPlain
        plain, text = _fast(params)
        _, inputs = _fast(list(input_keys))
    except _NotPlain:
        text = canonical_json(params)
        return json.loads(text), content_key(stage, stage_version, params, input_keys)
    # The envelope's keys in sorted order: input_keys, params, stage, stage_version.
    return plain, sha256_hex(
        f'{{"input_keys":{inputs},"params":{text},"stage":{_encode_str(stage)},'
        f'"stage_version":{stage_version}}}'
    )


def sha256_hex(text: str | bytes) -> str:
    """SHA-256 hex digest of ``text`` (UTF-8) or of bytes."""
    data = text.encode("utf-8") if isinstance(text, str) else text
    return hashlib.sha256(data).hexdigest()


def file_sha256(path: str | Path) -> str:
    """SHA-256 hex digest of a file's bytes, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def array_digest(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 over every array's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(a.dtype.str.encode())
        h.update(repr(tuple(a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def content_key(
    stage: str, stage_version: int, params: Mapping[str, Any], input_keys: Sequence[str] = ()
) -> str:
    """The content key of a job: what it computes (stage, version, params) and from what."""
    return sha256_hex(
        canonical_json(
            {
                "stage": stage,
                "stage_version": stage_version,
                "params": params,
                "input_keys": list(input_keys),
            }
        )
    )


def _words(text: str) -> list[int]:
    """32-bit words of the SHA-256 of ``text`` (keys are hashed again so any text works)."""
    digest = hashlib.sha256(text.encode("utf-8")).digest()
    return [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 32, 4)]


def rng_for(seed: int, *names: str) -> np.random.Generator:
    """A generator seeded from the spec seed and names (a job key, a group id, a purpose).

    Different names give independent streams; the same names always give the same stream,
    whatever the job order, worker or thread count.
    """
    entropy = [int(seed) & 0xFFFFFFFF, (int(seed) >> 32) & 0xFFFFFFFF]
    for name in names:
        entropy.extend(_words(name))
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(entropy)))
