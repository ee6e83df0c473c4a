"""Benchmark (issue 30): the cost of a diffuse background per group against point noise.

Two parts:

1. **Library**: one background track of ``--seconds`` at 16 kHz heard by receivers of 1–16
   channels, as a diffuse field (:func:`~sonicspec.acoustics.receivers.diffuse.render_isotropic`,
   plus the once-per-job mixing matrices from the receiver's per-direction responses) and,
   for comparison, as a point source: one FFT convolution with a ``--rir-seconds`` RIR per
   channel (what the render step does for a static source).
2. **Method**: coherence shaping against the alternative, one uncorrelated copy of the track
   per plane wave (32, 128, 512 directions) through each direction's response: CPU and the
   coherence error against sin(kd)/(kd).
3. **Pipeline**: the same small spec built in-process (every job of one store, timed with
   ``getrusage``) with ``noise_field: point`` and ``noise_field: diffuse_spherical``, for a
   4-capsule circular array, first-order ambisonics and the sphere head; the CPU seconds of
   the per-group steps (placement, arrange, rir, render, mix, export) per group, and their
   ratio.

Reproduce:
    python bench/bench_diffuse.py                      # both parts (a few minutes)
    python bench/bench_diffuse.py --skip-pipeline      # parts 1 and 3 only
    python bench/bench_diffuse.py --groups 1 --seconds 20   # quicker
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.signal import fftconvolve

from sonicspec.acoustics.bands import default_bands
from sonicspec.acoustics.engine import (
    SimulationSettings,
    direction_responses,
    receiver_aperture_m,
)
from sonicspec.acoustics.receivers.diffuse import (
    direction_count,
    isotropic_directions,
    isotropic_roots,
    render_isotropic,
)

FS = 16000
C = 343.0
GROUP_STEPS = ("placement", "arrange", "rir", "render", "mix", "export")

SPEC = """\
sonicspec: 1
name: bench_diffuse
seed: 3
sample_rate_hz: 16000
scenes:
  - kind: shoebox
    id: room
    size_m: [6.0, 5.0, 3.0]
    materials: {{walls: plaster_on_brick, floor: carpet_on_concrete,
                ceiling: acoustic_ceiling_tile}}
microphone: {mic}
placement:
  source_start_distance_m: [1.0, 3.0]
  source_end_distance_m: [1.0, 3.0]
  source_travel_distance_m: [1.0, 2.5]
  noise_distance_m: [1.0, 3.0]
  music_distance_m: [1.0, 3.0]
trajectory: {{kind: shortest_path, rir_spacing_m: 0.25}}
acoustics: {{rays: 2000, image_source_order: 2, max_rir_length_s: auto}}
corpora:
  speech: {{kind: generated, speakers_per_split: 3, utterances_per_speaker: 3}}
  noise: {{kind: generated, clips_per_split: 3, clip_duration_s: 5.0}}
  music: {{kind: generated, clips_per_split: 3, clip_duration_s: 5.0}}
mixture:
  duration_s: {seconds}
  speakers: 2
  utterances_per_speaker: [2, 3]
  noise_clips: [3, 4]
  music_clips: [3, 4]
  noise_field: {{field: {field}}}
  loudness: {{speech_lufs: -24, noise_lufs: -28, music_lufs: -31}}
  tasks:
    - {{kind: separation, speakers: 2, background: noise}}
    - {{kind: enhancement, background: both}}
splits:
  train: {{groups: {groups}, scenes: [room]}}
outputs: {{dir: out, store_dir: store, manifests: [lhotse], groups_per_shard: {groups}}}
"""

MICS = {
    "circular_array (4)": "{kind: circular_array, n: 4, radius_m: 0.05}",
    "ambisonics (order 1)": "{kind: ambisonics, order: 1}",
    "binaural (sphere head)": "{kind: binaural}",
}


def cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def settings() -> SimulationSettings:
    return SimulationSettings(
        sample_rate_hz=FS, bands_hz=default_bands(FS), rays=1, image_source_order=0,
        max_rir_length_s=1.0, energy_threshold_db=60.0, air_absorption=False,
        temperature_c=20.0, relative_humidity_pct=50.0, transmission=False,
        diffuse_rain=False, receiver_radius_m=0.1, histogram_bin_s=0.001,
        speed_of_sound_m_s=C)


def library(seconds: float, rir_seconds: float, repeat: int) -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(int(seconds * FS))
    print(f"\n1. library: a {seconds:g} s track at {FS} Hz (best of {repeat}; CPU s)")
    print(f"{'receiver':>24} {'directions':>10} {'matrices':>9} {'diffuse':>8} "
          f"{'point (1 RIR)':>14} {'ratio':>6}")
    mics = {"mono": {"kind": "mono"},
            "binaural (sphere head)": {"kind": "binaural", "yaw_deg": 0.0, "pitch_deg": 0.0,
                                       "hrtf": {"kind": "sphere", "head_radius_m": 0.0875,
                                                "ear_angle_deg": 100.0}},
            "circular_array (4, 5 cm)": {"kind": "circular_array", "n": 4, "radius_m": 0.05,
                                         "yaw_deg": 0.0, "pitch_deg": 0.0},
            "circular_array (8, 10 cm)": {"kind": "circular_array", "n": 8, "radius_m": 0.1,
                                          "yaw_deg": 0.0, "pitch_deg": 0.0},
            "ambisonics (order 3)": {"kind": "ambisonics", "order": 3, "yaw_deg": 0.0,
                                     "pitch_deg": 0.0}}
    s = settings()
    for name, mic in mics.items():
        t0 = cpu_s()
        n = direction_count("spherical", receiver_aperture_m(mic), FS, C)
        roots = isotropic_roots(direction_responses(isotropic_directions("spherical", n), s,
                                                    mic), FS)
        t_roots = cpu_s() - t0
        channels = roots.shape[1]
        rir = rng.standard_normal((channels, int(rir_seconds * FS))) * np.exp(
            -np.arange(int(rir_seconds * FS)) / (0.1 * FS))
        best_d = best_p = float("inf")
        for _ in range(repeat):
            t0 = cpu_s()
            render_isotropic(x, roots, np.random.default_rng(1))
            best_d = min(best_d, cpu_s() - t0)
            t0 = cpu_s()
            fftconvolve(x[None, :], rir, axes=-1)
            best_p = min(best_p, cpu_s() - t0)
        print(f"{name:>24} {n:>10} {t_roots:>8.2f}s {best_d:>7.2f}s {best_p:>13.2f}s "
              f"{best_d / best_p:>6.2f}")


def plane_waves(seconds: float) -> None:
    """The alternative: one uncorrelated copy per plane wave through each direction's
    response, summed (the copies drawn as :func:`render_isotropic` draws them, with an
    identity matrix), against coherence shaping; a 4-capsule array with a 20 cm pair."""
    from scipy import signal

    from sonicspec.acoustics.theory import spherical_isotropic_coherence

    mic = {"kind": "custom", "positions_m": [[0, 0, 0], [0.05, 0, 0], [0.1, 0, 0],
                                             [0.2, 0, 0]], "yaw_deg": 0.0, "pitch_deg": 0.0}
    s = settings()
    x = np.random.default_rng(0).standard_normal(int(seconds * FS))

    def rms_error(y: np.ndarray) -> float:
        errors = []
        for j, d in ((1, 0.05), (2, 0.1), (3, 0.2)):
            f, pxy = signal.csd(y[0], y[j], FS, nperseg=512)
            _, pxx = signal.welch(y[0], FS, nperseg=512)
            _, pyy = signal.welch(y[j], FS, nperseg=512)
            band = (f >= 100) & (f <= 4000)
            g = pxy.real[band] / np.sqrt(pxx[band] * pyy[band])
            errors.append(np.sqrt(np.mean((g - spherical_isotropic_coherence(f[band], d)) ** 2)))
        return float(max(errors))

    print(f"\n2. method: a {seconds:g} s track on 4 omni capsules (pairs 5, 10, 20 cm); the "
          "worst pair's coherence RMS error against sin(kd)/(kd), 100-4000 Hz; CPU s")
    print(f"{'method':>40} {'CPU':>7} {'RMS error':>10}")
    for n in (32, 128, 512):
        t0 = cpu_s()
        responses = direction_responses(isotropic_directions("spherical", n), s, mic)
        y = np.zeros((4, x.size + responses.shape[2] - 1))
        eye = np.broadcast_to(np.eye(32, dtype=np.complex128), (257, 32, 32))
        for start in range(0, n, 32):
            copies = render_isotropic(x, eye, np.random.default_rng(start))  # (32, n)
            for m in range(4):
                y[m] += fftconvolve(copies, responses[start:start + 32, m], axes=-1).sum(0)
        y /= np.sqrt(n)
        t = cpu_s() - t0
        print(f"{f'{n} uncorrelated plane waves':>40} {t:>6.2f}s {rms_error(y):>10.3f}")
    t0 = cpu_s()
    n = direction_count("spherical", receiver_aperture_m(mic), FS, C)
    roots = isotropic_roots(direction_responses(isotropic_directions("spherical", n), s, mic),
                            FS)
    y = render_isotropic(x, roots, np.random.default_rng(1))
    t = cpu_s() - t0
    print(f"{f'coherence shaping ({n} directions)':>40} {t:>6.2f}s {rms_error(y):>10.3f}")


def pipeline(seconds: float, groups: int) -> None:
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages import run_job

    print(f"\n3. pipeline: {groups} group(s) of {seconds:g} s, CPU s per group of the "
          f"per-group steps ({', '.join(GROUP_STEPS)})")
    print(f"{'microphone':>24} {'point':>8} {'diffuse':>8} {'ratio':>6}   "
          f"{'render point → diffuse':>24}")
    for mic_name, mic in MICS.items():
        totals, renders = {}, {}
        for field in ("point", "diffuse_spherical"):
            with tempfile.TemporaryDirectory() as tmp:
                path = Path(tmp) / "spec.yaml"
                path.write_text(SPEC.format(mic=mic, seconds=seconds, field=field,
                                            groups=groups))
                plan = compile_spec(load_spec(path))
                per_step: dict[str, float] = {}
                for job in plan.jobs:
                    t0 = cpu_s()
                    run_job(plan, job.key)
                    per_step[job.step] = per_step.get(job.step, 0.0) + cpu_s() - t0
            totals[field] = sum(per_step.get(s, 0.0) for s in GROUP_STEPS) / groups
            renders[field] = per_step["render"] / groups
        ratio = totals["diffuse_spherical"] / totals["point"]
        print(f"{mic_name:>24} {totals['point']:>7.2f}s {totals['diffuse_spherical']:>7.2f}s "
              f"{ratio:>6.3f}   {renders['point']:>10.2f}s → "
              f"{renders['diffuse_spherical']:.2f}s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="group / track length")
    parser.add_argument("--rir-seconds", type=float, default=0.5)
    parser.add_argument("--groups", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--skip-pipeline", action="store_true")
    args = parser.parse_args()
    t0 = time.perf_counter()
    library(args.seconds, args.rir_seconds, args.repeat)
    plane_waves(min(args.seconds, 20.0))
    if not args.skip_pipeline:
        pipeline(args.seconds, args.groups)
    print(f"\nwall {time.perf_counter() - t0:.1f} s, CPU {cpu_s():.1f} s")


if __name__ == "__main__":
    main()
