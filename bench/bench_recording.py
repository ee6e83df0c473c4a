"""Benchmark (issue 31): what the real-recording kit costs on a long take, and how well it aligns.

A dataset of one group with two talkers (band-limited noise bursts at a syllable rate, the
``source<k>_dry`` stems) of ``--seconds`` at ``--rate`` is written; ``write_sheet`` makes its
playback sheet; a recording is simulated from it as tests/test_recording.py does (each
loudspeaker through a direct path + exponential tail RIR, summed, a recorder clock
``--ppm`` off, a delay of 1234.37 recorder samples, white noise 20 dB below the talkers);
then ``align_take`` finds the chirps (two passes), measures the drift and resamples the
talkers' span. Printed: wall and CPU seconds (getrusage, this process; the machine is shared)
of the sheet and of the alignment, the start chirp's error (samples and ms) and the drift's
error (ppm).

Reproduce:
    python bench/bench_recording.py                          # 60 s at 48 kHz, +50 ppm
    python bench/bench_recording.py --seconds 10 --rate 16000 --ppm -50
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import soundfile as sf
from scipy.signal import butter, fftconvolve, resample_poly, sosfiltfilt

from sonicspec.dataload.recording import Chirp, align_take, write_sheet


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _dataset(root: Path, seconds: float, rate: int) -> None:
    rng = np.random.default_rng(7)
    band = butter(8, (80, min(7000, 0.4 * rate)), "bandpass", fs=rate, output="sos")
    n = int(seconds * rate)
    t = np.arange(n) / rate
    gid = "test/000000"
    (root / gid).mkdir(parents=True)
    meta = {"sample_rate_hz": rate, "num_samples": n}
    for k in (1, 2):
        env = np.maximum(0.0, np.sin(2 * np.pi * (3 + k) * t + k)) ** 2
        x = 0.3 * env * sosfiltfilt(band, rng.standard_normal(n))
        sf.write(root / gid / f"source{k}_dry.wav", x, rate, subtype="FLOAT")
        sf.write(root / gid / f"source{k}.wav", x, rate, subtype="FLOAT")
        meta[f"source{k}"] = {"file": f"{gid}/source{k}.wav"}
    (root / gid / "metadata.json").write_text(json.dumps(meta))
    (root / "dataset.json").write_text(json.dumps({"splits": {"test": {}}, "groups": [
        {"group": gid, "split": "test", "metadata": {"path": f"{gid}/metadata.json"}}]}))


def _record(sheet: Path, take: dict, rate: int, ppm: int, delay: float
            ) -> tuple[np.ndarray, float]:
    rng = np.random.default_rng(2026)
    played = [sf.read(sheet / ls["file"])[0] for ls in take["loudspeakers"]]
    room = np.zeros(len(played[0]) + int(0.3 * rate))
    direct = 0
    for i, p in enumerate(played):
        d = 20 + 17 * i
        direct = direct or d
        h = np.zeros(int(0.3 * rate))
        h[d] = 1.0
        tail = rng.standard_normal(len(h) - d - 32) * np.exp(-6.9 * np.arange(len(h) - d - 32)
                                                             / (0.3 * rate))
        h[d + 32:] = tail * np.sqrt(2.0 / np.sum(tail ** 2))
        wet = fftconvolve(p, h)
        room[:len(wet)] += wet[:len(room)]
    ratio = Fraction(1_000_000 + ppm, 1_000_000)
    y = resample_poly(room, ratio.numerator, ratio.denominator)
    n = len(y) + int(delay) + 64
    spec = np.fft.rfft(y, n)
    y = np.fft.irfft(spec * np.exp(-2j * np.pi * np.fft.rfftfreq(n) * delay), n)
    lay = take["layout_samples"]
    talkers = room[lay["lead"] + lay["chirp"] + lay["gap"]:][:lay["content"]]
    noise = rng.standard_normal(len(y))
    y += noise * np.sqrt(np.mean(talkers ** 2) / np.mean(noise ** 2)) * 0.1
    return y, (lay["lead"] + direct) * float(ratio) + delay


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=int, default=48000)
    ap.add_argument("--ppm", type=int, default=50)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _dataset(tmp / "data", args.seconds, args.rate)
        w, c = time.perf_counter(), _cpu()
        manifest = write_sheet(tmp / "data", tmp / "sheet", "test")
        sheet_w, sheet_c = time.perf_counter() - w, _cpu() - c
        take = manifest["takes"][0]
        y, truth = _record(tmp / "sheet", take, args.rate, args.ppm, 1234.37)
        w, c = time.perf_counter(), _cpu()
        a, cut = align_take(y[None], args.rate, take, Chirp(), "simulated")
        align_w, align_c = time.perf_counter() - w, _cpu() - c
    err = a.start_chirp - truth
    print(f"take: {args.seconds:g} s of talkers at {args.rate} Hz, 2 loudspeakers, "
          f"{len(y) / args.rate:.1f} s recorded, drift {args.ppm:+d} ppm")
    print(f"write_sheet: {sheet_w:.2f} s wall, {sheet_c:.2f} s CPU")
    print(f"align_take:  {align_w:.2f} s wall, {align_c:.2f} s CPU "
          f"(cut {cut.shape[1]} samples)")
    print(f"start chirp error: {err:+.3f} samples ({1000 * err / args.rate:+.4f} ms); "
          f"drift error: {a.drift_ppm - args.ppm:+.3f} ppm; correlation {a.correlation:.2f}")


if __name__ == "__main__":
    main()
