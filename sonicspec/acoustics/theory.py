"""Closed forms of diffuse-field room acoustics, used as oracles and sanity checks.

* Sabine and Eyring reverberation time with air absorption:
  ``T = 24 ln(10) V / (c (A + 4 m V))`` with ``A = S ᾱ`` (Sabine) or ``A = −S ln(1 − ᾱ)``
  (Eyring), ``m`` the air's energy attenuation (1/m).
* Kuttruff's correction of Eyring for the spread of free path lengths:
  ``A = −S ln(1 − ᾱ) (1 + γ²/2 · ln(1 − ᾱ))``, ``γ²`` the relative variance of the path
  lengths between reflections (Kuttruff, *Room Acoustics*, §5.5); for a shoebox γ² is found
  here by sampling diffusely reflected paths between its walls (:func:`shoebox_free_paths`,
  no ray tracer involved).
* The geometric-acoustics T30 of a shoebox whose walls reflect specularly or, with
  probability ``s``, in a Lambert direction (:func:`shoebox_decay_t60`): the total sound
  energy in the room, followed by an analytic walk between the six planes (no ray tracer, no
  receiver). Eyring and Kuttruff assume a diffuse field; with ``s < 1`` the field keeps
  specular memory and this walk is the reference.
* Mean free path ``4V/S``; critical distance ``√(A / 16π)`` (directivity 1).
* Barron & Lee (1988) revised theory: relative to the direct energy ``100/r²``, the reflected
  energy arriving after time ``t`` (after the direct sound at distance r) is
  ``(31200 T / V) e^{−0.04 r / T} e^{−13.82 t / T}``; the constants 0.04 = 13.82 / c and
  31200 = 1600 π c / (24 ln 10) follow from c, so they are computed from ``c`` here.
* The exact moving point source and receiver (:func:`moving_point_source`): every emitted
  sample arrives at its retarded time with 1/(4π r), Doppler included; with
  :func:`shoebox_moving_images`, the exact time-varying image-source sum of a shoebox. The
  reference the moving-source renderer is measured against (issue 18).
* A moving, turning directional source in free field and above one reflecting plane, heard
  by a static or moving receiver (:func:`directional_source_with_plane`): the same sums with
  the pattern's gain applied at each emission time for the direction each path leaves in,
  towards where the receiver (or its mirror image) is when that emission reaches it (issue 30).
* The infinite rigid wedge and thin half-plane (:class:`Wedge`): the exact diffracted field of
  a point source, Biot–Tolstoy–Medwin in time (:func:`wedge_diffraction_ir`) and its Fourier
  transform, Macdonald's solution (:func:`wedge_diffraction_spectrum`), with the geometric field
  and Keller's asymptote. The reference edge diffraction is measured against (issue 19).
* First-order microphone capsules (:func:`first_order_gain`): a plane wave from angle ``θ`` off
  the axis is heard with ``a + (1 − a) cos θ``, exactly (an ideal pressure/pressure-gradient
  capsule, the same at every frequency); a cardioid (``a = ½``) is silent at 180°, a
  figure-eight (``a = 0``) at 90°. The diffuse field such capsules hear
  (:func:`diffuse_cross_spectrum_quadrature`): the average over the sphere of
  ``g_i g_j e^{jk d·(p_i − p_j)}`` by Gauss–Legendre quadrature in ``cos θ`` and the trapezoid
  rule in azimuth (exact for the band-limited integrand as the orders grow), the reference the
  closed form of :mod:`~sonicspec.acoustics.receivers.capsules` is measured against (issue 30).
* Isotropic (diffuse) noise fields (issue 30): the coherence of two omnidirectional points,
  ``sin(kd)/(kd)`` in a spherically isotropic field and ``J₀(k d_h)`` in a cylindrically
  isotropic one, and the interaural coherence of the Brown–Duda head from its own transfer
  functions integrated over directions (:func:`brown_duda_diffuse_coherence`). The references
  the diffuse background is measured against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S

SIXTY_DB = 6 * math.log(10)  # 13.8155: ln(10⁶), the decay exponent for 60 dB


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise AcousticsError(f"{name}: expected > 0, got {value!r}")
    return float(value)


def sabine_t60(volume_m3: float, surface_m2: float, mean_absorption, air_m_per_m=0.0,
               speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """Sabine reverberation time, seconds (per band if arrays are given)."""
    v, s = _positive("volume_m3", volume_m3), _positive("surface_m2", surface_m2)
    a = np.asarray(mean_absorption, dtype=np.float64) * s
    m = np.asarray(air_m_per_m, dtype=np.float64)
    return 4 * SIXTY_DB * v / (speed_of_sound_m_s * (a + 4 * m * v))


def eyring_t60(volume_m3: float, surface_m2: float, mean_absorption, air_m_per_m=0.0,
               speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """Eyring reverberation time, seconds (per band if arrays are given)."""
    v, s = _positive("volume_m3", volume_m3), _positive("surface_m2", surface_m2)
    alpha = np.asarray(mean_absorption, dtype=np.float64)
    if np.any((alpha < 0) | (alpha >= 1)):
        raise AcousticsError(f"mean_absorption: expected values in [0, 1), got {alpha}")
    m = np.asarray(air_m_per_m, dtype=np.float64)
    return 4 * SIXTY_DB * v / (speed_of_sound_m_s * (-s * np.log1p(-alpha) + 4 * m * v))


def kuttruff_t60(volume_m3: float, surface_m2: float, mean_absorption, path_variance: float,
                 air_m_per_m=0.0, speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
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


def _lambert_directions(axis: np.ndarray, toward_plus: np.ndarray, rng: np.random.Generator
                        ) -> np.ndarray:
    """Cosine-weighted unit vectors leaving an axis-aligned wall: ``axis`` the wall's normal
    axis per path, ``toward_plus`` whether they point into +axis."""
    n = len(axis)
    rows = np.arange(n)
    u1, u2 = rng.random(n), rng.random(n)
    direction = np.empty((n, 3))
    direction[rows, (axis + 1) % 3] = np.sqrt(u1) * np.cos(2 * math.pi * u2)
    direction[rows, (axis + 2) % 3] = np.sqrt(u1) * np.sin(2 * math.pi * u2)
    direction[rows, axis] = np.sqrt(1.0 - u1) * np.where(toward_plus, 1.0, -1.0)
    return direction


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
    direction = _lambert_directions(axis, far_side == 0, rng)
    with np.errstate(divide="ignore", invalid="ignore"):
        to_wall = np.where(direction > 0, (size - start) / direction,
                           np.where(direction < 0, -start / direction, np.inf))
    to_wall[rows, axis] = np.where(direction[rows, axis] != 0, to_wall[rows, axis], np.inf)
    return to_wall.min(axis=1)


def shoebox_decay_t60(size_m, source_m, absorption, scattering: float, air_m_per_m=0.0,
                      speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S, n_paths: int = 40_000,
                      seed: int = 0) -> np.ndarray:
    """ISO 3382-1 T30 of the total sound energy in a shoebox, seconds (per band if
    ``absorption``/``air_m_per_m`` are arrays): Schroeder's backward integral of the energy
    still in the room, regression from −5 to −35 dB — what a receiver's T30 converges to.

    Energy particles leave ``source_m`` uniformly over the sphere; at each wall they keep
    ``1 − α`` of their energy and leave in a Lambert direction with probability
    ``scattering``, specularly otherwise — the reflection law of a stochastic ray tracer,
    walked here analytically between the six planes. Each particle makes as many reflections
    as bring it below 10⁻⁶ in every band; air absorption multiplies the energy by
    ``exp(−m c t)``. With ``scattering < 1`` the decay is a blend of exponentials (the field
    keeps specular memory), which the backward integral weights towards the slow ones, as it
    does for a measured or traced RIR."""
    size = np.array([_positive(f"size_m[{i}]", x) for i, x in enumerate(size_m)])
    if size.shape != (3,):
        raise AcousticsError(f"size_m: expected 3 lengths, got {size.shape}")
    source = np.asarray(source_m, dtype=np.float64)
    if source.shape != (3,) or not np.all((source > 0) & (source < size)):
        raise AcousticsError(f"source_m: expected a point inside the room, got {source_m!r}")
    alpha = np.atleast_1d(np.asarray(absorption, dtype=np.float64))
    if alpha.ndim != 1 or np.any((alpha <= 0) | (alpha >= 1)):
        raise AcousticsError(f"absorption: expected values in (0, 1), got {absorption!r}")
    if not 0 <= scattering <= 1:
        raise AcousticsError(f"scattering: expected a value in [0, 1], got {scattering!r}")
    try:
        air = np.broadcast_to(np.asarray(air_m_per_m, dtype=np.float64), alpha.shape)
    except ValueError:
        raise AcousticsError(f"air_m_per_m: expected one value per band of absorption "
                             f"({len(alpha)}), got {air_m_per_m!r}") from None
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    if not (isinstance(n_paths, int | np.integer) and n_paths >= 100):
        raise AcousticsError(f"n_paths: expected an integer >= 100, got {n_paths!r}")
    rng = np.random.default_rng(seed)
    rows = np.arange(n_paths)
    position = np.tile(source, (n_paths, 1))
    direction = rng.normal(size=(n_paths, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    n_reflections = math.ceil(6 / -math.log10(1 - alpha.min()))
    surface = 2 * float(size[0] * size[1] + size[0] * size[2] + size[1] * size[2])
    bin_s = float(eyring_t60(float(np.prod(size)), surface, alpha.min())) / 2000
    elapsed = np.zeros(n_paths)
    reflection_counts = []  # per reflection, how many particles reach their wall in each bin
    for _ in range(n_reflections):
        with np.errstate(divide="ignore", invalid="ignore"):
            to_wall = np.where(direction > 0, (size - position) / direction,
                               np.where(direction < 0, -position / direction, np.inf))
        axis = to_wall.argmin(axis=1)
        length = to_wall[rows, axis]
        position += direction * length[:, None]
        elapsed += length / c
        reflection_counts.append(np.bincount((elapsed / bin_s).astype(np.int64)))
        specular = direction.copy()
        specular[rows, axis] *= -1
        scattered = _lambert_directions(axis, specular[rows, axis] > 0, rng)
        direction = np.where((rng.random(n_paths) < scattering)[:, None], scattered, specular)
    n_bins = max(len(counts) for counts in reflection_counts)
    times = np.arange(n_bins) * bin_s
    t30 = np.empty(alpha.shape)
    for b, a in enumerate(alpha):
        lost = np.zeros(n_bins)
        for k, counts in enumerate(reflection_counts):
            # the energy lost at reflection k; the last one takes all that is left
            share = a * (1 - a) ** k if k < n_reflections - 1 else (1 - a) ** k
            lost[:len(counts)] += counts * share
        remaining = np.maximum(1.0 - np.cumsum(lost) / n_paths, 0.0)
        energy = remaining * np.exp(-air[b] * c * times)
        decay = np.cumsum(energy[::-1])[::-1]
        with np.errstate(divide="ignore"):
            level = 10 * np.log10(decay / decay[0])
        fit = (level <= -5.0) & (level >= -35.0)
        t30[b] = -60.0 / np.polyfit(times[fit], level[fit], 1)[0]
    return t30 if np.ndim(absorption) or np.ndim(air_m_per_m) else t30[0]


def mean_free_path_m(volume_m3: float, surface_m2: float) -> float:
    return 4 * _positive("volume_m3", volume_m3) / _positive("surface_m2", surface_m2)


def critical_distance_m(volume_m3: float, t60_s: float,
                        speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> float:
    """Distance where direct and reverberant energy are equal: √(A/16π), A from Sabine."""
    v, t = _positive("volume_m3", volume_m3), _positive("t60_s", t60_s)
    area = 4 * SIXTY_DB * v / (speed_of_sound_m_s * t)
    return math.sqrt(area / (16 * math.pi))


def barron_reflected_energy(distance_m: float, volume_m3: float, t60_s: float, after_s: float,
                            speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> float:
    """Reflected energy arriving ``after_s`` after the direct sound, relative units (Barron)."""
    r, v, t = (_positive("distance_m", distance_m), _positive("volume_m3", volume_m3),
               _positive("t60_s", t60_s))
    # Diffuse energy relative to a direct 100/r²: 100 · 16π / A with the Sabine area
    # A = 24 ln(10) V / (c T); for c = 343 m/s this is Barron's 31200 T / V.
    total = 1600 * math.pi * speed_of_sound_m_s * t / (4 * SIXTY_DB * v)
    return total * math.exp(-SIXTY_DB * r / (speed_of_sound_m_s * t)) * math.exp(
        -SIXTY_DB * after_s / t)


def barron_clarity_db(distance_m: float, volume_m3: float, t60_s: float, split_s: float = 0.05,
                      speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> float:
    """C50 (``split_s`` = 0.05) or C80 (0.08) by Barron's revised theory, dB."""
    direct = 100.0 / _positive("distance_m", distance_m) ** 2
    all_reflected = barron_reflected_energy(distance_m, volume_m3, t60_s, 0.0,
                                            speed_of_sound_m_s)
    late = barron_reflected_energy(distance_m, volume_m3, t60_s, split_s, speed_of_sound_m_s)
    return 10 * math.log10((direct + all_reflected - late) / late)


# --- moving point sources and receivers: the exact solution ---------------------------------
#
# A point source of strength s(t) at x_s(t) and a receiver at x_r(t): the sound emitted at t_e
# reaches the receiver at the t_a solving  c (t_a − t_e) = |x_s(t_e) − x_r(t_a)|,  with
# amplitude 1 / (4π r), r = c (t_a − t_e). For sampled signals (issue 18's definition):
#
#     y(t) = Σ_k s(k) · g_k / (4π r_k) · δ(t − t_a,k),   t_e,k = k / fs,
#
# each emitted sample a Dirac at its own arrival time, g_k a path gain (a reflection
# coefficient product for an image source). Doppler shift, level and delay follow from the
# geometry alone. The arrivals' density carries the Doppler factor dt_e/dt_a into the level:
# 1/(1 − v_r/c) for a source moving at radial speed v_r towards the receiver, 1 + v_r/c for a
# receiver moving towards the source (tested). Other source models give other powers of it
# (a monopole of mass flow: the square); at walking speed (1.5 m/s) it is 0.4 %, and it keeps
# a moving source and a moving receiver reciprocal to first order in v/c.
#
# The Diracs are rendered band-limited: a Kaiser-windowed sinc centred on each arrival (±32
# samples, β = 9), which reproduces a static source's fractional delay to within −80 dB for
# signals below 0.8 × Nyquist (test). It is slow (O(samples × 64)) and meant as a reference,
# not a renderer.

FRACTIONAL_DELAY_HALF_WIDTH = 32
FRACTIONAL_DELAY_KAISER_BETA = 9.0


def _track(points, n: int, name: str) -> np.ndarray:
    """``(n, 3)`` positions from one point or a per-sample trajectory."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape == (3,):
        return np.broadcast_to(p, (n, 3))
    if p.ndim != 2 or p.shape[1] != 3 or len(p) != n or not np.all(np.isfinite(p)):
        raise AcousticsError(f"{name}: expected a point (3,) or finite positions ({n}, 3), "
                             f"got shape {p.shape}")
    return p


def moving_arrival_times(source_m, receiver_m, n_samples: int, sample_rate_hz: float,
                         speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Arrival time (seconds) and path length (m) of every emitted sample ``k``.

    ``source_m``: a point or ``(n_samples, 3)`` positions at the emission times ``k / fs``.
    ``receiver_m``: a point or ``(m, 3)`` positions at the times ``j / fs`` (linearly
    interpolated between them, held beyond). The retarded-time equation is solved by fixed-point
    iteration, a contraction with factor ``|v_receiver| / c``.
    """
    fs = _positive("sample_rate_hz", sample_rate_hz)
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    src = _track(source_m, n_samples, "source_m")
    t_e = np.arange(n_samples) / fs
    rcv = np.asarray(receiver_m, dtype=np.float64)
    if rcv.shape == (3,):
        r = np.linalg.norm(src - rcv, axis=1)
        return t_e + r / c, r
    rcv = _track(rcv, len(rcv) if rcv.ndim == 2 and len(rcv) else -1, "receiver_m")

    def receiver_at(t: np.ndarray) -> np.ndarray:
        return _receiver_at(rcv, fs, t)

    t_a = t_e + np.linalg.norm(src - receiver_at(t_e), axis=1) / c
    for _ in range(50):
        new = t_e + np.linalg.norm(src - receiver_at(t_a), axis=1) / c
        done = np.max(np.abs(new - t_a)) < 1e-12
        t_a = new
        if done:
            break
    else:
        raise AcousticsError("receiver_m: the retarded time did not converge (does the "
                             "receiver move near the speed of sound?)")
    return t_a, c * (t_a - t_e)


def _receiver_at(receiver: np.ndarray, fs: float, t: np.ndarray) -> np.ndarray:
    """A receiver given at the times ``j / fs`` (``(m, 3)``) read at times ``t`` (seconds):
    linear between them, held beyond."""
    grid = np.arange(len(receiver)) / fs
    return np.stack([np.interp(t, grid, receiver[:, i]) for i in range(3)], axis=1)


def windowed_sinc(x: np.ndarray, half_width: int = FRACTIONAL_DELAY_HALF_WIDTH,
                  beta: float = FRACTIONAL_DELAY_KAISER_BETA) -> np.ndarray:
    """The band-limited unit impulse at offset ``x`` (samples): Kaiser-windowed sinc."""
    x = np.asarray(x, dtype=np.float64)
    inside = np.abs(x) < half_width
    w = np.i0(beta * np.sqrt(np.clip(1.0 - (x / half_width) ** 2, 0.0, None))) / np.i0(beta)
    return np.where(inside, np.sinc(x) * w, 0.0)


def moving_point_source(dry, source_m, receiver_m, sample_rate_hz: float, *,
                        speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S, gain=1.0,
                        n_out: int | None = None) -> np.ndarray:
    """The exact pressure at a (moving) receiver of a (moving) point source, ``(n_out,)``.

    Parameters
    ----------
    dry : (n,) float
        Source signal, one value per emission time ``k / fs``; a static source at distance
        ``r`` gives ``dry / (4π r)`` delayed by ``r / c``.
    source_m : (3,) or (n, 3) float
        Source position, metres, at each emission time.
    receiver_m : (3,) or (m, 3) float
        Receiver position, metres, at each output sample time (interpolated between them).
    sample_rate_hz : float
        Rate of ``dry`` and of the output.
    speed_of_sound_m_s : float
        Speed of sound.
    gain : float or (n,) float
        Path gain per emitted sample (e.g. the reflection coefficients of an image source).
    n_out : int, optional
        Output length; default: long enough for the last arrival.

    Returns
    -------
    (n_out,) float
        ``Σ_k dry[k] · gain[k] / (4π r_k) · sinc_w(n − fs · t_a,k)``; see the section comment.
    """
    s = np.asarray(dry, dtype=np.float64)
    if s.ndim != 1:
        raise AcousticsError(f"dry: expected a 1-D signal, got shape {s.shape}")
    fs = _positive("sample_rate_hz", sample_rate_hz)
    t_a, r = moving_arrival_times(source_m, receiver_m, len(s), fs, speed_of_sound_m_s)
    if np.any(r <= 0):
        raise AcousticsError("source_m: the source passes through the receiver (r = 0)")
    amp = s * np.broadcast_to(np.asarray(gain, dtype=np.float64), s.shape) / (4 * np.pi * r)
    tau = t_a * fs
    w = FRACTIONAL_DELAY_HALF_WIDTH
    if n_out is None:
        n_out = int(np.ceil(tau.max())) + w + 1 if len(s) else 0
    out = np.zeros(n_out)
    base = np.floor(tau).astype(np.int64)
    for offset in range(-w + 1, w + 1):  # one tap of every arrival per pass: bounded memory
        idx = base + offset
        keep = (idx >= 0) & (idx < n_out) & (amp != 0)
        np.add.at(out, idx[keep], amp[keep] * windowed_sinc(idx[keep] - tau[keep]))
    return out


def _mirror(points: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Points (or, with ``point`` 0, vectors) mirrored in the plane through ``point`` with
    unit ``normal``."""
    return points - 2.0 * ((points - point) @ normal)[:, None] * normal[None, :]


def directional_source_with_plane(dry, source_m, yaw_deg, receiver_m, sample_rate_hz: float,
                                  gain, *, plane_point_m=None, plane_normal=None,
                                  reflection: float = 1.0,
                                  speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                                  n_out: int | None = None) -> np.ndarray:
    """The exact pressure at a (moving) receiver of a moving, *turning* directional point
    source, in free field or above one reflecting plane, ``(n_out,)``.

    Each emitted sample leaves with the pattern's gain for the direction it leaves in, in the
    source's frame at that emission time: towards where the receiver is when that sample
    reaches it (its retarded-time reception, :func:`moving_arrival_times`) for the direct
    sound; for the plane's reflection towards the reflection point, i.e. towards the
    receiver's mirror image at that reception time (the mirror of the direction from the
    source's image to the receiver then). Both are :func:`moving_point_source` sums
    (retarded time, 1/(4πr), Doppler) with that gain per emitted sample; the reflection is
    the source's image with pressure factor ``reflection``.

    Parameters
    ----------
    dry : (n,) float
        Source signal at the emission times ``k / fs``.
    source_m : (3,) or (n, 3) float
        Source position at each emission time, metres.
    yaw_deg : float or (n,) float
        Where the source faces at each emission time: degrees counter-clockwise from +x
        seen from above (the front is horizontal).
    receiver_m : (3,) or (m, 3) float
        The receiver, metres: a point, or its position at each output sample time ``j / fs``
        (linear between them, held beyond), as :func:`moving_point_source` takes it.
    sample_rate_hz : float
    gain : callable
        ``gain(local) -> (n,)``: the pattern's pressure gain for unit directions ``(n, 3)``
        in the source's frame (+x its front, +z up).
    plane_point_m, plane_normal : (3,) float, optional
        The reflecting plane (a point on it, its normal); none: free field.
    reflection : float
        The plane's pressure reflection factor.
    speed_of_sound_m_s : float
    n_out : int, optional
        Output length; default: long enough for the last arrival.
    """
    s = np.asarray(dry, dtype=np.float64)
    fs = _positive("sample_rate_hz", sample_rate_hz)
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    src = _track(source_m, len(s), "source_m")
    rcv = np.asarray(receiver_m, dtype=np.float64)
    if rcv.shape != (3,) and (rcv.ndim != 2 or rcv.shape[1] != 3 or not len(rcv)
                              or not np.all(np.isfinite(rcv))):
        raise AcousticsError(f"receiver_m: expected a point (3,) or finite positions (m, 3) "
                             f"at the output sample times, got shape {rcv.shape}")
    yaw = np.radians(np.broadcast_to(np.asarray(yaw_deg, dtype=np.float64), s.shape))
    cos_y, sin_y = np.cos(yaw), np.sin(yaw)

    def gains(d: np.ndarray) -> np.ndarray:
        d = d / np.linalg.norm(d, axis=1)[:, None]
        local = np.stack([cos_y * d[:, 0] + sin_y * d[:, 1], -sin_y * d[:, 0] + cos_y * d[:, 1],
                          d[:, 2]], axis=1)
        return np.asarray(gain(local), dtype=np.float64).reshape(len(s))

    def heard_at(position: np.ndarray) -> np.ndarray:
        """Where the receiver is when each emission from ``position`` reaches it."""
        if rcv.shape == (3,):
            return rcv[None]
        t_a, _ = moving_arrival_times(position, rcv, len(s), fs, c)
        return _receiver_at(rcv, fs, t_a)

    paths = [(src, gains(heard_at(src) - src))]
    if plane_point_m is not None:
        p0 = np.asarray(plane_point_m, dtype=np.float64).reshape(3)
        nrm = np.asarray(plane_normal, dtype=np.float64).reshape(3)
        if not np.linalg.norm(nrm) > 0:
            raise AcousticsError(f"plane_normal: expected a non-zero vector, got {plane_normal!r}")
        nrm = nrm / np.linalg.norm(nrm)
        image = _mirror(src, p0, nrm)
        leaving = _mirror(heard_at(image) - image, np.zeros(3), nrm)  # mirrored back
        paths.append((image, reflection * gains(leaving)))
    if n_out is None:
        last = max(float(np.max(moving_arrival_times(p, rcv, len(s), fs, c)[0])) * fs
                   for p, _ in paths) if len(s) else 0.0
        n_out = int(np.ceil(last)) + FRACTIONAL_DELAY_HALF_WIDTH + 1
    out = np.zeros(n_out)
    for position, g in paths:
        out += moving_point_source(s, position, rcv, fs, speed_of_sound_m_s=c, gain=g,
                                   n_out=n_out)
    return out


def shoebox_moving_images(size_m, source_m, order: int) -> list[tuple[np.ndarray, int]]:
    """Image sources of a (moving) source in a shoebox ``[0, Lx] × [0, Ly] × [0, Lz]``.

    Returns ``(positions (n, 3), reflections)`` for every image up to ``order`` reflections
    (Allen & Berkley: per axis the image ``(1 − 2q) x + 2 m L`` has ``|m − q| + |m|``
    reflections), the source itself first. Each image moves as the mirror of the source.
    """
    size = np.asarray(size_m, dtype=np.float64)
    if size.shape != (3,) or np.any(size <= 0):
        raise AcousticsError(f"size_m: expected three positive lengths, got {size_m!r}")
    if not isinstance(order, int) or order < 0:
        raise AcousticsError(f"order: expected an integer >= 0, got {order!r}")
    src = np.atleast_2d(np.asarray(source_m, dtype=np.float64))
    # (m, q, reflections) along one axis; the same for all three.
    axis = [(m, q, abs(m - q) + abs(m)) for m in range(-order, order + 1) for q in (0, 1)
            if abs(m - q) + abs(m) <= order]
    images = []
    for mx, qx, nx in axis:
        for my, qy, ny in axis:
            for mz, qz, nz in axis:
                total = nx + ny + nz
                if total > order:
                    continue
                sign = 1 - 2 * np.array([qx, qy, qz])
                shift = 2 * np.array([mx, my, mz]) * size
                images.append((total, (src * sign + shift)))
    images.sort(key=lambda item: item[0])
    return [(pos, n) for n, pos in images]


# --- Edge diffraction: the infinite rigid wedge and the thin half-plane (issue 19) -----------
#
# A wedge is its edge (a point on it and the unit direction e) and its two rigid faces: face 0
# leaves the edge along the unit vector f0 (perpendicular to e); face 1 is face 0 turned by the
# *open* angle θ_w about e (right hand), so the air fills 0 ≤ θ ≤ θ_w in cylindrical
# coordinates (r, θ, z) about the edge. θ_w = 2π is a thin half-plane, 3π/2 the corner of a
# room's outside wall (a door jamb seen from the room it opens onto).
#
# The exact diffracted field of a point source is the Biot–Tolstoy solution in the form given
# by Medwin (1981) and Svensson, Fred & Vanderkooy (JASA 106, 1999), with ν = π/θ_w:
#
#     h(t) = −(c ν / 2π) · β(η) / (r_S r_R sinh η) · 1/(4π),  t > τ₀ = L/c,
#     cosh η = (c²t² − r_S² − r_R² − (z_R − z_S)²) / (2 r_S r_R),
#     β = Σ_{±,±} sin(ν φ) / (cosh νη − cos νφ),  φ = π ± θ_S ± θ_R,
#
# the last factor 1/(4π) making the free field δ(t − R/c)/(4πR), the engine's convention.
# L = √((r_S + r_R)² + (z_R − z_S)²) is the shortest path over the edge. Macdonald's (1915)
# frequency-domain solution is its Fourier transform; :func:`wedge_diffraction_spectrum` takes
# that transform numerically (a substitution t = τ₀ + s² removes the 1/√(t − τ₀) onset
# singularity; the tail is a Fourier integral done by QUADPACK's QAWF). At a zone boundary
# (φ = 0 or 2θ_w: the receiver on the shadow boundary of the direct sound or of a face's
# reflection) one term of β becomes a Lorentzian of width → 0 whose integral is exactly half
# the geometric wave that switches off: the total field is continuous. On the boundary itself
# the term is zero and the geometric wave counts half (:func:`wedge_geometric_field`).


@dataclass(frozen=True)
class Wedge:
    """An infinite rigid wedge: edge point and direction, face-0 direction, open angle (rad)."""

    point: np.ndarray
    edge: np.ndarray
    face0: np.ndarray
    open_angle: float

    def __post_init__(self) -> None:
        p = np.asarray(self.point, dtype=np.float64)
        e = np.asarray(self.edge, dtype=np.float64)
        f = np.asarray(self.face0, dtype=np.float64)
        for name, v in (("point", p), ("edge", e), ("face0", f)):
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise AcousticsError(f"Wedge.{name}: expected a finite 3-vector, got {v!r}")
        if np.linalg.norm(e) < 1e-12 or np.linalg.norm(f) < 1e-12:
            raise AcousticsError("Wedge: expected non-zero edge and face0 directions")
        e = e / np.linalg.norm(e)
        f = f - np.dot(f, e) * e
        if np.linalg.norm(f) < 1e-9:
            raise AcousticsError("Wedge.face0: expected a direction not along the edge")
        if not (math.pi < self.open_angle <= 2 * math.pi):
            raise AcousticsError(f"Wedge.open_angle: expected a value in (π, 2π] rad, got "
                                 f"{self.open_angle!r}")
        object.__setattr__(self, "point", p)
        object.__setattr__(self, "edge", e)
        object.__setattr__(self, "face0", f / np.linalg.norm(f))

    @staticmethod
    def half_plane(point, edge, face0) -> Wedge:
        """A thin rigid screen: the half-plane leaving ``point`` along ``face0``."""
        return Wedge(np.asarray(point, float), np.asarray(edge, float),
                     np.asarray(face0, float), 2 * math.pi)

    @property
    def nu(self) -> float:
        """Wedge index ν = π / θ_w."""
        return math.pi / self.open_angle

    def at(self, r: float, theta_deg: float, z: float) -> np.ndarray:
        """The point at cylindrical coordinates ``(r, θ, z)`` about the edge (θ in degrees
        from face 0 into the air): the inverse of :meth:`cylindrical`."""
        th = math.radians(theta_deg)
        across = np.cross(self.edge, self.face0)
        return self.point + r * (math.cos(th) * self.face0 + math.sin(th) * across) + z * self.edge

    def cylindrical(self, x) -> tuple[float, float, float]:
        """``(r, θ, z)`` of a point about the edge; θ measured from face 0 into the air."""
        d = np.asarray(x, dtype=np.float64) - self.point
        z = float(np.dot(d, self.edge))
        radial = d - z * self.edge
        r = float(np.linalg.norm(radial))
        if r < 1e-9:
            raise AcousticsError(f"point {np.asarray(x).tolist()}: on the wedge's edge")
        theta = math.atan2(float(np.dot(np.cross(self.face0, radial), self.edge)),
                           float(np.dot(self.face0, radial))) % (2 * math.pi)
        if theta > self.open_angle + 1e-12:
            raise AcousticsError(f"point {np.asarray(x).tolist()}: inside the wedge "
                                 f"(θ = {theta:.4f} > θ_w = {self.open_angle:.4f})")
        return r, min(theta, self.open_angle), z


@dataclass(frozen=True)
class _EdgeGeometry:
    r_s: float
    r_r: float
    dz: float
    nu: float
    phis: tuple[float, float, float, float]

    @property
    def length_m(self) -> float:
        return math.hypot(self.r_s + self.r_r, self.dz)


def _edge_geometry(wedge: Wedge, source, receiver) -> _EdgeGeometry:
    r_s, th_s, z_s = wedge.cylindrical(source)
    r_r, th_r, z_r = wedge.cylindrical(receiver)
    phis = (math.pi + th_s + th_r, math.pi + th_s - th_r, math.pi - th_s + th_r,
            math.pi - th_s - th_r)
    return _EdgeGeometry(r_s, r_r, z_r - z_s, wedge.nu, phis)


def _btm_of_s(g: _EdgeGeometry, s: np.ndarray, c: float) -> np.ndarray:
    """``2 s · h(τ₀ + s²)``: the BTM response in the variable ``s = √(t − τ₀)`` (finite at 0)."""
    s = np.asarray(s, dtype=np.float64)
    tau0 = g.length_m / c
    x = c * c * s * s * (2 * tau0 + s * s) / (2 * g.r_s * g.r_r)  # cosh η − 1, without rounding
    sinh_eta = np.sqrt(x * (x + 2))
    eta = np.log1p(x + sinh_eta)
    nu = g.nu
    beta = np.zeros_like(s)
    for phi in g.phis:
        # cosh νη − cos νφ written as a sum of squares: exact near a zone boundary.
        half = math.sin(nu * phi / 2)
        if abs(half) < 1e-12:  # on the zone boundary: the term is 0 (see the section comment)
            continue
        den = 2 * np.sinh(nu * eta / 2) ** 2 + 2 * half**2
        beta += math.sin(nu * phi) / den
    # h = −c ν β / (8 π² r_S r_R sinh η); 2 s / sinh η stays finite as s → 0.
    ratio = np.where(s > 0, 2 * s / np.where(sinh_eta > 0, sinh_eta, 1.0),
                     2 * math.sqrt(g.r_s * g.r_r / (2 * c * c * tau0)))
    return -c * nu * beta * ratio / (8 * math.pi**2 * g.r_s * g.r_r)


def _btm_of_t(g: _EdgeGeometry, t: np.ndarray, c: float) -> np.ndarray:
    tau0 = g.length_m / c
    s = np.sqrt(np.maximum(np.asarray(t, dtype=np.float64) - tau0, 0.0))
    return np.where(s > 0, _btm_of_s(g, s, c) / np.where(s > 0, 2 * s, 1.0), 0.0)


def _boundary_widths(g: _EdgeGeometry, c: float) -> list[float]:
    """Widths in ``s`` of the Lorentzians of near-boundary terms (hints for the quadrature)."""
    tau0 = g.length_m / c
    a = c * math.sqrt(tau0 / (g.r_s * g.r_r))  # η ≈ √2 · a · s near the onset
    out = []
    for phi in g.phis:
        eps = abs(math.sin(g.nu * phi / 2))
        if 0 < eps < 0.3:
            out.append(2 * eps / (g.nu * a * math.sqrt(2)))
    return out


def wedge_diffraction_ir(wedge: Wedge, source_m, receiver_m, sample_rate_hz: float,
                         n_samples: int, speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
                         ) -> np.ndarray:
    """The exact diffracted impulse response, integrated over each sample, ``(n_samples,)``.

    Sample ``n`` holds ``∫ h(t) dt`` over ``[(n − ½)/fs, (n + ½)/fs)``: the response to a unit
    impulse whose free field is ``δ(t − R/c) / (4πR)``, so the direct sound of the same source
    would be one sample of height ``1 / (4πR)``. The onset singularity is integrated exactly
    (adaptive quadrature in ``s = √(t − τ₀)``), the rest by 8-point Gauss–Legendre per sample.
    """
    from scipy.integrate import quad

    fs = _positive("sample_rate_hz", sample_rate_hz)
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    g = _edge_geometry(wedge, source_m, receiver_m)
    tau0 = g.length_m / c
    edges_t = (np.arange(n_samples + 1) - 0.5) / fs
    out = np.zeros(n_samples)
    first = int(np.searchsorted(edges_t, tau0, side="right")) - 1
    if first >= n_samples:
        return out
    first = max(first, 0)
    s_edges = np.sqrt(np.maximum(edges_t - tau0, 0.0))
    widths = _boundary_widths(g, c)
    # Adaptive quadrature until the narrowest near-boundary Lorentzian has died down.
    reach = 20 * max(widths, default=0.0)
    n_exact = max(4, int(np.searchsorted(s_edges, reach)) - first)
    n_exact = min(n_exact, 400, n_samples - first)
    for k in range(first, first + n_exact):
        lo, hi = s_edges[k], s_edges[k + 1]
        pts = [w for w in widths if lo < w < hi] or None
        out[k] = quad(lambda s: float(_btm_of_s(g, np.array([s]), c)[0]), lo, hi,
                      points=pts, limit=400, epsabs=0, epsrel=1e-10)[0]
    rest = np.arange(first + n_exact, n_samples)
    if len(rest):
        nodes, weights = np.polynomial.legendre.leggauss(8)
        lo, hi = s_edges[rest], s_edges[rest + 1]
        s = 0.5 * (hi - lo)[:, None] * nodes[None, :] + 0.5 * (hi + lo)[:, None]
        vals = _btm_of_s(g, s.ravel(), c).reshape(s.shape)
        out[rest] = 0.5 * (hi - lo) * (vals @ weights)
    return out


def wedge_diffraction_spectrum(wedge: Wedge, source_m, receiver_m, frequencies_hz,
                               speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """The exact diffracted transfer function ``H(f) = ∫ h(t) e^{−j2πft} dt``, complex.

    Same normalisation as :func:`wedge_diffraction_ir` (free field ``e^{−jkR} / (4πR)``). The
    first few periods after the onset are integrated in ``s = √(t − τ₀)``, the tail by QAWF.
    """
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    g = _edge_geometry(wedge, source_m, receiver_m)
    widths = _boundary_widths(g, c)
    freqs = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
    return np.array([_spectrum_at(g, _positive("frequencies_hz", f), c, widths)
                     for f in freqs], dtype=np.complex128)


def _spectrum_at(g: _EdgeGeometry, f: float, c: float, widths: list[float]) -> complex:
    from scipy.integrate import quad

    tau0 = g.length_m / c
    w = 2 * math.pi * f
    span = 6.0 / f  # six periods after the onset in s, the rest as a Fourier tail
    s_max = math.sqrt(span)
    pts = [x for x in widths if x < s_max] or None

    def head(s: float, part) -> float:
        return float(_btm_of_s(g, np.array([s]), c)[0]) * part(w * s * s)

    re = quad(head, 0, s_max, args=(math.cos,), points=pts, limit=1500, epsabs=0,
              epsrel=1e-9)[0]
    im = -quad(head, 0, s_max, args=(math.sin,), points=pts, limit=1500, epsabs=0,
               epsrel=1e-9)[0]

    def tail(u: float) -> float:
        return float(_btm_of_t(g, np.array([tau0 + span + u]), c)[0])

    # ∫_{τ₀+T}^∞ h(t) e^{−jωt} dt with t = τ₀ + T + u (QAWF).
    tc = quad(tail, 0, np.inf, weight="cos", wvar=w, limlst=200)[0]
    ts = quad(tail, 0, np.inf, weight="sin", wvar=w, limlst=200)[0]
    return complex((re + 1j * im + (tc - 1j * ts) * np.exp(-1j * w * span))
                   * np.exp(-1j * w * tau0))


def wedge_geometric_field(wedge: Wedge, source_m, receiver_m, frequencies_hz,
                          speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """The geometric field (direct sound and the faces' specular reflections where they are
    visible; half on a zone boundary), complex, free field ``e^{−jkR} / (4πR)``."""
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    r_s, th_s, z_s = wedge.cylindrical(source_m)
    r_r, th_r, z_r = wedge.cylindrical(receiver_m)
    k = 2 * math.pi * np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64)) / c
    tw = wedge.open_angle
    out = np.zeros(len(k), dtype=np.complex128)
    # (image angle, visibility margin: > 0 visible, 0 on the boundary)
    for theta_img, margin in ((th_s, math.pi - abs(th_r - th_s)),
                              (-th_s, math.pi - (th_s + th_r)),
                              (2 * tw - th_s, (th_s + th_r) - (2 * tw - math.pi))):
        if margin < -1e-12:
            continue
        weight = 0.5 if abs(margin) <= 1e-12 else 1.0
        dist = math.sqrt(r_s**2 + r_r**2 - 2 * r_s * r_r * math.cos(th_r - theta_img)
                         + (z_r - z_s) ** 2)
        out += weight * np.exp(-1j * k * dist) / (4 * math.pi * dist)
    return out


def edge_path_length_m(wedge: Wedge, source_m, receiver_m) -> float:
    """Length of the shortest path from source to receiver over the edge, metres."""
    return _edge_geometry(wedge, source_m, receiver_m).length_m


def keller_wedge_diffraction(wedge: Wedge, source_m, receiver_m, frequencies_hz,
                             speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> np.ndarray:
    """Keller's geometrical theory of diffraction (1962) for a rigid wedge, complex; valid far
    from the edge and from the zone boundaries (``k r ≫ 1``), where it is the exact field's
    asymptote. ``D = e^{−jπ/4} sin(π/n) / (n √(2πk) sin β₀) · [1/(cos(π/n) − cos((θ_R − θ_S)/n))
    + 1/(cos(π/n) − cos((θ_R + θ_S)/n))]``, ``n = θ_w/π``, spread ``√(s'/(s (s + s')))``."""
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    r_s, th_s, z_s = wedge.cylindrical(source_m)
    r_r, th_r, z_r = wedge.cylindrical(receiver_m)
    k = 2 * math.pi * np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64)) / c
    n = wedge.open_angle / math.pi
    big_l = math.hypot(r_s + r_r, z_r - z_s)
    sin_b0 = (r_s + r_r) / big_l
    s_src, s_rcv = big_l * r_s / (r_s + r_r), big_l * r_r / (r_s + r_r)
    bracket = (1 / (math.cos(math.pi / n) - math.cos((th_r - th_s) / n))
               + 1 / (math.cos(math.pi / n) - math.cos((th_r + th_s) / n)))
    d = np.exp(-1j * math.pi / 4) * math.sin(math.pi / n) / (n * np.sqrt(2 * math.pi * k)
                                                             * sin_b0) * bracket
    incident = np.exp(-1j * k * s_src) / (4 * math.pi * s_src)
    return incident * d * math.sqrt(s_src / (s_rcv * (s_src + s_rcv))) * np.exp(-1j * k * s_rcv)


# --- first-order capsules (issue 30) ----------------------------------------------------------

def first_order_gain(alpha, theta_rad):
    """The gain of an ideal first-order capsule, ``a + (1 − a) cos θ``, for a plane wave
    ``θ`` radians off its axis (``a``: 1 omni, ½ cardioid, 0 figure-eight)."""
    a = np.asarray(alpha, dtype=np.float64)
    if np.any((a < 0) | (a > 1)):
        raise AcousticsError(f"alpha: expected 0 <= a <= 1, got {alpha!r}")
    return a + (1.0 - a) * np.cos(np.asarray(theta_rad, dtype=np.float64))


def diffuse_cross_spectrum_quadrature(offsets_m, axes, alphas, frequencies_hz, *,
                                      n_polar: int = 64, n_azimuth: int = 128,
                                      speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
                                      ) -> np.ndarray:
    """``(F, M, M)``: ``(1/4π) ∮ g_i(d) g_j(d) e^{jk d·(p_i − p_j)} dΩ`` for first-order
    capsules at ``offsets_m`` ``(M, 3)`` with unit ``axes`` ``(M, 3)`` and omni parts
    ``alphas`` ``(M,)``: the cross-spectrum of a spherically isotropic field of unit power
    (per direction, a plane wave of random phase). Gauss–Legendre nodes in ``cos θ``
    (``n_polar``), equally spaced azimuths (``n_azimuth``)."""
    p = np.asarray(offsets_m, dtype=np.float64).reshape(-1, 3)
    u = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    a = np.asarray(alphas, dtype=np.float64).reshape(-1)
    z, wz = np.polynomial.legendre.leggauss(n_polar)
    phi = 2 * math.pi * np.arange(n_azimuth) / n_azimuth
    rho = np.sqrt(1 - z**2)
    d = np.stack([np.outer(rho, np.cos(phi)), np.outer(rho, np.sin(phi)),
                  np.repeat(z[:, None], n_azimuth, axis=1)], axis=-1).reshape(-1, 3)
    w = np.repeat(wz / 2, n_azimuth) / n_azimuth  # sums to one
    g = a[:, None] + (1 - a[:, None]) * (u @ d.T)  # (M, N)
    k = 2 * math.pi * np.asarray(frequencies_hz, dtype=np.float64).reshape(-1) \
        / speed_of_sound_m_s
    h = g[None] * np.exp(1j * k[:, None, None] * (p @ d.T)[None])  # (F, M, N)
    return (h * w) @ np.conj(np.swapaxes(h, 1, 2))
# --- diffuse (isotropic) fields: the coherence between two receivers (issue 30) --------------

def _wavenumbers(frequencies_hz, speed_of_sound_m_s: float) -> np.ndarray:
    f = np.asarray(frequencies_hz, dtype=np.float64)
    if not np.all(np.isfinite(f) & (f >= 0)):
        raise AcousticsError("frequencies_hz: expected finite frequencies >= 0, got "
                             f"{f[~(np.isfinite(f) & (f >= 0))].ravel()[:3].tolist()}")
    return 2 * math.pi * f / _positive("speed_of_sound_m_s", speed_of_sound_m_s)


def _distance(name: str, value: float) -> float:
    if not (math.isfinite(value) and value >= 0):
        raise AcousticsError(f"{name}: expected a distance >= 0, got {value!r}")
    return float(value)


def spherical_isotropic_coherence(frequencies_hz, distance_m: float,
                                  speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
                                  ) -> np.ndarray:
    """Coherence of two omnidirectional points ``distance_m`` apart in a spherically
    isotropic (3-D diffuse) field: ``Γ(f) = sin(kd) / (kd)``, ``k = 2πf / c`` (Cook et al.
    1955). Real: the field has no preferred direction, so the cross-spectrum has no phase."""
    k = _wavenumbers(frequencies_hz, speed_of_sound_m_s)
    d = _distance("distance_m", distance_m)
    return np.sinc(k * d / math.pi)  # numpy's sinc is sin(πx)/(πx)


def cylindrical_isotropic_coherence(frequencies_hz, horizontal_distance_m: float,
                                    speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
                                    ) -> np.ndarray:
    """Coherence of two omnidirectional points in a cylindrically isotropic (2-D diffuse)
    field, plane waves from every horizontal direction alike: ``Γ(f) = J₀(k d_h)``, ``d_h``
    the points' horizontal distance (a vertical offset is heard identically by every
    horizontal wave)."""
    from scipy.special import j0

    k = _wavenumbers(frequencies_hz, speed_of_sound_m_s)
    return j0(k * _distance("horizontal_distance_m", horizontal_distance_m))


#: Brown & Duda (1998) head-shadow constants, the same as the receiver's.
BROWN_DUDA_ALPHA_MIN = 0.1
BROWN_DUDA_THETA_MIN_DEG = 150.0


def brown_duda_response(frequencies_hz, cos_theta, head_radius_m: float,
                        speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                        sample_rate_hz: float | None = None) -> np.ndarray:
    """Transfer function of the Brown–Duda (1998) spherical head at one ear, relative to the
    head's centre, for plane waves arriving at angle ``θ`` from the ear axis:
    ``H = e^{−jωτ(θ)} (1 + jα(θ) ω/(2ω₀)) / (1 + jω/(2ω₀))``, ``ω₀ = c/a``, ``τ`` the
    Woodworth ray-path delay (``−(a/c) cos θ`` lit, ``(a/c)(θ − π/2)`` shadowed) and
    ``α(θ) = 1 + α_min/2 + (1 − α_min/2) cos(θ/θ_min · 180°)``. ``sample_rate_hz``: the shadow
    filter as the renderer realises it, the bilinear transform, whose response at ``ω`` is
    the analog one at ``2 f_s tan(ω / 2f_s)`` (the delay stays exact). Shape: ``(F, *θ)``."""
    w = _wavenumbers(frequencies_hz, 1.0)  # ω = 2πf
    a = _positive("head_radius_m", head_radius_m)
    c = _positive("speed_of_sound_m_s", speed_of_sound_m_s)
    cos_t = np.clip(np.asarray(cos_theta, dtype=np.float64), -1.0, 1.0)
    theta = np.arccos(cos_t)
    tau = np.where(theta < math.pi / 2, -a / c * cos_t, a / c * (theta - math.pi / 2))
    alpha = (1 + BROWN_DUDA_ALPHA_MIN / 2) + (1 - BROWN_DUDA_ALPHA_MIN / 2) * np.cos(
        theta / math.radians(BROWN_DUDA_THETA_MIN_DEG) * math.pi)
    wa = w
    if sample_rate_hz is not None:
        fs = _positive("sample_rate_hz", sample_rate_hz)
        if np.any(w >= math.pi * fs):
            raise AcousticsError(f"frequencies_hz: expected < Nyquist ({fs / 2:g} Hz) with "
                                 "sample_rate_hz")
        wa = 2 * fs * np.tan(w / (2 * fs))
    shape = (-1,) + (1,) * cos_t.ndim
    x = 1j * wa.reshape(shape) / (2 * c / a)
    return np.exp(-1j * w.reshape(shape) * tau) * (1 + alpha * x) / (1 + x)


def brown_duda_diffuse_coherence(frequencies_hz, head_radius_m: float = 0.0875,
                                 ear_angle_deg: float = 100.0, field: str = "spherical", *,
                                 speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
                                 sample_rate_hz: float | None = None,
                                 n_polar: int = 192, n_azimuth: int = 384) -> np.ndarray:
    """Interaural coherence of the Brown–Duda head in an isotropic field, from its own
    transfer functions (:func:`brown_duda_response`) integrated over directions:
    ``Γ = Re ∫ H_L H_R* dΩ / √(∫ |H_L|² dΩ ∫ |H_R|² dΩ)``.

    The ears are horizontal, at ``±ear_angle_deg`` from the front. ``spherical``: Gauss–
    Legendre in the height ``z`` (``n_polar`` nodes) times the trapezoid rule in azimuth
    (``n_azimuth``, spectrally exact for periodic integrands); ``cylindrical``: the
    trapezoid rule over horizontal directions. Independent of the renderer's direction sets.
    """
    if field not in ("spherical", "cylindrical"):
        raise AcousticsError(f"field: expected 'spherical' or 'cylindrical', got {field!r}")
    if not 0 <= ear_angle_deg <= 180:
        raise AcousticsError(f"ear_angle_deg: expected 0..180, got {ear_angle_deg!r}")
    phi = 2 * math.pi * (np.arange(n_azimuth) + 0.5) / n_azimuth
    if field == "spherical":
        z, wz = np.polynomial.legendre.leggauss(n_polar)
    else:
        z, wz = np.zeros(1), np.ones(1)
    r = np.sqrt(1 - z**2)
    dirs = np.stack([r[:, None] * np.cos(phi)[None, :], r[:, None] * np.sin(phi)[None, :],
                     np.broadcast_to(z[:, None], (len(z), n_azimuth))], axis=-1).reshape(-1, 3)
    weights = np.repeat(wz, n_azimuth) / (wz.sum() * n_azimuth)
    e = math.radians(ear_angle_deg)
    ears = np.array([[math.cos(e), math.sin(e), 0.0], [math.cos(e), -math.sin(e), 0.0]])
    f = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
    out = np.zeros(f.shape)
    for i in range(0, f.size, 64):
        hl, hr = (brown_duda_response(f[i:i + 64], dirs @ ear, head_radius_m,
                                      speed_of_sound_m_s, sample_rate_hz) for ear in ears)
        cross = (hl * np.conj(hr)).real @ weights
        norm = np.sqrt((np.abs(hl) ** 2 @ weights) * (np.abs(hr) ** 2 @ weights))
        out[i:i + 64] = cross / norm
    return out.reshape(np.shape(frequencies_hz))
