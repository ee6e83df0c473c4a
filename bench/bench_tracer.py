"""Tracer throughput: rays/s against the raw Embree ceiling, one RIR, many receivers at once.

Reproduce:  python bench/bench_tracer.py            (about a minute on 2 cores)
            python bench/bench_tracer.py --pra      (adds pyroomacoustics' hybrid simulator)
            python bench/bench_tracer.py --only trajectory   (the trajectory case alone)
            python bench/bench_tracer.py --only equal-accuracy  (one RIR vs pyroomacoustics)

Figures printed:
* raw embreex first-hit rate (the ceiling) in the 10 x 7 x 3 m shoebox, 1 and 2 threads;
* tracer throughput: surface hits per second (each hit = one first-hit query, one Lambert
  shadow ray per receiver, sphere tests and the bookkeeping in numpy);
* one RIR's histograms (direct + image sources order 3 + rays) at 2 000 and 20 000 rays, with
  T30 per band against Eyring (with ISO 9613-1 air absorption) and the seed-to-seed spread;
* N = 1, 10, 100 receivers traced at once;
* trajectory: 100 source points along a 5 m line, static mic — sonicspec's ``simulate_rirs``
  (one trace from the mic, reciprocity) against 100 separate pyroomacoustics hybrid RIRs, side
  by side, with times, T30 per band against Eyring, and the tracer on 1 vs 2 threads.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sonicspec.acoustics import engine
from sonicspec.acoustics.late.raytrace import RayTraceSettings, trace_rays
from sonicspec.acoustics.paths.direct import direct_sound
from sonicspec.acoustics.paths.image_sources import image_sources, planar_regions
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.acoustics.room.simplify import simplified_scene
from sonicspec.acoustics.theory import shoebox_decay_t60
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.units import SPEED_OF_SOUND_M_S as C_M_S

BANDS_HZ = np.array([125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0])
SIZE = (10.0, 7.0, 3.0)
SRC = np.array([2.1, 3.3, 1.4])
RCV = np.array([[7.2, 4.9, 1.6]])


def shoebox(lx: float, ly: float, lz: float) -> tuple[np.ndarray, np.ndarray]:
    v = np.array(
        [
            [0, 0, 0],
            [lx, 0, 0],
            [lx, ly, 0],
            [0, ly, 0],
            [0, 0, lz],
            [lx, 0, lz],
            [lx, ly, lz],
            [0, ly, lz],
        ],
        dtype=float,
    )
    f = [(0, 1, 2), (0, 2, 3), (4, 6, 5), (4, 7, 6)]
    for i in range(4):
        j = (i + 1) % 4
        f += [(i, j + 4, j), (i, i + 4, j + 4)]
    return v, np.array(f)


def iso9613_energy_per_m(f_hz: np.ndarray, temperature_c: float = 20.0, rh_pct: float = 50.0):
    t, t0, t01 = temperature_c + 273.15, 293.15, 273.16
    h = rh_pct * 10 ** (-6.8346 * (t01 / t) ** 1.261 + 4.6151)
    fr_o = 24 + 4.04e4 * h * (0.02 + h) / (0.391 + h)
    fr_n = (t / t0) ** -0.5 * (9 + 280 * h * np.exp(-4.170 * ((t / t0) ** (-1 / 3) - 1)))
    db = (
        8.686
        * f_hz**2
        * (
            1.84e-11 * (t / t0) ** 0.5
            + (t / t0) ** -2.5
            * (
                0.01275 * np.exp(-2239.1 / t) / (fr_o + f_hz**2 / fr_o)
                + 0.1068 * np.exp(-3352.0 / t) / (fr_n + f_hz**2 / fr_n)
            )
        )
    )
    return db / (10 * math.log10(math.e))


def schroeder_t30(energy: np.ndarray, bin_s: float) -> np.ndarray:
    edc = np.cumsum(energy[::-1], axis=0)[::-1]
    t = np.arange(len(energy)) * bin_s
    out = []
    for b in range(energy.shape[1]):
        with np.errstate(divide="ignore"):
            db = 10 * np.log10(edc[:, b] / edc[0, b])
        sel = (db <= -5) & (db >= -35)
        out.append(-60.0 / np.polyfit(t[sel], db[sel], 1)[0])
    return np.array(out)


def scene_for(alpha: float, s: float) -> AcousticScene:
    v, f = shoebox(*SIZE)
    n, b = len(f), len(BANDS_HZ)
    return AcousticScene(v, f, np.full((n, b), alpha), np.full((n, b), s), np.zeros((n, b)))


def raw_embree(scene: AcousticScene, n: int = 400_000, repeats: int = 5) -> None:
    rng = np.random.default_rng(0)
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.c_[rng.uniform(0.5, 9.5, n), rng.uniform(0.5, 6.5, n), rng.uniform(0.5, 2.5, n)]
    o32 = (o - scene._shift).astype(np.float32)
    d32 = d.astype(np.float32)
    emb = scene._embree
    emb.run(o32, d32)
    t = time.perf_counter()
    for _ in range(repeats):
        emb.run(o32, d32, output=1)
    one = n * repeats / (time.perf_counter() - t)
    t = time.perf_counter()
    for _ in range(repeats):
        emb.run(o32, d32, query="OCCLUDED")
    occ = n * repeats / (time.perf_counter() - t)
    half = n // 2
    with ThreadPoolExecutor(2) as ex:
        t = time.perf_counter()
        for _ in range(repeats):
            list(
                ex.map(
                    lambda sl: emb.run(o32[sl], d32[sl], output=1), [slice(0, half), slice(half, n)]
                )
            )
        two = n * repeats / (time.perf_counter() - t)
    print(f"raw embreex first hit (with distances), 1 thread : {one / 1e6:6.2f} M rays/s")
    print(f"raw embreex first hit (with distances), 2 threads: {two / 1e6:6.2f} M rays/s")
    print(f"raw embreex occlusion, 1 thread                  : {occ / 1e6:6.2f} M rays/s")


def one_rir(
    scene: AcousticScene,
    air: np.ndarray,
    n_rays: int,
    seed: int,
    receivers=RCV,
    diffuse_rain: bool = True,
):
    t0 = time.perf_counter()
    regions = planar_regions(scene)
    ism = image_sources(scene, SRC, receivers, max_order=3, air_m_per_band=air, regions=regions)
    direct = direct_sound(scene, SRC, receivers, air_m_per_band=air)
    t1 = time.perf_counter()
    settings = RayTraceSettings(
        n_rays=n_rays,
        max_time_s=1.5,
        specular_order_excluded=ism.max_order,
        diffuse_rain=diffuse_rain,
    )
    res = trace_rays(
        scene, SRC, receivers, np.random.default_rng(seed), settings, air_m_per_band=air
    )
    t2 = time.perf_counter()
    h = res[0].histogram
    energy = (
        h.energy
        + ism.arrivals[0].energy_histogram(h.bin_s, h.n_bins)
        + direct[0].energy_histogram(h.bin_s, h.n_bins)
    )
    return energy, h.bin_s, t1 - t0, t2 - t1, res[0]


TRAJ_MIC = np.array([5.0, 5.5, 1.6])
TRAJ_LINE = (np.array([2.5, 2.0, 1.5]), np.array([7.5, 2.0, 1.5]))  # 5 m, 3.5-4.3 m from the mic


def _timed(module, name: str, totals: dict[str, float]) -> None:
    """Wrap ``module.name`` so its wall time adds up in ``totals[name]``."""
    inner = getattr(module, name)

    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            totals[name] = totals.get(name, 0.0) + time.perf_counter() - t

    setattr(module, name, wrapper)


def _t30_stats(rirs: list[np.ndarray], fs: int, bands: tuple[float, ...]) -> np.ndarray:
    from sonicspec.acoustics.metrics import room_acoustic_figures

    return np.array([room_acoustic_figures(r, fs, bands).t30_s for r in rirs])


def warm_up() -> None:
    """Loads the tracer's compiled kernels (numba's on-disk cache; compiled on first use)
    once per process, as every build job does, and prints what that costs."""
    v, f = shoebox(4.0, 3.0, 2.5)
    scene = AcousticScene(v, f, np.full((len(f), 1), 0.2), np.full((len(f), 1), 0.5),
                          np.zeros((len(f), 1)))
    t = time.perf_counter()
    trace_rays(scene, np.array([1.0, 1.0, 1.0]), np.array([[3.0, 2.0, 1.5]]),
               np.random.default_rng(0), RayTraceSettings(n_rays=50, max_time_s=0.05))
    print(f"(compiled tracer kernels loaded once per process: {time.perf_counter() - t:.2f} s)")


def trajectory(n_points: int = 100, n_rays: int = 2_000) -> None:
    """One static mic, a moving source: one trace for all points vs one pra RIR per point."""
    from sonicspec.acoustics.bands import default_bands

    fs = 16_000
    bands = default_bands(fs)  # the spec's "auto": 125 Hz - 4 kHz at 16 kHz
    settings = engine.SimulationSettings(
        sample_rate_hz=fs, bands_hz=bands, rays=n_rays, image_source_order=3,
        max_rir_length_s=1.5, energy_threshold_db=80.0, air_absorption=True, temperature_c=20.0,
        relative_humidity_pct=50.0, transmission=False, diffuse_rain=True,
        receiver_radius_m=0.1, histogram_bin_s=0.001, speed_of_sound_m_s=C_M_S,
    )  # fmt: skip
    v, f = shoebox(*SIZE)
    n, b = len(f), len(bands)
    scene = AcousticScene(v, f, np.full((n, b), 0.2), np.full((n, b), 0.5), np.zeros((n, b)))
    a, z = TRAJ_LINE
    points = a + np.linspace(0.0, 1.0, n_points)[:, None] * (z - a)
    air = iso9613_energy_per_m(np.array(bands))
    eyring = 24 * math.log(10) * 210.0 / (C_M_S * (-242.0 * math.log(0.8) + 4 * air * 210.0))
    print(f"\n## trajectory: {n_points} source points on a 5 m line, static mic, 10 x 7 x 3 m, "
          f"alpha 0.2, s 0.5, {n_rays} rays, ISM order 3, {fs} Hz, bands {list(bands)}")
    print("Eyring T30 [s]:", np.round(eyring, 3))

    # sonicspec: the engine's own function (what the rir stage calls), its pieces timed in passing
    warm_up()
    totals: dict[str, float] = {}
    for name in ("direct_sound", "image_sources", "trace_rays", "synthesize_rir"):
        _timed(engine, name, totals)
    t = time.perf_counter()
    rirs, facts = engine.simulate_rirs(scene, TRAJ_MIC, points, settings,
                                       np.random.default_rng(0))
    t_ss = time.perf_counter() - t
    rest = t_ss - sum(totals.values())
    print(f"sonicspec simulate_rirs: {t_ss:6.2f} s for {n_points} RIRs "
          f"({t_ss / n_points * 1e3:.0f} ms/RIR): trace {totals['trace_rays']:.2f} s, image "
          f"sources {totals['image_sources']:.2f} s, direct {totals['direct_sound']:.2f} s, "
          f"synthesis {totals['synthesize_rir']:.2f} s, other {rest:.2f} s; escaped "
          f"{max(fc['escaped_ray_fraction'] for fc in facts):.1e}")
    t30_ss = _t30_stats([r[0] for r in rirs], fs, bands)

    # the tracer alone on 1 and 2 threads (2 000 rays in 4 batches, all points as receivers)
    for n_threads in (1, 2):
        ray_settings = RayTraceSettings(n_rays=n_rays, max_time_s=1.5, batch_size=n_rays // 4)
        t = time.perf_counter()
        trace_rays(scene, TRAJ_MIC, points, np.random.default_rng(1), ray_settings, air,
                   n_threads=n_threads)
        print(f"  tracer alone, {n_threads} thread(s), {n_points} receivers: "
              f"{time.perf_counter() - t:6.2f} s")

    try:
        import pyroomacoustics as pra
    except ImportError:
        print("pyroomacoustics not installed: the comparison is skipped")
        return

    def pra_room(sources, mics):
        room = pra.ShoeBox(list(SIZE), fs=fs, materials=pra.Material(0.2, 0.5), max_order=3,
                           ray_tracing=True, air_absorption=True)
        room.set_ray_tracing(n_rays=n_rays)
        for src in sources:
            room.add_source(list(src))
        room.add_microphone_array(np.asarray(mics, dtype=float).T)
        return room

    np.random.seed(0)  # noqa: NPY002 — pyroomacoustics draws from numpy's global generator
    t = time.perf_counter()
    pra_rirs = []
    for p in points:
        room = pra_room([p], [TRAJ_MIC])
        room.compute_rir()
        pra_rirs.append(np.asarray(room.rir[0][0]))
    t_pra = time.perf_counter() - t
    print(f"pyroomacoustics, {n_points} separate hybrid RIRs: {t_pra:6.2f} s "
          f"({t_pra / n_points * 1e3:.0f} ms/RIR)")
    # pyroomacoustics with reciprocity too: one source at the mic, every point a microphone
    t = time.perf_counter()
    room = pra_room([TRAJ_MIC], points)
    room.compute_rir()
    t_pra_rec = time.perf_counter() - t
    pra_rec = [np.asarray(room.rir[m][0]) for m in range(n_points)]
    print(f"pyroomacoustics, reciprocal (1 source at the mic, {n_points} mics): "
          f"{t_pra_rec:6.2f} s")
    print(f"speed-up of simulate_rirs: {t_pra / t_ss:5.1f}x {n_points} separate pra RIRs "
          f"(target >= 20x), {t_pra_rec / t_ss:5.1f}x pra reciprocal")
    t30_pra = _t30_stats(pra_rirs, fs, bands)
    t30_rec = _t30_stats(pra_rec, fs, bands)
    print("T30 over the points, per band: mean [s], mean error vs Eyring %, spread (std) %")
    for label, t30 in (("sonicspec", t30_ss), ("pra separate", t30_pra),
                       ("pra reciprocal", t30_rec)):
        mean = np.nanmean(t30, axis=0)
        print(f"  {label:15s} {np.round(mean, 3)}  err {np.round((mean / eyring - 1) * 100, 1)}"
              f"  spread {np.round(np.nanstd(t30, axis=0) / mean * 100, 1)}")


def equal_accuracy(seeds: int = 6) -> None:
    """One whole RIR (16 kHz, 1.5 s, ISM order 3 + rays), sonicspec vs pyroomacoustics' hybrid,
    over ray counts: time, broadband T30 error and seed spread, both measured by the same
    ISO 3382-1 routine. Equal accuracy: the cheapest sonicspec setting whose error and spread
    are no worse than pyroomacoustics' at each of its settings — with the error taken against
    Eyring (the issue's reference) and against the exact geometric-acoustics decay of this
    room (``shoebox_decay_t60``: the same reflection law walked analytically, no receiver).
    pyroomacoustics runs at its default energy threshold (10⁻⁷, which truncates its RIR at
    ~0.85 s here) and at 10⁻¹² (its whole decay)."""
    from sonicspec.acoustics.bands import default_bands
    from sonicspec.acoustics.metrics import room_acoustic_figures

    fs = 16_000
    bands = default_bands(fs)
    air = iso9613_energy_per_m(np.array(bands))
    s_eff = 2 * (70 + 30 + 21)
    # Broadband reference: Eyring at 500 Hz-1 kHz (ISO 3382-1's single number bands).
    eyring = np.mean([24 * math.log(10) * 210.0 / (C_M_S * (-s_eff * math.log(0.8)
                                                            + 4 * a * 210.0)) for a in air[2:4]])
    settings = dict(sample_rate_hz=fs, bands_hz=bands, image_source_order=3,
                    max_rir_length_s=1.5, energy_threshold_db=80.0, air_absorption=True,
                    temperature_c=20.0, relative_humidity_pct=50.0, transmission=False,
                    diffuse_rain=True, receiver_radius_m=0.1, histogram_bin_s=0.001,
                    speed_of_sound_m_s=C_M_S)
    v, f = shoebox(*SIZE)
    n, b = len(f), len(bands)
    scene = AcousticScene(v, f, np.full((n, b), 0.2), np.full((n, b), 0.5), np.zeros((n, b)))
    regions = planar_regions(scene)
    exact = float(np.mean(shoebox_decay_t60(SIZE, SRC, [0.2, 0.2], 0.5, air[2:4])))

    def mid_t30(rir: np.ndarray) -> float:
        return float(np.mean(room_acoustic_figures(rir, fs, bands).t30_s[2:4]))

    def stats(name: str, rays: int, times: list[float], t30: list[float]) -> tuple:
        t30a = np.array(t30)
        err = abs(t30a.mean() / eyring - 1) * 100
        err_x = abs(t30a.mean() / exact - 1) * 100
        spread = t30a.std(ddof=1) / t30a.mean() * 100
        t = float(np.median(times))
        print(f"{name:16s} {rays:6d} rays: {t:6.3f} s/RIR, T30(500-1k) {t30a.mean():.3f} s, "
              f"|err| vs Eyring {err:4.1f} %, vs exact {err_x:4.1f} %, "
              f"seed spread {spread:4.1f} %")
        return rays, t, err, spread, err_x

    warm_up()
    print(f"\n## equal accuracy: one RIR, 10 x 7 x 3 m, alpha 0.2, s 0.5, 16 kHz, 1.5 s, "
          f"{seeds} seeds; T30 (500 Hz-1 kHz): Eyring {eyring:.3f} s, exact {exact:.3f} s")
    ours = []
    for rays in (100, 200, 500, 1_000, 2_000):
        st = engine.SimulationSettings(rays=rays, **settings)
        times, t30 = [], []
        for seed in range(seeds):
            t = time.perf_counter()
            (rir,), _ = engine.simulate_rirs(scene, RCV[0], SRC[None], st,
                                             np.random.default_rng(seed), regions)
            times.append(time.perf_counter() - t)
            t30.append(mid_t30(rir[0]))
        ours.append(stats("sonicspec", rays, times, t30))
    try:
        import pyroomacoustics as pra
    except ImportError:
        print("pyroomacoustics not installed: the comparison is skipped")
        return
    for threshold in (None, 1e-12):
        name = "pyroom" if threshold is None else "pyroom thr 1e-12"
        extra = {} if threshold is None else {"energy_thres": threshold}
        for rays in (1_000, 2_000, 5_000, 10_000):
            times, t30 = [], []
            for seed in range(seeds):
                np.random.seed(seed)  # noqa: NPY002 (pyroomacoustics has no generator argument)
                t = time.perf_counter()
                room = pra.ShoeBox(list(SIZE), fs=fs, materials=pra.Material(0.2, 0.5),
                                   max_order=3, ray_tracing=True, air_absorption=True)
                room.set_ray_tracing(n_rays=rays, **extra)
                room.add_source(list(SRC))
                room.add_microphone(list(RCV[0]))
                room.compute_rir()
                times.append(time.perf_counter() - t)
                t30.append(mid_t30(np.asarray(room.rir[0][0])))
            _, t_pra, err_pra, spread_pra, err_x_pra = stats(name, rays, times, t30)
            for label, col, limit in (("Eyring", 2, err_pra), ("exact", 4, err_x_pra)):
                match = [o for o in ours if o[col] <= limit and o[3] <= spread_pra]
                if match:
                    best = min(match, key=lambda o: o[1])
                    print(f"           -> error vs {label}: sonicspec at {best[0]} rays is as "
                          f"accurate, {t_pra / best[1]:.1f}x faster")
                else:
                    print(f"           -> error vs {label}: no sonicspec setting here is as "
                          "accurate")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pra", action="store_true", help="also time pyroomacoustics' hybrid")
    parser.add_argument("--only", choices=["trajectory", "equal-accuracy"],
                        help="run just this case")
    args = parser.parse_args()
    print(
        f"# bench_tracer  python {platform.python_version()}  numpy {np.__version__}  "
        f"{platform.machine()}  cores={len(__import__('os').sched_getaffinity(0))}"
    )
    print("# reproduce: python bench/bench_tracer.py" + (" --pra" if args.pra else "")
          + (f" --only {args.only}" if args.only else ""))
    if args.only == "trajectory":
        trajectory()
        return
    if args.only == "equal-accuracy":
        equal_accuracy()
        return
    air = iso9613_energy_per_m(BANDS_HZ)
    scene = scene_for(0.2, 0.5)
    raw_embree(scene)
    eyring = 24 * math.log(10) * 210.0 / (C_M_S * (-242.0 * math.log(0.8) + 4 * air * 210.0))
    print("\n## one RIR, 10 x 7 x 3 m, alpha 0.2, s 0.5, ISM order 3 + rays, 1.5 s, 7 bands")
    print("Eyring T30 [s]:", np.round(eyring, 3))
    for n_rays, rain in ((500, True), (2_000, True), (20_000, True), (2_000, False)):
        if not rain:
            print("-- receiver spheres only (no diffuse rain), for the variance comparison")
        t30s, times, c50s = [], [], []
        for seed in range(3 if n_rays > 2_000 else 5):
            energy, bin_s, t_ism, t_rt, res = one_rir(scene, air, n_rays, seed, diffuse_rain=rain)
            t30s.append(schroeder_t30(energy, bin_s))
            early = round(0.05 / bin_s)
            c50s.append(10 * np.log10(energy[:early, 3].sum() / energy[early:, 3].sum()))
            times.append(t_rt)
        t30s = np.array(t30s)
        hits = n_rays * res.mean_reflections
        print(
            f"{n_rays:6d} rays: trace {np.median(times):6.2f} s (ISM+direct {t_ism * 1e3:.0f} ms), "
            f"{hits / np.median(times) / 1e6:.2f} M hits/s, {res.mean_reflections:.0f} hits/ray, "
            f"escaped {res.escaped_ray_fraction:.1e}"
        )
        err = np.abs(t30s.mean(axis=0) / eyring - 1) * 100
        spread = t30s.std(axis=0, ddof=1) / t30s.mean(axis=0) * 100
        print(f"        T30 mean [s] {np.round(t30s.mean(axis=0), 3)}")
        print(f"        |T30/Eyring-1| % {np.round(err, 1)}")
        print(f"        seed spread (std) % {np.round(spread, 1)}")
        print(
            f"        C50 1 kHz {np.mean(c50s):.2f} dB, "
            f"seed spread (std) {np.std(c50s, ddof=1):.2f} dB"
        )

    print("\n## many receivers at once (2 000 rays, 1.5 s): cost vs N")
    rng = np.random.default_rng(0)
    receivers = np.c_[rng.uniform(1, 9, 100), rng.uniform(1, 6, 100), rng.uniform(0.5, 2.5, 100)]
    for per_hit in (8, 0):
        label = "all receivers" if per_hit == 0 else f"{per_hit} receivers"
        print(f"-- diffuse rain onto {label} per hit")
        base = None
        for n_rcv in (1, 10, 100):
            rcv = receivers[:n_rcv]
            t = time.perf_counter()
            ism = image_sources(scene, SRC, rcv, max_order=3, air_m_per_band=air)
            t_ism = time.perf_counter() - t
            settings = RayTraceSettings(
                n_rays=2_000, max_time_s=1.5, rain_receivers_per_hit=per_hit
            )
            t = time.perf_counter()
            res = trace_rays(
                scene, SRC, rcv, np.random.default_rng(1), settings, air_m_per_band=air
            )
            t_rt = time.perf_counter() - t
            total = t_ism + t_rt
            base = base or total
            t30 = np.array(
                [
                    schroeder_t30(
                        r.histogram.energy
                        + a.energy_histogram(r.histogram.bin_s, r.histogram.n_bins),
                        r.histogram.bin_s,
                    )[3]
                    for r, a in zip(res, ism.arrivals, strict=True)
                ]
            )
            print(
                f"N = {n_rcv:3d}: ISM {t_ism:6.2f} s  rays {t_rt:6.2f} s  total {total:6.2f} s  "
                f"= {total / base:5.1f} x N=1  ({total / n_rcv * 1e3:.0f} ms/receiver); "
                f"1 kHz T30 over receivers {t30.mean():.3f} s "
                f"± {t30.std() / t30.mean() * 100:.1f} %"
            )

    print("\n## threads (20 000 rays in 4 batches, 1 receiver; bytes identical by design)")
    for n_threads in (1, 2):
        settings = RayTraceSettings(n_rays=20_000, max_time_s=1.5, batch_size=5_000)
        t = time.perf_counter()
        trace_rays(scene, SRC, RCV, np.random.default_rng(1), settings, air, n_threads=n_threads)
        print(f"{n_threads} thread(s): {time.perf_counter() - t:6.2f} s")

    print("\n## mesh size: shoebox walls subdivided (same acoustics), 2 000 rays, 1 receiver")
    import trimesh

    v, f = shoebox(*SIZE)
    for level in range(0, 9, 2):
        vv, ff = v, f
        for _ in range(level):
            vv, ff = trimesh.remesh.subdivide(vv, ff)
        n, b = len(ff), len(BANDS_HZ)
        t = time.perf_counter()
        sc = AcousticScene(vv, ff, np.full((n, b), 0.2), np.full((n, b), 0.5), np.zeros((n, b)))
        t_build = time.perf_counter() - t
        t = time.perf_counter()
        ism = image_sources(sc, SRC, RCV, max_order=3, air_m_per_band=air)
        t_ism = time.perf_counter() - t
        settings = RayTraceSettings(n_rays=2_000, max_time_s=1.5)
        t = time.perf_counter()
        (res,) = trace_rays(sc, SRC, RCV, np.random.default_rng(1), settings, air)
        t_rt = time.perf_counter() - t
        # What the rir stage traces instead (at the spec's default simplify_tolerance_m).
        t = time.perf_counter()
        n_simple = simplified_scene(sc, AcousticsSpec().simplify_tolerance_m).n_faces
        t_simplify = time.perf_counter() - t
        print(
            f"{n:8d} triangles: scene {t_build:5.2f} s  ISM(3) {t_ism:5.2f} s "
            f"({len(ism.arrivals[0])} arrivals)  rays {t_rt:5.2f} s "
            f"({2_000 * res.mean_reflections / t_rt / 1e6:.2f} M hits/s); the rir stage's "
            f"simplification: {n_simple} triangles in {t_simplify:5.2f} s"
        )

    if args.pra:
        import pyroomacoustics as pra

        print("\n## pyroomacoustics 0.10.1 hybrid (ISM order 3 + its ray tracer), same room")
        for n_rays in (2_000, 10_000):
            for seed in range(3):
                # pyroomacoustics has no generator argument: seed numpy's global one
                np.random.seed(seed)  # noqa: NPY002
                room = pra.ShoeBox(
                    list(SIZE),
                    fs=16_000,
                    materials=pra.Material(0.2, 0.5),
                    max_order=3,
                    ray_tracing=True,
                    air_absorption=True,
                )
                room.set_ray_tracing(n_rays=n_rays)
                room.add_source(list(SRC))
                room.add_microphone(list(RCV[0]))
                t = time.perf_counter()
                room.compute_rir()
                dt = time.perf_counter() - t
                rt = pra.experimental.measure_rt60(room.rir[0][0], fs=16_000, decay_db=30)
                print(f"{n_rays:6d} rays, seed {seed}: {dt:6.2f} s, broadband T30 {rt:.3f} s")
        trajectory()


if __name__ == "__main__":
    main()
