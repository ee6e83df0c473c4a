"""Receivers beyond one omni capsule: microphone arrays and ambisonics (library level).

Both render from one set of arrivals whose directions are *directions of arrival at the
microphone* (unit vectors from the mic towards where the sound comes from, scene frame, z up).

* **Arrays** of omnidirectional capsules: every arrival is a plane wave (far field), so capsule
  ``m`` at offset ``p_m`` from the array centre hears it ``−(p_m · d)/c`` seconds relative to the
  centre — earlier when the capsule points towards the source. The late tail is a diffuse
  field: independent noise per capsule with the mono tail's per-band energy, then mixed per
  frequency so that capsules ``d`` apart have the spherically isotropic coherence
  ``Γ(f) = sin(kd)/(kd)``, ``k = 2πf/c`` (Habets & Gannot 2007: ``Y(f) = C(f)ᵀ X(f)`` with
  ``Cᵀ C = Γ``, here ``C = √Λ Vᵀ`` from the eigen-decomposition, which stays valid where ``Γ``
  is singular, as at low frequencies where every capsule hears the same). Each capsule keeps
  its energy (``Γ`` has a unit diagonal).
* **Ambisonics**, orders 1–3, ACN channel order, SN3D normalisation (AmbiX): every arrival is
  encoded with the real spherical harmonics of its direction (:func:`sh_sn3d`). The late tail
  is independent noise per channel, with the diffuse-field energy of SN3D channels: a channel
  of order ``l`` carries ``1/(2l + 1)`` of the W channel's energy.

Capsule offsets follow the spec: linear arrays along the array's local y axis (its left, looking
along +x), circular arrays in the horizontal plane, custom offsets as given; all rotated by yaw
(about z) and pitch.

* **Directional capsules** (:class:`~sonicspec.acoustics.receivers.capsules.Capsules`, first-order
  patterns with an axis each): every arrival is also weighted by each capsule's gain for its
  direction of arrival, and the late tail is mixed to the capsules' diffuse-field
  cross-spectral matrix (:func:`directional_diffuse`), complex where a capsule's axis has a
  component along the line to another, with each capsule's diffuse-field power on the
  diagonal. All-omni arrays keep the renderer above, bit for bit.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np

from sonicspec.acoustics.arrivals import Arrivals, EnergyHistogram
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.receivers.capsules import (
    Capsules,
    diffuse_cross_spectra,
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


def rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Rotation taking the array's local frame to the scene: pitch about y, then yaw about z."""
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    ry = np.array([[math.cos(p), 0, -math.sin(p)], [0, 1, 0], [math.sin(p), 0, math.cos(p)]])
    return rz @ ry


def local_directions(vectors_m: np.ndarray, yaw_deg, pitch_deg: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Azimuth and elevation (degrees) and length (m) of vectors from the microphone, in its
    own frame (:func:`rotation`): azimuth 0 along the look direction, positive to the left
    (counter-clockwise seen from above), elevation positive upwards. ``yaw_deg``: one yaw,
    or one per vector (a microphone that turns)."""
    v = np.asarray(vectors_m, dtype=np.float64).reshape(-1, 3)
    if np.ndim(yaw_deg) == 0:
        local = v @ rotation(float(yaw_deg), pitch_deg)
    else:  # R_zᵀ per vector, then the pitch
        y = np.radians(np.asarray(yaw_deg, dtype=np.float64))
        turned = np.column_stack([np.cos(y) * v[:, 0] + np.sin(y) * v[:, 1],
                                  -np.sin(y) * v[:, 0] + np.cos(y) * v[:, 1], v[:, 2]])
        local = turned @ rotation(0.0, pitch_deg)
    distance = np.linalg.norm(local, axis=1)
    azimuth = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
    elevation = np.degrees(np.arctan2(local[:, 2], np.hypot(local[:, 0], local[:, 1])))
    return azimuth, elevation, distance


def capsule_offsets(kind: str, *, n: int = 0, spacing_m: float = 0.0, radius_m: float = 0.0,
                    positions_m: Sequence[Sequence[float]] = (), yaw_deg: float = 0.0,
                    pitch_deg: float = 0.0) -> np.ndarray:
    """Offsets ``(M, 3)`` of the capsules from the array centre in the scene frame, metres."""
    if kind == "mono":
        local = np.zeros((1, 3))
    elif kind == "linear_array":
        local = np.zeros((n, 3))
        local[:, 1] = (np.arange(n) - (n - 1) / 2) * spacing_m
    elif kind == "circular_array":
        a = 2 * np.pi * np.arange(n) / n
        local = np.column_stack([radius_m * np.cos(a), radius_m * np.sin(a), np.zeros(n)])
    elif kind == "custom":
        local = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    else:
        raise AcousticsError(f"array kind: expected mono, linear_array, circular_array or custom, "
                             f"got {kind!r}")
    return local @ rotation(yaw_deg, pitch_deg).T


def sh_sn3d(order: int, directions: np.ndarray) -> np.ndarray:
    """Real spherical harmonics, ACN order, SN3D, up to ``order`` (≤ 3): ``(n, (order+1)²)``."""
    if not 0 <= order <= 3:
        raise AcousticsError(f"ambisonic order: expected 0..3, got {order!r}")
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    s3, s15 = math.sqrt(3), math.sqrt(15)
    columns = [np.ones_like(x)]
    if order >= 1:
        columns += [y, z, x]
    if order >= 2:
        columns += [s3 * x * y, s3 * y * z, (3 * z**2 - 1) / 2, s3 * x * z,
                    s3 / 2 * (x**2 - y**2)]
    if order >= 3:
        columns += [math.sqrt(5 / 8) * y * (3 * x**2 - y**2), s15 * x * y * z,
                    math.sqrt(3 / 8) * y * (5 * z**2 - 1), z * (5 * z**2 - 3) / 2,
                    math.sqrt(3 / 8) * x * (5 * z**2 - 1), s15 / 2 * z * (x**2 - y**2),
                    math.sqrt(5 / 8) * x * (x**2 - 3 * y**2)]
    return np.column_stack(columns)


def _scaled(arrivals: Arrivals, gains: np.ndarray, delays_s: np.ndarray) -> Arrivals:
    return Arrivals(arrivals.times_s + delays_s, arrivals.amplitudes * gains[:, None],
                    arrivals.directions, arrivals.order, arrivals.kind, arrivals.path_length_m,
                    arrivals.isometry, arrivals.path_id)


def array_early(arrivals: Arrivals, offsets_m: np.ndarray, bank: OctaveFilterBank,
                n_samples: int, speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                taps: int = DEFAULT_TAPS, *, capsules: Capsules | None = None) -> np.ndarray:
    """The early part of an array's RIRs, ``(M, n_samples)``: each arrival reaches capsule
    ``p`` earlier by ``d · p / c`` (a plane wave from its direction ``d``), weighted by the
    capsule's gain for ``d`` when ``capsules`` (in the scene's frame, their offsets
    ``offsets_m``) are directional."""
    offsets = np.asarray(offsets_m, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(offsets), n_samples))
    gains = (None if capsules is None or capsules.omni or not len(arrivals)
             else capsules.gains(arrivals.directions))
    for m, p in enumerate(offsets):
        delays = -(arrivals.directions @ p) / speed_of_sound_m_s
        g = np.ones(len(arrivals)) if gains is None else gains[:, m]
        out[m] = synthesize_early(_scaled(arrivals, g, delays), bank, n_samples, taps)
    return out


def ambisonic_early(arrivals: Arrivals, order: int, bank: OctaveFilterBank, n_samples: int,
                    taps: int = DEFAULT_TAPS, *, yaw_deg: float = 0.0,
                    pitch_deg: float = 0.0) -> np.ndarray:
    """The early part of an ambisonic RIR, ``((order + 1)², n_samples)``, ACN/SN3D, in the
    microphone's frame (:func:`rotation`: its x axis where it faces)."""
    local = arrivals.directions @ rotation(yaw_deg, pitch_deg)
    gains = sh_sn3d(order, local) if len(arrivals) else np.zeros(
        (0, (order + 1) ** 2))
    if not len(arrivals):
        return np.zeros(((order + 1) ** 2, n_samples))
    if arrivals.n_bands != bank.n_bands:
        raise AcousticsError(f"arrivals: expected {bank.n_bands} bands like the filter bank, "
                             f"got {arrivals.n_bands}")
    # One shaping filter per arrival, weighted per channel (it is linear in the weight).
    idx, w = _fractional_taps(arrivals.times_s, bank.sample_rate_hz, taps)
    amplitudes = arrivals.amplitudes
    flat = np.all(amplitudes == amplitudes[:, :1], axis=1)
    return _place_kernels(idx, w, amplitudes, flat, gains[:, :, None], bank, n_samples)


def synthesize_array_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                         offsets_m: np.ndarray, sample_rate_hz: float,
                         rng: np.random.Generator, *,
                         speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                         max_length_s: float = 2.0, bands_hz: tuple[float, ...] = (),
                         taps: int = DEFAULT_TAPS, capsules: Capsules | None = None
                         ) -> np.ndarray:
    """RIRs of capsules at ``offsets_m`` around the centre, ``(M, n_samples)``: omni, or
    the directional ``capsules`` (scene frame, at ``offsets_m``)."""
    offsets = np.asarray(offsets_m, dtype=np.float64).reshape(-1, 3)
    directional = capsules is not None and not capsules.omni
    bank = OctaveFilterBank(sample_rate_hz, bands_hz)
    reach = float(np.max(np.linalg.norm(offsets, axis=1))) / speed_of_sound_m_s
    n = rir_length_samples(arrivals, histogram, sample_rate_hz, max_length_s + reach, taps,
                           bank.padding() // 4)
    out = array_early(arrivals, offsets, bank, n, speed_of_sound_m_s, taps,
                      capsules=capsules if directional else None)
    if histogram is not None:
        tails = np.stack([synthesize_late(histogram, bank, n, rng) for _ in offsets])
        if directional:
            out += directional_diffuse(tails, capsules, sample_rate_hz, speed_of_sound_m_s)
        else:
            out += diffuse_coherence(tails, offsets, sample_rate_hz, speed_of_sound_m_s)
    return out


def directional_diffuse(signals: np.ndarray, capsules: Capsules, sample_rate_hz: float,
                        speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """Independent signals ``(M, n)`` of one power spectrum mixed into the diffuse field the
    free-field ``capsules`` hear: per frequency ``Y = conj(R)ᵀ X`` with ``R = S^½``
    (:func:`~sonicspec.acoustics.receivers.capsules.hermitian_root`) of the capsules'
    cross-spectral matrix ``S``
    (:func:`~sonicspec.acoustics.receivers.capsules.diffuse_cross_spectra`), so
    ``E[Y_i Y_j*] = S_ij`` times the inputs' spectrum: each capsule gets its pattern's
    diffuse-field power, each pair its cross-spectrum. ``R`` is computed on a grid fine
    enough for the array's largest delay and interpolated (cached per capsules)."""
    x = np.asarray(signals, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] != len(capsules):
        raise AcousticsError(f"directional_diffuse: expected one signal (M, n) per capsule "
                             f"({len(capsules)}), got {x.shape}")
    p = capsules.offsets_m
    span_s = float(np.max(np.linalg.norm(p[:, None] - p[None], axis=-1))) / speed_of_sound_m_s
    grid, roots = _diffuse_roots(capsules, float(sample_rate_hz), float(speed_of_sound_m_s),
                                 span_s)
    pad = seconds_to_samples_ceil(4 * span_s, sample_rate_hz) + 16
    return mix_by_roots(x, grid, roots, sample_rate_hz, pad)


@functools.lru_cache(maxsize=16)
def _diffuse_roots(capsules: Capsules, sample_rate_hz: float, speed_of_sound_m_s: float,
                   span_s: float) -> tuple[np.ndarray, np.ndarray]:
    n_grid = max(2048, 1 << math.ceil(math.log2(max(16 * span_s * sample_rate_hz, 1.0))))
    grid = np.fft.rfftfreq(n_grid, 1.0 / sample_rate_hz)
    return grid, hermitian_root(diffuse_cross_spectra(capsules, grid, speed_of_sound_m_s))


#: Frequencies per block of :func:`mix_by_roots` (bounds the memory: block × M² complex).
_MIX_BLOCK = 2048


def mix_by_roots(signals: np.ndarray, grid_hz: np.ndarray, roots: np.ndarray,
                 sample_rate_hz: float, pad_samples: int) -> np.ndarray:
    """Zero-phase mixing of ``(M, n)`` signals by ``Y_j = Σ_i conj(R_ij) X_i`` with the
    Hermitian roots ``R`` ``(G, M, M)`` given on the uniform grid ``grid_hz`` (from 0 Hz)
    and interpolated linearly between its points; blocks of frequencies at a time, so the
    memory is that of a block, not of every frequency. Padding as
    :func:`mix_per_frequency`."""
    n = signals.shape[1]
    n_fft = 1 << math.ceil(math.log2(n + 2 * pad_samples))
    frame = np.zeros((signals.shape[0], n_fft))
    frame[:, pad_samples:pad_samples + n] = signals
    spectrum = np.fft.rfft(frame, axis=-1)  # (M, F)
    freqs = np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz)
    step = grid_hz[1] - grid_hz[0]
    mixed = np.empty_like(spectrum)
    for i in range(0, len(freqs), _MIX_BLOCK):
        pos = np.clip(freqs[i:i + _MIX_BLOCK] / step, 0.0, len(grid_hz) - 1.0)
        lo = np.minimum(np.floor(pos).astype(np.int64), len(grid_hz) - 2)
        w = (pos - lo)[:, None, None]
        root = roots[lo] * (1.0 - w) + roots[lo + 1] * w
        mixed[:, i:i + _MIX_BLOCK] = np.einsum("fij,if->jf", np.conj(root),
                                               spectrum[:, i:i + _MIX_BLOCK])
    return np.fft.irfft(mixed, n=n_fft, axis=-1)[:, pad_samples:pad_samples + n]


def diffuse_coherence(signals: np.ndarray, positions_m: np.ndarray, sample_rate_hz: float,
                      speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """Mix independent signals ``(M, n)`` into a diffuse field heard at ``positions_m``.

    Per frequency, the mixing matrix ``C = Γ^½ = V √Λ Vᵀ`` of ``Γ = V Λ Vᵀ``,
    ``Γ_ij = sinc(k d_ij)``, gives outputs with coherence ``Γ`` and each input's power spectrum
    (when the inputs have equal spectra, as independent tails of one histogram do). The
    symmetric square root is unique and smooth in frequency; ``√Λ Vᵀ`` would also give ``Γ``,
    but eigenvectors reorder and flip sign where eigenvalues cross, and those jumps spread the
    mixing filters in time. Zero-phase filters of length about ``max d / c``; the signals are
    padded by that much so nothing wraps around.
    """
    x = np.asarray(signals, dtype=np.float64)
    pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    if x.ndim != 2 or x.shape[0] != len(pos):
        raise AcousticsError(f"diffuse_coherence: expected one signal (M, n) per position "
                             f"({len(pos)}), got {x.shape}")
    if len(pos) < 2:
        return x.copy()
    d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)

    def mixing(freqs_hz: np.ndarray) -> np.ndarray:
        k = 2 * math.pi * freqs_hz / speed_of_sound_m_s
        # (F, M, M); numpy's sinc is sin(πx)/(πx)
        gamma = np.sinc(k[:, None, None] * d[None, :, :] / math.pi)
        lam, vec = np.linalg.eigh(gamma)
        root = vec * np.sqrt(np.maximum(lam, 0.0))[:, None, :]
        return root @ np.swapaxes(vec, 1, 2)  # C = V √Λ Vᵀ, symmetric

    pad = seconds_to_samples_ceil(4 * d.max() / speed_of_sound_m_s, sample_rate_hz) + 16
    return mix_per_frequency(x, mixing, sample_rate_hz, pad)


def mix_per_frequency(signals: np.ndarray, mixing: Callable[[np.ndarray], np.ndarray],
                      sample_rate_hz: float, pad_samples: int) -> np.ndarray:
    """Zero-phase mixing of ``(M, n)`` signals by real matrices that depend on frequency.

    ``mixing(freqs_hz)`` gives ``C`` of shape ``(F, M, K)`` on the rfft grid and the outputs
    are ``Y_j(f) = Σ_i C_ij(f) X_i(f)``, ``(K, n)``. The signals sit ``pad_samples`` into a
    zero frame (at least the mixing filters' half length) so their non-causal tails neither
    wrap around nor are cut.
    """
    n = signals.shape[1]
    n_fft = 1 << math.ceil(math.log2(n + 2 * pad_samples))
    frame = np.zeros((signals.shape[0], n_fft))
    frame[:, pad_samples:pad_samples + n] = signals
    spectrum = np.fft.rfft(frame, axis=-1)  # (M, F)
    mix = mixing(np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz))
    mixed = np.einsum("fij,if->jf", mix, spectrum)  # Y_j = Σ_i C_ij X_i
    return np.fft.irfft(mixed, n=n_fft, axis=-1)[:, pad_samples:pad_samples + n]


def synthesize_ambisonic_rir(arrivals: Arrivals, histogram: EnergyHistogram | None,
                             order: int, sample_rate_hz: float, rng: np.random.Generator, *,
                             max_length_s: float = 2.0, bands_hz: tuple[float, ...] = (),
                             taps: int = DEFAULT_TAPS, yaw_deg: float = 0.0,
                             pitch_deg: float = 0.0) -> np.ndarray:
    """Ambisonic RIR, ACN/SN3D, ``((order + 1)², n_samples)``, in the microphone's frame
    (the late part is diffuse: the same in any frame)."""
    bank = OctaveFilterBank(sample_rate_hz, bands_hz)
    n = rir_length_samples(arrivals, histogram, sample_rate_hz, max_length_s, taps,
                           bank.padding() // 4)
    out = ambisonic_early(arrivals, order, bank, n, taps, yaw_deg=yaw_deg,
                          pitch_deg=pitch_deg)
    for ch in range(out.shape[0]):
        if histogram is not None:
            degree = math.isqrt(ch)
            out[ch] += synthesize_late(histogram, bank, n, rng) / math.sqrt(2 * degree + 1)
    return out
