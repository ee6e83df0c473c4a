"""Isotropic (diffuse) background fields at any receiver (library level, issue 30).

A diffuse field is the sum of uncorrelated plane waves from every direction alike: all
directions of the sphere (*spherically isotropic*) or of the horizontal plane (*cylindrically
isotropic*). Its second-order statistics at a receiver are its cross-spectral matrix

    ``Φ(f) = E_Ω[ H(f, Ω) H(f, Ω)ᴴ ]``,

``H(f, Ω)`` the receiver's channels' responses to a unit plane wave from ``Ω``. Omni capsules
``d`` apart get ``Φ_ij = sin(kd)/(kd)`` (``J₀(k d_h)`` in the cylindrical field), ambisonic
SN3D channels ``Φ = diag(1/(2l + 1))``, the ears of a head its diffuse-field interaural
coherence (:mod:`sonicspec.acoustics.theory` has each exactly).

How a background is rendered:

* ``Φ`` is computed from the receiver's own per-direction responses (the caller gives them,
  ``(N, M, taps)``: :func:`sonicspec.acoustics.engine.direction_responses` renders them
  through the receiver's early-part synthesis, so whatever pattern a capsule has applies),
  averaged over ``N`` uniform directions (:func:`isotropic_directions`, as many as the
  receiver's aperture needs: :func:`direction_count`), on the STFT grid.
* The one background signal ``s`` is turned into ``M`` mutually uncorrelated copies with the
  same short-time spectrum: its STFT ``S(t, f)`` times independent uniform random phases
  ``u_i(t, f)`` (frames of about 32 ms). Then per bin, Habets' coherence shaping
  (Habets, Cohen & Gannot 2008, JASA 124(5)): ``Y(t, f) = C(f) u(t, f) S(t, f)`` with
  ``C = Φ^½`` (the Hermitian square root: unique, smooth in ``f``, valid where ``Φ`` is
  singular, as at low frequency where every capsule hears the same), so
  ``E[Y Yᴴ] = |S|² Φ``: exactly the diffuse field's cross-spectra, with ``M`` signals
  instead of one per direction. An omnidirectional capsule hears the background at the
  level of ``s`` itself.

Why random phases and not different segments of the clip, or decorrelation filters: shifted
segments of a tonal or stationary sound stay coherent (a hum shifted is the same hum), and they
put each sound event at another time in each channel; fixed decorrelation filters are linear
time-invariant, so two filtered copies of one signal are fully coherent when analysed with
windows longer than the filters. Phases drawn anew in every frame decorrelate any signal, keep
every channel's envelope that of the clip (events happen at once in all channels, as in a
room), and cost one STFT. The price: a transient is smeared over one frame (about 32 ms), as a
diffuse field's many reflections would smear it. Why not one signal per plane wave: ``N``
uncorrelated copies (thousands, for the 20 cm aperture of a small array at 16 kHz) cost ``N``
STFTs and still only approximate ``Φ`` by their finite sum; shaping ``M`` copies is exact for
any ``N``. A one-channel receiver needs no copies: it is ``s`` through ``√Φ`` (zero phase).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from sonicspec.errors import AcousticsError

IsotropicField = Literal["spherical", "cylindrical"]

#: STFT frame of the random-phase copies, seconds (rounded to a power of two in samples).
FRAME_S = 0.032
#: Frames per block of the mixing (bounds the memory: channels × block × bins).
_BLOCK_FRAMES = 256


def isotropic_directions(field: IsotropicField, n: int) -> np.ndarray:
    """``n`` directions ``(n, 3)`` whose equal-weight mean is the average over the field:
    the Fibonacci lattice of the sphere (``spherical``) or ``n`` equally spaced horizontal
    directions (``cylindrical``; z up)."""
    from sonicspec.acoustics.directions import fibonacci_sphere

    if n < 1:
        raise AcousticsError(f"directions: expected n >= 1, got {n!r}")
    if field == "spherical":
        return fibonacci_sphere(n)
    if field == "cylindrical":
        phi = 2 * math.pi * (np.arange(n) + 0.5) / n
        return np.column_stack([np.cos(phi), np.sin(phi), np.zeros(n)])
    raise AcousticsError(f"field: expected 'spherical' or 'cylindrical', got {field!r}")


def direction_count(field: IsotropicField, aperture_m: float, sample_rate_hz: float,
                    speed_of_sound_m_s: float) -> int:
    """Directions enough to average plane waves over a receiver ``aperture_m`` across (the
    largest distance between two of its channels' acoustic centres) up to Nyquist: the
    integrand ``e^{jk d·Ω}`` holds spherical harmonics up to degree ``kd``, so about
    ``2 (kd + 8)²`` Fibonacci points (1,024–16,384) or ``4 (kd + 8)`` horizontal ones
    (256–4,096)."""
    kd = math.pi * sample_rate_hz / speed_of_sound_m_s * max(0.0, float(aperture_m))
    if field == "spherical":
        return int(min(16384, max(1024, math.ceil(2 * (kd + 8) ** 2))))
    return int(min(4096, max(256, math.ceil(4 * (kd + 8)))))


def frame_samples(sample_rate_hz: float) -> int:
    """The STFT frame of :func:`render_isotropic`: the power of two nearest ``FRAME_S``."""
    return 1 << max(4, round(math.log2(FRAME_S * sample_rate_hz)))


def cross_spectral_matrix(responses: np.ndarray, n_fft: int) -> np.ndarray:
    """``Φ(f) = mean_n H_n(f) H_n(f)ᴴ``, ``(n_fft // 2 + 1, M, M)`` complex, of per-direction
    impulse responses ``(N, M, taps)`` (each wholly inside its ``taps``; a delay common to
    all channels cancels). ``taps`` longer than ``n_fft``: computed on their own grid and
    read at ``n_fft``'s bins (both powers of two)."""
    h = np.asarray(responses, dtype=np.float64)
    if h.ndim != 3 or h.shape[0] == 0:
        raise AcousticsError(f"responses: expected (directions, channels, taps), got {h.shape}")
    grid = max(n_fft, 1 << math.ceil(math.log2(h.shape[2])))
    if grid % n_fft:
        raise AcousticsError(f"n_fft: expected a power of two, got {n_fft!r}")
    step = grid // n_fft
    m = h.shape[1]
    phi = np.zeros((n_fft // 2 + 1, m, m), dtype=np.complex128)
    for start in range(0, len(h), 512):
        spec = np.fft.rfft(h[start:start + 512], grid, axis=-1)[:, :, ::step]  # (n, M, F)
        spec = np.ascontiguousarray(np.transpose(spec, (2, 1, 0)))  # (F, M, n)
        phi += spec @ np.conj(np.swapaxes(spec, 1, 2))
    return phi / len(h)


def hermitian_root(phi: np.ndarray) -> np.ndarray:
    """``C = V √Λ Vᴴ`` of each Hermitian ``Φ = V Λ Vᴴ`` ``(F, M, M)`` (negative round-off
    eigenvalues taken as zero): ``C Cᴴ = Φ``."""
    p = np.asarray(phi)
    p = (p + np.conj(np.swapaxes(p, -1, -2))) / 2
    lam, vec = np.linalg.eigh(p)
    return (vec * np.sqrt(np.maximum(lam, 0.0))[..., None, :]) @ np.conj(np.swapaxes(vec, -1, -2))


def _window(n: int) -> np.ndarray:
    """Square-root periodic Hann: analysis and synthesis windows whose product overlap-adds
    to one at half-frame hops."""
    return np.sqrt(0.5 - 0.5 * np.cos(2 * math.pi * np.arange(n) / n))


def render_isotropic(signal: np.ndarray, root: np.ndarray, rng: np.random.Generator
                     ) -> np.ndarray:
    """The background ``signal`` ``(n,)`` heard as a diffuse field, ``(M, n)``.

    ``root``: ``Φ^½`` per bin of the STFT frame (:func:`hermitian_root` of
    :func:`cross_spectral_matrix` at ``n_fft`` = the frame, ``(frame // 2 + 1, M, M)``).
    Frames hop by half their length, square-root Hann windows. ``M > 1``: every copy's
    phases are drawn from ``rng`` (uniform, independent per copy, frame and bin), and the
    output is scaled so that its expected power spectrum is ``Φ_mm`` times the signal's
    (a random-phase frame spreads its windowed energy over the whole frame). ``M = 1``: the
    signal through ``√Φ`` without drawing.
    """
    x = np.asarray(signal, dtype=np.float64)
    c = np.asarray(root)
    if x.ndim != 1:
        raise AcousticsError(f"signal: expected one channel (n,), got shape {x.shape}")
    if c.ndim != 3 or c.shape[1] != c.shape[2] or c.shape[0] < 2:
        raise AcousticsError(f"root: expected (bins, M, M), got {c.shape}")
    n_bins, m = c.shape[0], c.shape[1]
    frame = 2 * (n_bins - 1)
    hop = frame // 2
    n = x.size
    blocks = -(-n // hop) + 2  # whole hops covering [-hop, n + hop)
    padded = np.zeros(blocks * hop)
    padded[hop:hop + n] = x
    win = _window(frame)
    n_frames = blocks - 1
    out = np.zeros((m, blocks, hop))
    if m > 1:
        # E|random-phase frame|² per sample = Σ w_a² x² / frame; Σ_k w_s² = 1.
        scale = math.sqrt(frame / float(np.sum(win**2)))
        c = c.astype(np.complex64)
    for k0 in range(0, n_frames, _BLOCK_FRAMES):
        k1 = min(n_frames, k0 + _BLOCK_FRAMES)
        idx = (np.arange(k0, k1) * hop)[:, None] + np.arange(frame)[None, :]
        spec = np.fft.rfft(padded[idx] * win, axis=-1)  # (T, F)
        if m > 1:
            angle = (2 * math.pi) * rng.random((n_bins, m, k1 - k0), dtype=np.float32)
            u = np.cos(angle) + 1j * np.sin(angle)  # complex64, (F, M, T)
            # DC and Nyquist stay real: a random sign.
            u[[0, -1]] = np.where(angle[[0, -1]] < math.pi, 1.0, -1.0)
            # Y_m(t, f) = S(t, f) Σ_i C_mi(f) u_i(t, f) (einsum: numpy's batched matmul of
            # small complex matrices is 50x slower).
            mixed = np.einsum("fmi,fit->mtf", c, u)  # (M, T, F)
            y = mixed * (scale * spec)[None, :, :]
        else:
            y = (c[:, 0, 0].real[None, :] * spec)[None, :, :]
        frames = np.fft.irfft(y, frame, axis=-1) * win  # (M, T, frame)
        out[:, k0:k1] += frames[:, :, :hop]
        out[:, k0 + 1:k1 + 1] += frames[:, :, hop:]
    return out.reshape(m, -1)[:, hop:hop + n]


def isotropic_roots(responses: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """``Φ^½`` on :func:`render_isotropic`'s frame for per-direction ``responses``
    ``(N, M, taps)`` at ``sample_rate_hz``: the mixing matrices of a receiver's diffuse
    field."""
    return hermitian_root(cross_spectral_matrix(responses, frame_samples(sample_rate_hz)))
