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
* **Specular splitting** (``RayTraceSettings.splitting = r > 0``): a ray that has never been
  scattered transmits (probability ``τ̄/(τ̄ + (1-τ)(1-α)‾)``) or reflects; reflected, it goes on
  specularly with the specular share, and the scattered share leaves as a child ray (Lambert,
  then one continuing ray per hit) with probability ``q = min(1, r·E/E₀)``, its energy divided
  by ``q`` — unbiased (tested against the plain scheme). With little scattering the late
  field rides on long specular chains; choosing one event per hit makes each chain survive
  by chance (``0.9^k`` after ``k`` walls), a heavy-tailed noise that splitting removes. Child
  probability ∝ energy keeps the children's energies alike and their number bounded. With
  guiding (below), a ray carrying a guiding weight below 1 — sent into a band at launch, at
  its birth as a child or at its first diffuse reflection — splits too: a child sent along
  a long-lived horizontal chain would otherwise keep it only by chance, which measured as
  the remaining heavy tail (one seed in 24 with T30 41 % long in the apartment of
  ``bench_rlr``; 7 % with it).
* **Horizontal guiding** (``RayTraceSettings.guiding = β > 0``; the spec's default 0.3): a
  share β of the launched directions, of each path's first diffuse reflection and of the
  splitting's children is drawn from thin horizontal bands ``|z| < w`` (z up) instead, each
  weighted by (plain density)/(mixture density) — unbiased (tested). Where floor and ceiling
  absorb more than the walls the late tail is carried by near-horizontal rays; plain
  sampling sends ~1 % of rays there. Termination and roulette compare a ray's energy with
  its weight, so a band ray is not stopped for being weighted down.
* **Air**: energy decays as ``exp(-m·L)`` along the path (``m`` = ISO 9613-1 ``air_m_per_band``).
  Since every contribution arriving at time ``t`` has travelled ``L = c·t``, this factor is
  applied per histogram bin at its centre (±0.4 % at 8 kHz for 1 ms bins) rather than per ray.
* **Termination**: a ray stops when its largest band energy is ``energy_threshold_db`` below its
  launch energy, or after ``max_time_s``. Energy below the threshold is dropped (a bias of at
  most ``10^(-threshold/10)`` of the total); no reflection-count cap, so live rooms are not
  truncated. With ``roulette_db = r > 0`` (the spec's default, 30) a ray whose largest band
  energy (with air) falls ``r`` dB below ``E₀`` plays Russian roulette at each hit: it goes on
  with probability ``E/E_r`` and is raised to ``E_r`` — unbiased, and most weak rays stop
  after a few more hits instead of dozens (tested against following every ray). Rays that
  hit nothing escaped the mesh: they are counted (``escaped_ray_fraction``), never silently
  dropped.
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
    With ``free_air_volume`` the sphere grows past the clearance (a scan's ceiling caps it
    near 1 m, where the late tail's horizontal rays need a wider target); beyond the
    clearance a chord counts only if the receiver sees its midpoint, and ``V`` is the volume
    of the air the receiver sees inside the sphere — both from one visibility map per
    receiver (see ``_visible_air``). The same estimator, averaged over more of the
    receiver's own room, never over air behind a wall (tested against the clearance-capped
    sphere in a flutter room and against a partition).
    It only counts segments whose last reflection was specular
    and whose path either has a diffuse reflection somewhere or more than
    ``specular_order_excluded`` reflections — purely specular paths up to that order are the
    image sources, and the first segment (no reflection) is the direct sound.

* **Histograms**: per receiver, per-band energy in ``bin_s`` bins up to ``max_time_s``, with the
  band-summed energy-weighted sums of the arrival direction (towards the last reflection point,
  or against the ray for sphere hits) and of the ray's departure direction (unless
  ``RayTraceSettings.directions`` is False: then NaN, and a little less is summed).
* **Many receivers**: one trace serves every receiver; sphere tests and shadow rays are the
  only per-receiver cost, and the shadow rays are bounded by ``rain_receivers_per_hit``: with
  more receivers each hit rains onto a random, evenly strided subset (weighted, unbiased), so
  100 receivers cost a few times one, not 100× (bench_tracer). For a moving source and a static
  microphone use reciprocity: trace from the microphone and pass the trajectory points as
  ``receivers``; ``EnergyHistogram.departure_sum`` then holds the direction at the microphone.
* **Execution**: per bounce step, one Embree query for the live rays' hits, one compiled pass
  (:mod:`._trace_kernels`, numba) for everything done per hit, one Embree query for the
  rain's shadow rays; faces with equal coefficients share one table row (a scan's 10⁵ faces
  have a few dozen materials), so the per-hit tables stay in cache.
* **Shortcuts that do not change the result** (each tested against the slow path): in a convex
  room (every vertex inside every face plane, no transmission) a shadow ray
  between two points inside it cannot be blocked and is not traced; receivers farther than
  ``max_receiver_radius_m`` from every face plane skip the clearance rays.
* **Determinism**: all randomness comes from the ``rng`` passed in (one spawned child generator
  per fixed batch of rays); batches may run on a thread pool but their histograms are summed
  in batch order, so the bytes of the result depend only on the inputs and the generator's
  state, never on the thread count.
* **Not modelled**: diffraction in the traced late field (the engine adds the early
  edge-diffracted paths, :mod:`sonicspec.acoustics.paths.edge_paths`), angle-dependent
  absorption, diffuse (scattered) transmission, phase/interference (energy only; the image
  sources carry the coherent early part), and surfaces thinner than ``AcousticScene.eps_m``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields

import numpy as np

from sonicspec.acoustics.arrivals import EnergyHistogram, TraceResult
from sonicspec.acoustics.directions import fibonacci_sphere
from sonicspec.acoustics.late import _trace_kernels as K
from sonicspec.acoustics.paths.direct import check_air, check_points
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S

__all__ = ["RayTraceSettings", "receiver_clearance_m", "trace_rays"]

# Largest (receivers × faces) for the plane-distance shortcut of the receivers' clearance.
_PLANE_TEST_PAIRS = 1 << 22
# Convex rooms of up to this many faces skip shadow rays between points inside them.
_CONVEX_MAX_FACES = 64
# "Strictly inside" a plane: farther than this on its inner side, metres.
_INSIDE_M = K._INSIDE_M
_NO_PLANES = np.zeros((0, 3))
_NO_OFFSETS = np.zeros(0)
_NO_TRANSMISSION = np.zeros((0, 0))
# Blocked shadow rays gathered before one walk through the walls (each walk step is one Embree
# call whatever its size, so walking many at once saves most of the calls).
_WALK_BATCH = 1 << 15
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


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
    free_air_volume : bool
        False: the specular-detection sphere stops growing at the receiver's clearance, so it
        always lies in free air. True: it grows to ``max_receiver_radius_m`` through nearby
        surfaces; there it counts only the air the receiver sees (a visibility map of 6,144
        Embree rays per receiver gives both the test and the volume ``V``). More crossings,
        less noise; the late energy density is then averaged over the visible air within that
        radius (never over air behind a wall or furniture).
    splitting : float
        0: one continuing ray per hit (see the module docstring). r > 0: specular splitting
        — a ray never scattered (or, with ``guiding``, carrying a guiding weight below 1)
        goes on specularly with the specular share, and its scattered
        share leaves as a child ray with probability ``min(1, r · E/E₀)`` (``E`` its largest
        band energy, ``E₀`` its launch energy), weighted by the inverse. Unbiased either way;
        it removes the chance of whether a long specular chain survives, the dominant noise
        of the late field in rooms with little scattering.
    roulette_db : float
        0: a ray is followed until ``energy_threshold_db`` down or ``max_time_s``. r > 0:
        once its strongest band (with air) falls ``r`` dB below its launch energy, Russian
        roulette: it goes on with probability ``E/E_r`` and its energy is raised to ``E_r``
        (unbiased). Weak rays then stop after a few more hits on average instead of spending
        tens of hits on the last tens of dB, and the tail past ``energy_threshold_db`` is no
        longer cut when ``r < energy_threshold_db`` (rays then stop only at ``max_time_s``).
    guiding : float
        0: directions as in the module docstring. β in (0, 1): a share β of the launched
        directions, of each path's first diffuse reflection and of the splitting's children
        goes to thin horizontal bands (``|z| <`` each of ``guiding_widths``, equal shares),
        weighted by the ratio of the plain to the mixed density (unbiased). In rooms whose
        floor and ceiling absorb more than the walls (furnished scans) the late tail rides on
        near-horizontal rays, a sliver of the sphere plain sampling reaches with few rays.
        Later diffuse reflections stay plain Lambert: a path multiplies at most two weights
        (products of many degenerate: in a live diffuse room most rays would carry almost
        nothing). Termination and roulette levels scale with the ray's weights.
    guiding_widths : tuple of float
        Half-widths in ``z`` (the sine of the elevation) of the guiding's bands.
    """

    n_rays: int = 20_000
    max_time_s: float = 2.0
    energy_threshold_db: float = 80.0
    bin_s: float = 0.001
    receiver_radius_m: float = 0.1
    radius_growth: float = 0.05
    max_receiver_radius_m: float = 1.0
    specular_order_excluded: int = 3
    speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S
    batch_size: int = 8192
    diffuse_rain: bool = True
    rain_receivers_per_hit: int = 8
    directions: bool = True
    splitting: float = 0.0
    free_air_volume: bool = False
    roulette_db: float = 0.0
    guiding: float = 0.0
    guiding_widths: tuple[float, ...] = (0.005, 0.02, 0.08)

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
            ("splitting", self.splitting, self.splitting >= 0, ">= 0 (0: off)"),
            ("roulette_db", self.roulette_db, self.roulette_db >= 0, ">= 0 (0: off)"),
            ("guiding", self.guiding, 0 <= self.guiding < 1, "in [0, 1) (0: off)"),
            (
                "guiding_widths",
                self.guiding_widths,
                len(self.guiding_widths) > 0 and all(0 < w <= 1 for w in self.guiding_widths),
                "one or more half-widths in (0, 1]",
            ),
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


def _guided_launch(n: int, rng: np.random.Generator, beta: float,
                   widths: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``n`` launch directions and their weights: ``floor(n·β/J)`` per horizontal band
    ``|z| < w_j`` (a lattice uniform in ``z`` and golden-ratio spaced in azimuth, randomly
    shifted), the rest on the rotated Fibonacci sphere. Each component is stratified and has
    a fixed count, so weighting every direction by ``p_uniform / Σ_j (n_j/n)·p_j`` (the
    balance heuristic over the components) keeps the sum unbiased."""
    counts = [math.floor(n * beta / len(widths))] * len(widths)  # leaves >= 1 on the sphere
    n_sphere = n - sum(counts)
    parts = [_rotated_fibonacci_sphere(n_sphere, rng)] if n_sphere else []
    for m, w in zip(counts, widths, strict=True):
        if m == 0:
            continue
        shift = rng.random(2)
        i = np.arange(m)
        z = w * (2.0 * (i + shift[0]) / m - 1.0)
        phi = 2.0 * math.pi * ((i * _GOLDEN + shift[1]) % 1.0)
        r = np.sqrt(1.0 - z * z)
        parts.append(np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1))
    dirs = np.concatenate(parts)
    az = np.abs(dirs[:, 2])
    density = n_sphere / n + sum(m / n * (az < w) / w for m, w in zip(counts, widths, strict=True))
    return dirs, 1.0 / density


def trace_rays(
    scene: AcousticScene,
    source: np.ndarray,
    receivers: np.ndarray,
    rng: np.random.Generator,
    settings: RayTraceSettings | None = None,
    air_m_per_band: np.ndarray | None = None,
    n_threads: int = 1,
    progress: Callable[[int, int], None] | None = None,
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
    progress : callable, optional
        Called as ``progress(rays_done, rays_total)`` after every batch (for long traces).

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
    clear = np.maximum(
        settings.receiver_radius_m,
        np.minimum(
            settings.max_receiver_radius_m,
            _clearance_below(scene, receivers, settings.max_receiver_radius_m),
        ),
    )
    if settings.free_air_volume:
        radius_cap = np.full(len(receivers), max(settings.receiver_radius_m,
                                                 settings.max_receiver_radius_m))
        depth, volume = _visible_air(scene, receivers, radius_cap)
    else:
        radius_cap, volume = clear, np.zeros((len(receivers), 2))
        depth = np.zeros((len(receivers), 0))
    rcv = _Receivers.build(scene, receivers, radius_cap, clear, volume, depth)
    sizes = [
        min(settings.batch_size, settings.n_rays - start)
        for start in range(0, settings.n_rays, settings.batch_size)
    ]
    rngs = rng.spawn(len(sizes))
    tables = _event_tables(scene)

    def run(i: int) -> tuple[_Histograms, int, int]:
        acc = _Histograms.zeros(len(receivers), n_bins, scene.n_bands, settings.directions)
        esc, hits = _trace_batch(
            scene, source[0], rcv, rngs[i], settings, air, sizes[i], acc, tables
        )
        return acc, esc, hits

    total: _Histograms | None = None
    escaped = 0
    interactions = 0
    folded = [0]

    def fold(result: tuple[_Histograms, int, int]) -> None:
        nonlocal total, escaped, interactions
        acc, esc, hits = result
        escaped += esc
        interactions += hits
        if total is None:
            total = acc
        else:
            total.energy += acc.energy
            total.directions += acc.directions
        folded[0] += 1
        if progress is not None:
            progress(sum(sizes[: folded[0]]), settings.n_rays)

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
    not_traced = np.full((n_bins, 3), np.nan)
    out = []
    for r in range(len(receivers)):
        raw = total.energy[r]  # (n_bins, n_bands)
        energy = raw * air_gain
        if settings.directions:
            before = raw.sum(axis=1)
            ratio = energy.sum(axis=1) / np.where(before > 0, before, 1.0)
            ratio = np.where(before > 0, ratio, 0.0)[:, None]
            arrival = total.directions[r, :, :3] * ratio
            departure = total.directions[r, :, 3:] * ratio
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
    """Per-face geometry and per-material event probabilities and energy gains.

    Faces with the same coefficients form one class (a scan has a few dozen materials and
    ~10⁵ faces): the compiled step reads small class tables that stay in cache instead of
    per-face ones. Event e (0 transmit, 1 specular, 2 diffuse) has per-band weight ``w_e`` and
    is chosen with probability ``P_e = mean_b(w_e) / Σ_e' mean_b(w_e')``; the ray's energy is
    multiplied by ``gain[e] = w_e / P_e`` (0 where ``P_e = 0``), so its expectation is
    ``Σ_e w_e`` per band.
    """

    planes: np.ndarray  # (F, 4) unit normal and plane offset per face
    face_class: np.ndarray  # (F,) int32 coefficient class of each face
    p_t: np.ndarray  # (C,) P(transmit)
    p_ts: np.ndarray  # (C,) P(transmit) + P(specular)
    gain: np.ndarray  # (3, C, B)
    w_diff: np.ndarray  # (C, B) scattered energy fraction (1-τ)(1-α)s
    scatters: np.ndarray  # (C,) any band scatters
    ps_t: np.ndarray  # (C,) P(transmit) of a splitting ray
    split_gain: np.ndarray  # (3, C, B) its gains: transmit, specular, scattered (child: × 1/q)


def _event_tables(scene: AcousticScene) -> _EventTables:
    """Built once per scene (a trajectory's many traces reuse it)."""
    return scene.memoized("raytrace.event_tables", lambda: _build_event_tables(scene))


def _build_event_tables(scene: AcousticScene) -> _EventTables:
    face_class, first = scene.coefficient_classes()
    alpha, scattering, tau = (np.take(x, first, axis=0)
                              for x in (scene.absorption, scene.scattering, scene.transmission))
    w_refl = (1.0 - tau) * (1.0 - alpha)
    w_diff = w_refl * scattering
    weights = np.stack([tau, w_refl - w_diff, w_diff])  # (3, C, B)
    means = weights.mean(axis=2)  # (3, C)
    total = means.sum(axis=0)
    prob = means / np.where(total > 0, total, 1.0)
    gain = np.where(prob[:, :, None] > 0, weights / np.where(prob > 0, prob, 1.0)[:, :, None], 0)
    # A splitting ray transmits or reflects; reflected, it goes on specularly and its
    # scattered share leaves as a child ray (with probability q; the gain here is for q = 1).
    p_split = means[0] / np.where(means[0] + means[1] + means[2] > 0,
                                  means[0] + means[1] + means[2], 1.0)
    refl = np.where(p_split < 1.0, 1.0 - p_split, 1.0)[:, None]
    split_gain = np.stack([
        np.where(p_split[:, None] > 0, tau / np.where(p_split > 0, p_split, 1.0)[:, None], 0.0),
        (w_refl - w_diff) / refl, w_diff / refl])
    tables = _EventTables(
        planes=np.ascontiguousarray(np.column_stack([scene.normals, scene.plane_d])),
        face_class=face_class.astype(np.int32),
        p_t=np.ascontiguousarray(prob[0]),
        # A face that absorbs everything (total 0): every pick lands on "diffuse", gain 0.
        p_ts=prob[0] + prob[1],
        gain=np.ascontiguousarray(gain),
        w_diff=np.ascontiguousarray(w_diff),
        scatters=np.any(w_diff > 0, axis=1),
        ps_t=np.ascontiguousarray(p_split),
        split_gain=np.ascontiguousarray(split_gain),
    )
    return tables


@dataclass(eq=False)
class _Histograms:
    """Per-receiver sums of one batch: ``energy (K, n_bins, n_bands)`` without air absorption
    (applied per bin at the end, see :func:`trace_rays`), and ``directions (K, n_bins, 6)``:
    the energy-weighted arrival and departure direction sums (``(K, 0, 6)`` when not kept)."""

    energy: np.ndarray
    directions: np.ndarray

    @classmethod
    def zeros(cls, n_receivers: int, n_bins: int, n_bands: int, directions: bool) -> _Histograms:
        return cls(np.zeros((n_receivers, n_bins, n_bands)),
                   np.zeros((n_receivers, n_bins if directions else 0, 6)))


def _trace_batch(
    scene: AcousticScene,
    src: np.ndarray,
    rcv: _Receivers,
    rng: np.random.Generator,
    st: RayTraceSettings,
    air: np.ndarray,
    n: int,
    acc: _Histograms,
    ev: _EventTables,
) -> tuple[int, int]:
    """Trace ``n`` rays to termination; returns (escaped rays, surface interactions).

    Each bounce step: one Embree query for the live rays' hits, one compiled pass
    (:func:`._trace_kernels.bounce`) for everything done per hit, then one Embree query for
    the diffuse rain's shadow rays. Ray energies exclude air absorption (applied per bin
    afterwards) except in the termination test.
    """
    limit = st.rain_receivers_per_hit
    stride = 1 if limit == 0 or rcv.n <= limit else -(-rcv.n // limit)
    n_slots = rcv.n if stride == 1 else -(-rcv.n // stride)
    fp, ip = _kernel_params(scene, rcv, st, air, acc.energy.shape[1], stride)
    split = st.splitting > 0
    # Uniform draws per hit: event, two for a direction, the split, the roulette and the
    # guiding's proposal draws.
    guided = st.guiding > 0
    n_draws = (K.U_GUIDE + 1 if guided else
               K.U_ROULETTE + 1 if st.roulette_db > 0 else (4 if split else 3))
    widths = np.asarray(st.guiding_widths, dtype=np.float64)
    plane_n, plane_off = rcv.planes if rcv.planes is not None else (_NO_PLANES, _NO_OFFSETS)

    # Separate streams: ray paths do not depend on how the rain is subsampled or walked.
    rng, rain_rng = rng.spawn(2)
    if guided:
        dirs, ref = _guided_launch(n, rng, st.guiding, st.guiding_widths)
    else:
        dirs, ref = _rotated_fibonacci_sphere(n, rng), np.ones(n)
    departure = dirs.copy()
    pos = np.repeat(src[None, :], n, axis=0)
    energy = np.repeat(ref[:, None] / st.n_rays, scene.n_bands, axis=1)
    length = np.zeros(n)
    n_refl = np.zeros(n, dtype=np.int64)
    any_diffuse = np.zeros(n, dtype=bool)
    last_diffuse = np.zeros(n, dtype=bool)
    no_offsets = np.zeros(0, dtype=np.int64)
    walks: list[_RainQueue] = []  # blocked shadow rays waiting to be walked through walls
    n_walks = 0  # how many
    escaped = 0
    interactions = 0
    while n:
        face, tfar = scene.first_hits(pos[:n], dirs[:n])
        u = rng.random((n, n_draws))
        offsets = rain_rng.integers(0, stride, n) if stride > 1 else no_offsets
        m = n * n_slots if st.diffuse_rain else 0
        req = _RainQueue.empty(m, scene.n_bands, st.directions)
        kids = _Children.empty(n if split else 0, scene.n_bands)
        n, n_req, esc, hits, n_kids = K.bounce(
            (pos, dirs, energy, length, n_refl, any_diffuse, last_diffuse, departure, ref),
            (face, tfar, u, offsets),
            (ev.planes, ev.face_class, ev.p_t, ev.p_ts, ev.gain, ev.w_diff, ev.scatters,
             ev.ps_t, ev.split_gain),
            (rcv.pos, rcv.cap, rcv.inside, plane_n, plane_off, rcv.order, rcv.key, rcv.clear,
             rcv.volume, rcv.depth),
            air, fp, ip, widths,
            (acc.energy, acc.directions),
            (req.origin, req.direction, req.length, req.receiver, req.bin, req.energy,
             req.departure),
            (kids.pos, kids.dirs, kids.energy, kids.length, kids.n_refl, kids.departure,
             kids.ref),
        )  # fmt: skip
        escaped += esc
        interactions += hits
        if n_req:
            n_walks += _settle_rain(scene, req.head(n_req), rain_rng, acc, st.directions, walks)
            if n_walks >= _WALK_BATCH:
                _walk_rain(scene, rcv, walks, acc, st.directions)
                n_walks = 0
        if n_kids:  # children join the live rays: diffusely reflected once
            pos, dirs, energy, length, n_refl, departure, ref = (
                np.concatenate([a[:n], b[:n_kids]]) for a, b in (
                    (pos, kids.pos), (dirs, kids.dirs), (energy, kids.energy),
                    (length, kids.length), (n_refl, kids.n_refl), (departure, kids.departure),
                    (ref, kids.ref)))
            yes = np.ones(n_kids, dtype=bool)
            any_diffuse = np.concatenate([any_diffuse[:n], yes])
            last_diffuse = np.concatenate([last_diffuse[:n], yes])
            n += n_kids
    _walk_rain(scene, rcv, walks, acc, st.directions)
    return escaped, interactions


def _kernel_params(scene: AcousticScene, rcv: _Receivers, st: RayTraceSettings,
                   air: np.ndarray, n_bins: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """The float and integer parameter vectors of :func:`._trace_kernels.bounce`."""
    to_p2 = 1.0 / (4.0 * math.pi)  # p² per unit "energy per area": see the module docstring
    fp = np.zeros(K.N_FLOAT_PARAMS)
    fp[K.F_SPEED] = st.speed_of_sound_m_s
    fp[K.F_BIN] = st.bin_s
    fp[K.F_RADIUS] = st.receiver_radius_m
    fp[K.F_GROWTH] = st.radius_growth
    fp[K.F_MAX_LEN] = st.speed_of_sound_m_s * st.max_time_s
    fp[K.F_E_STOP] = 10.0 ** (-st.energy_threshold_db / 10.0) / st.n_rays
    fp[K.F_EPS] = scene.eps_m
    fp[K.F_TO_P2] = to_p2
    # ΔΩ/π per πR², converted to p², times the rain's subsampling weight.
    fp[K.F_RAIN_SCALE] = stride * to_p2 / (math.pi * math.pi * st.receiver_radius_m**2)
    fp[K.F_CHILD_P] = st.splitting
    fp[K.F_E0] = 1.0 / st.n_rays
    fp[K.F_E_ROULETTE] = (10.0 ** (-st.roulette_db / 10.0) / st.n_rays if st.roulette_db > 0
                          else 0.0)
    fp[K.F_GUIDE] = st.guiding
    # No detection sphere is larger than this: the reach of the receiver culling.
    fp[K.F_R_MAX] = (1.0 + 1e-9) * max(st.receiver_radius_m, float(rcv.cap.max())) + 1e-9
    ip = np.zeros(K.N_INT_PARAMS, dtype=np.int64)
    ip[K.I_N_BINS] = n_bins
    ip[K.I_EXCLUDED] = st.specular_order_excluded
    ip[K.I_RAIN] = int(st.diffuse_rain)
    ip[K.I_DIRECTIONS] = int(st.directions)
    ip[K.I_STRIDE] = stride
    ip[K.I_AIR] = int(np.any(air > 0))
    ip[K.I_CONVEX] = int(rcv.planes is not None)
    ip[K.I_SPLIT] = int(st.splitting > 0)
    ip[K.I_AXIS] = rcv.axis
    ip[K.I_MAP_N] = _VISIBILITY_CELLS if rcv.depth.shape[1] else 0
    return fp, ip


@dataclass(frozen=True, eq=False)
class _Children:
    """Child rays spawned in one bounce step by splitting rays (see ``splitting``)."""

    pos: np.ndarray
    dirs: np.ndarray
    energy: np.ndarray
    length: np.ndarray
    n_refl: np.ndarray
    departure: np.ndarray
    ref: np.ndarray

    @classmethod
    def empty(cls, m: int, n_bands: int) -> _Children:
        return cls(np.empty((m, 3)), np.empty((m, 3)), np.empty((m, n_bands)), np.empty(m),
                   np.empty(m, dtype=np.int64), np.empty((m, 3)), np.empty(m))


@dataclass(frozen=True, eq=False)
class _RainQueue:
    """Shadow rays of one bounce step: start, unit direction, length, receiver, time bin,
    band energies (before transmission) and the departure direction of their ray."""

    origin: np.ndarray
    direction: np.ndarray
    length: np.ndarray
    receiver: np.ndarray
    bin: np.ndarray
    energy: np.ndarray
    departure: np.ndarray

    @classmethod
    def empty(cls, m: int, n_bands: int, directions: bool) -> _RainQueue:
        return cls(np.empty((m, 3)), np.empty((m, 3)), np.empty(m), np.empty(m, dtype=np.int64),
                   np.empty(m, dtype=np.int64), np.empty((m, n_bands)),
                   np.empty((m if directions else 0, 3)))

    def _arrays(self) -> tuple[np.ndarray, ...]:
        return tuple(getattr(self, f.name) for f in fields(self))

    def _map(self, fn: Callable[[np.ndarray], np.ndarray]) -> _RainQueue:
        """``fn`` on every field's rows; an empty field (departures not kept) stays empty."""
        return _RainQueue(*(fn(x) if len(x) else x for x in self._arrays()))

    def take(self, rows: np.ndarray) -> _RainQueue:
        return self._map(lambda x: np.take(x, rows, axis=0))

    def head(self, n: int) -> _RainQueue:
        return self._map(lambda x: x[:n])

    @classmethod
    def concatenate(cls, queues: list[_RainQueue]) -> _RainQueue:
        if len(queues) == 1:
            return queues[0]
        return cls(*(np.concatenate(parts) for parts in zip(*(q._arrays() for q in queues),
                                                             strict=True)))


def _settle_rain(scene: AcousticScene, req: _RainQueue, rng: np.random.Generator,
                 acc: _Histograms, directions: bool, walks: list[_RainQueue]) -> int:
    """Traces the queued shadow rays and adds those that reach their receiver.

    A blocked shadow ray through transmitting surfaces is walked through them with
    probability ``q = max τ`` (Russian roulette) and its ``Π τ`` divided by ``q``: unbiased,
    and ``Π τ / q <= 1`` since it crosses at least one surface; the rest stop here. Most
    blocked rays would come out tens of dB down, and walking them was most of the cost. The
    chosen ones are appended to ``walks`` and walked together by :func:`_walk_rain` (a walk
    takes one Embree call per surface crossed, whatever the number of rays). Returns how many
    it appended.
    """
    blocked = scene.occluded_along(req.origin, req.direction, req.length)
    q = min(1.0, scene.max_transmission)
    n_walked = 0
    if q > 0 and blocked.any():
        walked = np.flatnonzero(blocked)
        walked = walked[rng.random(walked.size) < q]
        if walked.size:
            walks.append(req.take(walked))
            n_walked = walked.size
    K.deposit(req.receiver, req.bin, req.direction, req.energy, req.departure, blocked,
              _NO_TRANSMISSION, directions, acc.energy, acc.directions)
    return n_walked


def _walk_rain(scene: AcousticScene, rcv: _Receivers, walks: list[_RainQueue],
               acc: _Histograms, directions: bool) -> None:
    """Walks the blocked shadow rays chosen by the roulette through the surfaces they cross
    and adds them weighted by ``Π τ / q``; empties ``walks``."""
    if not walks:
        return
    req = _RainQueue.concatenate(walks)
    walks.clear()
    trans = scene.crossed_transmission(req.origin, np.take(rcv.pos, req.receiver, axis=0))
    trans /= min(1.0, scene.max_transmission)
    K.deposit(req.receiver, req.bin, req.direction, req.energy, req.departure,
              np.zeros(len(req.receiver), dtype=bool), trans, directions, acc.energy,
              acc.directions)


def receiver_clearance_m(
    scene: AcousticScene, receivers: np.ndarray, n_directions: int = 4096
) -> np.ndarray:
    """Distance from each receiver to the nearest surface, metres (sampled by Embree rays).

    ``n_directions`` rays on a Fibonacci sphere; the nearest hit distance times the cosine of
    half the lattice spacing bounds the distance to a plane from below. Small objects between
    the rays can be missed (the radius is then slightly too large near them).
    """
    receivers = check_points("receivers", receivers)
    spacing = math.sqrt(4.0 * math.pi / n_directions)
    dist = _hit_distances(scene, receivers, fibonacci_sphere(n_directions))
    return dist.min(axis=1) * math.cos(spacing)


def _hit_distances(scene: AcousticScene, receivers: np.ndarray, dirs: np.ndarray
                   ) -> np.ndarray:
    """Distance ``(K, D)`` from every receiver to the first surface along every direction
    (``inf`` where the ray escapes), several receivers per Embree call (about 2^18 rays):
    far fewer calls for many receivers."""
    out = np.empty((len(receivers), len(dirs)))
    per = max(1, (1 << 18) // len(dirs))
    for r0 in range(0, len(receivers), per):
        block = receivers[r0 : r0 + per]
        _, dist = scene.intersect(np.repeat(block, len(dirs), axis=0),
                                  np.tile(dirs, (len(block), 1)))
        out[r0 : r0 + len(block)] = dist.reshape(len(block), len(dirs))
    return out


# Cells per cube-face edge of a receiver's visibility map (6 · 32² = 6,144 Embree rays).
_VISIBILITY_CELLS = 32


def _cube_cells(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit centre directions ``(6n², 3)`` and exact solid angles ``(6n²,)`` of the cells of a
    cube map, in the order :func:`._trace_kernels.cube_cell` indexes them (face ``2a + (x_a <
    0)``, then the cell along axis ``(a+1) % 3``, then along ``(a+2) % 3``)."""
    edges = np.linspace(-1.0, 1.0, n + 1)
    mid = 0.5 * (edges[1:] + edges[:-1])

    def corner(u, v):  # solid angle of the face rectangle [0, u] × [0, v] at distance 1
        return np.arctan(u * v / np.sqrt(1.0 + u * u + v * v))

    u0, v0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    u1, v1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")
    cell = (corner(u1, v1) - corner(u0, v1) - corner(u1, v0) + corner(u0, v0)).ravel()
    uc, vc = (g.ravel() for g in np.meshgrid(mid, mid, indexing="ij"))
    dirs, solid = [], []
    for face in range(6):
        a, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
        d = np.empty((n * n, 3))
        d[:, a], d[:, (a + 1) % 3], d[:, (a + 2) % 3] = sign, uc, vc
        dirs.append(d / np.linalg.norm(d, axis=1, keepdims=True))
        solid.append(cell)
    return np.concatenate(dirs), np.concatenate(solid)


def _visible_air(scene: AcousticScene, receivers: np.ndarray, cap: np.ndarray,
                 n_radii: int = 65, n_cells: int = _VISIBILITY_CELLS
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Each receiver's visibility map and the volume of the air it sees within radii
    ``r_j = j/(n_radii-1) · cap``.

    The map holds, per cube-map cell, the distance from the receiver to the first surface
    along the cell's centre direction (one Embree ray each; ``inf`` where the ray escapes).
    The visible region is the union of each cell's cone cut at that distance, so its volume
    within ``r`` is exactly ``Σ_cells ΔΩ · min(d, r)³ / 3``, and the tracer tests a point
    against the same map: the estimator and its volume describe the same region. Air behind
    a wall or a cupboard is not part of it, wherever the ball reaches.

    Returns ``(depth (K, 6·n_cells²) float64, volume (K, n_radii) m³)``.
    """
    dirs, solid = _cube_cells(n_cells)
    depth = _hit_distances(scene, receivers, dirs)
    volume = np.empty((len(receivers), n_radii))
    for k in range(len(receivers)):
        # Cells sorted by depth: within r, the nearer ones count their whole cone (running
        # sums of ΔΩ·d³) and the rest a cone cut at r (r³ × the rest of their ΔΩ).
        order = np.argsort(depth[k], kind="stable")
        d, w = depth[k][order], solid[order]
        near = np.concatenate([[0.0], np.cumsum(w * np.where(np.isfinite(d), d, 0.0) ** 3)])
        seen = np.concatenate([[0.0], np.cumsum(w)])
        radii = np.linspace(0.0, cap[k], n_radii)
        j = np.searchsorted(d, radii, side="left")  # cells nearer than each radius
        volume[k] = (near[j] + radii**3 * (seen[-1] - seen[j])) / 3.0
    return depth, volume


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


@dataclass(frozen=True, eq=False)
class _Receivers:
    """Receiver positions, largest specular-detection radii and the convex-room shortcut."""

    pos: np.ndarray  # (K, 3) float64
    cap: np.ndarray  # (K,) largest specular-detection radius
    planes: tuple[np.ndarray, np.ndarray] | None  # a convex room's inward planes (n, d)
    inside: np.ndarray  # (K,) receiver strictly inside those planes
    axis: int  # the axis along which the receivers spread widest
    order: np.ndarray  # (K,) receivers sorted along it
    key: np.ndarray  # (K,) their coordinates along it, ascending
    clear: np.ndarray  # (K,) largest radius of a ball entirely in free air
    volume: np.ndarray  # (K, J) volume of the visible air in the ball at radii j/(J-1) · cap
    depth: np.ndarray  # (K, cells) visibility map (see _visible_air); (K, 0) when not used

    @property
    def n(self) -> int:
        return len(self.pos)

    @classmethod
    def build(cls, scene: AcousticScene, receivers: np.ndarray, cap: np.ndarray,
              clear: np.ndarray, volume: np.ndarray, depth: np.ndarray) -> _Receivers:
        planes = _convex_planes(scene)
        inside = np.zeros(len(receivers), dtype=bool)
        if planes is not None:
            inside = (receivers @ planes[0].T - planes[1]).min(axis=1) > _INSIDE_M
        axis = int(np.argmax(np.ptp(receivers, axis=0)))
        order = np.argsort(receivers[:, axis], kind="stable")
        return cls(pos=np.ascontiguousarray(receivers), cap=np.ascontiguousarray(cap),
                   planes=planes, inside=inside, axis=axis, order=order.astype(np.int64),
                   key=np.ascontiguousarray(receivers[order, axis]),
                   clear=np.ascontiguousarray(clear), volume=np.ascontiguousarray(volume),
                   depth=np.ascontiguousarray(depth))


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
            return (np.ascontiguousarray(sign * scene.normals),
                    np.ascontiguousarray(sign * scene.plane_d))
    return None
