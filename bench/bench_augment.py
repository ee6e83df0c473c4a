"""Benchmark (issue 30): the CPU cost of device and channel effects per group.

A SonicSet group writes nine mixtures of 60 s at 16 kHz (separation of two of the three
speakers with noise and with music, enhancement of each speaker). Each effect of
:mod:`sonicspec.audio.augment` is timed alone on one such mixture (speech-like: pink noise in
syllable-rate bursts over a harmonic voice), then a typical chain as the docs' example draws it:

    response (p 0.8) · self_noise · gain · clipping (p 0.1) · resample 8 kHz (p 0.3) ·
    one_of mp3 / opus / gsm (p 0.6)

The chain's cost per group is the mean over 40 draws of one mixture's time × 9, and with
every effect applied, once per codec, × 9. CPU seconds (``time.process_time``, after a warm-up
run on one second) on one core; wall times too, the machine being shared. The same for a
4-capsule array (every effect per channel).

Reproduce:
    python bench/bench_augment.py                # about 2 min
    python bench/bench_augment.py --seconds 20   # quicker
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np

from sonicspec.audio.augment import apply_chain, draw_chain, parse_chain

RATE = 16000
MIXTURES_PER_GROUP = 9

TYPICAL = {"effects": [
    {"kind": "response", "preset": ["smartphone", "laptop", "headset"], "probability": 0.8},
    {"kind": "self_noise", "snr_db": [25, 45], "color": "pink"},
    {"kind": "gain", "gain_db": [-6, 6]},
    {"kind": "clipping", "threshold_dbfs": [-6, -1], "probability": 0.1},
    {"kind": "resample", "rate_hz": [8000], "probability": 0.3},
    {"kind": "one_of", "probability": 0.6, "weights": [2, 1, 1], "effects": [
        {"kind": "mp3", "bitrate_kbps": [32, 64, 128]},
        {"kind": "opus", "bitrate_kbps": [12, 32]},
        {"kind": "gsm"}]},
]}

ALONE = [
    ("response (smartphone)", {"kind": "response", "preset": ["smartphone"]}),
    ("self_noise (pink)", {"kind": "self_noise", "snr_db": [30, 30], "color": "pink"}),
    ("gain", {"kind": "gain", "gain_db": [3, 3]}),
    ("clipping", {"kind": "clipping", "threshold_dbfs": [-3, -3]}),
    ("resample 8 kHz and back", {"kind": "resample", "rate_hz": [8000]}),
    ("mp3 64 kbit/s", {"kind": "mp3", "bitrate_kbps": [64]}),
    ("opus 24 kbit/s", {"kind": "opus", "bitrate_kbps": [24, 24]}),
    ("gsm 06.10", {"kind": "gsm"}),
]


def speech_like(seconds: float, channels: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.maximum(np.fft.rfftfreq(n, 1 / RATE), 50.0)
    pink = np.fft.irfft(spec / np.sqrt(f), n)
    bursts = (0.5 + 0.5 * np.sin(2 * np.pi * 4.0 * t)) ** 2
    voice = sum(np.sin(2 * np.pi * 140.0 * k * t) / k for k in range(1, 20))
    x = bursts * (pink / np.std(pink) + 0.3 * voice)
    x = 0.1 * x / np.std(x)
    return np.stack([np.roll(x, 7 * c) for c in range(channels)])


def timed(draw: list, x: np.ndarray) -> tuple[float, float]:
    """(CPU s, wall s) of one application, after a warm-up on a short signal (imports,
    filter design caches)."""
    apply_chain(draw, x[:, :RATE], RATE)
    c, w = time.process_time(), time.perf_counter()
    apply_chain(draw, x, RATE)
    return time.process_time() - c, time.perf_counter() - w


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="mixture length, s (60)")
    ap.add_argument("--draws", type=int, default=40, help="draws of the typical chain (40)")
    args = ap.parse_args()
    print(f"# bench_augment: {args.seconds:g} s mixtures at {RATE} Hz; python "
          f"{platform.python_version()}, numpy {np.__version__}")
    print(f"# command: python bench/bench_augment.py --seconds {args.seconds:g} "
          f"--draws {args.draws}")
    for channels in (1, 4):
        x = speech_like(args.seconds, channels)
        print(f"\n## {channels} channel(s): each effect alone, one mixture")
        print("| effect | CPU s | wall s | × realtime (CPU) |")
        print("| --- | ---: | ---: | ---: |")
        for label, effect in ALONE:
            draw = draw_chain(parse_chain({"effects": [effect]}), np.random.default_rng(0))
            cpu, wall = timed(draw, x)
            print(f"| {label} | {cpu:.3f} | {wall:.3f} | {args.seconds / cpu:.0f} |")
        chain = parse_chain(TYPICAL)
        cpus = []
        for s in range(args.draws):
            cpus.append(timed(draw_chain(chain, np.random.default_rng(s)), x)[0])
        mean = float(np.mean(cpus))
        print(f"\ntypical chain, {args.draws} draws: mean {mean:.3f} CPU s per mixture "
              f"(median {np.median(cpus):.3f}, max {max(cpus):.3f}); per group of "
              f"{MIXTURES_PER_GROUP} mixtures {MIXTURES_PER_GROUP * mean:.2f} CPU s")
        for codec in ({"kind": "mp3", "bitrate_kbps": 128}, {"kind": "opus", "bitrate_kbps": 32.0},
                      {"kind": "gsm"}):
            every = draw_chain(chain, np.random.default_rng(0))
            for d in every:
                d["applied"] = True
            every[-1]["effect"] = {**codec, "applied": True, "targets": False}
            cpu = timed(every, x)[0]
            print(f"every effect applied, {codec['kind']}: {cpu:.3f} CPU s per mixture, "
                  f"{MIXTURES_PER_GROUP * cpu:.2f} CPU s per group")
    return 0


if __name__ == "__main__":
    sys.exit(main())
