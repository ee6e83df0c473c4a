"""Benchmark (issue 18): today's moving-source rendering against the exact moving point source.

The issue's scene in free field (a hall whose surfaces absorb everything: the direct path is
all there is): a source walks a straight line at 1.5 m/s past a mono microphone (closest
approach 1 m, at the middle of the walk), RIRs at points every ``spacing`` metres along the
line. Each RIR is the exact direct path of its point (``1/(4π r)`` at ``r/c``, a ±32-sample
Kaiser-windowed sinc: ``theory.windowed_sinc``), so every difference from the exact solution
comes from the interpolation between the points, none from the RIRs. The dry signal is
speech-shaped noise (pink noise, 3 s, band-limited to 0.8 × Nyquist; speech from espeak-ng
with ``--speech``). The reference is ``theory.moving_point_source`` of the same dry signal
along the same walk (positions at emission times, the walk timed as
``audio.render.path_position_from_distances`` times it).

The last rows: ``acoustics.moving.delays.render_path``, the time-varying delay that issue 18 asks
for (positions along the walk, no RIR points), and the time of the exact reference.

Figures (``audio.fidelity``), over the frames while the source walks: SNR against the exact
signal, and the smoothed (1/6 octave) spectral deviation, 200–5000 Hz, 64 ms frames: the worst
dip and the 5th percentile. Issue 18 measured, for speech through the spec:
``sample_crossfade`` at 0.25 m −26 dB worst, −7.9 dB 5th percentile, SNR 7.5 dB.

Reproduce:
    python bench/bench_motion.py                 # ~1 min
    python bench/bench_motion.py --speech        # espeak-ng speech as the dry signal
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from sonicspec.acoustics.moving.delays import render_path
from sonicspec.acoustics.theory import moving_point_source, windowed_sinc
from sonicspec.audio.fidelity import dip_figures, snr_db, spectral_deviation_db
from sonicspec.audio.render import INTERPOLATIONS, path_position_from_distances, render_moving

FS = 16000
C = 343.0
SPEED = 1.5
LENGTH_M = 4.5  # the walk: 3 s at 1.5 m/s, from 2.25 m before the closest approach to after


def dry_signal(speech: bool, n: int) -> np.ndarray:
    if speech:
        import soundfile as sf

        with tempfile.TemporaryDirectory() as tmp:
            wav = Path(tmp) / "s.wav"
            text = ("The quick brown fox jumps over the lazy dog while the moving source "
                    "walks past the microphone at a steady pace.")
            subprocess.run(["espeak-ng", "-w", str(wav), "-s", "150", text], check=True)
            x, rate = sf.read(str(wav))
        from scipy.signal import resample_poly

        x = resample_poly(x, FS, rate)
        x = np.tile(x, int(np.ceil(n / x.size)))[:n]
    else:
        spec = np.fft.rfft(np.random.default_rng(7).standard_normal(n))
        f = np.fft.rfftfreq(n, 1 / FS)
        spec[1:] /= np.sqrt(f[1:] / 100.0)  # pink above 100 Hz
        spec[f > 0.8 * FS / 2] = 0
        x = np.fft.irfft(spec, n)
    return x / np.max(np.abs(x))


def direct_rirs(points: np.ndarray, mic: np.ndarray, length: int) -> np.ndarray:
    r = np.linalg.norm(points - mic, axis=1)
    taps = np.arange(length)
    return (windowed_sinc(taps[None, :] - (r / C * FS)[:, None]) / (4 * np.pi * r)[:, None]
            )[:, None, :]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speech", action="store_true", help="espeak-ng speech as dry signal")
    args = parser.parse_args()
    n = int(LENGTH_M / SPEED * FS)
    dry = dry_signal(args.speech, n)
    mic = np.array([0.0, 1.0, 1.5])
    print(f"dry: {'espeak-ng speech' if args.speech else 'pink noise'}, {n / FS:.1f} s at "
          f"{SPEED} m/s past a mono microphone 1 m away; free field (direct path only)")
    print("| method | RIR spacing | SNR vs exact dB | worst dip dB | 5th pct dip dB | s |")
    print("|---|---|---|---|---|---|")
    rows = [("static source (one RIR)", None, 0.25)] + [
        (m, m, s) for s in (0.25, 0.05) for m in INTERPOLATIONS]
    for label, method, spacing in rows:
        n_points = round(LENGTH_M / spacing) + 1
        d = np.linspace(0.0, LENGTH_M, n_points)
        points = np.stack([d - LENGTH_M / 2, np.zeros_like(d), np.full_like(d, 1.5)], 1)
        length = int(np.ceil(np.linalg.norm(points - mic, axis=1).max() / C * FS)) + 64
        start = time.perf_counter()
        if method is None:  # the static case: the source stays at the first point
            rirs = direct_rirs(points[:1], mic, length)
            position = np.zeros(n)
            walk = np.broadcast_to(points[0], (n, 3))
            y = render_moving(dry, rirs, position, "sample_crossfade")[0]
        else:
            rirs = direct_rirs(points, mic, length)
            position = path_position_from_distances(d, n, None, SPEED, FS)
            travelled = np.interp(position, np.arange(n_points), d)
            walk = np.stack([travelled - LENGTH_M / 2, np.zeros(n), np.full(n, 1.5)], 1)
            y = render_moving(dry, rirs, position, method)[0]
        seconds = time.perf_counter() - start
        start = time.perf_counter()
        exact = moving_point_source(dry, walk, mic, FS, speed_of_sound_m_s=C, n_out=y.size)
        reference_s = time.perf_counter() - start
        active = (int(0.1 * FS), n - int(0.1 * FS))
        dev, _, _ = spectral_deviation_db(exact, y, FS, active=active)
        dips = dip_figures(dev)
        core = slice(active[0], active[1])
        print(f"| {label} | {'' if method is None else f'{spacing} m'} | "
              f"{snr_db(exact[core], y[core]):.1f} | {dips['worst_db']:.1f} | "
              f"{dips['p5_db']:.1f} | {seconds:.2f} |")
        if method == INTERPOLATIONS[-1] and spacing == 0.05:
            # The time-varying delay needs no RIR points: the positions along the walk.
            start = time.perf_counter()
            y = render_path(dry, walk, mic, FS, speed_of_sound_m_s=C, n_out=y.size)
            seconds = time.perf_counter() - start
            dev, _, _ = spectral_deviation_db(exact, y, FS, active=active)
            dips = dip_figures(dev)
            print(f"| time-varying delay (acoustics.moving) | exact positions | "
                  f"{snr_db(exact[core], y[core]):.1f} | {dips['worst_db']:.2f} | "
                  f"{dips['p5_db']:.2f} | {seconds:.2f} |")
            print(f"| (the exact reference itself, theory.moving_point_source) | | | | | "
                  f"{reference_s:.2f} |")
    print(f"\n$ python bench/bench_motion.py{' --speech' if args.speech else ''}")


if __name__ == "__main__":
    main()
