"""Benchmark (issue 18): the cost of `interpolation: paths` against `sample_crossfade`.

A 60 s, 16 kHz track of a source walking 90 m at 1.5 m/s down a 100 x 8 x 4 m hall (image
sources to order 2: 25 paths), RIRs every 0.75 m (121 points, the engine's own, 2,000 rays,
0.5 s), rendered three ways, side by side in one run:

* `paths`: every exact path as a time-varying delay (`acoustics.moving.delays.render_paths`, the
  compiled loop) plus the late part crossfaded (`audio.render.render_sample_crossfade`);
* `sample_crossfade` of the whole RIRs (the recipe's method, today's default);
* the naive reference of one path: the same time-varying delay as a vectorised numpy sum
  (what `render_path` was before its compiled loop; the tests compare the two), timed on
  one path and scaled by the path count.

Mono and an 8-capsule circular array (each capsule its own image of every path), then
first-order ambisonics and the binaural sphere head (`paths` and `sample_crossfade` only).
Figures: seconds per output second, as CPU time of this process (`time.process_time`: on a
machine shared with other jobs the wall clock measures them too; every method here runs on
one thread) and as wall time, and the peak memory each adds (tracemalloc). The compiled loops
are loaded (numba's on-disk cache, compiled on a first run) before the timing, once per
process: that one-off cost is printed apart.

Reproduce:
    python bench/bench_render_paths.py          # ~4 min on 2 cores
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

import sonicspec as ss
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.engine import (
    acoustic_scene,
    array_offsets,
    early_part,
    simulate_rirs,
)
from sonicspec.acoustics.moving.delays import PathSet, Receiver, render_paths
from sonicspec.acoustics.theory import moving_arrival_times, windowed_sinc
from sonicspec.audio.render import render_sample_crossfade
from sonicspec.geometry.navigation import resample_polyline
from sonicspec.spec.microphone import AmbisonicsMicSpec, BinauralMicSpec
from sonicspec.stages.render import path_receiver

FS = 16000
SECONDS = 60


def vectorised_path(dry: np.ndarray, path: np.ndarray, image: np.ndarray, n_out: int
                    ) -> np.ndarray:
    """One path's time-varying delay as the vectorised sum (the naive reference)."""
    t_a, r = moving_arrival_times(path, image, dry.size, FS)
    tau, j, k = t_a * FS, np.arange(float(n_out)), np.arange(float(dry.size))
    u = np.interp(j, tau, k)
    acc = np.zeros(n_out)
    base = np.floor(u).astype(np.int64)
    for offset in range(-7, 9):
        m = base + offset
        ok = (m >= 0) & (m < dry.size)
        acc[ok] += dry[m[ok]] * windowed_sinc(u[ok] - m[ok], 8, 6.0)
    return acc * np.interp(u, k, 1 / (4 * np.pi * r)) * np.interp(j, tau, 1 / np.gradient(tau))


def timed(fn, *args, **kwargs):
    """``(result, CPU seconds, wall seconds, peak MB)`` of one call."""
    tracemalloc.start()
    start, cpu = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    cpu, seconds = time.process_time() - cpu, time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return out, cpu, seconds, peak


def paths_and_tail(dry, index, points, paths, bank, late, receiver) -> np.ndarray:
    n = dry.size
    return (render_paths(dry, index, points, paths, bank, n_out=n, receiver=receiver)
            + render_sample_crossfade(dry, late, index)[:, :n])


def main() -> None:
    print("interpolation: paths vs sample_crossfade; reproduce: python bench/bench_render_paths.py")
    n = SECONDS * FS
    dry = np.random.default_rng(0).standard_normal(n)
    room = ss.Scene.shoebox([100.0, 8.0, 4.0], {"walls": "plaster_on_brick"})
    ends = np.array([[5.0, 3.0, 1.6], [95.0, 3.5, 1.6]])
    points = resample_polyline(ends, 0.75)
    mic = np.array([50.0, 5.0, 1.4])
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    index = np.interp(np.clip(np.arange(n) / FS * 1.5, 0, along[-1]), along,
                      np.arange(len(points)))
    settings = ss.RirSettings(rays=2000, image_source_order=2, max_rir_length_s=0.5,
                              diffraction=False).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    bank = OctaveFilterBank(FS, settings.bands_hz)
    print(f"{len(points)} RIR points, {SECONDS} s at {FS} Hz")
    print(f"{'receiver':>10} {'method':>22} {'s per output s':>15} {'(wall)':>7} {'peak MB':>8}")
    loaded = False
    for name, microphone in (
            ("mono", {"kind": "mono", "trajectory": {"kind": "static"}}),
            ("8 capsules", {"kind": "circular_array", "n": 8, "radius_m": 0.05,
                            "yaw_deg": 0.0, "pitch_deg": 0.0,
                            "trajectory": {"kind": "static"}}),
            ("FOA", AmbisonicsMicSpec(kind="ambisonics", order=1).model_dump(mode="json")),
            ("binaural", BinauralMicSpec(kind="binaural").model_dump(mode="json"))):
        rirs, facts = simulate_rirs(scene, mic, points, settings, np.random.default_rng(1),
                                    microphone=microphone, keep_arrivals=True)
        length = max(r.shape[-1] for r in rirs)
        stack = np.zeros((len(rirs), rirs[0].shape[0], length))
        for i, r in enumerate(rirs):
            stack[i, :, :r.shape[-1]] = r
        late = stack.copy()
        for i, f in enumerate(facts):
            late[i, :, :rirs[i].shape[-1]] -= early_part(f.early_arrivals_at_mic, settings,
                                                         rirs[i].shape[-1], microphone)
        directional = microphone["kind"] != "mono"
        paths = PathSet.identify(points, [f.early_arrivals for f in facts],
                                 at_mic=[f.early_arrivals_at_mic for f in facts]
                                 if directional else None)
        if name == "8 capsules":
            receiver = Receiver("array", offsets_m=array_offsets(microphone), center_m=mic)
        elif name in ("FOA", "binaural"):
            receiver = path_receiver((AmbisonicsMicSpec if name == "FOA" else BinauralMicSpec
                                      ).model_validate(microphone), mic)
        else:
            receiver = Receiver()
        # numba's compiled loops, loaded once per process: a 1 s walk over the whole path
        # first, so every path and every loop this receiver uses is met before the timing
        _, cpu, _, _ = timed(paths_and_tail, dry[::SECONDS], index[::SECONDS], points, paths,
                             bank, late, receiver)
        if not loaded:
            print(f"(loading the compiled loops, once per process: {cpu:.2f} s)")
            loaded = True
        _, c_paths, t_paths, m_paths = timed(paths_and_tail, dry, index, points, paths, bank,
                                             late, receiver)
        _, c_cross, t_cross, m_cross = timed(render_sample_crossfade, dry, stack, index)
        print(f"{name:>10} {'paths (' + str(len(paths)) + ' paths)':>22} "
              f"{c_paths / SECONDS:15.3f} {t_paths / SECONDS:7.3f} {m_paths:8.0f}")
        print(f"{name:>10} {'sample_crossfade':>22} {c_cross / SECONDS:15.3f} "
              f"{t_cross / SECONDS:7.3f} {m_cross:8.0f}")
        if name in ("FOA", "binaural"):
            print(f"{name:>10} paths vs sample_crossfade: {c_paths / c_cross:.1f}x the time")
            continue
        track = np.stack([np.interp(index, np.arange(len(points)), points[:, i])
                          for i in range(3)], axis=1)
        _, c_one, t_one, _ = timed(vectorised_path, dry, track, paths.images_m[0], n)
        scale = len(paths) * rirs[0].shape[0]
        c_naive, t_naive = c_one * scale, t_one * scale
        print(f"{name:>10} {'naive delays (scaled)':>22} {c_naive / SECONDS:15.3f} "
              f"{t_naive / SECONDS:7.3f} {'':>8}")
        print(f"{name:>10} paths vs naive: {c_naive / c_paths:.1f}x faster "
              f"(wall: {t_naive / t_paths:.1f}x); vs sample_crossfade: "
              f"{c_paths / c_cross:.1f}x the time")


if __name__ == "__main__":
    main()
