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
* **Late tail**: a diffuse field at the ears. Two independent noises with the mono tail's
  per-band energy are mixed per frequency (:func:`diffuse_binaural_tails`) so that the ears
  get the head's diffuse-field interaural coherence ``Γ(f)``, the real part of the normalised
  interaural cross-spectrum averaged over directions uniform on the sphere
  (:func:`binaural_diffuse_coherence`): for the sphere head from its own per-direction ear
  filters (Woodworth delay and head shadow) over 2048 Fibonacci directions; for an HRIR set
  from its measured pairs, each weighted by the area of its nearest-direction (spherical
  Voronoi) cell. ``Γ`` is ~1 below ~100 Hz, first crosses zero near 650 Hz for the default
  head (real heads: ~500 Hz, Lindevald & Benade 1986) and stays within ±0.1 above 2 kHz.
  Modelled: the coherence and each ear's energy. Not modelled: the ears' diffuse-field
  *spectra* (the tail stays diffuse-field equalised, the same spectrum at both ears as the mono
  tail), any interaural phase or level difference of the tail (``Γ``'s imaginary part, zero
  for a symmetric head, is dropped; the mixing filters are zero-phase), and a tail that is not
  isotropic (the histogram carries no directions).
"""

from __future__ import annotations

import contextlib
import functools
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from scipy import signal
from scipy.spatial import QhullError, SphericalVoronoi, cKDTree

from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.directions import fibonacci_sphere
from sonicspec.acoustics.receivers.arrays import mix_by_roots, mix_per_frequency, rotation
from sonicspec.acoustics.receivers.capsules import (
    Capsules,
    diffuse_cross_spectra_numeric,
    hermitian_root,
)
from sonicspec.acoustics.receivers.synthesis import (
    DEFAULT_TAPS,
    _fractional_taps,
    _place_kernels,
    rir_length_samples,
    synthesize_early,
    synthesize_late,
)
from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S, seconds_to_samples_ceil

ALPHA_MIN = 0.1
THETA_MIN_DEG = 150.0
DIFFUSE_DIRECTIONS = 2048  # uniform directions of the sphere head's diffuse-field average
_GRID_FFT = 2048  # Γ(f) is computed fs/2048 apart (23 Hz at 48 kHz), then interpolated


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
                       speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
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


def ear_axes(head: SphereHead, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Left and right ear unit vectors in the scene frame, ``(2, 3)``."""
    e = math.radians(head.ear_angle_deg)
    local = np.array([[math.cos(e), math.sin(e), 0.0], [math.cos(e), -math.sin(e), 0.0]])
    return local @ rotation(yaw_deg, pitch_deg).T


def shadow_filters(head: SphereHead, sample_rate_hz: float, speed_of_sound_m_s: float
                    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Bilinear-transformed low- and high-pass halves ``(b, a)`` of H(s): ``H = LP + α·HP``."""
    w0 = speed_of_sound_m_s / head.head_radius_m
    lp = signal.bilinear([1.0], [1 / (2 * w0), 1.0], fs=sample_rate_hz)
    hp = signal.bilinear([1 / (2 * w0), 0.0], [1 / (2 * w0), 1.0], fs=sample_rate_hz)
    return lp, hp


def _with(arrivals: Arrivals, gains: np.ndarray, delays_s: np.ndarray) -> Arrivals:
    return Arrivals(arrivals.times_s + delays_s, arrivals.amplitudes * gains[:, None],
                    arrivals.directions, arrivals.order, arrivals.kind, arrivals.path_length_m,
                    arrivals.isometry, arrivals.path_id)


def _check(sample_rate_hz: float) -> None:
    if not sample_rate_hz > 0:
        raise AcousticsError(f"sample_rate_hz: expected > 0, got {sample_rate_hz!r}")


def sphere_binaural_early(arrivals: Arrivals, head: SphereHead, bank: OctaveFilterBank,
                          n_samples: int, *, yaw_deg: float = 0.0, pitch_deg: float = 0.0,
                          speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                          taps: int = DEFAULT_TAPS) -> np.ndarray:
    """The early part of a sphere-head binaural RIR, ``(2, n_samples)``: each arrival at each
    ear delayed by Woodworth's path round the head, through the Brown–Duda shadow filter
    ``H = LP + α(θ)·HP`` (:func:`shadow_filters`)."""
    return sphere_capsules_early(arrivals, head, ear_axes(head, yaw_deg, pitch_deg), bank,
                                 n_samples, speed_of_sound_m_s=speed_of_sound_m_s, taps=taps)


def sphere_capsules_early(arrivals: Arrivals, head: SphereHead, axes: np.ndarray,
                          bank: OctaveFilterBank, n_samples: int, *,
                          speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                          taps: int = DEFAULT_TAPS) -> np.ndarray:
    """The early part at capsules flush on a rigid sphere (``head``'s radius), one per unit
    vector of ``axes`` ``(M, 3)`` (scene frame), ``(M, n_samples)``: the ears of
    :func:`sphere_binaural_early`, as many as asked (a spherical array such as the em32)."""
    (b_lp, a_lp), (b_hp, a_hp) = shadow_filters(head, bank.sample_rate_hz, speed_of_sound_m_s)
    out = np.zeros((len(axes), n_samples))
    for ear, axis in enumerate(axes):
        if len(arrivals):
            cos_t = arrivals.directions @ axis
            delays = woodworth_delays_s(cos_t, head.head_radius_m, speed_of_sound_m_s)
            plain = synthesize_early(_with(arrivals, np.ones(len(arrivals)), delays), bank,
                                     n_samples, taps)
            shaded = synthesize_early(_with(arrivals, shadow_alpha(cos_t), delays), bank,
                                      n_samples, taps)
            out[ear] = signal.lfilter(b_lp, a_lp, plain) + signal.lfilter(b_hp, a_hp, shaded)
    return out


def synthesize_sphere_binaural_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                                   head: SphereHead, sample_rate_hz: float,
                                   rng: np.random.Generator, *, yaw_deg: float = 0.0,
                                   pitch_deg: float = 0.0,
                                   speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
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
        The only source of randomness (late tail noise: the left ear's draws, then the right's,
        before they are mixed to the head's diffuse-field coherence).
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
    out = sphere_binaural_early(arrivals, head, bank, n, yaw_deg=yaw_deg, pitch_deg=pitch_deg,
                                speed_of_sound_m_s=speed_of_sound_m_s, taps=taps)
    if histogram is not None:
        tails = np.stack([synthesize_late(histogram, bank, n, rng) for _ in range(2)])
        out += diffuse_binaural_tails(tails, head, sample_rate_hz,
                                      speed_of_sound_m_s=speed_of_sound_m_s)
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
    out = hrir_binaural_early(arrivals, hset, bank, n, yaw_deg=yaw_deg, pitch_deg=pitch_deg,
                              taps=taps)
    if histogram is not None:
        tails = np.stack([synthesize_late(histogram, bank, n, rng) for _ in range(2)])
        # The set as given (not ``hset``, a new object per call when resampled) keys the cache.
        out += diffuse_binaural_tails(tails, hrirs, sample_rate_hz)
    return out


def hrir_binaural_early(arrivals: Arrivals, hrirs: HrirSet, bank: OctaveFilterBank,
                        n_samples: int, *, yaw_deg: float = 0.0, pitch_deg: float = 0.0,
                        taps: int = DEFAULT_TAPS) -> np.ndarray:
    """The early part of a binaural RIR through measured HRIRs, ``(2, n_samples)``: each
    arrival through the HRIR pair of the nearest measured direction (``hrirs`` at the bank's
    rate)."""
    if not len(arrivals):
        return np.zeros((2, n_samples))
    if arrivals.n_bands != bank.n_bands:
        raise AcousticsError(f"arrivals: expected {bank.n_bands} bands like the filter "
                             f"bank, got {arrivals.n_bands}")
    # Directions into the head frame, then the nearest measured direction (max cosine).
    local = arrivals.directions @ rotation(yaw_deg, pitch_deg)
    nearest = np.argmax(local @ hrirs.directions.T, axis=1)
    idx, w = _fractional_taps(arrivals.times_s, bank.sample_rate_hz, taps)
    # Each arrival: its fractional-delay tap ⊛ its HRIR pair ⊛ its causal shaping filter.
    amplitudes = arrivals.amplitudes
    flat = np.all(amplitudes == amplitudes[:, :1], axis=1)
    return _place_kernels(idx, w, amplitudes, flat, hrirs.hrirs[nearest], bank, n_samples)


def covering_angle_rad(hrirs: HrirSet, n_points: int = 1 << 14) -> float:
    """The largest angle from any direction to its nearest measured one (the set's
    covering radius, from ``n_points`` Fibonacci directions)."""
    from scipy.spatial import cKDTree

    chord, _ = cKDTree(hrirs.directions).query(fibonacci_sphere(n_points))
    return float(2 * np.arcsin(min(1.0, chord.max() / 2)))


def hrir_weights(hrirs: HrirSet, directions: np.ndarray, radius_rad: float
                 ) -> dict[int, np.ndarray]:
    """Weights of the measured HRIRs for directions that move, by measured direction:
    ``w_m ∝ (1 − θ_m / radius)²`` over the measurements within ``radius`` of each
    direction (``θ_m`` the angle to it), normalised to sum to 1. Continuous in the
    direction (a fixed radius, at least the set's covering angle, so the sum never
    vanishes): a source that turns round the head glides from one HRIR to the next instead
    of switching."""
    from scipy.spatial import cKDTree

    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    # A zero direction (a path not heard at either neighbouring point, so silent there):
    # any weights do; the front's.
    d = np.where(norm > 0, d / np.where(norm > 0, norm, 1.0), np.array([1.0, 0.0, 0.0]))
    chord = 2 * math.sin(min(radius_rad, math.pi) / 2)
    near = cKDTree(hrirs.directions).query_ball_point(d, chord + 1e-12)
    rows = np.repeat(np.arange(len(d)), [len(x) for x in near])
    cols = np.concatenate([np.asarray(x, dtype=np.int64) for x in near]) if len(d) else \
        np.zeros(0, np.int64)
    cos = np.einsum("ij,ij->i", d[rows], hrirs.directions[cols])
    w = np.maximum(0.0, 1.0 - np.arccos(np.clip(cos, -1.0, 1.0)) / radius_rad) ** 2
    total = np.bincount(rows, w, minlength=len(d))
    w = w / np.where(total > 0, total, 1.0)[rows]
    out: dict[int, np.ndarray] = {}
    for m in np.unique(cols):
        sel = cols == m
        weights = np.zeros(len(d))
        weights[rows[sel]] = w[sel]
        out[int(m)] = weights
    return out


def _check_freqs(freqs_hz: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    f = np.atleast_1d(np.asarray(freqs_hz, dtype=np.float64))
    if f.ndim != 1:
        raise AcousticsError(f"freqs_hz: expected a 1-d array, got shape {f.shape}")
    bad = f[~((f >= 0) & (f <= sample_rate_hz / 2))]
    if bad.size:
        raise AcousticsError(f"freqs_hz: expected frequencies in 0..{sample_rate_hz / 2:g} Hz "
                             f"(Nyquist), got {bad.size} outside, e.g. {bad[0]:g} Hz")
    return f


def _normalised(cross: np.ndarray, power_l: np.ndarray, power_r: np.ndarray) -> np.ndarray:
    """Re cross / √(P_L P_R), clipped to [−1, 1]; 0 (incoherent) where an ear has no power."""
    norm = np.sqrt(power_l * power_r)
    ok = norm > 1e-12 * max(float(norm.max(initial=0.0)), 1e-300)
    return np.clip(np.divide(cross, norm, out=np.zeros_like(cross), where=ok), -1.0, 1.0)


def nearest_direction_weights(directions: np.ndarray) -> np.ndarray:
    """Share of the sphere whose nearest measured direction is each one, ``(n,)``, summing to 1.

    Under nearest-direction lookup a uniform (diffuse) field gives each measured HRIR pair the
    arrivals of its spherical Voronoi cell, so the cell areas / 4π weight a diffuse-field
    average over a non-uniform grid (a partial grid's edge cells cover the unmeasured rest, as
    they do in rendering). Exact duplicates get zero weight after the first, as the renderer
    never picks them. Grids that have no spherical Voronoi diagram (fewer than four distinct
    directions, all on one great circle, near-duplicates) are weighted by counting the cells of
    a fine Fibonacci lattice instead.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    norms = np.linalg.norm(d, axis=1, keepdims=True)
    bad = int(np.sum(~np.all(np.isfinite(d), axis=1) | (norms[:, 0] == 0)))
    if len(d) == 0 or bad:
        raise AcousticsError(f"directions: expected at least one vector, all finite and "
                             f"non-zero, got {len(d)} with {bad} zero or non-finite")
    unique, first = np.unique(d / norms, axis=0, return_index=True)
    areas = None
    if len(unique) >= 4:
        with contextlib.suppress(ValueError, QhullError):
            areas = SphericalVoronoi(unique).calculate_areas() / (4 * math.pi)
    if areas is None:
        areas = _counted_weights(unique)
    weights = np.zeros(len(d))
    weights[first] = areas
    return weights / weights.sum()


def _counted_weights(directions: np.ndarray, n_points: int = 1 << 16) -> np.ndarray:
    """Nearest-direction cell areas / 4π of distinct unit ``directions`` by counting lattice
    points (error about one cell boundary's worth, ``~1/√m`` of a cell of ``m`` points)."""
    _, nearest = cKDTree(directions).query(fibonacci_sphere(n_points))
    return np.bincount(nearest, minlength=len(directions)) / n_points


def sphere_head_coherence(head: SphereHead, freqs_hz: np.ndarray, sample_rate_hz: float, *,
                          speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                          n_directions: int = DIFFUSE_DIRECTIONS) -> np.ndarray:
    """Diffuse-field interaural coherence ``Γ(f)`` of the sphere head as the renderer models it.

    ``Γ = Re Σ_d H_L H_R* / √(Σ_d |H_L|² Σ_d |H_R|²)`` over ``n_directions`` uniform
    (Fibonacci) directions, each ear's ``H`` being the Woodworth delay times the bilinear
    head-shadow filter of :func:`synthesize_sphere_binaural_rir`. As ``H = e^{−jωτ}(LP + α HP)``,
    each sum over directions reduces to four sums of ``e^{−jωΔτ}`` times 1, ``α_R``, ``α_L``
    and ``α_L α_R``. A uniform field has no preferred direction, so the head's orientation does
    not matter. The imaginary part (zero for a left-right symmetric head) is dropped.
    """
    _check(sample_rate_hz)
    f = _check_freqs(freqs_hz, sample_rate_hz)
    if n_directions < 1:
        raise AcousticsError(f"n_directions: expected >= 1, got {n_directions!r}")
    (b_lp, a_lp), (b_hp, a_hp) = shadow_filters(head, sample_rate_hz, speed_of_sound_m_s)
    lp = signal.freqz(b_lp, a_lp, worN=f, fs=sample_rate_hz)[1]
    hp = signal.freqz(b_hp, a_hp, worN=f, fs=sample_rate_hz)[1]
    dirs = fibonacci_sphere(n_directions)
    cos_l, cos_r = (dirs @ axis for axis in ear_axes(head, 0.0, 0.0))
    dtau = (woodworth_delays_s(cos_l, head.head_radius_m, speed_of_sound_m_s)
            - woodworth_delays_s(cos_r, head.head_radius_m, speed_of_sound_m_s))
    al, ar = shadow_alpha(cos_l), shadow_alpha(cos_r)
    u = np.stack([np.ones_like(al), ar, al, al * ar], axis=1) / n_directions  # (N, 4)
    sums = np.zeros((len(f), 4), dtype=np.complex128)
    for i in range(0, len(f), 512):
        # Phases reduced mod 2π in float64, then cos/sin in float32 (5x faster, errors ~1e-6).
        phase = np.remainder(2 * np.pi * f[i:i + 512, None] * dtau[None, :], 2 * np.pi)
        phase = phase.astype(np.float32)
        sums[i:i + 512] = np.cos(phase) @ u - 1j * (np.sin(phase) @ u)  # Σ e^{−jωΔτ} u
    # (LP + α_L HP)(LP + α_R HP)* = |LP|² + α_R LP HP* + α_L HP LP* + α_L α_R |HP|²
    lp2, hp2, lh = np.abs(lp) ** 2, np.abs(hp) ** 2, lp * np.conj(hp)
    cross = (lp2 * sums[:, 0] + lh * sums[:, 1] + np.conj(lh) * sums[:, 2]
             + hp2 * sums[:, 3]).real
    power_l = lp2 + 2 * lh.real * al.mean() + hp2 * np.mean(al**2)
    power_r = lp2 + 2 * lh.real * ar.mean() + hp2 * np.mean(ar**2)
    return _normalised(cross, power_l, power_r)


def hrir_set_coherence(hrirs: HrirSet, freqs_hz: np.ndarray, *,
                       weights: np.ndarray | None = None) -> np.ndarray:
    """Diffuse-field interaural coherence ``Γ(f)`` of a measured set, at its own sample rate.

    ``Γ = Re Σ_d w_d H_L H_R* / √(Σ_d w_d |H_L|² Σ_d w_d |H_R|²)`` with ``w`` the
    :func:`nearest_direction_weights` of the set's directions (or ``weights``): the share of a
    diffuse field each pair renders. The spectra are summed on an rfft grid of at least twice
    the HRIR length and interpolated to ``freqs_hz``. The imaginary part is dropped.
    """
    fs = hrirs.sample_rate_hz
    _check(fs)
    f = _check_freqs(freqs_hz, fs)
    n_dir, _, taps = hrirs.hrirs.shape
    if weights is None:
        w = nearest_direction_weights(hrirs.directions)
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n_dir,) or not np.all(w >= 0) or not w.sum() > 0:
            raise AcousticsError(f"weights: expected {n_dir} non-negative weights with a "
                                 f"positive sum, got shape {w.shape}")
    n_fft = max(_GRID_FFT, 1 << math.ceil(math.log2(2 * taps)))
    sums = np.zeros((3, n_fft // 2 + 1))
    used = np.flatnonzero(w > 0)
    for start in range(0, len(used), 256):
        idx = used[start:start + 256]
        spec = np.fft.rfft(hrirs.hrirs[idx], n_fft, axis=-1)  # (b, 2, F)
        ww = w[idx, None]
        sums[0] += np.sum(ww * (spec[:, 0] * np.conj(spec[:, 1])).real, axis=0)
        sums[1] += np.sum(ww * np.abs(spec[:, 0]) ** 2, axis=0)
        sums[2] += np.sum(ww * np.abs(spec[:, 1]) ** 2, axis=0)
    grid = np.fft.rfftfreq(n_fft, 1.0 / fs)
    cross, power_l, power_r = (np.interp(f, grid, s) for s in sums)
    return _normalised(cross, power_l, power_r)


def binaural_diffuse_coherence(model: SphereHead | HrirSet, sample_rate_hz: float, *,
                               speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
                               ) -> tuple[np.ndarray, np.ndarray]:
    """``(freqs_hz, Γ)`` of a head model's diffuse field on a grid up to Nyquist (read-only).

    Cached per model, rate and speed of sound (a sphere head takes ~0.1 s, a 1,500-direction
    HRIR set a few tens of ms: a rir job renders many RIRs with one head); an :class:`HrirSet`
    by identity. A set measured at a lower rate than ``sample_rate_hz`` gives ``Γ = 0`` above
    its own Nyquist.
    """
    _check(sample_rate_hz)
    return _coherence_grid(model, float(sample_rate_hz), float(speed_of_sound_m_s))


@functools.lru_cache(maxsize=16)
def _coherence_grid(model: SphereHead | HrirSet, sample_rate_hz: float,
                    speed_of_sound_m_s: float) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(model, SphereHead):
        freqs = np.fft.rfftfreq(_GRID_FFT, 1.0 / sample_rate_hz)
        gamma = sphere_head_coherence(model, freqs, sample_rate_hz,
                                      speed_of_sound_m_s=speed_of_sound_m_s)
    else:
        # On the set's own rate: resampling adds nothing to the measured band, and its images
        # above the old Nyquist would pass for coherent low frequencies. Beyond the measured
        # band the ears are taken as incoherent (Γ = 0), the diffuse high-frequency limit.
        n_fft = max(_GRID_FFT, 1 << math.ceil(math.log2(
            2 * model.hrirs.shape[-1] * sample_rate_hz / model.sample_rate_hz)))
        freqs = np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz)
        gamma = np.zeros_like(freqs)
        measured = freqs <= model.sample_rate_hz / 2
        gamma[measured] = hrir_set_coherence(model, freqs[measured])
    freqs.flags.writeable = False
    gamma.flags.writeable = False
    return freqs, gamma


def diffuse_binaural_tails(tails: np.ndarray, model: SphereHead | HrirSet,
                           sample_rate_hz: float, *,
                           speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """Two independent tails ``(2, n)`` mixed into the ears of a diffuse field, ``(2, n)``.

    Per frequency ``y_L = a x₁ + b x₂``, ``y_R = a x₁ − b x₂`` with ``a = √((1 + Γ)/2)``,
    ``b = √((1 − Γ)/2)`` and ``Γ`` the model's :func:`binaural_diffuse_coherence`: for inputs
    of equal power spectrum ``S``, ``E[y_L y_R*] = (a² − b²) S = Γ S`` and
    ``E|y|² = (a² + b²) S = S``, so each ear keeps the tail's energy. This is the two-channel
    closed form of :func:`~sonicspec.acoustics.receivers.arrays.diffuse_coherence`'s ``C = √Λ Vᵀ``,
    smooth where ``Γ`` crosses zero (an eigen-solver swaps the eigenvalues there), so the
    zero-phase filters stay a few interaural delays long.
    """
    x = np.asarray(tails, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] != 2:
        raise AcousticsError(f"tails: expected two signals (2, n), got {x.shape}")
    grid, gamma = binaural_diffuse_coherence(model, sample_rate_hz,
                                             speed_of_sound_m_s=speed_of_sound_m_s)

    def mixing(freqs_hz: np.ndarray) -> np.ndarray:
        g = np.interp(freqs_hz, grid, gamma)
        a, b = np.sqrt((1 + g) / 2), np.sqrt((1 - g) / 2)
        return np.stack([np.stack([a, a], axis=-1), np.stack([b, -b], axis=-1)], axis=1)

    if isinstance(model, SphereHead):
        # Filters span the largest interaural delay, the Woodworth one of a lateral source.
        itd_s = model.head_radius_m / speed_of_sound_m_s * (math.pi / 2 + 1)
        pad = seconds_to_samples_ceil(4 * itd_s, sample_rate_hz) + 16
    else:
        # Γ of a measured set has no structure finer than its HRIRs' length.
        pad = 2 * math.ceil(model.hrirs.shape[-1] * sample_rate_hz / model.sample_rate_hz) + 16
    return mix_per_frequency(x, mixing, sample_rate_hz, pad)


# --- spherical arrays: capsules flush on a rigid sphere (the em32) ----------------------------

def sphere_responses(capsules: Capsules, freqs_hz: np.ndarray, sample_rate_hz: float,
                     directions: np.ndarray,
                     speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """``(F, M, N)``: what capsules on a rigid sphere hear of unit plane waves from
    ``directions`` ``(N, 3)`` as the renderer models it (Woodworth delay round the sphere and
    the Brown–Duda shadow filter ``LP + α HP``, each capsule an ear on its axis)."""
    radius = capsules.sphere_radius_m
    if radius is None:
        raise AcousticsError("sphere_responses: the capsules are not on a rigid sphere")
    f = np.asarray(freqs_hz, dtype=np.float64)
    (b_lp, a_lp), (b_hp, a_hp) = shadow_filters(SphereHead(head_radius_m=radius),
                                                sample_rate_hz, speed_of_sound_m_s)
    lp = signal.freqz(b_lp, a_lp, worN=f, fs=sample_rate_hz)[1]
    hp = signal.freqz(b_hp, a_hp, worN=f, fs=sample_rate_hz)[1]
    cos_t = capsules.axes @ np.asarray(directions, dtype=np.float64).reshape(-1, 3).T  # (M, N)
    tau = woodworth_delays_s(cos_t, radius, speed_of_sound_m_s)
    alpha = shadow_alpha(cos_t)
    # e^{−jωτ} from its cosine and sine (numpy's complex exp is several times slower)
    phase = (2 * math.pi) * f[:, None, None] * tau[None]
    delay = np.empty(phase.shape, dtype=np.complex128)
    delay.real = np.cos(phase)
    delay.imag = -np.sin(phase)
    return delay * (lp[:, None, None] + alpha[None] * hp[:, None, None])


def sphere_cross_spectra(capsules: Capsules, freqs_hz: np.ndarray, sample_rate_hz: float,
                         speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S, *,
                         n_directions: int = 1024, chunk: int = 32) -> np.ndarray:
    """Diffuse-field cross-spectra ``(F, M, M)`` of capsules on a rigid sphere: their
    :func:`sphere_responses` averaged over ``n_directions`` uniform (Fibonacci) directions,
    ``chunk`` frequencies at a time (memory ``chunk × M × N``). For two ears this is the
    cross-spectrum :func:`sphere_head_coherence` normalises."""
    f = np.asarray(freqs_hz, dtype=np.float64).reshape(-1)
    dirs = fibonacci_sphere(n_directions)
    out = np.zeros((len(f), len(capsules), len(capsules)), dtype=np.complex128)
    for i in range(0, len(f), chunk):
        h = sphere_responses(capsules, f[i:i + chunk], sample_rate_hz, dirs,
                             speed_of_sound_m_s)
        out[i:i + chunk] = diffuse_cross_spectra_numeric(h)
    return out


@functools.lru_cache(maxsize=8)
def _sphere_roots(capsules: Capsules, sample_rate_hz: float, speed_of_sound_m_s: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    grid = np.fft.rfftfreq(_GRID_FFT // 2, 1.0 / sample_rate_hz)
    return grid, hermitian_root(sphere_cross_spectra(capsules, grid, sample_rate_hz,
                                                     speed_of_sound_m_s))


def synthesize_sphere_array_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                                capsules: Capsules, sample_rate_hz: float,
                                rng: np.random.Generator, *,
                                speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                                max_length_s: float = 2.0, bands_hz: tuple[float, ...] = (),
                                taps: int = DEFAULT_TAPS) -> np.ndarray:
    """RIRs of capsules on a rigid sphere (``capsules`` in the scene's frame, with their
    ``sphere_radius_m``), ``(M, n_samples)``: the early arrivals as the sphere head's ears
    (:func:`sphere_capsules_early`), the late tail as independent noises mixed to the
    sphere's diffuse-field cross-spectra (:func:`sphere_cross_spectra`, on a grid
    ``fs/1024`` apart, cached per capsules).

    Parameters are those of :func:`synthesize_sphere_binaural_rir`, with ``capsules`` for
    the head and its orientation (already turned into the scene)."""
    _check(sample_rate_hz)
    head = SphereHead(head_radius_m=float(capsules.sphere_radius_m))
    bank = OctaveFilterBank(sample_rate_hz, bands_hz)
    reach = 2 * head.head_radius_m / speed_of_sound_m_s
    n = rir_length_samples(arrivals, histogram, sample_rate_hz, max_length_s + reach, taps,
                           bank.padding() // 4)
    out = sphere_capsules_early(arrivals, head, capsules.axes, bank, n,
                                speed_of_sound_m_s=speed_of_sound_m_s, taps=taps)
    if histogram is not None:
        tails = np.stack([synthesize_late(histogram, bank, n, rng) for _ in capsules.axes])
        grid, roots = _sphere_roots(capsules, float(sample_rate_hz), float(speed_of_sound_m_s))
        itd_s = head.head_radius_m / speed_of_sound_m_s * (math.pi / 2 + 1)
        pad = seconds_to_samples_ceil(4 * itd_s, sample_rate_hz) + 16
        out += mix_by_roots(tails, grid, roots, sample_rate_hz, pad)
    return out
