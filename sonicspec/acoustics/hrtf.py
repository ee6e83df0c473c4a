"""Binaural receivers: the analytic rigid-sphere head and measured HRIR sets (library level).

Directions of arrival are scene-frame unit vectors from the listener towards the apparent
source (z up); the head faces +x at yaw 0 and its left is +y, like a SOFA listener frame.

* **Sphere head** (:func:`synthesize_sphere_binaural_rir`): the Brown–Duda (1998) structural
  approximation of Rayleigh's rigid sphere, not the series solution. Each ear gets, per arrival,
  (1) the Woodworth ray-path delay ``−(a/c) cos θ`` for a lit ear (``θ < 90°``) and
  ``(a/c)(θ − π/2)`` for a shadowed one, ``θ`` the angle between the ear axis and the
  direction of arrival, so a lateral source gives ITD ``(a/c)(π/2 + 1)``; and (2) the one-pole,
  one-zero head-shadow filter ``H(s) = (1 + α(θ) s/(2ω₀)) / (1 + s/(2ω₀))``, ``ω₀ = c/a``, with
  ``α(θ) = 1 + α_min/2 + (1 − α_min/2) cos(180° θ/θ_min)``, ``α_min = 0.1``, ``θ_min = 150°``:
  unity at low frequency, +6 dB for the lit ear and −20 dB behind the head at high frequency.
  ``H`` is linear in α (a low-pass plus α times a high-pass), so the arrivals' taps are summed
  into two trains per ear (weights 1 and α) and each train is filtered once: exact and
  vectorised. The torso/shoulder echo of Brown–Duda is left out.
* **Measured HRIRs** (:class:`HrirSet`, e.g. from a SOFA SimpleFreeFieldHRIR file via
  :func:`hrir_set_from_sofa`): each arrival takes the HRIR pair of the nearest measured
  direction (no interpolation), placed at the arrival's fractional delay; the set is resampled
  to the RIR's rate if its own differs.
* **Late tail**: independent noise per ear with the mono tail's per-band energy (diffuse field,
  ears treated as incoherent and diffuse-field equalised; the low-frequency interaural
  coherence is neglected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from scipy import signal

from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.receivers import rotation
from sonicspec.acoustics.synthesis import (
    DEFAULT_TAPS,
    _filter_bands,
    _fractional_taps,
    rir_length_samples,
    synthesize_early,
    synthesize_late,
)
from sonicspec.errors import AcousticsError

ALPHA_MIN = 0.1
THETA_MIN_DEG = 150.0


@dataclass(frozen=True)
class SphereHead:
    """Settings of the rigid-sphere head: radius (m) and ear azimuth from the front (deg)."""

    head_radius_m: float = 0.0875
    ear_angle_deg: float = 100.0

    def __post_init__(self) -> None:
        if not 0.0 < self.head_radius_m <= 0.5:
            raise AcousticsError(f"head_radius_m: expected 0 < r <= 0.5, got "
                                 f"{self.head_radius_m!r}")
        if not 0.0 <= self.ear_angle_deg <= 180.0:
            raise AcousticsError(f"ear_angle_deg: expected 0..180, got {self.ear_angle_deg!r}")


@dataclass(frozen=True, eq=False)
class HrirSet:
    """Measured head-related impulse responses.

    Attributes
    ----------
    directions : (n, 3) float64
        Unit directions of the measured sources in the listener frame (+x front, +y left).
    hrirs : (n, 2, taps) float64
        Left and right impulse responses per direction.
    sample_rate_hz : float
        Their sample rate.
    """

    directions: np.ndarray
    hrirs: np.ndarray
    sample_rate_hz: float

    def __post_init__(self) -> None:
        d = np.asarray(self.directions, dtype=np.float64)
        h = np.asarray(self.hrirs, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != 3 or h.ndim != 3 or h.shape[:2] != (len(d), 2):
            raise AcousticsError(f"HRIR set: expected directions (n, 3) and hrirs (n, 2, taps), "
                                 f"got {d.shape} and {h.shape}")
        if len(d) == 0:
            raise AcousticsError("HRIR set: expected at least one direction, got 0")
        norms = np.linalg.norm(d, axis=1, keepdims=True)
        if np.any(norms == 0):
            raise AcousticsError("HRIR set: expected non-zero source positions, got a zero one")
        object.__setattr__(self, "directions", d / norms)
        object.__setattr__(self, "hrirs", h)

    def resampled(self, sample_rate_hz: float) -> HrirSet:
        """The same set at another sample rate (polyphase resampling)."""
        if math.isclose(self.sample_rate_hz, sample_rate_hz):
            return self
        ratio = Fraction(sample_rate_hz / self.sample_rate_hz).limit_denominator(1000)
        h = signal.resample_poly(self.hrirs, ratio.numerator, ratio.denominator, axis=-1)
        return HrirSet(self.directions, h, float(sample_rate_hz))


def hrir_set_from_sofa(sofa: Any) -> HrirSet:
    """An :class:`HrirSet` from a ``sofar.Sofa`` object of convention SimpleFreeFieldHRIR."""
    convention = getattr(sofa, "GLOBAL_SOFAConventions", None)
    if convention != "SimpleFreeFieldHRIR":
        raise AcousticsError(f"SOFA convention: expected SimpleFreeFieldHRIR, got {convention!r}")
    pos = np.atleast_2d(np.asarray(sofa.SourcePosition, dtype=np.float64))
    kind = str(getattr(sofa, "SourcePosition_Type", "spherical")).lower()
    if kind == "cartesian":
        dirs = pos[:, :3]
    else:
        az, el = np.radians(pos[:, 0]), np.radians(pos[:, 1])
        dirs = np.column_stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
    ir = np.asarray(sofa.Data_IR, dtype=np.float64)
    if ir.ndim != 3 or ir.shape[1] != 2:
        raise AcousticsError(f"SOFA Data_IR: expected (measurements, 2 ears, taps), got "
                             f"{ir.shape}")
    fs = float(np.asarray(sofa.Data_SamplingRate).ravel()[0])
    return HrirSet(dirs, ir, fs)


def woodworth_delays_s(cos_theta: np.ndarray, head_radius_m: float,
                       speed_of_sound_m_s: float = 343.0) -> np.ndarray:
    """Woodworth ray-path delay at an ear relative to the head centre, seconds.

    ``cos_theta`` is the cosine of the angle between the ear axis and the direction of arrival.
    """
    theta = np.arccos(np.clip(cos_theta, -1.0, 1.0))
    a_c = head_radius_m / speed_of_sound_m_s
    return np.where(theta < np.pi / 2, -a_c * np.cos(theta), a_c * (theta - np.pi / 2))


def shadow_alpha(cos_theta: np.ndarray) -> np.ndarray:
    """Brown–Duda high-frequency gain α(θ) of the head-shadow filter (1 at θ = 90°-ish)."""
    theta_deg = np.degrees(np.arccos(np.clip(cos_theta, -1.0, 1.0)))
    return (1 + ALPHA_MIN / 2) + (1 - ALPHA_MIN / 2) * np.cos(
        np.radians(theta_deg / THETA_MIN_DEG * 180.0))


def _ear_axes(head: SphereHead, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Left and right ear unit vectors in the scene frame, ``(2, 3)``."""
    e = math.radians(head.ear_angle_deg)
    local = np.array([[math.cos(e), math.sin(e), 0.0], [math.cos(e), -math.sin(e), 0.0]])
    return local @ rotation(yaw_deg, pitch_deg).T


def _with(arrivals: Arrivals, gains: np.ndarray, delays_s: np.ndarray) -> Arrivals:
    return Arrivals(arrivals.times_s + delays_s, arrivals.amplitudes * gains[:, None],
                    arrivals.directions, arrivals.order, arrivals.kind, arrivals.path_length_m)


def _check(sample_rate_hz: float) -> None:
    if not sample_rate_hz > 0:
        raise AcousticsError(f"sample_rate_hz: expected > 0, got {sample_rate_hz!r}")


def synthesize_sphere_binaural_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                                   head: SphereHead, sample_rate_hz: float,
                                   rng: np.random.Generator, *, yaw_deg: float = 0.0,
                                   pitch_deg: float = 0.0, speed_of_sound_m_s: float = 343.0,
                                   max_length_s: float = 2.0, bands_hz: tuple[float, ...] = (),
                                   taps: int = DEFAULT_TAPS) -> np.ndarray:
    """Binaural RIR through the Brown–Duda sphere head, ``(2, n_samples)`` (left, right).

    Parameters
    ----------
    arrivals, histogram
        One receiver's discrete arrivals and late energy histogram (or None).
    head
        Head radius and ear angle.
    sample_rate_hz
        Output rate, Hz.
    rng
        The only source of randomness (late tail noise).
    yaw_deg, pitch_deg
        Head orientation: yaw about z (0 faces +x), then pitch.

    Returns
    -------
    np.ndarray
        ``(2, n_samples)`` sound pressure at the ears per unit point source.
    """
    _check(sample_rate_hz)
    bank = OctaveFilterBank(sample_rate_hz, bands_hz)
    reach = 2 * head.head_radius_m / speed_of_sound_m_s
    n = rir_length_samples(arrivals, histogram, sample_rate_hz, max_length_s + reach, taps,
                           bank.padding() // 4)
    # Bilinear-transformed low- and high-pass halves of H(s): H = LP + α·HP.
    w0 = speed_of_sound_m_s / head.head_radius_m
    b_lp, a_lp = signal.bilinear([1.0], [1 / (2 * w0), 1.0], fs=sample_rate_hz)
    b_hp, a_hp = signal.bilinear([1 / (2 * w0), 0.0], [1 / (2 * w0), 1.0], fs=sample_rate_hz)
    out = np.zeros((2, n))
    for ear, axis in enumerate(_ear_axes(head, yaw_deg, pitch_deg)):
        if len(arrivals):
            cos_t = arrivals.directions @ axis
            delays = woodworth_delays_s(cos_t, head.head_radius_m, speed_of_sound_m_s)
            plain = synthesize_early(_with(arrivals, np.ones(len(arrivals)), delays), bank, n,
                                     taps)
            shaded = synthesize_early(_with(arrivals, shadow_alpha(cos_t), delays), bank, n,
                                      taps)
            out[ear] = signal.lfilter(b_lp, a_lp, plain) + signal.lfilter(b_hp, a_hp, shaded)
        if histogram is not None:
            out[ear] += synthesize_late(histogram, bank, n, rng)
    return out


def synthesize_hrir_binaural_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                                 hrirs: HrirSet, sample_rate_hz: float,
                                 rng: np.random.Generator, *, yaw_deg: float = 0.0,
                                 pitch_deg: float = 0.0, max_length_s: float = 2.0,
                                 bands_hz: tuple[float, ...] = (),
                                 taps: int = DEFAULT_TAPS) -> np.ndarray:
    """Binaural RIR through measured HRIRs (nearest direction), ``(2, n_samples)``.

    Parameters are those of :func:`synthesize_sphere_binaural_rir`, with ``hrirs`` (resampled
    to ``sample_rate_hz`` when their rate differs) in place of the sphere head.
    """
    _check(sample_rate_hz)
    hset = hrirs.resampled(sample_rate_hz)
    bank = OctaveFilterBank(sample_rate_hz, bands_hz)
    h_len = hset.hrirs.shape[-1]
    n = rir_length_samples(arrivals, histogram, sample_rate_hz, max_length_s, taps,
                           bank.padding() // 4 + h_len)
    out = np.zeros((2, n))
    if len(arrivals):
        if arrivals.n_bands != bank.n_bands:
            raise AcousticsError(f"arrivals: expected {bank.n_bands} bands like the filter "
                                 f"bank, got {arrivals.n_bands}")
        # Directions into the head frame, then the nearest measured direction (max cosine).
        local = arrivals.directions @ rotation(yaw_deg, pitch_deg)
        nearest = np.argmax(local @ hset.directions.T, axis=1)
        idx, w = _fractional_taps(arrivals.times_s, sample_rate_hz, taps)
        # Each arrival's kernel: its fractional-delay tap convolved with its HRIR pair (FFT,
        # all arrivals at once); kernels start at the tap's first sample.
        k_len = taps + h_len - 1
        n_fft = 1 << math.ceil(math.log2(k_len))
        kernels = np.fft.irfft(np.fft.rfft(w, n_fft)[:, None, :]
                               * np.fft.rfft(hset.hrirs[nearest], n_fft, axis=-1),
                               n_fft, axis=-1)[..., :k_len]
        pos = idx[:, :1] + np.arange(k_len)[None, :]
        keep = (pos >= 0) & (pos < n)
        for ear in range(2):
            trains = np.zeros((bank.n_bands, n))
            for b in range(bank.n_bands):
                np.add.at(trains[b], pos[keep],
                          (kernels[:, ear] * arrivals.amplitudes[:, b][:, None])[keep])
            out[ear] = _filter_bands(trains, bank)
    if histogram is not None:
        for ear in range(2):
            out[ear] += synthesize_late(histogram, bank, n, rng)
    return out
