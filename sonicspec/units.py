"""Unit aliases and the single seconds-to-samples conversion.

The aliases document intent in signatures; they are plain floats at run time.
"""

from __future__ import annotations

import math
from typing import TypeAlias

Seconds: TypeAlias = float
Meters: TypeAlias = float
Decibels: TypeAlias = float
Lufs: TypeAlias = float
Hertz: TypeAlias = float

SPEED_OF_SOUND_M_S: float = 343.0
"""Speed of sound in air (about 20 °C), m/s: the spec's default and every library default."""

OCTAVE_BANDS_HZ: tuple[float, ...] = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0)
"""Octave-band centre frequencies used for every per-band quantity (DESIGN.md §5)."""


def seconds_to_samples(seconds: Seconds, sample_rate_hz: float) -> int:
    """Number of whole samples in ``seconds`` at ``sample_rate_hz`` (rounded to nearest).

    The one place time becomes an index, so every module rounds the same way.
    """
    if sample_rate_hz <= 0:
        raise ValueError(f"sample_rate_hz: expected > 0, got {sample_rate_hz}")
    return math.floor(seconds * sample_rate_hz + 0.5)


def bands_below_nyquist(
    sample_rate_hz: float, bands_hz: tuple[float, ...] = OCTAVE_BANDS_HZ
) -> tuple[float, ...]:
    """Octave bands whose upper edge (centre * sqrt 2) lies below Nyquist.

    A band straddling Nyquist cannot be represented, so it is dropped (DESIGN.md §5).
    """
    nyquist = sample_rate_hz / 2.0
    return tuple(f for f in bands_hz if f * math.sqrt(2.0) <= nyquist)
