"""Benchmark (issue 19): what ``max_rir_length_s: auto`` costs against the old fixed 2 s.

For each room, one microphone and a walk of 8 source points (what one source of a group
costs: one trace serves its points, then 8 RIRs are synthesised), with the spec's acoustics
defaults (20,000 rays, roulette from 30 dB, horizontal guiding) and with the demo's (4,000
rays, image sources to order 2), at 16 kHz, mono:

- ``fixed 2 s``: ``max_rir_length_s: 2`` (the old default: rays followed to 2 s at most);
- ``auto``: ``max_rir_length_s: auto`` (rays followed to ``max_rir_cap_s``, 10 s, each RIR
  ending where every band's decay is 60 dB down, continued where the rays ran out).

Rooms: the demo's three (``specs/demo.yaml``: living room, office, hexagonal hall) with their
materials, the issue's live room (10 × 7 × 3 m, α = 0.02, s = 0.5: T30 ≈ 7 s) and two
5 × 4 × 3 m rooms joined by a door (α 0.1, s 0.3), the source walking in the other room.
Reported: the CPU time of ``simulate_rirs`` (trace + image sources + synthesis; the best of
``--repeat`` runs, one thread, after one warm-up call that compiles the tracer; CPU time,
not wall time, as the bench machine is shared and wall times moved 2x between runs), the
mean RIR
length, the mean T30 at 1 kHz of the 8 RIRs (nan: one of them does not decay 35 dB), how
each RIR's length was chosen, and the cap's warnings.

Reproduce:
    python bench/bench_tails.py              # about 3 min on one core
    python bench/bench_tails.py --repeat 1   # quicker, noisier
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from sonicspec.acoustics import engine
from sonicspec.acoustics.metrics import room_acoustic_figures
from sonicspec.errors import SonicspecWarning
from sonicspec.spec import load_spec
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.stages.inspect import build_scene
from sonicspec.stages.rir import spec_materials
from sonicspec.testing import rooms

ROOT = Path(__file__).resolve().parents[1]
FS = 16_000
N_POINTS = 8


def demo_rooms():
    """(name, AcousticScene per settings, mic, points) of the demo's three scenes."""
    loaded = load_spec(ROOT / "specs" / "demo.yaml")
    library = spec_materials(loaded.spec.materials.model_dump(mode="json"))
    out = []
    for scene_id in ("living_room", "office", "hall"):
        mesh = build_scene(loaded, scene_id)[0]
        lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
        mic = lo + (hi - lo) * np.array([0.25, 0.7, 0.0]) + [0, 0, 1.5]
        start = lo + (hi - lo) * np.array([0.7, 0.3, 0.0]) + [0, 0, 1.5]
        points = start + np.linspace(0.0, 1.75, N_POINTS)[:, None] * [0.0, 1.0, 0.0]
        out.append((scene_id, lambda s, m=mesh: engine.acoustic_scene(m, library, s), mic,
                    points))
    return out


def synthetic_rooms():
    live = rooms.shoebox(10.0, 7.0, 3.0)
    door = rooms.door_rooms()
    line = np.linspace(0.0, 1.75, N_POINTS)[:, None] * [0.0, 1.0, 0.0]
    return [
        ("live room (α 0.02)", lambda s: rooms.uniform_scene(*live, 0.02, 0.5, 0.0,
                                                             len(s.bands_hz)),
         np.array([7.2, 4.9, 1.6]), np.array([2.1, 2.3, 1.4]) + line),
        ("door rooms (α 0.1)", lambda s: rooms.uniform_scene(*door, 0.1, 0.3, 0.0,
                                                             len(s.bands_hz)),
         np.array([2.0, 1.0, 1.5]), np.array([8.5, 1.5, 1.2]) + line),
    ]


def run(scene, mic, points, settings, repeat: int, name: str):
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.process_time()
        rirs, facts = engine.simulate_rirs(scene, mic, points, settings,
                                           np.random.default_rng(0), where=name)
        best = min(best, time.process_time() - start)
        out = (rirs, facts)
    return best, out


def describe(facts) -> str:
    rules = set()
    for f in facts:
        tail = f.tail
        if any(v is not None for v in tail.level_at_limit_db):
            rules.add("cut at the limit")
        elif any(v is not None for v in tail.continued_from_s):
            rules.add("continued")
        else:
            rules.add("decay 60 dB down")
    return ", ".join(sorted(rules))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    presets = {"spec defaults (20,000 rays)": {},
               "demo (4,000 rays, order 2)": {"rays": 4000, "image_source_order": 2}}
    # Warm-up: the tracer's first call compiles it.
    warm = engine.SimulationSettings.from_spec(AcousticsSpec(rays=100).model_dump(
        mode="json"), FS, 343.0)
    name, make, mic, points = synthetic_rooms()[1]
    engine.simulate_rirs(make(warm), mic, points[:1], warm, np.random.default_rng(0))
    print(f"python {platform.python_version()}, {platform.machine()}, 1 thread, {FS} Hz, "
          f"{N_POINTS} points per trace, best of {args.repeat}")
    print("| room | settings | CPU fixed 2 s | CPU auto | ratio | length fixed / auto | "
          "T30 1 kHz fixed / auto | auto: how the length was chosen |")
    print("|---|---|---|---|---|---|---|---|")
    notes: list[str] = []
    for name, make, mic, points in demo_rooms() + synthetic_rooms():
        for label, acoustics in presets.items():
            row = {}
            for length in (2.0, "auto"):
                settings = engine.SimulationSettings.from_spec(AcousticsSpec(
                    **acoustics, max_rir_length_s=length).model_dump(mode="json"), FS, 343.0)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always", SonicspecWarning)
                    elapsed, (rirs, facts) = run(make(settings), mic, points, settings,
                                                 args.repeat, name)
                notes += [f"{name}, {label}, {length}: {w.message}" for w in caught[:1]]
                k = list(settings.bands_hz).index(1000.0)
                t30 = [room_acoustic_figures(r[0].astype(float), FS,
                                             settings.bands_hz).t30_s[k] for r in rirs]
                t30 = np.mean(t30) if np.all(np.isfinite(t30)) else float("nan")
                row[length] = (elapsed, np.mean([r.shape[-1] for r in rirs]) / FS, t30,
                               describe(facts))
            (tf, lf, t30f, _), (ta, la, t30a, how) = row[2.0], row["auto"]
            print(f"| {name} | {label} | {tf:.2f} s | {ta:.2f} s | {ta / tf:.2f} | "
                  f"{lf:.2f} / {la:.2f} s | {t30f:.2f} / {t30a:.2f} s | {how} |", flush=True)
    print("T30 nan: the RIR does not decay 35 dB (cut). Warnings (the first of each run):")
    for note in notes:
        print(f"- {note}")
    print("command: python bench/bench_tails.py --repeat", args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
