"""Atmospheric absorption after ISO 9613-1 (pure-tone attenuation coefficient).

The standard's formulas: saturation vapour pressure from the triple-point temperature, molar
concentration of water vapour ``h``, the relaxation frequencies of oxygen and nitrogen, and the
classical + rotational + vibrational attenuation. ``air_energy_coefficient_per_m`` converts the
result in dB/m to the energy coefficient ``m`` (1/m) used by Eyring's formula and the tracer:
energy decays as ``exp(-m d)`` over a distance ``d``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sonicspec.errors import AcousticsError

REFERENCE_PRESSURE_KPA = 101.325
REFERENCE_TEMPERATURE_K = 293.15
TRIPLE_POINT_K = 273.16


def air_absorption_db_per_m(freqs_hz: Sequence[float] | np.ndarray, temperature_c: float = 20.0,
                            relative_humidity_pct: float = 50.0,
                            pressure_kpa: float = REFERENCE_PRESSURE_KPA) -> np.ndarray:
    """Pure-tone atmospheric attenuation coefficient α, dB/m (ISO 9613-1, eq. 3–5 and B.1)."""
    f = np.asarray(freqs_hz, dtype=np.float64)
    if np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise AcousticsError(f"freqs_hz: expected positive frequencies, got {f.tolist()}")
    if not -60 <= temperature_c <= 60:
        raise AcousticsError(f"temperature_c: expected -60..60 °C, got {temperature_c!r}")
    if not 0 <= relative_humidity_pct <= 100:
        raise AcousticsError(f"relative_humidity_pct: expected 0..100, got "
                             f"{relative_humidity_pct!r}")
    if not pressure_kpa > 0:
        raise AcousticsError(f"pressure_kpa: expected > 0, got {pressure_kpa!r}")
    t = temperature_c + 273.15
    pa = pressure_kpa / REFERENCE_PRESSURE_KPA
    c_sat = -6.8346 * (TRIPLE_POINT_K / t) ** 1.261 + 4.6151
    h = relative_humidity_pct * 10.0**c_sat / pa  # molar concentration of water vapour, %
    tr = t / REFERENCE_TEMPERATURE_K
    fr_o = pa * (24.0 + 4.04e4 * h * (0.02 + h) / (0.391 + h))
    fr_n = pa * tr**-0.5 * (9.0 + 280.0 * h * math.exp(-4.170 * (tr ** (-1.0 / 3.0) - 1.0)))
    return 8.686 * f**2 * (
        1.84e-11 / pa * tr**0.5
        + tr**-2.5 * (0.01275 * math.exp(-2239.1 / t) / (fr_o + f**2 / fr_o)
                      + 0.1068 * math.exp(-3352.0 / t) / (fr_n + f**2 / fr_n))
    )


def air_energy_coefficient_per_m(freqs_hz: Sequence[float] | np.ndarray,
                                 temperature_c: float = 20.0,
                                 relative_humidity_pct: float = 50.0,
                                 pressure_kpa: float = REFERENCE_PRESSURE_KPA) -> np.ndarray:
    """Energy attenuation coefficient ``m`` (1/m): α_dB / (10 log10 e)."""
    alpha = air_absorption_db_per_m(freqs_hz, temperature_c, relative_humidity_pct, pressure_kpa)
    return alpha / (10.0 * math.log10(math.e))
