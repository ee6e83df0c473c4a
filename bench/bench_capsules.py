"""Benchmark (issue 30): what directional capsules and device presets cost over omni capsules.

A group's receiver work, twice per microphone: the rir step's RIRs (one trace from the
microphone and 24 RIR points of a walk in a furnished-like 6 × 5 × 3 m shoebox, 4,000 rays,
image sources to order 2, 16 kHz, RIRs up to 1 s) and the render step's exact paths
(``interpolation: paths``: a 6 s walk through those points rendered per capsule). Each
microphone is timed against the same geometry with omni capsules:

- mono: an omni capsule vs a cardioid;
- a 6-capsule circle (5 cm): omni vs cardioids facing out;
- ``respeaker_4mic`` (omni, a device) vs the same square with hypercardioids;
- ``em32`` (32 capsules on the rigid sphere) vs 32 omni capsules at the same places in free
  field (the sphere's filters and its diffuse cross-spectra are its cost, not the patterns').

CPU seconds (``resource.getrusage``, every thread of the process) next to wall seconds; the bar
is 15 % over omni (issue 30) for the patterns; the sphere is reported, not barred.

Reproduce:
    python bench/bench_capsules.py            # about 3 min of CPU
    python bench/bench_capsules.py --quick    # 8 points, a 3 s walk
"""

from __future__ import annotations

import argparse
import platform
import resource
import subprocess
import time
from pathlib import Path

import numpy as np

FS = 16000


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def setup(points: int):
    import sonicspec as ss
    from sonicspec.acoustics.engine import acoustic_scene

    room = ss.Scene.shoebox([6.0, 5.0, 3.0], {"walls": "plaster_on_brick",
                                              "floor": "parquet_on_concrete",
                                              "ceiling": "acoustic_ceiling_tile"})
    settings = ss.RirSettings(rays=4000, image_source_order=2, max_rir_length_s=1.0,
                              sample_rate_hz=FS, diffraction=False).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    walk = np.linspace([1.0, 1.0, 1.5], [5.0, 3.8, 1.5], points)
    return scene, settings, walk


def receivers() -> list[tuple[str, dict, dict]]:
    from sonicspec.acoustics.receivers.devices import device

    base = {"yaw_deg": 0.0, "pitch_deg": 0.0, "trajectory": {"kind": "static"}}
    square = device("respeaker_4mic").capsules.offsets_m.tolist()
    em32 = device("em32").capsules.offsets_m.tolist()
    return [
        ("mono: cardioid", {"kind": "mono", **base},
         {"kind": "mono", "capsule": {"pattern": "cardioid"}, **base}),
        ("6-circle: cardioids out", {"kind": "circular_array", "n": 6, "radius_m": 0.05, **base},
         {"kind": "circular_array", "n": 6, "radius_m": 0.05,
          "capsule": {"pattern": "cardioid", "facing": "outward"}, **base}),
        ("respeaker_4mic: hypercardioids", {"kind": "device", "device": "respeaker_4mic", **base},
         {"kind": "custom", "positions_m": square,
          "capsule": {"pattern": "hypercardioid", "facing": "outward"}, **base}),
        ("em32 (rigid sphere)", {"kind": "custom", "positions_m": em32, **base},
         {"kind": "device", "device": "em32", **base}),
    ]


def rir_cost(scene, settings, walk, microphone) -> tuple[float, float, list]:
    from sonicspec.acoustics.engine import simulate_rirs

    c0, t0 = cpu_s(), time.perf_counter()
    _, facts = simulate_rirs(scene, np.array([3.0, 2.5, 1.5]), walk, settings,
                             np.random.default_rng(1), microphone=microphone,
                             keep_arrivals=True)
    return cpu_s() - c0, time.perf_counter() - t0, facts


def render_cost(walk, facts, microphone, seconds: float) -> tuple[float, float]:
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import scene_capsules
    from sonicspec.acoustics.moving.delays import PathSet, Receiver, render_paths
    from sonicspec.acoustics.receivers.hrtf import SphereHead

    mic = np.array([3.0, 2.5, 1.5])
    paths = PathSet.identify(walk, [f.early_arrivals for f in facts],
                             at_mic=[f.early_arrivals_at_mic for f in facts])
    caps = scene_capsules(microphone)
    if microphone["kind"] == "mono" and caps is None:
        receiver = Receiver()
    elif caps is None:
        from sonicspec.acoustics.engine import array_offsets

        receiver = Receiver("array", offsets_m=array_offsets(microphone), center_m=mic)
    elif caps.sphere_radius_m is not None:
        receiver = Receiver("sphere_head", head=SphereHead(head_radius_m=caps.sphere_radius_m),
                            ear_axes=caps.axes, center_m=mic)
    else:
        receiver = Receiver("array", offsets_m=caps.offsets_m, center_m=mic,
                            capsule_axes=caps.axes, capsule_alphas=caps.alphas)
    n = int(seconds * FS)
    dry = np.random.default_rng(2).standard_normal(n)
    index = np.linspace(0, len(walk) - 1, n)
    bank = OctaveFilterBank(FS, ())
    c0, t0 = cpu_s(), time.perf_counter()
    render_paths(dry, index, walk, paths, bank, n_out=n + 2000, receiver=receiver)
    return cpu_s() - c0, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="8 points, a 3 s walk")
    args = parser.parse_args()
    points, seconds = (8, 3.0) if args.quick else (24, 6.0)
    scene, settings, walk = setup(points)
    rir_cost(scene, settings, walk, {"kind": "mono", "yaw_deg": 0.0, "pitch_deg": 0.0,
                                     "trajectory": {"kind": "static"}})  # warm the caches
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True, cwd=Path(__file__).parent).stdout.strip()
    print(f"# bench_capsules at {head}, {platform.python_version()}, {points} RIR points, "
          f"{seconds:g} s walk\n")
    print("| receiver | rir CPU s omni → directional | rir over omni | render CPU s omni → "
          "directional | render over omni | group over omni |")
    print("|---|---|---|---|---|---|")
    for label, omni, directional in receivers():
        r0, _, f0 = rir_cost(scene, settings, walk, omni)
        r1, _, f1 = rir_cost(scene, settings, walk, directional)
        p0, _ = render_cost(walk, f0, omni, seconds)
        p1, _ = render_cost(walk, f1, directional, seconds)
        print(f"| {label} | {r0:.2f} → {r1:.2f} | {100 * (r1 / r0 - 1):+.0f} % | "
              f"{p0:.2f} → {p1:.2f} | {100 * (p1 / p0 - 1):+.0f} % | "
              f"{100 * ((r1 + p1) / (r0 + p0) - 1):+.0f} % |", flush=True)


if __name__ == "__main__":
    main()
