"""Writing the dataset folder: audio and JSON files, each written atomically.

A file is written to a temporary name beside its final place and renamed, so a dataset folder
never holds half a file, whatever happens to the process writing it.
"""

from __future__ import annotations

import errno
import json
import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.errors import StoreError

SUBTYPES = {"PCM_16", "PCM_24", "FLOAT"}
FORMATS = {"flac": "FLAC", "wav": "WAV"}


def _temp_beside(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one rename.

    On any failure the temporary file is removed and ``path`` keeps its old content; an
    ``OSError`` becomes a :class:`StoreError` naming the file (and a full disk as such).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_beside(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        hint = "; the disk is full" if exc.errno == errno.ENOSPC else ""
        raise StoreError(f"cannot write {path}: {exc.strerror or exc}{hint}") from exc
    finally:
        if tmp.exists():
            tmp.unlink()


def write_audio(path: Path, audio: np.ndarray, sample_rate_hz: int, *, audio_format: str = "flac",
                subtype: str = "PCM_16") -> Path:
    """Write ``audio`` (channels, samples) or (samples,) as FLAC or WAV, atomically.

    Samples are floats in [-1, 1]; PCM subtypes are rounded by libsndfile. Values beyond full
    scale would clip, which the mixer prevents upstream, so here it is an error.
    """
    import soundfile as sf

    if audio_format not in FORMATS:
        raise StoreError(f"audio_format: expected one of {sorted(FORMATS)}, got {audio_format!r}")
    if subtype not in SUBTYPES or (audio_format == "flac" and subtype == "FLOAT"):
        raise StoreError(f"subtype: {subtype!r} cannot be written as {audio_format}")
    data = np.asarray(audio, dtype=np.float64)
    if data.ndim == 1:
        data = data[None, :]
    if data.ndim != 2:
        raise StoreError(f"{path.name}: expected (channels, samples) audio, got {data.shape}")
    if not np.all(np.isfinite(data)):
        raise StoreError(f"{path.name}: audio has NaN or infinite samples")
    peak = float(np.max(np.abs(data))) if data.size else 0.0
    if subtype != "FLOAT" and peak > 1.0:
        raise StoreError(f"{path.name}: peak {peak:.3f} exceeds full scale and would clip")
    with atomic_path(path) as tmp:
        if subtype == "FLOAT":
            # libsndfile stamps float WAVs with the time of writing (PEAK chunk); scipy writes
            # the plain RIFF/fmt/data layout, so the same samples give the same bytes.
            from scipy.io import wavfile

            with open(tmp, "wb") as fh:
                wavfile.write(fh, int(sample_rate_hz), data.T.astype(np.float32))
        else:
            sf.write(str(tmp), data.T, int(sample_rate_hz), subtype=subtype,
                     format=FORMATS[audio_format])
    return path


def write_json(path: Path, data: Any) -> Path:
    """Write JSON (sorted keys, indented, final newline), atomically."""
    text = json.dumps(data, indent=2, sort_keys=True, ensure_ascii=False) + "\n"
    return write_text(path, text)


def write_text(path: Path, text: str) -> Path:
    """Write UTF-8 text, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path
