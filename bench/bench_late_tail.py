"""Where the late tail of the bench apartment comes from, and one way to sample it better.

Experiments behind the "Session 7" and "Session 8" notes of ``bench/RESULTS.md`` (section of
``bench_rlr.py``), on the same furnished apartment, materials and positions as ``bench_rlr.py``:

* ``--by-azimuth``: launches only near-horizontal rays (|z| < 0.02) within one azimuth
  sector at a time, traced from the mic with the ``sonicset`` preset's splitting, ball and
  roulette, and prints the 1 kHz energy of those launches (normalised to the whole source
  energy: a density per solid angle) in 100–300, 300–600 and 600–1,000 ms (3 seeds per
  sector; azimuth 0° is +x, the room's 10 m side).
* ``--azimuth-guiding GAMMA WIDTH_DEG`` (repeatable): session 7's preset (3,000 rays,
  roulette 30 dB) with a share GAMMA of each horizontal band's launches drawn within
  ±WIDTH_DEG of the four axis azimuths (0°, 90°, 180°, 270°), weighted by the balance
  heuristic over the mixture (so unbiased);
  prints the T30 error of seeds 1–16 against the converged reference of ``bench_rlr.py``
  (mean of 16 runs of its ``ref_setting``, computed here) — mean, spread and worst seed per
  band. GAMMA 0 is the preset itself. The launch sampler is patched in this process only
  (``raytrace._guided_launch``): an experiment, not a setting of the package.
* ``--roulette DB ...``: CPU and T30 spread over 32 seeds of 4,000 rays with the preset's
  estimators (image sources to order 1) for each roulette level — how the preset's 20 dB was
  chosen.
* ``--tail-roughness``: how bursty the late envelope of the (current) preset is, raw and as
  the rir stage smooths it (``EnergyHistogram.smoothed``), with roulette from 30 and 20 dB.

Reproduce:  python bench/bench_late_tail.py --by-azimuth                      (~2 minutes)
            python bench/bench_late_tail.py --tail-roughness                  (~10 seconds)
            python bench/bench_late_tail.py --roulette 30 25 20 15 10         (~2 minutes)
            python bench/bench_late_tail.py --azimuth-guiding 0 10 --azimuth-guiding 0.5 10 \\
                --azimuth-guiding 0.7 10 --azimuth-guiding 0.5 5 --azimuth-guiding 0.5 20 \\
                --azimuth-guiding 0.3 10                                        (~6 minutes)
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_rlr import (
    BANDS_HZ,
    MIC_M,
    REF_RUNS,
    REF_SEED_BASE,
    SOURCE_M,
    apartment_mesh,
    ref_setting,
    sonicspec_rir,
    sonicspec_settings,
)

import sonicspec.acoustics.late.raytrace as raytrace
from sonicspec.acoustics.engine import acoustic_scene, ray_trace_settings
from sonicspec.acoustics.paths.image_sources import planar_regions
from sonicspec.geometry.materials import load_library

# Session 7's `sonicset` preset, the baseline of these experiments (the preset now traces
# 4,000 rays with roulette from 20 dB down): rays, order, splitting, ball, roulette, guiding.
PRESET = (3000, 2, 2.0, 4.0, 30.0, 0.5)
AXES_RAD = np.radians([0.0, 90.0, 180.0, 270.0])
SECTOR_EDGES_DEG = (-45, -20, -10, -5, -2, 0, 2, 5, 10, 20, 45, 70, 80, 85, 88, 90, 92, 95,
                    100, 110, 135)
BAND_1K = BANDS_HZ.index(1000.0)


def sector_launch(lo_deg: float, hi_deg: float):
    """A launch sampler: |z| < 0.02 and azimuth uniform in [lo, hi] degrees, weight 1."""
    def launch(n, rng, beta, widths):
        z = rng.uniform(-0.02, 0.02, n)
        phi = np.radians(rng.uniform(lo_deg, hi_deg, n))
        r = np.sqrt(1.0 - z * z)
        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1), np.ones(n)
    return launch


def axis_guided_launch(gamma: float, half_width_rad: float):
    """The package's guided launch with a share ``gamma`` of every band's directions moved to
    the azimuth windows around ``AXES_RAD`` (their z kept; balance-heuristic weights)."""
    plain = raytrace._guided_launch

    def launch(n, rng, beta, widths):
        dirs, weight = plain(n, rng, beta, widths)
        m = math.floor(n * beta / len(widths))  # directions per band, after the sphere's
        n_sphere = n - m * len(widths)
        for start in range(n_sphere, n, m):
            rows = start + rng.permutation(m)[:round(gamma * m)]
            u = (np.arange(len(rows)) * raytrace._GOLDEN + rng.random()) % 1.0
            k = np.floor(4.0 * u).astype(int)
            within = (7.0 * (4.0 * u - k)) % 1.0  # uniform in [0, 1), stratified
            phi = AXES_RAD[k] + half_width_rad * (2.0 * within - 1.0)
            r = np.hypot(dirs[rows, 0], dirs[rows, 1])
            dirs[rows, 0], dirs[rows, 1] = r * np.cos(phi), r * np.sin(phi)
        angle = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2.0 * math.pi)
        off_axis = np.min(np.abs((angle[:, None] - AXES_RAD[None, :] + math.pi)
                                 % (2.0 * math.pi) - math.pi), axis=1)
        # Azimuth density of the band components relative to uniform; the band terms of the
        # plain sampler's density (1 / weight - sphere share) depend on z alone.
        q = (1.0 - gamma) + gamma * math.pi / (4.0 * half_width_rad) * (off_axis < half_width_rad)
        return dirs, 1.0 / (n_sphere / n + q * (1.0 / weight - n_sphere / n))
    return launch


def by_azimuth(mesh) -> None:
    settings = sonicspec_settings(*PRESET)
    scene = acoustic_scene(mesh, load_library("sonicset"), settings)
    st = dataclasses.replace(ray_trace_settings(settings, 2), guiding=0.999)
    air = settings.air()
    print("1 kHz energy of each sector's 3,000 launches (|z| < 0.02), normalised as if they "
          "carried the whole source energy: the late energy per solid angle, by azimuth")
    for lo, hi in itertools.pairwise(SECTOR_EDGES_DEG):
        raytrace._guided_launch = sector_launch(lo, hi)
        windows = []
        for seed in range(3):
            (res,) = raytrace.trace_rays(scene, MIC_M, SOURCE_M[None],
                                         np.random.default_rng(seed), st, air)
            e = res.histogram.energy[:, BAND_1K]
            windows.append([e[100:300].sum(), e[300:600].sum(), e[600:1000].sum()])
        w = np.mean(windows, axis=0)
        print(f"azimuth {lo:5d}..{hi:5d} deg: 100-300 ms {w[0]:.2e}  300-600 ms {w[1]:.2e}  "
              f"600-1000 ms {w[2]:.2e}", flush=True)


def reference(mesh):
    """The apartment's scene and regions, and bench_rlr's converged T30 (mean of its 16 runs)."""
    ref_settings = sonicspec_settings(*ref_setting(20_000, False))
    scene = acoustic_scene(mesh, load_library("sonicset"), ref_settings)
    regions = planar_regions(scene)
    t0 = time.perf_counter()
    runs = [sonicspec_rir(scene, regions, ref_settings, REF_SEED_BASE + k, 2)[1]["expected"]
            for k in range(REF_RUNS)]
    ref_t30 = np.mean([r["t30_s"] for r in runs], axis=0)
    print(f"reference: mean of {REF_RUNS} runs of bench_rlr's ref_setting "
          f"({time.perf_counter() - t0:.0f} s): T30 " + ", ".join(f"{t:.3f}" for t in ref_t30)
          + " s")
    return scene, regions, ref_t30


def t30_errors(scene, regions, settings, ref_t30: np.ndarray, seeds: int
               ) -> tuple[np.ndarray, float]:
    """T30 error per band (%) of seeds 1…``seeds`` of ``settings`` against ``ref_t30``, and
    the median CPU per RIR."""
    errors, cpu = [], []
    for seed in range(1, seeds + 1):
        c0 = time.process_time()
        t30 = sonicspec_rir(scene, regions, settings, seed, 1)[1]["expected"]["t30_s"]
        cpu.append(time.process_time() - c0)
        errors.append(100.0 * (np.asarray(t30) / ref_t30 - 1.0))
    return np.array(errors), float(np.median(cpu))


def per_band(values) -> str:
    return " ".join(f"{v:5.1f}" for v in values)


def roulette_spread(mesh, levels_db: list[float], seeds: int = 32) -> None:
    """CPU and T30 spread of 4,000 rays with the preset's estimators (image sources to order 1)
    for each roulette level, over ``seeds`` seeds: what the preset's roulette was chosen by."""
    scene, regions, ref_t30 = reference(mesh)
    print(f"T30 error against it, seeds 1-{seeds}, per band "
          + "/".join(f"{b:g}" for b in BANDS_HZ) + " Hz:")
    for level in levels_db:
        settings = sonicspec_settings(4000, 1, 2.0, 4.0, level, 0.5)
        errors, cpu = t30_errors(scene, regions, settings, ref_t30, seeds)
        e = np.abs(errors)
        worst_of_8 = np.mean([e[k:k + 8].max() for k in range(0, len(e) - 7, 8)])
        print(f"roulette {level:g} dB ({cpu:.3f} s CPU): sd {per_band(errors.std(0))} | worst "
              f"{per_band(e.max(0))} % | worst of 8 seeds, mean over groups {worst_of_8:.1f} %",
              flush=True)


def azimuth_guiding(mesh, variants: list[tuple[float, float]]) -> None:
    original = raytrace._guided_launch
    scene, regions, ref_t30 = reference(mesh)
    settings = sonicspec_settings(*PRESET)
    print("T30 error of the preset (3,000 rays) against it, seeds 1-16, per band "
          + "/".join(f"{b:g}" for b in BANDS_HZ) + " Hz:")
    for gamma, width_deg in variants:
        raytrace._guided_launch = (axis_guided_launch(gamma, math.radians(width_deg))
                                   if gamma > 0 else original)
        e, cpu = t30_errors(scene, regions, settings, ref_t30, 16)
        print(f"gamma {gamma:g}, ±{width_deg:g} deg ({cpu:.2f} s CPU): mean "
              f"{per_band(e.mean(0))} | sd {per_band(e.std(0))} | worst "
              f"{per_band(np.abs(e).max(0))} %", flush=True)
    raytrace._guided_launch = original


def tail_roughness(mesh) -> None:
    """How bursty the late envelope is: the 1 kHz histogram of 8 traces of the preset with
    roulette from 30 and 20 dB down, raw and as the rir stage smooths it, summed in 10 ms
    windows from 0.3 to 1.5 s: the scatter of their levels around a fitted decay, the empty
    windows (after the last ray, or between bursts) and how far T30 moves."""
    from sonicspec.acoustics.engine import LATE_ENVELOPE_RELATIVE_WIDTH
    from sonicspec.acoustics.metrics import figures_from_energy

    for roulette in (30.0, 20.0):
        settings = sonicspec_settings(4000, 3, 2.0, 4.0, roulette, 0.5)
        scene = acoustic_scene(mesh, load_library("sonicset"), settings)
        st, air = ray_trace_settings(settings, 2), settings.air()
        hists = [raytrace.trace_rays(scene, MIC_M, SOURCE_M[None], np.random.default_rng(seed),
                                     st, air)[0].histogram for seed in range(1, 9)]
        for width in (0.0, LATE_ENVELOPE_RELATIVE_WIDTH):
            scatter, empty, moved = [], [], []
            for raw in hists:
                h = raw.smoothed(width)
                w = h.energy[:1500, BAND_1K].reshape(-1, 10).sum(axis=1)[30:]
                t = 0.305 + 0.01 * np.arange(len(w))
                level = 10 * np.log10(w[w > 0])
                fit = np.polyval(np.polyfit(t[w > 0], level, 1), t[w > 0])
                scatter.append(np.std(level - fit))
                empty.append(np.sum(w == 0))
                t30 = [np.array(figures_from_energy(x.energy, x.bin_s)["t30_s"]) for x in (raw, h)]
                moved.append(np.max(np.abs(t30[1] / t30[0] - 1)))
            print(f"roulette {roulette:g} dB, envelope window ±{50 * width:g} % of t: scatter "
                  f"{np.mean(scatter):.1f} dB, empty 10 ms windows {np.mean(empty):.1f} of "
                  f"{len(w)}, T30 moved by up to {100 * max(moved):.2f} %", flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--by-azimuth", action="store_true")
    parser.add_argument("--tail-roughness", action="store_true")
    parser.add_argument("--roulette", nargs="+", type=float, metavar="DB",
                        help="roulette levels to compare (4,000 rays, the preset's estimators)")
    parser.add_argument("--azimuth-guiding", nargs=2, type=float, action="append",
                        metavar=("GAMMA", "WIDTH_DEG"), default=[])
    args = parser.parse_args()
    if not (args.by_azimuth or args.azimuth_guiding or args.tail_roughness or args.roulette):
        parser.error("give --by-azimuth, --tail-roughness, --roulette DB... and/or "
                     "--azimuth-guiding GAMMA WIDTH_DEG")
    mesh = apartment_mesh(100_000)
    print(f"apartment: {mesh.n_faces:,} triangles; reproduce: python bench/bench_late_tail.py "
          + " ".join(sys.argv[1:]))
    if args.by_azimuth:
        by_azimuth(mesh)
    if args.azimuth_guiding:
        azimuth_guiding(mesh, [(g, w) for g, w in args.azimuth_guiding])
    if args.tail_roughness:
        tail_roughness(mesh)
    if args.roulette:
        roulette_spread(mesh, args.roulette)
    return 0


if __name__ == "__main__":
    sys.exit(main())
