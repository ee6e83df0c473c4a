"""Closed forms of diffuse-field room acoustics, used as oracles and sanity checks.

* Sabine and Eyring reverberation time with air absorption:
  ``T = 24 ln(10) V / (c (A + 4 m V))`` with ``A = S ᾱ`` (Sabine) or ``A = −S ln(1 − ᾱ)``
  (Eyring), ``m`` the air's energy attenuation (1/m).
* Kuttruff's correction of Eyring for the spread of free path lengths:
  ``A = −S ln(1 − ᾱ) (1 + γ²/2 · ln(1 − ᾱ))``, ``γ²`` the relative variance of the path
  lengths between reflections (Kuttruff, *Room Acoustics*, §5.5); for a shoebox γ² is found
  here by sampling diffusely reflected paths between its walls (:func:`shoebox_free_paths`,
  no ray tracer involved).
* Mean free path ``4V/S``; critical distance ``√(A / 16π)`` (directivity 1).
* Barron & Lee (1988) revised theory: relative to the direct energy ``100/r²``, the reflected
  energy arriving after time ``t`` (after the direct sound at distance r) is
  ``(31200 T / V) e^{−0.04 r / T} e^{−13.82 t / T}``; the constants 0.04 = 13.82 / c and
  31200 = 1600 π c / (24 ln 10) follow from c, so they are computed from ``c`` here.
"""

from __future__ import annotations

import math

import numpy as np

from sonicspec.errors import AcousticsError

SIXTY_DB = 6 * math.log(10)  # 13.8155: ln(10⁶), the decay exponent for 60 dB


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise AcousticsError(f"{name}: expected > 0, got {value!r}")
    return float(value)


def sabine_t60(volume_m3: float, surface_m2: float, mean_absorption, air_m_per_m=0.0,
               speed_of_sound_m_s: float = 343.0) -> np.ndarray:
    """Sabine reverberation time, seconds (per band if arrays are given)."""
    v, s = _positive("volume_m3", volume_m3), _positive("surface_m2", surface_m2)
    a = np.asarray(mean_absorption, dtype=np.float64) * s
    m = np.asarray(air_m_per_m, dtype=np.float64)
    return 4 * SIXTY_DB * v / (speed_of_sound_m_s * (a + 4 * m * v))


def eyring_t60(volume_m3: float, surface_m2: float, mean_absorption, air_m_per_m=0.0,
               speed_of_sound_m_s: float = 343.0) -> np.ndarray:
    """Eyring reverberation time, seconds (per band if arrays are given)."""
    v, s = _positive("volume_m3", volume_m3), _positive("surface_m2", surface_m2)
    alpha = np.asarray(mean_absorption, dtype=np.float64)
    if np.any((alpha < 0) | (alpha >= 1)):
        raise AcousticsError(f"mean_absorption: expected values in [0, 1), got {alpha}")
    m = np.asarray(air_m_per_m, dtype=np.float64)
    return 4 * SIXTY_DB * v / (speed_of_sound_m_s * (-s * np.log1p(-alpha) + 4 * m * v))


def kuttruff_t60(volume_m3: float, surface_m2: float, mean_absorption, path_variance: float,
                 air_m_per_m=0.0, speed_of_sound_m_s: float = 343.0) -> np.ndarray:
    """Eyring's reverberation time corrected for the relative variance ``path_variance``
    (γ²) of the free path lengths, seconds (per band if arrays are given)."""
    v, s = _positive("volume_m3", volume_m3), _positive("surface_m2", surface_m2)
    alpha = np.asarray(mean_absorption, dtype=np.float64)
    if np.any((alpha < 0) | (alpha >= 1)):
        raise AcousticsError(f"mean_absorption: expected values in [0, 1), got {alpha}")
    if not (math.isfinite(path_variance) and path_variance >= 0):
        raise AcousticsError(f"path_variance: expected >= 0, got {path_variance!r}")
    log_r = np.log1p(-alpha)
    a = -s * log_r * (1.0 + 0.5 * path_variance * log_r)
    m = np.asarray(air_m_per_m, dtype=np.float64)
    return 4 * SIXTY_DB * v / (speed_of_sound_m_s * (a + 4 * m * v))


def shoebox_free_paths(size_m, n_paths: int = 1_000_000, seed: int = 0) -> np.ndarray:
    """Lengths of straight paths in a shoebox that leave a wall point (uniform over the
    surface) in a Lambert direction and end on the next wall, metres. Their mean is ``4V/S``
    and ``var / mean²`` is the γ² of :func:`kuttruff_t60`."""
    size = np.array([_positive(f"size_m[{i}]", x) for i, x in enumerate(size_m)])
    if size.shape != (3,):
        raise AcousticsError(f"size_m: expected 3 lengths, got {size.shape}")
    rng = np.random.default_rng(seed)
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    wall = rng.choice(6, n_paths, p=areas / areas.sum())
    axis, far_side = wall // 2, wall % 2
    rows = np.arange(n_paths)
    start = rng.random((n_paths, 3)) * size
    start[rows, axis] = far_side * size[axis]
    u1, u2 = rng.random(n_paths), rng.random(n_paths)
    direction = np.empty((n_paths, 3))
    direction[rows, (axis + 1) % 3] = np.sqrt(u1) * np.cos(2 * math.pi * u2)
    direction[rows, (axis + 2) % 3] = np.sqrt(u1) * np.sin(2 * math.pi * u2)
    direction[rows, axis] = np.sqrt(1.0 - u1) * np.where(far_side == 1, -1.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        to_wall = np.where(direction > 0, (size - start) / direction,
                           np.where(direction < 0, -start / direction, np.inf))
    to_wall[rows, axis] = np.where(direction[rows, axis] != 0, to_wall[rows, axis], np.inf)
    return to_wall.min(axis=1)


def mean_free_path_m(volume_m3: float, surface_m2: float) -> float:
    return 4 * _positive("volume_m3", volume_m3) / _positive("surface_m2", surface_m2)


def critical_distance_m(volume_m3: float, t60_s: float, speed_of_sound_m_s: float = 343.0
                        ) -> float:
    """Distance where direct and reverberant energy are equal: √(A/16π), A from Sabine."""
    v, t = _positive("volume_m3", volume_m3), _positive("t60_s", t60_s)
    area = 4 * SIXTY_DB * v / (speed_of_sound_m_s * t)
    return math.sqrt(area / (16 * math.pi))


def barron_reflected_energy(distance_m: float, volume_m3: float, t60_s: float, after_s: float,
                            speed_of_sound_m_s: float = 343.0) -> float:
    """Reflected energy arriving ``after_s`` after the direct sound, relative units (Barron)."""
    r, v, t = (_positive("distance_m", distance_m), _positive("volume_m3", volume_m3),
               _positive("t60_s", t60_s))
    # Diffuse energy relative to a direct 100/r²: 100 · 16π / A with the Sabine area
    # A = 24 ln(10) V / (c T); for c = 343 m/s this is Barron's 31200 T / V.
    total = 1600 * math.pi * speed_of_sound_m_s * t / (4 * SIXTY_DB * v)
    return total * math.exp(-SIXTY_DB * r / (speed_of_sound_m_s * t)) * math.exp(
        -SIXTY_DB * after_s / t)


def barron_clarity_db(distance_m: float, volume_m3: float, t60_s: float, split_s: float = 0.05,
                      speed_of_sound_m_s: float = 343.0) -> float:
    """C50 (``split_s`` = 0.05) or C80 (0.08) by Barron's revised theory, dB."""
    direct = 100.0 / _positive("distance_m", distance_m) ** 2
    all_reflected = barron_reflected_energy(distance_m, volume_m3, t60_s, 0.0,
                                            speed_of_sound_m_s)
    late = barron_reflected_energy(distance_m, volume_m3, t60_s, split_s, speed_of_sound_m_s)
    return 10 * math.log10((direct + all_reflected - late) / late)
