"""Edge diffraction: UTD against the exact half-plane, its cost per path, and its cost in a
furnished apartment (issue 19).

1. The half-plane (Biot–Tolstoy–Medwin / Macdonald, ``sonicspec.acoustics.theory``): source
   1 m from the edge at 60° from the screen, receiver 2 m from the edge swept from the lit
   side across the shadow boundary (240°) into the deep shadow. Per octave band 250–4000 Hz:
   the total field (direct sound where visible + diffracted wave) relative to the free field,
   exact against the engine's (a UTD band amplitude at the edge path's delay added to the
   direct sound, each flat over the band as the filter bank renders it). The figure is
   ``bench/figures/half_plane_diffraction.png`` (README). Printed: the worst error of the
   diffracted wave alone and of the total, and the largest step between receivers 1 cm apart.
2. Method cost: the exact BTM response of one path (integrated per sample at 96 kHz, 0.1 s)
   against UTD band amplitudes of 10,000 paths.
3. The furnished apartment of ``bench_rlr.py`` (~100 k triangles, SonicSet materials) with
   the `sonicset` preset: one RIR, and the RIRs of a 20-point trajectory (one trace), with
   diffraction off and on (same seed, interleaved, best of 5; the per-scene edge search is
   reported apart), the diffracting edges found and kept, the diffracted paths.

Reproduce: ``python bench/bench_diffraction.py`` (``--skip-apartment`` for parts 1–2 only).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sonicspec.acoustics.paths.diffraction import band_nodes_hz, first_order_band_amplitudes
from sonicspec.acoustics.theory import Wedge, wedge_diffraction_ir, wedge_geometric_field

C = 343.0
BANDS = (250.0, 500.0, 1000.0, 2000.0, 4000.0)
FIGURE = Path(__file__).resolve().parent / "figures" / "half_plane_diffraction.png"
SCREEN = Wedge.half_plane([0, 0, 0], [0, 0, 1], [0, -1, 0])
R_SRC, TH_SRC, R_RCV = 1.0, 60.0, 2.0
FS_EXACT, N_EXACT = 96_000, 1 << 15


def at(r: float, theta_deg: float, z: float = 0.0) -> np.ndarray:
    f1 = np.cross(SCREEN.edge, SCREEN.face0)
    th = math.radians(theta_deg)
    return SCREEN.point + r * (math.cos(th) * SCREEN.face0 + math.sin(th) * f1) + z * SCREEN.edge


def exact_levels(src, rcv) -> tuple[np.ndarray, np.ndarray]:
    """Band RMS of the exact diffracted wave and of the exact total, relative to free field."""
    h = wedge_diffraction_ir(SCREEN, src, rcv, FS_EXACT, N_EXACT, C)
    f = np.fft.rfftfreq(N_EXACT, 1 / FS_EXACT)
    diff = np.fft.rfft(h) / np.sinc(f / FS_EXACT)
    total = diff + wedge_geometric_field(SCREEN, src, rcv, np.maximum(f, 1e-9), C)
    free = 1 / (4 * math.pi * float(np.linalg.norm(rcv - src)))
    out_d, out_t = [], []
    for b in BANDS:
        band = (f >= b / 2**0.5) & (f < b * 2**0.5)
        out_d.append(np.sqrt(np.mean(np.abs(diff[band]) ** 2)) / free)
        out_t.append(np.sqrt(np.mean(np.abs(total[band]) ** 2)) / free)
    return np.array(out_d), np.array(out_t)


def engine_levels(src, rcv) -> tuple[np.ndarray, np.ndarray]:
    """The engine's diffracted band amplitude and total (direct + diffracted), same units."""
    (rs, ts, zs), (rr, tr, zr) = SCREEN.cylindrical(src), SCREEN.cylindrical(rcv)
    amp, length = first_order_band_amplitudes([rs], [ts], [rr], [tr], [zr - zs],
                                              [SCREEN.open_angle], BANDS, C)
    r = float(np.linalg.norm(rcv - src))
    f, w = band_nodes_hz(BANDS)
    total = amp[0][:, None] * np.exp(-2j * np.pi * f * length[0] / C)
    if abs(tr - ts) < math.pi:  # direct sound visible
        total = total + np.exp(-2j * np.pi * f * r / C) / (4 * math.pi * r)
    free = 1 / (4 * math.pi * r)
    return np.abs(amp[0]) / free, np.sqrt(np.sum(w * np.abs(total) ** 2, axis=1)) / free


def half_plane() -> dict:
    src = at(R_SRC, TH_SRC)
    boundary = TH_SRC + 180.0
    coarse = np.arange(201.0, 357.0, 2.0)  # never exactly on the boundary (240°)
    step_deg = math.degrees(0.01 / R_RCV)  # 1 cm along the receiver's circle
    fine = boundary + step_deg * (np.arange(-25, 25) + 0.5)
    angles = np.unique(np.concatenate([coarse, fine]))
    rows = []
    for th in angles:
        rcv = at(R_RCV, th)
        ed, et = exact_levels(src, rcv)
        ud, ut = engine_levels(src, rcv)
        rows.append((th, ed, et, ud, ut))
    th = np.array([r[0] for r in rows])
    ed, et, ud, ut = (np.array([r[k] for r in rows]) for k in range(1, 5))
    shadow = th > boundary
    err_diff = 20 * np.log10(ud[shadow] / ed[shadow])
    err_total = 20 * np.log10(ut / et)
    in_fine = (th >= fine[0]) & (th <= fine[-1])
    steps = np.abs(np.diff(20 * np.log10(ut[in_fine]), axis=0))
    return {"theta": th, "exact_total": et, "engine_total": ut, "boundary": boundary,
            "max_err_diffracted_db": np.abs(err_diff).max(axis=0),
            "max_err_total_db": np.abs(err_total).max(axis=0),
            "max_step_1cm_db": steps.max(axis=0)}


def plot(res: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=110)
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(BANDS)))
    for k, b in enumerate(BANDS):
        ax.plot(res["theta"], 20 * np.log10(res["exact_total"][:, k]), color=colours[k],
                lw=1.6, label=f"{b:g} Hz exact")
        ax.plot(res["theta"][::3], 20 * np.log10(res["engine_total"][::3, k]), "o", ms=2.6,
                color=colours[k], mfc="none")
    ax.axvline(res["boundary"], color="0.5", ls=":", lw=1)
    ax.text(res["boundary"] + 1.5, -1.5, "shadow boundary", fontsize=7, color="0.4")
    ax.set_xlabel("receiver angle from the screen (°); lit < 240° < shadow")
    ax.set_ylabel("level re free field (dB)")
    ax.set_title("Half-plane: exact (lines) vs sonicspec UTD (circles), octave bands",
                 fontsize=9)
    ax.legend(fontsize=7, ncol=2, loc="lower left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE)
    plt.close(fig)


def method_cost() -> dict:
    src, rcv = at(R_SRC, TH_SRC), at(R_RCV, 280.0, 0.4)
    t0 = time.perf_counter()
    for _ in range(5):
        wedge_diffraction_ir(SCREEN, src, rcv, FS_EXACT, FS_EXACT // 10, C)
    btm = (time.perf_counter() - t0) / 5
    rng = np.random.default_rng(0)
    n = 10_000
    args = (rng.uniform(0.3, 3, n), rng.uniform(0, 1, n), rng.uniform(0.3, 3, n),
            rng.uniform(4, 6, n), rng.uniform(-1, 1, n), np.full(n, 2 * math.pi))
    t0 = time.perf_counter()
    first_order_band_amplitudes(*args, (125.0, *BANDS), C)
    utd = (time.perf_counter() - t0) / n
    return {"btm_s_per_path": btm, "utd_s_per_path": utd}


def apartment() -> dict:
    from bench_rlr import MIC_M, SOURCE_M, apartment_mesh, preset_acoustics

    from sonicspec.acoustics.engine import (
        SimulationSettings,
        acoustic_scene,
        scene_edges,
        simulate_rirs,
    )
    from sonicspec.acoustics.paths.edge_paths import close_pairs
    from sonicspec.acoustics.paths.image_sources import planar_regions
    from sonicspec.geometry.materials import load_library

    settings = SimulationSettings.from_spec(preset_acoustics(), 16_000, C)
    mesh = apartment_mesh(100_000)
    scene = acoustic_scene(mesh, load_library("sonicset"), settings)
    regions = planar_regions(scene)
    t0 = time.perf_counter()
    edges = scene_edges(scene, settings.diffraction_max_edges)
    pairs = close_pairs(edges)
    edge_s = time.perf_counter() - t0  # once per scene (memoized by the engine)
    # issue 32: the edges ranked for one group's positions (a 101-point walk and the mic),
    # distances and sight from up to 32 of them; once per group in the rir step
    walk = np.concatenate([MIC_M[None], SOURCE_M[None] + np.linspace(0, 1, 100)[:, None]
                           * np.array([[-2.0, -1.5, 0.0]])])
    t0 = time.perf_counter()
    ranked = scene_edges(scene, settings.diffraction_max_edges, walk)
    rank_s = time.perf_counter() - t0
    shared = len({tuple(p) for p in np.round(edges.start, 6)}
                 & {tuple(p) for p in np.round(ranked.start, 6)})
    out = {"triangles": mesh.n_faces, "traced_triangles": scene.n_faces,
           "edges_found": edges.n_found, "edges_kept": len(edges), "pairs": len(pairs),
           "edge_search_s": edge_s, "edge_rank_for_a_walk_s": rank_s,
           "kept_also_by_length_and_exposure": shared}
    # Off and on interleaved, best of 5 each (the machine is shared): one source, and a
    # 20-point trajectory (one trace, diffraction per point).
    line = SOURCE_M[None] + np.linspace(0, 1, 20)[:, None] * np.array([[-2.0, -1.5, 0.0]])
    for name, points in (("one", SOURCE_M[None]), ("trajectory", line)):
        best = {False: math.inf, True: math.inf}
        facts = {}
        for _ in range(5):
            for on in (False, True):
                s = dataclasses.replace(settings, diffraction=on)
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    _, f = simulate_rirs(scene, MIC_M, points, s, np.random.default_rng(0),
                                         regions=regions)
                best[on] = min(best[on], time.perf_counter() - t0)
                facts[on] = f
        for on in (False, True):
            out[f"{name}_{'on' if on else 'off'}"] = {
                "rir_s": best[on], "direct": facts[on][0].direct,
                "arrivals": int(np.mean([f.arrivals for f in facts[on]])),
                "diffracted_paths": int(np.mean([f.diffracted_paths for f in facts[on]]))}
        out[f"{name}_overhead_pct"] = 100 * (best[True] / best[False] - 1)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-apartment", action="store_true")
    args = parser.parse_args()
    res = half_plane()
    plot(res)
    print("half-plane, source 1 m at 60°, receiver 2 m, bands", BANDS)
    print("  worst |UTD − exact|, diffracted wave in the shadow (dB):",
          np.round(res["max_err_diffracted_db"], 2))
    print("  worst |engine − exact|, total field, lit and shadow (dB):",
          np.round(res["max_err_total_db"], 2))
    print("  largest step between receivers 1 cm apart across the boundary (dB):",
          np.round(res["max_step_1cm_db"], 2))
    print(f"  figure: {FIGURE} ({FIGURE.stat().st_size / 1000:.0f} kB)")
    cost = method_cost()
    print(f"method cost per path: exact BTM IR {cost['btm_s_per_path'] * 1e3:.0f} ms, "
          f"UTD band amplitudes {cost['utd_s_per_path'] * 1e6:.1f} µs")
    if not args.skip_apartment:
        a = apartment()
        print(f"apartment ({a['triangles']} triangles, {a['traced_triangles']} traced), "
              f"sonicset preset: {a['edges_found']} diffracting edges found, "
              f"{a['edges_kept']} kept, {a['pairs']} second-order pairs; search "
              f"{a['edge_search_s']:.2f} s once per scene")
        for name, label in (("one", "one source"), ("trajectory", "20 points, one trace")):
            for k in ("off", "on"):
                v = a[f"{name}_{k}"]
                print(f"  {label}, diffraction {k}: {v['rir_s']:.3f} s, direct {v['direct']}, "
                      f"{v['arrivals']} early arrivals, {v['diffracted_paths']} diffracted "
                      "(per point)")
            print(f"  {label}: overhead {a[name + '_overhead_pct']:+.0f} %")
    print("reproduce: python bench/bench_diffraction.py")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
