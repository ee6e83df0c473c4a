"""Unit aliases, the speed of sound, and the seconds-to-samples conversions.

The aliases document intent in signatures; they are plain floats at run time. Time becomes a
number of samples through :func:`seconds_to_samples` (nearest), or through
:func:`seconds_to_samples_floor` (whole samples that fit) and :func:`seconds_to_samples_ceil`
(samples needed to hold it) where a length must not round the other way.
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


def _check_rate(sample_rate_hz: float) -> None:
    if not sample_rate_hz > 0:
        raise ValueError(f"sample_rate_hz: expected > 0, got {sample_rate_hz}")


def seconds_to_samples(seconds: Seconds, sample_rate_hz: float) -> int:
    """Samples in ``seconds`` at ``sample_rate_hz``, rounded to the nearest (a tie to the even
    one, as Python's ``round``).

    The one place time becomes an index, so every module rounds the same way.
    """
    _check_rate(sample_rate_hz)
    return round(seconds * sample_rate_hz)


def seconds_to_samples_floor(seconds: Seconds, sample_rate_hz: float) -> int:
    """Whole samples that fit in ``seconds`` (>= 0) at ``sample_rate_hz``: rounded down."""
    _check_rate(sample_rate_hz)
    return int(seconds * sample_rate_hz)


def seconds_to_samples_ceil(seconds: Seconds, sample_rate_hz: float) -> int:
    """Samples needed to hold ``seconds`` at ``sample_rate_hz``: rounded up."""
    _check_rate(sample_rate_hz)
    return math.ceil(seconds * sample_rate_hz)


def bands_below_nyquist(
    sample_rate_hz: float, bands_hz: tuple[float, ...] = OCTAVE_BANDS_HZ
) -> tuple[float, ...]:
    """Octave bands whose upper edge (centre * sqrt 2) lies below Nyquist.

    A band straddling Nyquist cannot be represented, so it is dropped (DESIGN.md §5).
    """
    nyquist = sample_rate_hz / 2.0
    return tuple(f for f in bands_hz if f * math.sqrt(2.0) <= nyquist)
