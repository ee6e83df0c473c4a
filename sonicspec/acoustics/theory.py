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
"""

from __future__ import annotations

import math

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
    grid = np.arange(len(rcv)) / fs

    def receiver_at(t: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, grid, rcv[:, i]) for i in range(3)], axis=1)

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
