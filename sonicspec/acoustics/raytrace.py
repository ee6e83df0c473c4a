"""Stochastic ray tracing of the late field with diffuse rain, in vectorised batches on Embree.

Model (every approximation is listed here)
-------------------------------------------
* **Source**: a unit omnidirectional point source. ``n_rays`` rays leave it on a stratified
  sphere (a Fibonacci lattice, randomly rotated per batch), each carrying energy ``1/n_rays`` in
  every band. Results are squared pressure for a unit source (see :mod:`.arrivals`): an intensity
  ``I`` (energy per area, source power 1) is converted by ``p² = I/(4π)``, which makes a free-field
  ray count give ``p² = 1/(4πr)²``, the direct sound's convention.
* **Surfaces** (energy coefficients per band, see :class:`~.scene.AcousticScene`): of the
  incident energy ``E``, ``τ`` is transmitted, ``(1-τ)(1-α)(1-s)`` reflected specularly,
  ``(1-τ)(1-α)s`` scattered (Lambert) and the rest absorbed. Coefficients are random-incidence
  values applied at every angle; faces act on both sides.
* **One continuing ray per hit**: the ray takes *one* of transmit / specular / diffuse with
  probability proportional to the band-mean weight of that event, and its per-band energy is
  multiplied by ``weight / probability`` — unbiased in every band (the expectation is exactly
  ``τ + (1-τ)(1-α)``), without splitting rays. Diffuse directions are cosine-weighted.
* **Air**: energy decays as ``exp(-m·L)`` along the path (``m`` = ISO 9613-1 ``air_m_per_band``).
  Since every contribution arriving at time ``t`` has travelled ``L = c·t``, this factor is
  applied per histogram bin at its centre (±0.4 % at 8 kHz for 1 ms bins) rather than per ray.
* **Termination**: a ray stops when its largest band energy is ``energy_threshold_db`` below its
  launch energy, or after ``max_time_s``. Energy below the threshold is dropped (a bias of at
  most ``10^(-threshold/10)`` of the total); no reflection-count cap, so live rooms are not
  truncated. Rays that hit nothing escaped the mesh: they are counted
  (``escaped_ray_fraction``), never silently dropped.
* **Detection, two estimators summed** (each path is counted by exactly one of them, and none of
  the paths the direct sound or the image-source method render):

  - *Diffuse rain* (next-event estimation): at every hit, the scattered share
    ``E·(1-τ)(1-α)s`` is sent to every receiver by a shadow ray, with the Lambert weight
    ``cosθ·ΔΩ/π`` of the solid angle ``ΔΩ`` the receiver sphere (radius ``receiver_radius_m``)
    subtends, divided by its cross-section ``πR²`` (→ ``cosθ/(πd²)`` far away, capped near the
    surface where ``ΔΩ → 2π``). A shadow ray through transmitting surfaces is multiplied by
    their ``τ``; a blocked one is walked through them only with probability ``q = max τ`` of
    the scene (Russian roulette, weight ``1/q``: unbiased, and cheap where walls carry
    ``τ ≈ 0.01``). This counts every path whose *last* reflection is diffuse.
  - *Receiver sphere* (for paths whose last reflection is specular): a ray segment crossing the
    receiver sphere adds ``E·ℓ/V`` (chord length ``ℓ``, sphere volume ``V``), the unbiased
    volume estimator of intensity. Its variance falls with the number of crossings, ∝ R², so
    the radius grows with the path length ``L``: ``R = max(receiver_radius_m,
    min(radius_growth·L, max_receiver_radius_m, clearance))`` — a relative time smear of
    ``radius_growth`` (5 %: ±2.5 ms at 50 ms), harmless for a decaying late field; the
    *clearance* (distance from the receiver to the nearest surface, sampled once per receiver
    by 4096 Embree rays) keeps the sphere in free air so ``V`` is the volume really crossed.
    It only counts segments whose last reflection was specular
    and whose path either has a diffuse reflection somewhere or more than
    ``specular_order_excluded`` reflections — purely specular paths up to that order are the
    image sources, and the first segment (no reflection) is the direct sound.

* **Histograms**: per receiver, per-band energy in ``bin_s`` bins up to ``max_time_s``, with the
  band-summed energy-weighted sums of the arrival direction (towards the last reflection point,
  or against the ray for sphere hits) and of the ray's departure direction (unless
  ``RayTraceSettings.directions`` is False: then NaN, and the trace is about a sixth faster).
* **Many receivers**: one trace serves every receiver; sphere tests and shadow rays are the
  only per-receiver cost, and the shadow rays are bounded by ``rain_receivers_per_hit``: with
  more receivers each hit rains onto a random, evenly strided subset (weighted, unbiased), so
  100 receivers cost ≈6× one, not 100× (bench_tracer). For a moving source and a static
  microphone use reciprocity: trace from the microphone and pass the trajectory points as
  ``receivers``; ``EnergyHistogram.departure_sum`` then holds the direction at the microphone.
* **Shortcuts that do not change the result** (each tested against the slow path): sphere
  tests screen (ray, receiver) pairs in float32 with a margin before the exact float64 test;
  in a convex room (every vertex inside every face plane, no transmission) a shadow ray
  between two points inside it cannot be blocked and is not traced; receivers farther than
  ``max_receiver_radius_m`` from every face plane skip the clearance rays.
* **Determinism**: all randomness comes from the ``rng`` passed in (one spawned child generator
  per fixed batch of rays); batches may run on a thread pool but their histograms are summed
  in batch order, so the bytes of the result depend only on the inputs and the generator's
  state, never on the thread count.
* **Not modelled**: diffraction (occluded paths get no bent sound), angle-dependent
  absorption, diffuse (scattered) transmission, phase/interference (energy only; the image
  sources carry the coherent early part), and surfaces thinner than ``AcousticScene.eps_m``.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from sonicspec.acoustics.arrivals import EnergyHistogram, TraceResult
from sonicspec.acoustics.direct import DEFAULT_SPEED_OF_SOUND_M_S, check_air, check_points
from sonicspec.acoustics.directions import fibonacci_sphere
from sonicspec.acoustics.scene import AcousticScene
from sonicspec.errors import AcousticsError

__all__ = ["RayTraceSettings", "receiver_clearance_m", "trace_rays"]

# Upper bound on (rays × receivers) pairs handled in one numpy step (memory ≈ 100 B per pair).
_PAIRS_PER_STEP = 1 << 19
# Histogram contributions buffered before one bincount pass.
_FLUSH_ENTRIES = 1 << 21
# Margin of the float32 receiver-sphere screen, relative to the squared coordinates (its
# rounding error is below 1e-6 of them).
_SCREEN_REL = 1e-5
# Up to this many receivers, every (ray, receiver) pair goes to the exact sphere test.
_FEW_RECEIVERS = 4
# Largest (rows × columns × inner) float32 product of the sphere screen per matrix product.
_SCREEN_PRODUCT = 1 << 18
# Largest (receivers × faces) for the plane-distance shortcut of the receivers' clearance.
_PLANE_TEST_PAIRS = 1 << 22
# Rain pairs are added as dense (slot, hit) blocks when at least this share of them count.
_RAIN_DENSE = 0.75
# Convex rooms of up to this many faces skip shadow rays between points inside them.
_CONVEX_MAX_FACES = 64
# "Strictly inside" a plane: farther than this on its inner side, metres.
_INSIDE_M = 1e-9


@dataclass(frozen=True)
class RayTraceSettings:
    """Settings of :func:`trace_rays`.

    Attributes
    ----------
    n_rays : int
        Rays launched from the source.
    max_time_s : float
        Histogram length and the latest time a ray is followed to, seconds.
    energy_threshold_db : float
        A ray stops once its strongest band is this far below its launch energy, dB.
    bin_s : float
        Histogram bin width, seconds.
    receiver_radius_m : float
        Radius of the receiver sphere for diffuse rain's solid angle and the smallest radius of
        specular detection, metres.
    radius_growth : float
        Specular-detection radius per metre of path length (see the module docstring).
    max_receiver_radius_m : float
        Largest specular-detection radius, metres.
    specular_order_excluded : int
        Purely specular paths with at most this many reflections are left to the image sources
        (pass the ``max_order`` an :class:`~.image_sources.ImageSourceResult` reports).
    speed_of_sound_m_s : float
        Speed of sound, m/s.
    batch_size : int
        Rays traced together (memory ∝ batch size × receivers).
    diffuse_rain : bool
        True: diffuse rain + receiver spheres (default, low variance). False: receiver spheres
        only (the classic receiver-volume method; every path but the direct sound and the
        image sources is counted by the sphere), kept as a reference and for comparison.
    rain_receivers_per_hit : int
        0: every hit rains onto every receiver. M > 0 with more than M receivers: every hit
        rains onto about M of them (every S-th from a random offset, ``S = ceil(N/M)``, weighted
        by S — unbiased), so the shadow-ray cost per hit stays bounded as N grows; each
        receiver then gets 1/S of the rain samples (more variance, see bench_tracer).
    directions : bool
        Also accumulate the energy-weighted arrival and departure direction sums (about a
        sixth of the trace's time). False: ``EnergyHistogram.direction_sum`` and
        ``departure_sum`` are NaN (not computed); the energies are the same bytes.
    """

    n_rays: int = 20_000
    max_time_s: float = 2.0
    energy_threshold_db: float = 80.0
    bin_s: float = 0.001
    receiver_radius_m: float = 0.1
    radius_growth: float = 0.05
    max_receiver_radius_m: float = 1.0
    specular_order_excluded: int = 3
    speed_of_sound_m_s: float = DEFAULT_SPEED_OF_SOUND_M_S
    batch_size: int = 8192
    diffuse_rain: bool = True
    rain_receivers_per_hit: int = 8
    directions: bool = True

    def __post_init__(self) -> None:
        checks = [
            ("n_rays", self.n_rays, self.n_rays >= 1, ">= 1"),
            ("max_time_s", self.max_time_s, self.max_time_s > 0, "> 0"),
            ("energy_threshold_db", self.energy_threshold_db, self.energy_threshold_db > 0, "> 0"),
            ("bin_s", self.bin_s, 0 < self.bin_s <= self.max_time_s, "in (0, max_time_s]"),
            ("receiver_radius_m", self.receiver_radius_m, self.receiver_radius_m > 0, "> 0"),
            ("radius_growth", self.radius_growth, self.radius_growth >= 0, ">= 0"),
            (
                "max_receiver_radius_m",
                self.max_receiver_radius_m,
                self.max_receiver_radius_m >= self.receiver_radius_m,
                ">= receiver_radius_m",
            ),
            (
                "specular_order_excluded",
                self.specular_order_excluded,
                self.specular_order_excluded >= 0,
                ">= 0",
            ),
            ("speed_of_sound_m_s", self.speed_of_sound_m_s, self.speed_of_sound_m_s > 0, "> 0"),
            ("batch_size", self.batch_size, self.batch_size >= 1, ">= 1"),
            (
                "rain_receivers_per_hit",
                self.rain_receivers_per_hit,
                self.rain_receivers_per_hit >= 0,
                ">= 0 (0: all receivers)",
            ),
        ]
        for name, value, ok, allowed in checks:
            if not ok:
                raise AcousticsError(f"RayTraceSettings.{name}: expected {allowed}, got {value}")


def _rotated_fibonacci_sphere(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` near-uniform unit vectors (Fibonacci lattice) under a uniformly random rotation."""
    pts = fibonacci_sphere(n)
    q, rr = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(rr))  # Haar-uniform orthogonal matrix
    return pts @ q.T


def _cosine_hemisphere(normal: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Lambert (cosine-weighted) directions around unit ``normal`` (n, 3)."""
    # Orthonormal basis without branches (Duff et al. 2017).
    nx, ny, nz = normal.T
    sign = np.where(nz >= 0, 1.0, -1.0)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    r = np.sqrt(u1)
    phi = 2.0 * math.pi * u2
    x = r * np.cos(phi)  # along t1 = (1 + sign·nx²·a, sign·b, -sign·nx)
    y = r * np.sin(phi)  # along t2 = (b, sign + ny²·a, -ny)
    z = np.sqrt(np.maximum(0.0, 1.0 - u1))
    out = np.empty_like(normal)
    out[:, 0] = x * (1.0 + sign * nx * nx * a) + y * b + z * nx
    out[:, 1] = x * (sign * b) + y * (sign + ny * ny * a) + z * ny
    out[:, 2] = -x * (sign * nx) - y * ny + z * nz
    return out


class _Accumulator:
    """Buffers (receiver, bin) contributions and folds them into histograms by bincount.

    ``hist`` holds one row per quantity over the flat (receiver, bin) index: the band
    energies, then the energy-weighted arrival and departure direction sums (3 rows each).
    Callers write contributions straight into the buffer as rows (:meth:`reserve`), so every
    bincount reads and adds contiguous memory and nothing is copied on the way. Energies are
    accumulated *without* air absorption (it is applied per bin at the end, see
    :func:`trace_rays`).
    """

    def __init__(self, n_receivers: int, n_bins: int, n_bands: int, directions: bool) -> None:
        self.n_bins = n_bins
        self.n_bands = n_bands
        self.directions = directions
        self.size = n_receivers * n_bins
        rows = n_bands + 6 if directions else n_bands
        self.hist = np.zeros((rows, self.size))
        # A bincount costs O(entries + size); buffering twice the histogram's size keeps the
        # O(size) part under a third, at about 100 B per buffered entry.
        capacity = min(_FLUSH_ENTRIES, max(1 << 16, 2 * self.size))
        self._flat = np.empty(capacity, dtype=np.int64)
        self._rows = np.empty((rows, capacity))
        self._used = 0

    def reserve(self, receiver: np.ndarray, bin_index: np.ndarray) -> np.ndarray:
        """Rows ``(n_bands [+ 6], m)`` for ``m`` contributions (all with ``bin_index < n_bins``)
        to fill: band energies, then (``directions``) the arrival direction × band-summed
        energy and the departure direction likewise."""
        m = bin_index.size
        if self._used + m > self._flat.size:
            self.flush()
            if m > self._flat.size:
                self._flat = np.empty(m, dtype=np.int64)
                self._rows = np.empty((self._rows.shape[0], m))
        sl = slice(self._used, self._used + m)
        np.multiply(receiver, self.n_bins, out=self._flat[sl])
        self._flat[sl] += bin_index
        self._used += m
        return self._rows[:, sl]

    def flush(self) -> None:
        if self._used == 0:
            return
        flat = self._flat[: self._used]
        for j in range(self._rows.shape[0]):
            self.hist[j] += np.bincount(
                flat, weights=self._rows[j, : self._used], minlength=self.size
            )
        self._used = 0


def trace_rays(
    scene: AcousticScene,
    source: np.ndarray,
    receivers: np.ndarray,
    rng: np.random.Generator,
    settings: RayTraceSettings | None = None,
    air_m_per_band: np.ndarray | None = None,
    n_threads: int = 1,
) -> list[TraceResult]:
    """Late-field energy histograms at every receiver from one stochastic ray trace.

    Parameters
    ----------
    scene : AcousticScene
        The mesh with its per-face coefficients.
    source : (3,) float
        Source position, metres (under reciprocity: the static microphone).
    receivers : (n, 3) float
        Receiver positions, metres (under reciprocity: the trajectory points).
    rng : numpy.random.Generator
        The only source of randomness; one child generator is spawned per batch of rays.
    settings : RayTraceSettings, optional
        Ray count, duration, threshold, binning, receiver radius, excluded specular order.
    air_m_per_band : (n_bands,) float, optional
        ISO 9613-1 air energy attenuation per band, 1/m. None: no air absorption.
    n_threads : int
        Batches traced concurrently (Embree and large numpy operations release the GIL).
        Batches are fixed by ``settings.batch_size`` and their histograms are summed in batch
        order, so the result bytes do not depend on ``n_threads``.

    Returns
    -------
    list of TraceResult
        One per receiver; see the module docstring for the model and the estimators.

    Notes
    -----
    Air absorption depends only on the total path length, which is ``c·t`` for every
    contribution arriving at time ``t``; it is therefore applied per histogram bin,
    ``exp(-m·c·t_centre)``, instead of per ray (exact up to ``±m·c·bin_s/2`` within a bin:
    ±0.4 % at 8 kHz for 1 ms bins). The termination test uses the ray's energy with air.
    """
    settings = settings or RayTraceSettings()
    source = check_points("source", source)
    if len(source) != 1:
        raise AcousticsError(f"source: expected one position, got {len(source)}")
    receivers = check_points("receivers", receivers)
    air = check_air(air_m_per_band, scene.n_bands)
    if not isinstance(rng, np.random.Generator):
        raise AcousticsError(
            f"rng: expected a numpy.random.Generator, got {type(rng).__name__}; "
            "hint: numpy.random.default_rng(seed)"
        )
    if not isinstance(n_threads, int | np.integer) or n_threads < 1:
        raise AcousticsError(f"n_threads: expected an integer >= 1, got {n_threads!r}")
    n_bins = math.ceil(settings.max_time_s / settings.bin_s - 1e-9)
    radius_cap = np.maximum(
        settings.receiver_radius_m,
        np.minimum(
            settings.max_receiver_radius_m,
            _clearance_below(scene, receivers, settings.max_receiver_radius_m),
        ),
    )
    rcv = _Receivers.build(scene, receivers, radius_cap)
    sizes = [
        min(settings.batch_size, settings.n_rays - start)
        for start in range(0, settings.n_rays, settings.batch_size)
    ]
    rngs = rng.spawn(len(sizes))
    tables = _event_tables(scene)

    def run(i: int) -> tuple[_Accumulator, int, int]:
        acc = _Accumulator(len(receivers), n_bins, scene.n_bands, settings.directions)
        esc, hits = _trace_batch(
            scene, source[0], rcv, rngs[i], settings, air, sizes[i], acc, tables
        )
        acc.flush()
        return acc, esc, hits

    total: _Accumulator | None = None
    escaped = 0
    interactions = 0

    def fold(result: tuple[_Accumulator, int, int]) -> None:
        nonlocal total, escaped, interactions
        acc, esc, hits = result
        escaped += esc
        interactions += hits
        if total is None:
            total = acc
        else:
            total.hist += acc.hist

    if n_threads == 1 or len(sizes) == 1:
        for i in range(len(sizes)):
            fold(run(i))
    else:
        with ThreadPoolExecutor(max_workers=n_threads) as pool:
            # Windows of n_threads batches bound the memory; folding in batch order keeps
            # the sums (hence the bytes) independent of the thread count.
            for w0 in range(0, len(sizes), n_threads):
                for result in pool.map(run, range(w0, min(len(sizes), w0 + n_threads))):
                    fold(result)
    if total is None:  # unreachable: n_rays >= 1 is validated, so there is a batch
        raise AcousticsError("trace_rays: expected at least one batch of rays, got none")

    # Air absorption per bin (see Notes); direction sums follow the band-summed energy.
    t_centre = (np.arange(n_bins) + 0.5) * settings.bin_s
    air_gain = np.exp(-np.outer(t_centre * settings.speed_of_sound_m_s, air))  # (n_bins, B)
    b = scene.n_bands
    not_traced = np.full((n_bins, 3), np.nan)
    out = []
    for r in range(len(receivers)):
        rows = total.hist[:, r * n_bins : (r + 1) * n_bins].T  # (n_bins, n_bands [+ 6])
        raw = rows[:, :b]
        energy = raw * air_gain
        if settings.directions:
            before = raw.sum(axis=1)
            ratio = energy.sum(axis=1) / np.where(before > 0, before, 1.0)
            ratio = np.where(before > 0, ratio, 0.0)[:, None]
            arrival, departure = rows[:, b : b + 3] * ratio, rows[:, b + 3 :] * ratio
        else:
            arrival = departure = not_traced
        hist = EnergyHistogram(
            bin_s=settings.bin_s, energy=energy, direction_sum=arrival, departure_sum=departure
        )
        out.append(
            TraceResult(
                histogram=hist,
                n_rays=settings.n_rays,
                escaped_ray_fraction=escaped / settings.n_rays,
                specular_order_excluded=settings.specular_order_excluded,
                mean_reflections=interactions / settings.n_rays,
            )
        )
    return out


@dataclass(frozen=True, eq=False)
class _EventTables:
    """Per-face event probabilities and per-band energy gains of the continuing ray.

    Event e (0 transmit, 1 specular, 2 diffuse) has per-band weight ``w_e`` and is chosen with
    probability ``P_e = mean_b(w_e) / Σ_e' mean_b(w_e')``; the ray's energy is multiplied by
    ``gain[e] = w_e / P_e`` (0 where ``P_e = 0``), so its expectation is ``Σ_e w_e`` per band.
    """

    p_t: np.ndarray  # (F,) P(transmit)
    p_ts: np.ndarray  # (F,) P(transmit) + P(specular)
    gain: np.ndarray  # (3, F, B)
    w_diff_t: np.ndarray  # (B, F) scattered energy fraction (1-τ)(1-α)s
    scatters: np.ndarray  # (F,) any band scatters


def _event_tables(scene: AcousticScene) -> _EventTables:
    tau = scene.transmission
    w_refl = (1.0 - tau) * (1.0 - scene.absorption)
    w_diff = w_refl * scene.scattering
    weights = np.stack([tau, w_refl - w_diff, w_diff])  # (3, F, B)
    means = weights.mean(axis=2)  # (3, F)
    total = means.sum(axis=0)
    prob = means / np.where(total > 0, total, 1.0)
    gain = np.where(prob[:, :, None] > 0, weights / np.where(prob > 0, prob, 1.0)[:, :, None], 0)
    return _EventTables(
        p_t=prob[0],
        # A face that absorbs everything (total 0): every pick lands on "diffuse", gain 0.
        p_ts=prob[0] + prob[1],
        gain=gain,
        w_diff_t=np.ascontiguousarray(w_diff.T),
        scatters=np.any(w_diff > 0, axis=1),
    )


def _trace_batch(
    scene: AcousticScene,
    src: np.ndarray,
    rcv: _Receivers,
    rng: np.random.Generator,
    st: RayTraceSettings,
    air: np.ndarray,
    n: int,
    acc: _Accumulator,
    ev: _EventTables,
) -> tuple[int, int]:
    """Trace ``n`` rays to termination; returns (escaped rays, surface interactions).

    Ray energies here exclude air absorption (applied per bin afterwards) except in the
    termination test.
    """
    c = st.speed_of_sound_m_s
    max_len = c * st.max_time_s
    e0 = 1.0 / st.n_rays
    e_stop = e0 * 10.0 ** (-st.energy_threshold_db / 10.0)
    # p² per unit "energy per area": see the module docstring.
    to_p2 = 1.0 / (4.0 * math.pi)
    eps = scene.eps_m
    rcv_chunk = max(1, _PAIRS_PER_STEP // max(1, n))
    has_air = bool(np.any(air > 0))

    # Separate streams: ray paths do not depend on how the rain is subsampled.
    rng, rain_rng = rng.spawn(2)
    dirs = _rotated_fibonacci_sphere(n, rng)
    departure = dirs.copy()
    pos = np.repeat(src[None, :], n, axis=0)
    energy = np.full((n, scene.n_bands), e0)
    length = np.zeros(n)
    n_refl = np.zeros(n, dtype=np.int64)
    any_diffuse = np.zeros(n, dtype=bool)
    last_diffuse = np.zeros(n, dtype=bool)
    escaped = 0
    interactions = 0

    normals = scene.normals
    n_faces = scene.n_faces
    gain_rows = ev.gain.reshape(3 * n_faces, scene.n_bands)  # row event·F + face
    # (Row gathers use np.take / np.compress: several times faster than fancy indexing of
    # 2-D arrays, which matters at every bounce.)
    while len(pos):
        face, t = scene.intersect(pos, dirs)
        miss = face < 0
        n_miss = int(np.count_nonzero(miss))
        escaped += n_miss
        # Receiver spheres: paths whose last reflection is specular, beyond the image sources.
        # (An escaping ray's segment is infinite; it is still tested, then dropped.)
        eligible = any_diffuse | (n_refl > st.specular_order_excluded)
        if st.diffuse_rain:
            eligible &= ~last_diffuse
        idx = np.flatnonzero(eligible)
        if idx.size:
            _sphere_hits(
                pos, dirs, t, energy, length, departure, idx, rcv, st, to_p2, rcv_chunk, acc
            )
        if n_miss:
            keep = ~miss
            face, t, length = face[keep], t[keep], length[keep]
            n_refl, any_diffuse, last_diffuse = n_refl[keep], any_diffuse[keep], last_diffuse[keep]
            pos, dirs, energy, departure = (
                np.compress(keep, x, axis=0) for x in (pos, dirs, energy, departure)
            )
        n_live = len(pos)
        if n_live == 0:
            break
        # Fly to the hit.
        hit = pos + t[:, None] * dirs
        length = length + t
        interactions += n_live
        nrm = np.take(normals, face, axis=0)
        cos_in = np.einsum("ij,ij->i", dirs, nrm)
        n_side = nrm * np.where(cos_in < 0, 1.0, -1.0)[:, None]  # normal facing the ray
        alive_time = length < max_len
        # Diffuse rain: the scattered share goes to every receiver via a shadow ray.
        if st.diffuse_rain:
            sel = np.flatnonzero(alive_time & ev.scatters[face])
            if sel.size == n_live:
                r_hit, r_side, r_energy, r_face, r_len, r_dep = (
                    hit, n_side, energy, face, length, departure
                )  # fmt: skip
            else:
                r_hit, r_side, r_energy, r_dep = (
                    np.take(x, sel, axis=0) for x in (hit, n_side, energy, departure)
                )
                r_face, r_len = face[sel], length[sel]
            if sel.size:
                scattered = r_energy.T * np.take(ev.w_diff_t, r_face, axis=1)
                _rain(
                    scene, r_hit, r_side, scattered, r_len, r_dep, rcv, st, to_p2, rain_rng, acc
                )
        # Choose the continuing event by band-mean weights (0 transmit, 1 specular, 2 diffuse;
        # p_ts >= p_t) and reweight per band (unbiased).
        u = rng.random((n_live, 3))
        pick = u[:, 0]
        is_t = pick < ev.p_t[face]
        event = 2 - is_t - (pick < ev.p_ts[face])
        is_d = event == 2
        energy = energy * np.take(gain_rows, event * n_faces + face, axis=0)
        # New directions: specular mirror, Lambert around the facing normal, or straight on.
        new_dirs = dirs - 2.0 * (cos_in[:, None] * nrm)
        d_idx = np.flatnonzero(is_d)
        if d_idx.size:
            new_dirs[d_idx] = _cosine_hemisphere(
                np.take(n_side, d_idx, axis=0), u[d_idx, 1], u[d_idx, 2]
            )
        if is_t.any():
            new_dirs[is_t] = dirs[is_t]
        dirs = new_dirs / np.sqrt(np.einsum("ij,ij->i", new_dirs, new_dirs))[:, None]
        pos = hit + np.where(is_t, -eps, eps)[:, None] * n_side
        reflected = ~is_t
        n_refl = n_refl + reflected
        any_diffuse = any_diffuse | is_d
        last_diffuse = np.where(reflected, is_d, last_diffuse)
        if has_air:
            strongest = (energy * np.exp(-np.outer(length, air))).max(axis=1)
        else:
            strongest = energy.max(axis=1)
        alive = (strongest >= e_stop) & alive_time
        if not alive.all():
            length, n_refl = length[alive], n_refl[alive]
            any_diffuse, last_diffuse = any_diffuse[alive], last_diffuse[alive]
            pos, dirs, energy, departure = (
                np.compress(alive, x, axis=0) for x in (pos, dirs, energy, departure)
            )
    return escaped, interactions


def _sphere_candidates(
    origin: np.ndarray,
    direction: np.ndarray,
    seg_len: np.ndarray,
    rays: np.ndarray,
    rcv: _Receivers,
    rcv_chunk: int,
) -> tuple[np.ndarray, np.ndarray]:
    """(ray, receiver) pairs whose segment may cross the receiver's largest sphere: a float32
    screen (small matrix products over chunks of rays and receivers) with a margin far above
    its rounding error, so it never misses a pair the exact test would keep."""
    o = np.take(origin, rays, axis=0) - rcv.centre
    d = np.take(direction, rays, axis=0)
    od = np.einsum("ij,ij->i", o, d)
    oo = np.einsum("ij,ij->i", o, o)
    # tc = d·(R - o) and |R - o|² as products of augmented vectors.
    a_tc = np.column_stack([d, -od]).astype(np.float32)
    a_w2 = np.column_stack([-2.0 * o, oo, np.ones(len(o))]).astype(np.float32)
    scale = float(np.max(oo, initial=0.0)) + rcv.max_sq
    margin_sq = np.float32(_SCREEN_REL * (1.0 + 4.0 * scale))
    margin = np.float32(_SCREEN_REL * (1.0 + 2.0 * math.sqrt(scale)))
    seg_hi = (seg_len[rays] + margin).astype(np.float32)[:, None]
    # Small enough products that BLAS runs them on one thread (it spreads larger ones over
    # every core, which costs CPU time for no gain here).
    step = max(1, _SCREEN_PRODUCT // (5 * min(rcv.n, rcv_chunk)))
    found_ray, found_k = [], []
    for r0 in range(0, rcv.n, rcv_chunk):
        sl = slice(r0, r0 + rcv_chunk)
        for i0 in range(0, len(rays), step):
            rs = slice(i0, i0 + step)
            tc = a_tc[rs] @ rcv.aug_tc[:, sl]
            d2 = a_w2[rs] @ rcv.aug_w2[:, sl]
            d2 -= tc * tc
            # Within the largest radius of the line, and of the segment along it.
            near = d2 < rcv.cap_sq32[sl] + margin_sq
            near &= tc > -(rcv.cap32[sl] + margin)
            near &= tc < seg_hi[rs] + rcv.cap32[sl]
            ray, k = np.divmod(np.flatnonzero(near), near.shape[1])  # (2-D nonzero is slow)
            found_ray.append(ray + i0)
            found_k.append(k + r0)
    return rays[np.concatenate(found_ray)], np.concatenate(found_k)


def _sphere_hits(
    origin: np.ndarray,
    direction: np.ndarray,
    seg_len: np.ndarray,
    energy: np.ndarray,
    path_len: np.ndarray,
    departure: np.ndarray,
    rays: np.ndarray,
    rcv: _Receivers,
    st: RayTraceSettings,
    to_p2: float,
    rcv_chunk: int,
    acc: _Accumulator,
) -> None:
    """Volume estimator ``E·ℓ/V`` for segments of ``rays`` (indices into the ray arrays)
    crossing receiver spheres.

    With a few receivers every (ray, receiver) pair is tested; with more, a float32 screen
    (:func:`_sphere_candidates`) picks the candidate pairs first. Either way the chord of each
    pair is computed in float64, exactly as if every pair had been tested.
    """
    c = st.speed_of_sound_m_s
    if rcv.n == 1:
        pairs = [(rays, np.zeros(len(rays), dtype=np.int64))]
    elif rcv.n <= _FEW_RECEIVERS:
        pairs = [(np.tile(rays, rcv.n), np.repeat(np.arange(rcv.n), len(rays)))]
    else:
        pairs = [_sphere_candidates(origin, direction, seg_len, rays, rcv, rcv_chunk)]
    for ray, k in pairs:
        if ray.size == 0:
            continue
        cap = rcv.cap[k]
        w = np.take(rcv.pos, k, axis=0)
        w -= np.take(origin, ray, axis=0)
        dr = np.take(direction, ray, axis=0)
        tc_c = np.einsum("ij,ij->i", w, dr)
        d2_c = np.einsum("ij,ij->i", w, w) - tc_c * tc_c
        path = path_len[ray]
        radius = np.maximum(
            st.receiver_radius_m,
            np.minimum(st.radius_growth * (path + np.maximum(tc_c, 0.0)), cap),
        )
        half = np.sqrt(np.maximum(radius * radius - d2_c, 0.0))
        # Chord of the sphere within the free segment [0, seg_len].
        t_in = np.maximum(tc_c - half, 0.0)
        t_out = np.minimum(tc_c + half, seg_len[ray])
        chord = t_out - t_in
        good = (d2_c < radius * radius) & (chord > 0)
        if not good.all():
            ray, k, t_in, t_out, chord, radius, path = (
                ray[good], k[good], t_in[good], t_out[good], chord[good], radius[good], path[good]
            )  # fmt: skip
            dr = np.compress(good, dr, axis=0)
        if ray.size == 0:
            continue
        t_mid = 0.5 * (t_in + t_out)
        time_bin = np.floor((path + t_mid) / (c * st.bin_s)).astype(np.int64)
        late = time_bin < acc.n_bins
        if not late.all():
            ray, k, time_bin, chord, radius = (
                ray[late], k[late], time_bin[late], chord[late], radius[late]
            )  # fmt: skip
            dr = np.compress(late, dr, axis=0)
        if ray.size == 0:
            continue
        volume = 4.0 / 3.0 * math.pi * radius**3
        weight = chord / volume * to_p2
        b = acc.n_bands
        rows = acc.reserve(k, time_bin)
        np.multiply(np.take(energy, ray, axis=0).T, weight, out=rows[:b])
        if acc.directions:
            total = rows[:b].sum(axis=0)
            np.multiply(dr.T, -total, out=rows[b : b + 3])
            np.multiply(np.take(departure, ray, axis=0).T, total, out=rows[b + 3 :])


def receiver_clearance_m(
    scene: AcousticScene, receivers: np.ndarray, n_directions: int = 4096
) -> np.ndarray:
    """Distance from each receiver to the nearest surface, metres (sampled by Embree rays).

    ``n_directions`` rays on a Fibonacci sphere; the nearest hit distance times the cosine of
    half the lattice spacing bounds the distance to a plane from below. Small objects between
    the rays can be missed (the radius is then slightly too large near them).
    """
    receivers = check_points("receivers", receivers)
    dirs = fibonacci_sphere(n_directions)
    spacing = math.sqrt(4.0 * math.pi / n_directions)
    out = np.zeros(len(receivers))
    # Several receivers per Embree call (about 2^18 rays): far fewer calls for many receivers.
    per = max(1, (1 << 18) // n_directions)
    for r0 in range(0, len(receivers), per):
        block = receivers[r0 : r0 + per]
        _, dist = scene.intersect(
            np.repeat(block, n_directions, axis=0), np.tile(dirs, (len(block), 1))
        )
        out[r0 : r0 + len(block)] = dist.reshape(len(block), n_directions).min(axis=1)
    return out * math.cos(spacing)


def _clearance_below(scene: AcousticScene, receivers: np.ndarray, limit: float) -> np.ndarray:
    """:func:`receiver_clearance_m` wherever it can be below ``limit``; ``inf`` elsewhere.

    A receiver's distance to every face *plane* bounds its distance to the faces from below,
    and the sampled clearance never undercuts the true distance by more than float32
    rounding; receivers whose planes are all farther than ``limit`` (plus a margin) would get
    a clearance above ``limit``, so their 4096 rays are skipped (a shoebox's points more than
    ``limit`` from every wall: all of them).
    """
    near = np.ones(len(receivers), dtype=bool)
    if len(receivers) * scene.n_faces <= _PLANE_TEST_PAIRS:
        plane = np.abs(receivers @ scene.normals.T - scene.plane_d[None, :]).min(axis=1)
        spacing = math.sqrt(4.0 * math.pi / 4096)
        near = plane * math.cos(spacing) < limit + 1e-4
    out = np.full(len(receivers), np.inf)
    if near.any():
        out[near] = receiver_clearance_m(scene, receivers[near])
    return out


def _rain_slots(
    n_hits: int, n_rcv: int, stride: int, rng: np.random.Generator
) -> list[np.ndarray]:
    """Receivers that receive each hit's diffuse rain, as ``(slots, n_hits)`` index blocks
    (``n_rcv`` or more where a slot is empty), in chunks of bounded size.

    ``stride`` 1: every receiver (slot j is receiver j). ``stride`` S > 1: each hit rains onto
    every S-th receiver from a random offset, so every (hit, receiver) pair is chosen with
    probability exactly 1/S (the caller weights by S: unbiased).
    """
    if stride == 1:
        per = max(1, _PAIRS_PER_STEP // max(1, n_hits))
        return [
            np.broadcast_to(np.arange(r0, min(n_rcv, r0 + per))[:, None],
                            (min(n_rcv, r0 + per) - r0, n_hits))
            for r0 in range(0, n_rcv, per)
        ]
    offset = rng.integers(0, stride, n_hits)
    return [offset[None, :] + stride * np.arange(-(-n_rcv // stride))[:, None]]


def _rain(
    scene: AcousticScene,
    hit: np.ndarray,
    n_side: np.ndarray,
    scattered: np.ndarray,
    path_len: np.ndarray,
    departure: np.ndarray,
    rcv: _Receivers,
    st: RayTraceSettings,
    to_p2: float,
    rng: np.random.Generator,
    acc: _Accumulator,
) -> None:
    """Next-event estimate of the scattered energy at every receiver (Lambert, shadow rays).

    Pairs are laid out as (slot, hit) blocks: per-hit quantities broadcast along the slots
    instead of being gathered pair by pair, and pairs that get nothing (an empty slot, a
    receiver behind the surface, a blocked shadow ray, an arrival beyond the histogram) are
    added with weight 0 rather than compacted away, unless they are many.
    """
    radius = st.receiver_radius_m
    limit = st.rain_receivers_per_hit
    stride = 1 if limit == 0 or rcv.n <= limit else -(-rcv.n // limit)
    # ΔΩ/π per πR², converted to p², times the subsampling weight.
    scale = stride * to_p2 / (math.pi * math.pi * radius * radius)
    inv_bin_len = 1.0 / (st.speed_of_sound_m_s * st.bin_s)
    n_hits, b = len(hit), acc.n_bands
    start = hit + scene.eps_m * n_side  # shadow rays leave the surface on the lit side
    free_hit = None
    if rcv.planes is not None:  # convex room: a start inside it sees every inner receiver
        normals, offsets = rcv.planes
        free_hit = (start @ normals.T - offsets).min(axis=1) > _INSIDE_M
    scattered_sum = scattered.sum(axis=0)
    walk_probability = min(1.0, scene.max_transmission)
    for slots in _rain_slots(n_hits, rcv.n, stride, rng):
        ok = slots < rcv.n
        k = np.where(ok, slots, 0)
        vec = np.empty((3, *k.shape))
        for c in range(3):
            np.subtract(np.take(rcv.pos_t[c], k), hit[:, c], out=vec[c])
        dot = vec[0] * n_side[:, 0] + vec[1] * n_side[:, 1] + vec[2] * n_side[:, 2]
        ok &= dot > 0  # receivers on the side the energy is scattered to
        d = np.sqrt(np.einsum("cij,cij->ij", vec, vec))
        d[~ok] = 1.0  # (an empty slot may sit on the hit; it gets weight 0 anyway)
        u = vec / d
        flat_u = u.reshape(3, -1)
        test = ok if free_hit is None else ok & ~(free_hit & np.take(rcv.inside, k))
        pair = np.flatnonzero(test)
        blocked = np.zeros(0, dtype=np.int64)
        if pair.size:
            blocked = pair[
                scene.occluded_along(
                    np.take(start, pair % n_hits, axis=0), np.take(flat_u, pair, axis=1).T,
                    d.ravel()[pair],
                )
            ]
        trans = None
        if blocked.size and walk_probability > 0:
            # Russian roulette: a blocked shadow ray is walked through the surfaces it crosses
            # with probability q = max τ and its Π τ divided by q (unbiased, and Π τ / q <= 1
            # since it crosses at least one surface); the rest stop here. Most blocked rays
            # would come out tens of dB down, and walking them is most of the rain's cost.
            walk = rng.random(blocked.size) < walk_probability
            ok.ravel()[blocked[~walk]] = False
            blocked = blocked[walk]
            if blocked.size:
                tr = scene.crossed_transmission(
                    np.take(start, blocked % n_hits, axis=0),
                    np.take(rcv.pos, k.ravel()[blocked], axis=0),
                ) / walk_probability
                trans = np.ones((b, ok.size))
                trans[:, blocked] = tr.T
                ok.ravel()[blocked[~np.any(tr > 0, axis=1)]] = False
        else:
            ok.ravel()[blocked] = False
        time_bin = ((path_len + d) * inv_bin_len).astype(np.int64)
        ok &= time_bin < acc.n_bins
        n_ok = int(np.count_nonzero(ok))
        if n_ok == 0:
            continue
        cos_out = dot / d
        # Solid angle of the receiver sphere seen from the hit, exact (2π when inside it).
        sin2 = np.minimum(1.0, (radius / d) ** 2)
        solid = (2.0 * math.pi) * (1.0 - np.sqrt(1.0 - sin2))
        geom = cos_out * solid * scale
        if n_ok < _RAIN_DENSE * ok.size:  # mostly nothing: compact rather than add zeros
            keep = np.flatnonzero(ok)
            ray = keep % n_hits
            geom = geom.ravel()[keep]
            rows = acc.reserve(k.ravel()[keep], time_bin.ravel()[keep])
            np.multiply(np.take(scattered, ray, axis=1), geom, out=rows[:b])
            total = np.take(scattered_sum, ray) * geom
            if trans is not None:
                rows[:b] *= np.take(trans, keep, axis=1)
            arrival, dep = np.take(flat_u, keep, axis=1), np.take(departure, ray, axis=0).T
        else:
            geom[~ok] = 0.0
            time_bin[~ok] = 0
            rows = acc.reserve(k.ravel(), time_bin.ravel()).reshape(-1, *ok.shape)
            np.multiply(scattered[:, None, :], geom, out=rows[:b])
            total = scattered_sum * geom
            if trans is not None:
                rows[:b] *= trans.reshape(b, *ok.shape)
            arrival, dep = u, departure.T[:, None, :]
        if not acc.directions:
            continue
        if trans is not None:  # band-summed energy after the transmitting surfaces
            total = rows[:b].sum(axis=0)
        np.multiply(arrival, -total, out=rows[b : b + 3])
        np.multiply(dep, total, out=rows[b + 3 :])


@dataclass(frozen=True, eq=False)
class _Receivers:
    """Receiver positions and detection radii in the layouts the per-step tests use."""

    pos: np.ndarray  # (K, 3) float64
    pos_t: np.ndarray  # (3, K) float64
    cap: np.ndarray  # (K,) largest specular-detection radius
    centre: np.ndarray  # (3,) origin of the float32 screen's coordinates
    aug_tc: np.ndarray  # (4, K) float32: [R - centre; 1]
    aug_w2: np.ndarray  # (5, K) float32: [R - centre; 1; |R - centre|²]
    cap32: np.ndarray  # (K,) float32
    cap_sq32: np.ndarray  # (K,) float32
    max_sq: float  # largest |R - centre|²
    planes: tuple[np.ndarray, np.ndarray] | None  # a convex room's inward planes (n, d)
    inside: np.ndarray  # (K,) receiver strictly inside those planes

    @property
    def n(self) -> int:
        return len(self.pos)

    @classmethod
    def build(cls, scene: AcousticScene, receivers: np.ndarray, cap: np.ndarray) -> _Receivers:
        centre = scene.bounds.mean(axis=0)
        rel = receivers - centre
        sq = np.einsum("ij,ij->i", rel, rel)
        ones = np.ones(len(rel))
        planes = _convex_planes(scene)
        inside = np.zeros(len(receivers), dtype=bool)
        if planes is not None:
            inside = (receivers @ planes[0].T - planes[1]).min(axis=1) > _INSIDE_M
        return cls(
            pos=receivers,
            pos_t=np.ascontiguousarray(receivers.T),
            cap=cap,
            centre=centre,
            aug_tc=np.vstack([rel.T, ones]).astype(np.float32),
            aug_w2=np.vstack([rel.T, ones, sq]).astype(np.float32),
            cap32=cap.astype(np.float32),
            cap_sq32=(cap * cap).astype(np.float32),
            max_sq=float(sq.max()),
            planes=planes,
            inside=inside,
        )


def _convex_planes(scene: AcousticScene) -> tuple[np.ndarray, np.ndarray] | None:
    """The face planes oriented inwards, ``(normals (F, 3), offsets (F,))``, when every vertex
    lies on the inner side of every face plane (the faces bound a convex region: a shoebox,
    any convex room); None otherwise, with transmission, or for more than a few faces.

    Inside a convex region a segment between two points strictly inside every plane meets
    no face, so diffuse rain needs no shadow ray there (exactly what Embree would find, up to
    its float32 rounding at edges and corners).
    """
    if scene.has_transmission or scene.n_faces > _CONVEX_MAX_FACES:
        return None
    used = scene.vertices[np.unique(scene.faces)]
    side = used @ scene.normals.T - scene.plane_d[None, :]  # (V, F)
    tol = 1e-9 * max(1.0, float(np.max(np.abs(used))))
    for sign in (1.0, -1.0):
        if np.all(sign * side >= -tol):
            return sign * scene.normals, sign * scene.plane_d
    return None
