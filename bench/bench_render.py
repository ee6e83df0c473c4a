"""Benchmark (issue 5): a 60 s, 16 kHz track moving past 120 RIRs of 1 s each.

Times the block-wise sample crossfade against the naive reference (convolve the whole track
with every RIR, then blend) and against the floor, one FFT convolution with a single static
RIR; mono and 8 channels. Peak memory is the process's (VmHWM).

Reproduce:
    python bench/bench_render.py
    python bench/bench_render.py --seconds 20 --rirs 40     # quicker
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.signal import fftconvolve

from sonicspec.audio.render import render_naive, render_sample_crossfade


def peak_rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def timed(fn, *args) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t0, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rirs", type=int, default=120)
    parser.add_argument("--rir-seconds", type=float, default=1.0)
    parser.add_argument("--naive-prefix", type=float, default=0.25,
                        help="fraction of the RIRs the 8-channel naive run convolves "
                             "(scaled up; it is linear in the RIR count)")
    args = parser.parse_args()
    fs = 16000
    rng = np.random.default_rng(0)
    dry = rng.standard_normal(int(args.seconds * fs))
    length = int(args.rir_seconds * fs)
    decay = np.exp(-np.arange(length) / (0.1 * fs))
    pos = np.linspace(0, args.rirs - 1, dry.size)
    print(f"{args.seconds:g} s at {fs} Hz past {args.rirs} RIRs of {args.rir_seconds:g} s")
    print(f"{'channels':>8} {'block-wise':>11} {'naive':>10} {'speed-up':>9} "
          f"{'static floor':>13} {'per output s':>13} {'rel. error':>11}")
    for channels in (1, 8):
        rirs = rng.standard_normal((args.rirs, channels, length)) * decay
        t_block, y = timed(render_sample_crossfade, dry, rirs, pos)
        t_floor, _ = timed(fftconvolve, dry[None], rirs[0], "full", -1)
        if channels == 1:
            t_naive, ref = timed(render_naive, dry, rirs, pos)
            err = float(np.linalg.norm(y - ref) / np.linalg.norm(ref))
            note = ""
        else:
            k = max(2, int(args.naive_prefix * args.rirs))
            sub_pos = np.clip(pos, 0, k - 1)
            t_part, _ = timed(render_naive, dry, rirs[:k], sub_pos)
            t_naive, err, note = t_part * args.rirs / k, float("nan"), f" (naive: {k} RIRs, scaled)"
        print(f"{channels:>8} {t_block:>10.2f}s {t_naive:>9.1f}s {t_naive / t_block:>8.1f}x "
              f"{t_floor:>12.2f}s {t_block / args.seconds * 1000:>10.1f} ms {err:>11.1e}{note}")
    print(f"peak RSS {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
