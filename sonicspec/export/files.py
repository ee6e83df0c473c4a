"""Writing the dataset folder: audio and JSON files, each written atomically.

A file is written to a temporary name beside its final place and renamed
(:func:`sonicspec.atomic.atomic_path`), so a dataset folder never holds half a file, whatever
happens to the process writing it.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.atomic import atomic_path, write_text
from sonicspec.errors import StoreError

SUBTYPES = {"PCM_16", "PCM_24", "FLOAT"}
FORMATS = {"flac": "FLAC", "wav": "WAV"}
PCM_BITS = {"PCM_16": 16, "PCM_24": 24}

SCALE_TAG = "sonicspec_scale"
"""A scaled file's comment tag reads ``sonicspec_scale=<scale>``: the decoded samples (full
scale ±1, as soundfile, sox or ffmpeg decode them) times ``<scale>`` are the signal."""
_SCALE_RE = re.compile(rf"(?:^|\s){SCALE_TAG}=(\S*)")


def peak_scale(audio: np.ndarray, subtype: str, bits: int | None = None) -> float:
    """The per-file scale of ``audio`` written as ``subtype``: what a decoded full-scale sample
    stands for, chosen so that the file's peak lands on the top step of the ``bits``-bit grid
    (``2**(bits-1) - 1``), just under full scale. ``bits`` defaults to the subtype's own;
    fewer bits (the low ones zero) cost FLAC nothing: it drops bits that are zero in a whole
    block. 1.0 for silence. The file's samples are then ``audio / scale``, each within half a
    step, ``scale / 2**bits``, so the error relative to the peak is at most ``2**-bits``
    (1.0000001 times that)."""
    if subtype not in PCM_BITS:
        raise StoreError(f"subtype: a scale applies to {sorted(PCM_BITS)}, got {subtype!r}")
    bits = _precision(subtype, bits)
    data = np.asarray(audio, dtype=np.float64)
    peak = float(np.max(np.abs(data))) if data.size else 0.0
    if not math.isfinite(peak):
        raise StoreError("audio has NaN or infinite samples")
    if peak == 0.0:
        return 1.0
    top = 2 ** (bits - 1)
    return peak * top / (top - 1)


def _precision(subtype: str, bits: int | None) -> int:
    full = PCM_BITS[subtype]
    if bits is None:
        return full
    if not 8 <= int(bits) <= full:
        raise StoreError(f"bits: expected 8..{full} for {subtype}, got {bits!r}")
    return int(bits)


def check_scale(scale: Any, where: str) -> float:
    """``scale`` as a float if it is a finite number > 0; a :class:`StoreError` naming
    ``where`` and the value otherwise."""
    ok = isinstance(scale, (int, float)) and not isinstance(scale, bool)
    if not ok or not math.isfinite(float(scale)) or float(scale) <= 0.0:
        raise StoreError(f"{where}: expected a finite scale > 0, got {scale!r}")
    return float(scale)


def write_audio(path: Path, audio: np.ndarray, sample_rate_hz: int, *, audio_format: str = "flac",
                subtype: str = "PCM_16", scale: float | None = None, bits: int | None = None,
                compression_level: float | None = None) -> Path:
    """Write ``audio`` (channels, samples) or (samples,) as FLAC or WAV, atomically.

    Without ``scale``, samples are floats in [-1, 1]: PCM subtypes are rounded by libsndfile
    and values beyond full scale, which would clip, are an error. With ``scale`` (PCM only; see
    :func:`peak_scale`) the file holds ``audio / scale`` rounded to the ``bits``-bit grid
    (default: the subtype's bits) and its comment tag ``sonicspec_scale=<scale>``, so levels
    above 0 dBFS are kept; a sample that would still pass full scale is an error.
    ``compression_level`` (0…1, FLAC) is libsndfile's; None keeps its default (level 5).
    """
    import soundfile as sf

    if audio_format not in FORMATS:
        raise StoreError(f"audio_format: expected one of {sorted(FORMATS)}, got {audio_format!r}")
    if subtype not in SUBTYPES or (audio_format == "flac" and subtype == "FLOAT"):
        raise StoreError(f"subtype: {subtype!r} cannot be written as {audio_format}")
    if scale is not None and subtype == "FLOAT":
        raise StoreError(f"{path.name}: a scale applies to PCM subtypes; FLOAT keeps any level")
    if bits is not None and scale is None:
        raise StoreError(f"{path.name}: bits ({bits}) apply with a scale (see peak_scale)")
    data = np.asarray(audio, dtype=np.float64)
    if data.ndim == 1:
        data = data[None, :]
    if data.ndim != 2:
        raise StoreError(f"{path.name}: expected (channels, samples) audio, got {data.shape}")
    if not np.all(np.isfinite(data)):
        raise StoreError(f"{path.name}: audio has NaN or infinite samples")
    peak = float(np.max(np.abs(data))) if data.size else 0.0
    if scale is None and subtype != "FLOAT" and peak > 1.0:
        raise StoreError(f"{path.name}: peak {peak:.3f} exceeds full scale and would clip")
    samples: np.ndarray = data.T
    if scale is not None:
        scale = check_scale(scale, f"{path.name}: scale")
        samples = _quantise(data, scale, subtype, _precision(subtype, bits), path).T
    with atomic_path(path) as tmp:
        if subtype == "FLOAT":
            # libsndfile stamps float WAVs with the time of writing (PEAK chunk); scipy writes
            # the plain RIFF/fmt/data layout, so the same samples give the same bytes.
            from scipy.io import wavfile

            with open(tmp, "wb") as fh:
                wavfile.write(fh, int(sample_rate_hz), samples.astype(np.float32))
        else:
            with sf.SoundFile(str(tmp), "w", int(sample_rate_hz), samples.shape[1], subtype,
                              format=FORMATS[audio_format],
                              compression_level=compression_level) as fh:
                if scale is not None:
                    fh.comment = f"{SCALE_TAG}={scale!r}"
                fh.write(np.ascontiguousarray(samples))
    return path


def _quantise(data: np.ndarray, scale: float, subtype: str, bits: int, path: Path) -> np.ndarray:
    """``data / scale`` as the integers libsndfile stores unchanged: int16 for PCM_16; for
    PCM_24 int32 whose top 24 bits are the sample (the ``bits``-bit value shifted up)."""
    top = 2 ** (bits - 1)
    q = np.rint(data * (top / scale))
    worst = float(np.max(np.abs(q))) if q.size else 0.0
    if worst > top - 1:
        raise StoreError(f"{path.name}: peak {worst / top * scale:.6g} exceeds the scale "
                         f"{scale!r} and would clip; use peak_scale()")
    shift = (16 if subtype == "PCM_16" else 32) - bits
    return (q.astype(np.int32) << shift).astype(np.int16 if subtype == "PCM_16" else np.int32)


def read_scale_tag(path: Path) -> float | None:
    """The scale a file's own comment tag records (``sonicspec_scale=``); None when it has
    none; a :class:`StoreError` naming the file when the tag is there but not a finite scale
    > 0."""
    import soundfile as sf

    with sf.SoundFile(str(path)) as fh:
        return scale_from_comment(fh.comment, path)


def scale_from_comment(comment: str | None, path: Path | str) -> float | None:
    found = _SCALE_RE.search(comment or "")
    if found is None:
        return None
    try:
        value = float(found.group(1))
    except ValueError:
        value = found.group(1)
    return check_scale(value, f"{path}: comment tag {SCALE_TAG}")


def write_json(path: Path, data: Any) -> Path:
    """Write JSON (sorted keys, indented, final newline), atomically."""
    text = json.dumps(data, indent=2, sort_keys=True, ensure_ascii=False) + "\n"
    return write_text(path, text)

