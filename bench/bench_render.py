"""Benchmark (issue 5): a 60 s, 16 kHz track moving past 120 RIRs of 1 s each.

Times the three interpolations side by side (sample_crossfade, stft_crossfade, segment_ola,
best of ``--repeat`` runs) against the naive reference of sample_crossfade (convolve the whole
track with every RIR, then blend; one run) and against the floor, one FFT convolution with a
single static RIR; mono and 8 channels. Peak memory is the process's (VmHWM).

Reproduce:
    python bench/bench_render.py
    python bench/bench_render.py --seconds 20 --rirs 40     # quicker
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.signal import fftconvolve

from sonicspec.audio.render import INTERPOLATIONS, render_moving, render_naive


def peak_rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def timed(fn, *args, repeat: int = 1) -> tuple[float, np.ndarray]:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rirs", type=int, default=120)
    parser.add_argument("--rir-seconds", type=float, default=1.0)
    parser.add_argument("--naive-prefix", type=float, default=0.25,
                        help="fraction of the RIRs the 8-channel naive run convolves "
                             "(scaled up; it is linear in the RIR count)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs of each fast renderer; the best is reported")
    args = parser.parse_args()
    fs = 16000
    rng = np.random.default_rng(0)
    dry = rng.standard_normal(int(args.seconds * fs))
    length = int(args.rir_seconds * fs)
    decay = np.exp(-np.arange(length) / (0.1 * fs))
    pos = np.linspace(0, args.rirs - 1, dry.size)
    print(f"{args.seconds:g} s at {fs} Hz past {args.rirs} RIRs of {args.rir_seconds:g} s")
    print(f"{'channels':>8} {'mode':>17} {'time':>8} {'vs naive':>9} {'vs floor':>9} "
          f"{'per output s':>13}")
    for channels in (1, 8):
        rirs = rng.standard_normal((args.rirs, channels, length)) * decay
        t_floor, _ = timed(fftconvolve, dry[None], rirs[0], "full", -1, repeat=args.repeat)
        times, outputs = {}, {}
        for mode in INTERPOLATIONS:
            times[mode], outputs[mode] = timed(render_moving, dry, rirs, pos, mode,
                                               repeat=args.repeat)
        if channels == 1:
            t_naive, ref = timed(render_naive, dry, rirs, pos)
            y = outputs["sample_crossfade"]
            err = float(np.linalg.norm(y - ref) / np.linalg.norm(ref))
            note = f"sample_crossfade rel. error vs naive {err:.1e}"
        else:
            k = max(2, int(args.naive_prefix * args.rirs))
            sub_pos = np.clip(pos, 0, k - 1)
            t_part, _ = timed(render_naive, dry, rirs[:k], sub_pos)
            t_naive = t_part * args.rirs / k
            note = f"naive: {k} RIRs timed, scaled"
        del outputs
        for mode in INTERPOLATIONS:
            t = times[mode]
            print(f"{channels:>8} {mode:>17} {t:>7.2f}s {t_naive / t:>8.1f}x {t / t_floor:>8.1f}x "
                  f"{t / args.seconds * 1000:>10.1f} ms")
        print(f"{channels:>8} {'naive':>17} {t_naive:>7.1f}s   ({note})")
        print(f"{channels:>8} {'static floor':>17} {t_floor:>7.2f}s "
              f"{'':>19}{t_floor / args.seconds * 1000:>10.1f} ms")
    print(f"peak RSS {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
