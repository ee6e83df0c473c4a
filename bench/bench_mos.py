"""DNSMOS cost and values: espeak-ng speech, clean and at 0 dB in white noise, through
sonicspec's DNSMOS pipeline and (for comparison) the speechmos package's own.

    python bench/bench_mos.py [--dnsmos-dir DIR] [--seconds 30]

Needs onnxruntime and the ONNX files (``--dnsmos-dir``, default: speechmos' shipped files),
espeak-ng; speechmos' own pipeline is run too when it and librosa import. Prints the ratings
and the CPU seconds per clip second (``time.process_time``; onnxruntime kept on one thread).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import soundfile as sf
from scipy.signal import resample_poly

from sonicspec.dataload.mos import open_mos

TEXT = ("The birch canoe slid on the smooth planks. Glue the sheet to the dark blue background. "
        "It is easy to tell the depth of a well. These days a chicken leg is a rare dish.")


def speech(seconds: float) -> np.ndarray:
    exe = shutil.which("espeak-ng")
    if exe is None:
        sys.exit("espeak-ng is not installed")
    with tempfile.TemporaryDirectory() as tmp:
        wav = Path(tmp) / "s.wav"
        subprocess.run([exe, "-w", str(wav), TEXT], check=True, capture_output=True)
        x, rate = sf.read(wav)
    x = resample_poly(x, 320, rate // 50)
    x = np.tile(x, int(np.ceil(seconds * 16000 / len(x))))[:int(seconds * 16000)]
    return 0.3 * x / np.max(np.abs(x))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dnsmos-dir", default="speechmos")
    ap.add_argument("--seconds", type=float, default=30.0)
    args = ap.parse_args()
    model = open_mos("dnsmos", args.dnsmos_dir)
    clean = speech(args.seconds)
    noise = np.random.default_rng(0).standard_normal(len(clean))
    noisy = clean + noise * np.sqrt(np.mean(clean ** 2) / np.mean(noise ** 2))
    print(f"files: {[(f['path'], f['sha256'][:12]) for f in model.files]}")
    for name, x in (("clean", clean), ("0 dB white noise", noisy)):
        t0 = time.process_time()
        got = model(x, 16000)
        cpu = time.process_time() - t0
        print(f"{name:17s} " + " ".join(f"{k[7:]}={v:.3f}" for k, v in got.items())
              + f"  cpu {cpu:.2f} s for {args.seconds:.0f} s ({cpu / args.seconds:.3f} s/s)")
        try:
            import speechmos.dnsmos as ref
        except ImportError:
            continue
        r = ref.run(x.astype(np.float32), sr=16000)
        print(f"{'  speechmos':17s} sig={r['sig_mos']:.3f} bak={r['bak_mos']:.3f} "
              f"ovrl={r['ovrl_mos']:.3f} p808={r['p808_mos']:.3f}")


if __name__ == "__main__":
    main()
