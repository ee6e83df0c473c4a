"""Benchmark (issue 30): the cost of a directional talker heard by a moving microphone.

The render step's work for one talker under ``interpolation: paths`` when the microphone
walks too: the talker walks a 20 s zigzag at 1.2 m/s through a 12 x 8 x 3 m plaster room
(:mod:`bench_directivity`'s walk), the microphone is carried along y = 7.5 m at 0.4 m/s, and
the engine's exact early paths (image sources to order 2, 25 paths) are found at pairs of
the two positions every 0.1 s (the rir step pairs them where either reaches one of its RIR
points, 0.25 m apart: about as often) and followed by their isometries. Three talkers: omni,
cardioid (one gain in every band, exact per emission) and speech (the tilt in each pair's
filters), facing where they walk, with head turns (30°, 1 s). The gains of a directional
talker need where each path's image of the microphone is when each emission reaches it (the
retarded time, solved every 64 emissions).

Figures: CPU seconds of this process (``time.process_time``; one thread, the machine is
shared, wall time measures other jobs too) of ``render_paths`` with the moving receiver, the
best of ``REPEATS`` runs, and the overhead over omni. The RIRs at the pairs cost what a static
microphone's do (the pattern's gains per arrival: ``bench_directivity.py``).

Reproduce:
    python bench/bench_directivity_moving_mic.py          # ~2 min on a quiet core
"""

from __future__ import annotations

import time

import numpy as np

import sonicspec as ss
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.directivity import (
    SourceDirectivity,
    facing_yaw_deg,
    head_turns_deg,
    pattern_by_name,
    yaw_per_sample,
)
from sonicspec.acoustics.engine import acoustic_scene, early_arrivals
from sonicspec.acoustics.moving.delays import PathSet, Receiver, read_at, render_paths
from sonicspec.geometry.navigation import resample_polyline

FS = 16000
SECONDS = 20
SPEED = 1.2
PAIR_S = 0.1
REPEATS = 2
CORNERS = np.array([[1.0, 1.0, 1.6], [11.0, 2.0, 1.6], [1.0, 4.0, 1.6], [11.0, 7.0, 1.6]])
MIC_LINE = np.array([[2.0, 7.5, 1.5], [10.0, 7.5, 1.5]])


def best(fn):
    """(result, best CPU seconds, its wall seconds) over REPEATS runs."""
    out, cpu, wall = None, np.inf, np.inf
    for _ in range(REPEATS):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        c, w = time.process_time() - c, time.perf_counter() - w
        if c < cpu:
            cpu, wall = c, w
    return out, cpu, wall


def main() -> None:
    room = ss.Scene.shoebox([12.0, 8.0, 3.0], {"walls": "plaster_on_brick"})
    settings = ss.RirSettings(rays=100, image_source_order=2, max_rir_length_s=0.5,
                              sample_rate_hz=FS, diffraction=False).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    points = resample_polyline(CORNERS, 0.25)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    n = SECONDS * FS
    walked = np.interp(np.clip(np.arange(n) / FS * SPEED, 0, along[-1]), along,
                       np.arange(len(points)))
    source = read_at(points, walked)
    t = np.arange(n) / FS
    mic = MIC_LINE[0] + np.clip(t * 0.4 / 8.0, 0, 1)[:, None] * (MIC_LINE[1] - MIC_LINE[0])
    at = np.arange(0, n, int(PAIR_S * FS))
    pairs, mics = source[at], mic[at]
    arrivals = [early_arrivals(scene, mics[j], pairs[j:j + 1], settings).from_mic[0]
                for j in range(len(at))]
    paths = PathSet.identify_moving(pairs, mics, arrivals)
    index = np.interp(np.arange(n), at, np.arange(len(at), dtype=float))
    bank = OctaveFilterBank(FS, settings.bands_hz)
    dry = np.random.default_rng(0).standard_normal(n)
    hop = FS // 100
    frames = facing_yaw_deg(source[::hop], hop / FS, "walk", mic[::hop])
    frames = frames + head_turns_deg(len(frames), hop / FS, 30.0, 1.0,
                                     np.random.default_rng(1))
    yaw = yaw_per_sample(frames, hop, n)
    receiver = Receiver(mic_track_m=mics)
    print(f"{len(at)} pairs, {len(paths)} paths, {SECONDS} s walk, best of {REPEATS} "
          "(CPU s / wall s)")
    rows = []
    for name in ("omni", "cardioid", "speech"):
        talker = None if name == "omni" else SourceDirectivity(pattern_by_name(name), yaw)

        def render(talker=talker):
            return render_paths(dry, index, pairs, paths, bank, n_out=n, receiver=receiver,
                                source=talker)

        _, cpu, wall = best(render)
        rows.append((name, cpu, wall))
    base = rows[0][1]
    print("| talker | render CPU s (wall) | vs omni |")
    print("|---|---|---|")
    for name, cpu, wall in rows:
        print(f"| {name} | {cpu:.2f} ({wall:.2f}) | {100 * (cpu / base - 1):+.1f} % |")


if __name__ == "__main__":
    main()
