"""Benchmark (issue 28 item 15): what causal (minimum-phase) band shaping costs and buys.

Prints, for the early part of an RIR at 16 kHz (``synthesize_early``):
- the time for N arrivals with frequency-dependent band factors (each its own minimum-phase
  shaping filter) and for N flat arrivals (plain taps), median of 3;
- behind a screen (the causality test's room: a sheet 1.8 m high, surfaces absorbing 2–95 %),
  for each strongly frequency-dependent arrival alone: the largest sample before
  ``delay - 32`` (the fractional tap's half-width) and before ``delay - 6`` samples, relative
  to its peak.

Reproduce:
    python bench/bench_causal_shaping.py
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from sonicspec.acoustics import engine  # noqa: E402
from sonicspec.acoustics.arrivals import Arrivals  # noqa: E402
from sonicspec.acoustics.bands import OctaveFilterBank  # noqa: E402
from sonicspec.acoustics.receivers.synthesis import DEFAULT_TAPS, synthesize_early  # noqa: E402

FS = 16000


def arrivals(n: int, flat: bool, bank: OctaveFilterBank) -> Arrivals:
    rng = np.random.default_rng(0)
    amp = rng.uniform(0.01, 0.1, (n, 1)) * np.ones((n, bank.n_bands))
    if not flat:
        amp = amp * np.geomspace(1, 0.2, bank.n_bands) * rng.uniform(0.5, 1, (n, bank.n_bands))
    return Arrivals(np.sort(rng.uniform(0.003, 0.3, n)), amp, np.tile([1.0, 0, 0], (n, 1)),
                    np.ones(n, int), np.ones(n, np.int8), np.ones(n))


def timing() -> None:
    bank = OctaveFilterBank(FS)
    print(f"{'arrivals':>9} {'shaped s':>9} {'flat s':>8}")
    for n in (100, 400, 1600):
        row = []
        for flat in (False, True):
            a = arrivals(n, flat, bank)
            synthesize_early(a, bank, FS)
            times = []
            for _ in range(3):
                t = time.perf_counter()
                synthesize_early(a, bank, FS)
                times.append(time.perf_counter() - t)
            row.append(statistics.median(times))
        print(f"{n:>9} {row[0]:>9.3f} {row[1]:>8.3f}")


def precursors() -> None:
    from test_acoustics_causality import BANDS, one, screen_room, settings

    src, mic = np.array([2.5, 2.0, 1.0]), np.array([6.0, 2.0, 1.2])
    arr = engine.early_arrivals(screen_room(), mic, src[None], settings()).at_mic[0]
    bank = OctaveFilterBank(FS, BANDS)
    print(f"\n{'kind':>5} {'4k/125 dB':>10} {'before d-32':>12} {'before d-6':>11}")
    for i in range(len(arr)):
        a = one(arr, i)
        g = a.amplitudes[0]
        if g.max() < 3 * g.min():
            continue
        d = a.times_s[0] * FS
        h = synthesize_early(a, bank, int(d) + 4 * bank.padding())
        peak = np.abs(h).max()
        pre = [np.abs(h[:max(0, math.floor(d) - k)]).max(initial=0.0) / peak
               for k in (DEFAULT_TAPS // 2, 6)]
        kind = {1: "refl", 2: "diff"}.get(int(a.kind[0]), str(a.kind[0]))
        print(f"{kind:>5} {20 * np.log10(g[-1] / g[0]):>10.1f} {pre[0]:>12.2e} {pre[1]:>11.4f}")


if __name__ == "__main__":
    timing()
    precursors()
    print("\n$ python bench/bench_causal_shaping.py")
