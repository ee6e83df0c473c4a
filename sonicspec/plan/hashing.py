"""Content keys and seeds: the one place sonicspec hashes.

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


def sha256_hex(text: str | bytes) -> str:
    data = text.encode("utf-8") if isinstance(text, str) else text
    return hashlib.sha256(data).hexdigest()


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
