"""Directional capsules: first-order patterns, their orientations, and the diffuse field they
hear (library level).

A first-order capsule whose axis is the unit vector ``u`` hears a plane wave arriving from
direction ``d`` (a unit vector from the capsule towards where the sound comes from) with gain

    g(d) = a + (1 − a) (u · d),      0 ≤ a ≤ 1,

``a = 1`` omni, ``a = 0`` figure-eight (:data:`PATTERNS`). The patterns of ideal capsules are
**frequency independent** (real capsules turn towards omni at low and narrow at high
frequencies; that is not modelled): one gain per arrival, the same in every band, applied to
every path by its direction of arrival (direct sound, image sources, diffracted paths), and
negative in a figure-eight's or a hypercardioid's rear lobe (the polarity flips there).

**The late tail** is a diffuse field (the ray tracer's histogram carries no directions): the
capsules hear independent noises mixed per frequency to the diffuse-field cross-spectral
matrix of the capsules (:func:`diffuse_cross_spectra`), the average over directions uniform on
the sphere of ``g_i(d) g_j(d) e^{jk d·(p_i − p_j)}``. For first-order capsules it has the closed
form (``r = p_i − p_j``, ``x = k|r|``, ``r̂ = r/|r|``, ``b = 1 − a``, ``j_n`` spherical Bessel)

    S_ij = a_i a_j j0(x) + j j1(x) (a_i b_j u_j + a_j b_i u_i)·r̂
           + b_i b_j [(u_i·u_j) j1(x)/x − (u_i·r̂)(u_j·r̂) j2(x)],

from ``⟨e^{jq·d}⟩ = j0``, ``⟨d e^{jq·d}⟩ = j j1 q̂`` and ``⟨d dᵀ e^{jq·d}⟩ = (j1/q) I − j2 q̂q̂ᵀ``
(derivatives of ``j0(|q|)``; tested against the quadrature of
:func:`sonicspec.acoustics.theory.diffuse_cross_spectrum_quadrature`). Its diagonal is the
pattern's diffuse-field power ``a² + b²/3`` (a cardioid hears a third of a diffuse field's
energy, −4.8 dB; its random-energy efficiency). Omni capsules give
``sinc(kd)``, what :func:`~sonicspec.acoustics.receivers.arrays.diffuse_coherence` mixes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import spherical_jn

from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S

#: First-order patterns by name: the omni part ``a`` of ``a + (1 − a) cos θ``.
#: Supercardioid: the largest front-to-back energy ratio, ``a = (√3 − 1)/2``; hypercardioid:
#: the largest directivity factor (4, 6 dB), ``a = 1/4``; subcardioid ``a = 0.7`` (the
#: broad cardioid of studio catalogues; textbooks quote 0.7–0.75). Values as in Elko (2000),
#: "Superdirectional microphone arrays", in Gay & Benesty (eds.), *Acoustic Signal Processing
#: for Telecommunication*, ch. 10, table 10.1.
PATTERNS: dict[str, float] = {
    "omni": 1.0,
    "subcardioid": 0.7,
    "cardioid": 0.5,
    "supercardioid": (math.sqrt(3.0) - 1.0) / 2.0,
    "hypercardioid": 0.25,
    "figure_eight": 0.0,
}


def pattern_alpha(pattern: str) -> float:
    """The omni part ``a`` of a named first-order pattern (:data:`PATTERNS`)."""
    try:
        return PATTERNS[pattern]
    except KeyError:
        raise AcousticsError(f"capsule pattern: expected one of {', '.join(PATTERNS)}, got "
                             f"{pattern!r}") from None


def pattern_gain(alpha, cos_theta):
    """``a + (1 − a) cos θ``: the gain of a first-order capsule ``θ`` off its axis."""
    return alpha + (1.0 - alpha) * cos_theta


def diffuse_power(alpha) -> np.ndarray:
    """The pattern's response to a diffuse field, as a share of an omni's energy:
    ``a² + (1 − a)²/3`` (1 omni, 1/3 cardioid and figure-eight, 1/4 hypercardioid)."""
    a = np.asarray(alpha, dtype=np.float64)
    return a * a + (1.0 - a) ** 2 / 3.0


def unit_axis(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """The unit vector of an azimuth (from +x towards +y) and an elevation (up), ``(3,)``."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


@dataclass(frozen=True, eq=False)
class Capsules:
    """Capsules of one receiver in its own frame (x where it looks, y its left, z up).

    ``offsets_m`` ``(M, 3)`` from the centre, metres; ``axes`` ``(M, 3)`` unit vectors each
    capsule points to; ``alphas`` ``(M,)`` the omni part of each pattern (:data:`PATTERNS`);
    ``sphere_radius_m``: the capsules sit flush on a rigid sphere of that radius (their axes
    are then the outward normals and their patterns omni: the sphere does the shaping,
    :mod:`~sonicspec.acoustics.receivers.hrtf`'s Brown–Duda model), or None in free field.
    """

    offsets_m: np.ndarray
    axes: np.ndarray
    alphas: np.ndarray
    sphere_radius_m: float | None = None

    def __post_init__(self) -> None:
        off = np.asarray(self.offsets_m, dtype=np.float64).reshape(-1, 3)
        axes = np.asarray(self.axes, dtype=np.float64).reshape(-1, 3)
        alphas = np.asarray(self.alphas, dtype=np.float64).reshape(-1)
        if not (len(off) == len(axes) == len(alphas)) or len(off) == 0:
            raise AcousticsError(f"capsules: expected as many axes and patterns as offsets "
                                 f"(>= 1), got {len(off)}, {len(axes)} and {len(alphas)}")
        norms = np.linalg.norm(axes, axis=1)
        if np.any(norms < 1e-9):
            raise AcousticsError("capsules: every axis needs a direction (got a zero vector)")
        if np.any((alphas < 0) | (alphas > 1)):
            raise AcousticsError(f"capsules: expected pattern alphas in [0, 1], got "
                                 f"{alphas.tolist()}")
        if self.sphere_radius_m is not None:
            if not self.sphere_radius_m > 0:
                raise AcousticsError(f"capsules.sphere_radius_m: expected > 0, got "
                                     f"{self.sphere_radius_m!r}")
            if np.any(alphas != 1.0):
                raise AcousticsError("capsules: on a rigid sphere the capsules are omni "
                                     "(the sphere shapes them)")
        object.__setattr__(self, "offsets_m", off)
        object.__setattr__(self, "axes", axes / norms[:, None])
        object.__setattr__(self, "alphas", alphas)

    def __len__(self) -> int:
        return len(self.offsets_m)

    @property
    def omni(self) -> bool:
        """Every capsule omni in free field (the plain array renderer's case)."""
        return self.sphere_radius_m is None and bool(np.all(self.alphas == 1.0))

    def rotated(self, rotation_matrix: np.ndarray) -> Capsules:
        """The same capsules with offsets and axes turned by ``rotation_matrix`` (local to
        scene: ``v_scene = R v_local``)."""
        r = np.asarray(rotation_matrix, dtype=np.float64)
        return Capsules(self.offsets_m @ r.T, self.axes @ r.T, self.alphas, self.sphere_radius_m)

    def gains(self, directions: np.ndarray) -> np.ndarray:
        """Gains ``(n, M)`` for arrivals from ``directions`` ``(n, 3)`` (unit vectors in the
        frame the axes are in). A zero direction (a path silent there) gets gain 0."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        return pattern_gain(self.alphas[None, :], d @ self.axes.T) * np.any(
            d != 0, axis=1, keepdims=True)


def _j1_over_x(x: np.ndarray) -> np.ndarray:
    small = x < 1e-4
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 / 3.0 - x * x / 30.0, spherical_jn(1, safe) / safe)


def diffuse_cross_spectra(capsules: Capsules, freqs_hz: np.ndarray,
                          speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """The diffuse-field cross-spectral matrices ``(F, M, M)`` (Hermitian, complex) of
    first-order capsules in free field, closed form (module docstring), per unit power of
    an omni at the centre: ``S_ij = ⟨g_i g_j e^{jk d·(p_i − p_j)}⟩`` over directions ``d``."""
    if capsules.sphere_radius_m is not None:
        raise AcousticsError("diffuse_cross_spectra: capsules on a rigid sphere need "
                             "diffuse_cross_spectra_numeric with the sphere model")
    f = np.asarray(freqs_hz, dtype=np.float64).reshape(-1)
    p, u, a = capsules.offsets_m, capsules.axes, capsules.alphas
    b = 1.0 - a
    r = p[:, None, :] - p[None, :, :]  # (M, M, 3)
    dist = np.linalg.norm(r, axis=-1)
    rhat = np.divide(r, dist[..., None], out=np.zeros_like(r), where=dist[..., None] > 0)
    x = (2 * math.pi * f / speed_of_sound_m_s)[:, None, None] * dist[None]  # (F, M, M)
    j0, j1, j2 = (spherical_jn(n, x) for n in range(3))
    ui_r = np.einsum("ik,ijk->ij", u, rhat)  # u_i · r̂_ij
    uj_r = np.einsum("jk,ijk->ij", u, rhat)  # u_j · r̂_ij
    uu = u @ u.T
    first = a[:, None] * b[None, :] * uj_r + a[None, :] * b[:, None] * ui_r
    bb = b[:, None] * b[None, :]
    return (np.outer(a, a)[None] * j0 + 1j * j1 * first[None]
            + bb[None] * (uu[None] * _j1_over_x(x) - (ui_r * uj_r)[None] * j2))


def diffuse_cross_spectra_numeric(responses: np.ndarray,
                                  weights: np.ndarray | None = None) -> np.ndarray:
    """``(F, M, M)`` ``Σ_d w_d H_i(d) H_j(d)*`` for per-direction responses ``responses``
    ``(F, M, N)`` (complex) over ``N`` directions with weights ``w`` summing to one (uniform
    when None): the diffuse-field cross-spectra of any receiver whose response per direction
    is known (a rigid sphere, or a check of :func:`diffuse_cross_spectra`)."""
    h = np.asarray(responses)
    n = h.shape[-1]
    w = np.full(n, 1.0 / n) if weights is None else np.asarray(weights, dtype=np.float64)
    return (h * w) @ np.conj(np.swapaxes(h, 1, 2))


def free_field_responses(capsules: Capsules, freqs_hz: np.ndarray, directions: np.ndarray,
                         speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """``(F, M, N)``: what each free-field capsule hears of a unit plane wave from each of
    ``directions`` ``(N, 3)``: its gain and its lead ``e^{jk d·p}`` over the centre."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    k = 2 * math.pi * np.asarray(freqs_hz, dtype=np.float64) / speed_of_sound_m_s
    lead = np.exp(1j * k[:, None, None] * (capsules.offsets_m @ d.T)[None])
    return lead * capsules.gains(d).T[None]


def hermitian_root(spectra: np.ndarray) -> np.ndarray:
    """``R = V √Λ Vᴴ`` of each Hermitian positive semi-definite ``(F, M, M)`` matrix
    (negative eigenvalues of round-off clipped to zero): the smooth, unique square root."""
    lam, vec = np.linalg.eigh(spectra)
    return (vec * np.sqrt(np.maximum(lam, 0.0))[:, None, :]) @ np.conj(np.swapaxes(vec, 1, 2))
