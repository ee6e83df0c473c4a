"""Benchmark (issue 18): moving sources through the whole pipeline, `paths` against the blends.

Two specs, each built once per method in one run (side by side, same machine, --cores 1):

* the issue's check: a source walking a line at 1.5 m/s past a mono microphone in a 12 x 8 x
  4 m hall whose surfaces absorb 99 % (`tests/test_pipeline_motion.py`'s spec), targets
  `[dry, direct]`; the exported direct stem against the exact moving point source computed
  from the exported dry stem and position track, over the frames where the source moves and
  speaks: SNR (best gain) and the smoothed spectral deviation's worst and 5th-percentile dip;
* the demo spec (`specs/demo.yaml`, three rooms, order-2 image sources, 6 groups of 10 s):
  CPU seconds of the `rir` and `render` steps (Snakemake's benchmark files), and the store's
  size.

Reproduce:
    python bench/bench_motion_pipeline.py        # ~4 min on 2 cores
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import soundfile as sf

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_pipeline_motion import SPEC  # noqa: E402

from sonicspec.acoustics.theory import moving_point_source  # noqa: E402
from sonicspec.audio.fidelity import dip_figures, spectral_deviation_db  # noqa: E402

METHODS = ("sample_crossfade", "paths")


def build(spec: Path) -> None:
    subprocess.run([sys.executable, "-m", "sonicspec.cli", "build", str(spec), "--cores", "1"],
                   check=True, capture_output=True)


def step_seconds(store: Path, step: str) -> float:
    total = 0.0
    for f in (store / "benchmarks" / step).rglob("*"):
        if f.is_file():
            total += float(f.read_text().splitlines()[1].split("\t")[-1])  # cpu_time
    return total


def folder_mb(path: Path) -> float:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) / 1e6


def motion_figures(folder: Path) -> tuple[float, float, float]:
    group = folder / "out" / "train" / "000000"
    meta = json.loads((group / "metadata.json").read_text())["source1"]
    dry, fs = sf.read(group / "source1_dry.wav")
    direct, _ = sf.read(group / "source1_direct.wav")
    hop = round(meta["track"]["hop_s"] * fs)
    pos = np.asarray(meta["track"]["positions_m"])
    t = np.arange(dry.size)
    path = np.stack([np.interp(t, np.arange(len(pos)) * hop, pos[:, i]) for i in range(3)], 1)
    exact = moving_point_source(dry, path, np.array([6.0, 4.0, 1.5]), fs, n_out=dry.size)
    start, end = meta["start_end_points"][0][0], meta["start_end_points"][-1][1]
    moving = np.linalg.norm(np.diff(path, axis=0), axis=1) > 0
    core = slice(max(start, int(np.argmax(moving))) + 800, end - 800)
    ref, est = exact[core], direct[core]
    gain = float(np.dot(ref, est) / np.dot(est, est))
    snr = 10 * np.log10(np.sum(ref**2) / np.sum((ref - gain * est) ** 2))
    dev, _, _ = spectral_deviation_db(exact, gain * direct, fs, active=(core.start, core.stop))
    dips = dip_figures(dev)
    return snr, dips["worst_db"], dips["p5_db"]


def main() -> None:
    print("moving source through the pipeline; reproduce: python bench/bench_motion_pipeline.py")
    with tempfile.TemporaryDirectory() as tmp:
        print("\nissue 18's check (direct stem vs the exact moving point source):")
        print(f"{'method':>18} {'SNR dB':>8} {'worst dip dB':>13} {'p5 dip dB':>10}")
        for method in METHODS:
            folder = Path(tmp) / f"motion-{method}"
            folder.mkdir()
            (folder / "spec.yaml").write_text(SPEC.replace("METHOD", method))
            build(folder / "spec.yaml")
            snr, worst, p5 = motion_figures(folder)
            print(f"{method:>18} {snr:8.1f} {worst:13.2f} {p5:10.2f}")
        print("\nthe demo (specs/demo.yaml), CPU seconds per step and store size:")
        print(f"{'method':>18} {'rir s':>7} {'render s':>9} {'store MB':>9}")
        for method in METHODS:
            folder = Path(tmp) / f"demo-{method}"
            shutil.copytree(ROOT / "specs", folder, ignore=shutil.ignore_patterns("out"))
            text = (folder / "demo.yaml").read_text()
            text = re.sub(r"(\nmixture:\n)", rf"\1  interpolation: {method}\n", text)
            (folder / "demo.yaml").write_text(text)
            build(folder / "demo.yaml")
            store = folder / "out" / "store"
            print(f"{method:>18} {step_seconds(store, 'rir'):7.1f} "
                  f"{step_seconds(store, 'render'):9.1f} {folder_mb(store):9.1f}")


if __name__ == "__main__":
    main()
