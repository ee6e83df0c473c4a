"""Benchmark (issue 30): the cost of a directional talker per group against an omni one.

One group's work for one talker, as the rir and render steps do it: a 20 s walk at 1.2 m/s
along a 24 m zigzag through a 12 x 8 x 3 m room (plaster walls), RIRs every 0.25 m (97
points; 2,000 rays, image sources to order 2, 0.5 s, 16 kHz, the exact early paths kept),
then the walk rendered under ``interpolation: paths`` (every exact path as a time-varying
delay plus the late part crossfaded), mono. Three talkers: omni (today), cardioid (the same
gain in every band: applied per emission exactly) and speech (a different gain per band:
the tilt in each point's filters), facing where they walk, with head turns (30°, 1 s).

Figures: CPU seconds of this process (``time.process_time``; every step here is one thread,
and the machine is shared, so wall time measures other jobs too) for the RIRs (the rir step:
``simulate_rirs`` with the directivity per point) and for the render (``render_paths`` with
the pattern per emission), the best of ``REPEATS`` runs, and the overhead over omni.

Reproduce:
    python bench/bench_directivity.py          # ~3 min on a quiet core
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
    point_yaws_deg,
    yaw_per_sample,
)
from sonicspec.acoustics.engine import acoustic_scene, early_part, simulate_rirs
from sonicspec.acoustics.moving.delays import PathSet, read_at, render_paths
from sonicspec.audio.render import render_sample_crossfade
from sonicspec.geometry.navigation import resample_polyline

FS = 16000
SECONDS = 20
SPEED = 1.2
REPEATS = 3
MIC = np.array([6.0, 4.0, 1.5])
CORNERS = np.array([[1.0, 1.0, 1.6], [11.0, 2.0, 1.6], [1.0, 4.0, 1.6], [11.0, 7.0, 1.6]])


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
    settings = ss.RirSettings(rays=2000, image_source_order=2, max_rir_length_s=0.5,
                              sample_rate_hz=FS, diffraction=False).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    points = resample_polyline(CORNERS, 0.25)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    n = SECONDS * FS
    index = np.interp(np.clip(np.arange(n) / FS * SPEED, 0, along[-1]), along,
                      np.arange(len(points)))
    bank = OctaveFilterBank(FS, settings.bands_hz)
    dry = np.random.default_rng(0).standard_normal(n)
    hop = FS // 100
    frames = facing_yaw_deg(read_at(points, index[::hop]), hop / FS, "walk", MIC)
    frames = frames + head_turns_deg(len(frames), hop / FS, 30.0, 1.0,
                                     np.random.default_rng(1))
    yaw = yaw_per_sample(frames, hop, n)
    point_yaw = point_yaws_deg(points, "walk", MIC)
    print(f"{len(points)} RIR points, {SECONDS} s walk, best of {REPEATS} (CPU s / wall s)")
    rows = []
    for name in ("omni", "cardioid", "speech"):
        pattern = None if name == "omni" else pattern_by_name(name)
        per_point = None if pattern is None else [SourceDirectivity(pattern, float(y))
                                                  for y in point_yaw]

        def rirs(per_point=per_point):
            return simulate_rirs(scene, MIC, points, settings, np.random.default_rng(1),
                                 keep_arrivals=True, directivity=per_point)

        (stack, facts), rir_cpu, rir_wall = best(rirs)
        paths = PathSet.identify(points, [f.early_arrivals for f in facts])
        length = max(r.shape[-1] for r in stack)
        late = np.zeros((len(stack), 1, length))
        for i, (r, f) in enumerate(zip(stack, facts, strict=True)):
            late[i, :, :r.shape[-1]] = r - early_part(f.early_arrivals_at_mic, settings,
                                                      r.shape[-1])
        source = None if pattern is None else SourceDirectivity(pattern, yaw)

        def render(paths=paths, late=late, source=source):
            return (render_paths(dry, index, points, paths, bank, n_out=n, source=source)
                    + render_sample_crossfade(dry, late, index)[:, :n])

        _, render_cpu, render_wall = best(render)
        rows.append((name, rir_cpu, rir_wall, render_cpu, render_wall, len(paths)))
    base = rows[0][1] + rows[0][3]
    print("| talker | rir CPU s (wall) | render CPU s (wall) | group CPU s | vs omni |")
    print("|---|---|---|---|---|")
    for name, rc, rw, pc, pw, _ in rows:
        total = rc + pc
        print(f"| {name} | {rc:.2f} ({rw:.2f}) | {pc:.2f} ({pw:.2f}) | {total:.2f} | "
              f"{100 * (total / base - 1):+.1f} % |")
    print(f"paths rendered: {rows[0][5]}")


if __name__ == "__main__":
    main()
