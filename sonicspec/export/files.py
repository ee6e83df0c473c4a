"""Writing the dataset folder: audio and JSON files, each written atomically.

A file is written to a temporary name beside its final place and renamed
(:func:`sonicspec.atomic.atomic_path`), so a dataset folder never holds half a file, whatever
happens to the process writing it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.atomic import atomic_path, write_text
from sonicspec.errors import StoreError

SUBTYPES = {"PCM_16", "PCM_24", "FLOAT"}
FORMATS = {"flac": "FLAC", "wav": "WAV"}


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

