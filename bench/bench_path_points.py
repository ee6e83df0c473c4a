"""Points added between RIR points where the paths change (issue 18/19): what they buy and
what they cost.

1. Accuracy — a source walking out of sight round the jamb of a door (the door room of
   ``tests/test_acoustics_diffraction_engine.py``, diffraction on, image sources to order 1):
   the early part rendered by ``render_paths`` from RIR points 0.25 m apart, with and
   without the added points, against the same renderer on points 5 mm apart (the converged
   walk). SNR and smoothed spectral dips, 200–5000 Hz.
2. Cost — a 2.5 m walk in the furnished 100 k-triangle apartment of ``bench_rlr.py`` with the
   ``sonicset`` preset's acoustics at image-source order 1 and 3: the trace of the walk's RIR
   points against the refinement (``engine.refined_early_paths``), and how many points it adds.

    python bench/bench_path_points.py
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))


def accuracy() -> None:
    from test_acoustics_diffraction_engine import FS, C, door_room, settings

    from sonicspec.acoustics import engine
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.moving.delays import PathSet, render_paths
    from sonicspec.audio.fidelity import dip_figures, snr_db, spectral_deviation_db
    from sonicspec.geometry.navigation import resample_polyline

    scene, st = door_room(), settings(True, 1)
    mic = np.array([3.8, 0.5, 1.2])
    ends = np.array([[2.0, 2.7, 1.2], [2.0, 0.4, 1.2]])
    speed = 1.5
    n = int(np.linalg.norm(ends[1] - ends[0]) / speed * FS) + FS // 4
    dry = np.random.default_rng(1).standard_normal(n)
    bank = OctaveFilterBank(FS, st.bands_hz)

    def run(spacing: float, refine: bool):
        points = resample_polyline(ends, spacing)
        t0 = time.process_time()
        _, facts = engine.simulate_rirs(scene, mic, points, st, np.random.default_rng(0),
                                        keep_arrivals=True)
        heard = [f.early_arrivals for f in facts]
        if refine:
            fine = engine.refined_early_paths(scene, st, points,
                                              np.repeat(mic[None], len(points), 0), heard, heard)
            paths = PathSet.identify(fine.sources_m, fine.from_mic).with_index(fine.at_index)
        else:
            paths = PathSet.identify(points, heard)
        cpu = time.process_time() - t0
        along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0),
                                                                axis=1))])
        index = np.interp(np.clip(np.arange(n) / FS * speed, 0, along[-1]), along,
                          np.arange(len(points)))
        (y,) = render_paths(dry, index, points, paths, bank, n_out=n, speed_of_sound_m_s=C)
        return y, len(points), paths.weights.shape[1], len(paths), cpu

    dense, *_ = run(0.005, False)
    core = slice(int(0.1 * FS), n - int(0.3 * FS))
    print("1. a walk out of sight through a door (vs the same renderer on 5 mm points)")
    print(f"{'RIR points':>12} {'added':>7} {'path points':>12} {'paths':>6} {'CPU s':>6} "
          f"{'SNR dB':>7} {'worst dip':>10} {'p5 dip':>7}")
    for refine in (False, True):
        y, pts, path_pts, k, cpu = run(0.25, refine)
        dev, _, _ = spectral_deviation_db(dense, y, FS, active=(core.start, core.stop))
        dips = dip_figures(dev)
        print(f"{pts:>12} {'yes' if refine else 'no':>7} {path_pts:>12} {k:>6} {cpu:>6.2f} "
              f"{snr_db(dense[core], y[core]):>7.1f} {dips['worst_db']:>10.2f} "
              f"{dips['p5_db']:>7.2f}")


def cost() -> None:
    from bench_rlr import MIC_M, SOURCE_M, apartment_mesh, preset_acoustics

    from sonicspec.acoustics.engine import (
        SimulationSettings,
        acoustic_scene,
        refined_early_paths,
        simulate_rirs,
    )
    from sonicspec.acoustics.moving.delays import PathSet
    from sonicspec.acoustics.paths.image_sources import planar_regions
    from sonicspec.geometry.materials import load_library
    from sonicspec.geometry.navigation import resample_polyline

    mesh = apartment_mesh(100_000)
    points = resample_polyline(np.array([SOURCE_M, SOURCE_M + np.array([-2.0, -1.5, 0.0])]),
                               0.25)
    print("\n2. a 2.5 m walk (0.25 m RIR points) in the furnished apartment, `sonicset` "
          "acoustics, one core")
    print(f"{'order':>6} {'RIR points':>11} {'trace s':>8} {'added points s':>15} "
          f"{'path points':>12} {'paths':>6} {'diffracted':>11}")
    for order in (1, 3):
        settings = SimulationSettings.from_spec(preset_acoustics(image_source_order=order),
                                                16_000, 343.0)
        scene = acoustic_scene(mesh, load_library("sonicset"), settings)
        regions = planar_regions(scene)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.process_time()
            _, facts = simulate_rirs(scene, MIC_M, points, settings, np.random.default_rng(0),
                                     regions=regions, keep_arrivals=True)
            t1 = time.process_time()
            heard = [f.early_arrivals for f in facts]
            fine = refined_early_paths(scene, settings, points,
                                       np.repeat(MIC_M[None], len(points), 0), heard, heard,
                                       regions=regions,
                                       image_source_order=facts[0].image_source_order)
            t2 = time.process_time()
        paths = PathSet.identify(fine.sources_m, fine.from_mic)
        print(f"{order:>6} {len(points):>11} {t1 - t0:>8.2f} {t2 - t1:>15.2f} "
              f"{len(fine.at_index):>12} {len(paths):>6} {int(paths.diffracted.sum()):>11}")


if __name__ == "__main__":
    accuracy()
    cost()
    print("\ncommand: python bench/bench_path_points.py")
