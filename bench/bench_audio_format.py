"""Benchmark (issue 27): which lossless audio format keeps the paper's levels at the least size.

A SonicSet group is 14 files of 60 s at 16 kHz: three reverberant speech tracks, the noise and
the music tracks, and nine mixtures (separation of two of the three speakers with noise, with
music; enhancement of each speaker with noise). Their levels are the paper's (speech −17, noise
−21, music −24 LUFS, no peak limit), so tracks and mixtures peak above 0 dBFS, which is why
sonicset.yaml wrote float WAV.

The signals are made as a build makes them, from the demo's generated corpora written as 16-bit
FLAC like LibriSpeech (espeak-ng speech; synthesised rain/wind/fan/engine/clock/knock noise and
instrumental music): utterances, clips and gaps as sonicset.yaml draws them, each source through
a room response of its own (a direct sound and an exponential diffuse tail, T60 0.4–0.9 s,
DRR −3…+6 dB, high bands decaying faster), brought to its level with BS.1770. Then every file of
the group is written with :func:`sonicspec.export.files.write_audio` in each format, read back
with soundfile (and the scale applied), and compared with the float64 signal:

- float32 WAV (today's sonicset output);
- 16-bit FLAC with a per-file scale (the size yardstick: the same audio as 16-bit FLAC);
- 24-bit FLAC with a per-file scale, at FLAC compression levels 0, 5 (libsndfile's default)
  and 8;
- 24-bit FLAC holding 20 and 18 bits (the low bits zero: FLAC stores bits that are zero in a
  whole block for free);
- 24-bit WAV with a scale (no compression, for reference).

Columns: kB per second of one file (the mean over the group's 14), size relative to 16-bit
FLAC, encode and decode speed (seconds of audio per second of CPU, one core, decode = whole
file to float32 with the scale applied), the largest error relative to the file's peak (worst
file; decoded in float64) and the SNR of the worst file.

Reproduce:
    python bench/bench_audio_format.py                # one group of 60 s, about 1 min
    python bench/bench_audio_format.py --seconds 20   # quicker
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.signal import fftconvolve, lfilter

RATE = 16000


def corpora(root: Path) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Three speakers' utterances and the noise and music clips, as 16-bit files decode."""
    import soundfile as sf

    from sonicspec.audio.generated import generate_background_corpus, generate_speech_corpus

    generate_speech_corpus(root / "speech", ["train"], 3, 8, seed=7)
    generate_background_corpus(root / "noise", "noise", ["train"], 8, 8.0, seed=7)
    generate_background_corpus(root / "music", "music", ["train"], 8, 8.0, seed=7)

    def read(paths: list[Path]) -> list[np.ndarray]:
        return [sf.read(str(p), dtype="float64")[0] for p in sorted(paths)]

    speakers = [read(list(d.rglob("*.flac")))
                for d in sorted((root / "speech" / "generated-train").iterdir())]
    return (speakers, read(list((root / "noise").rglob("*.flac"))),
            read(list((root / "music").rglob("*.flac"))))


def room_response(rng: np.random.Generator) -> np.ndarray:
    """A direct sound and an exponentially decaying diffuse tail (T60 0.4–0.9 s, DRR −3…+6 dB),
    its high frequencies decaying faster (a one-pole low-pass whose cut-off falls)."""
    t60 = rng.uniform(0.4, 0.9)
    n = int(t60 * RATE)
    t = np.arange(n) / RATE
    tail = rng.standard_normal(n) * np.exp(-6.91 * t / t60)
    tail = 0.5 * (tail + lfilter([0.3], [1, -0.7], tail))
    delay = int(rng.uniform(0.002, 0.02) * RATE)
    tail[:delay] = 0.0
    drr_db = rng.uniform(-3, 6)
    tail *= 1.0 / np.sqrt(np.sum(tail**2) * 10 ** (drr_db / 10))
    tail[0] = 1.0
    return tail


def arrange(clips: list[np.ndarray], n: int, gap_s: float, rng: np.random.Generator
            ) -> np.ndarray:
    """Clips one after another with random gaps up to ``gap_s``, to ``n`` samples."""
    out = np.zeros(n)
    pos = 0
    for k in rng.permutation(len(clips) * 4) % len(clips):
        pos += int(rng.uniform(0, gap_s) * RATE)
        if pos >= n:
            break
        c = clips[k][:n - pos]
        out[pos:pos + c.size] += c
        pos += c.size
    return out


def group(seconds: float, root: Path, seed: int = 0) -> dict[str, np.ndarray]:
    """One SonicSet-like group's 14 files, float64, at the paper's levels."""
    from sonicspec.audio.mix import gain_to_loudness

    rng = np.random.default_rng(seed)
    speakers, noise, music = corpora(root)
    n = int(seconds * RATE)
    tracks = {}
    for i, utts in enumerate(speakers, start=1):
        tracks[f"source{i}"] = (arrange(utts, n, 8.0, rng), -17.0)
    tracks["noise"] = (arrange(noise, n, 4.0, rng), -21.0)
    tracks["music"] = (arrange(music, n, 4.0, rng), -24.0)
    out = {}
    for name, (dry, lufs) in tracks.items():
        wet = fftconvolve(dry, room_response(rng))[:n]
        gain, _ = gain_to_loudness(wet, RATE, lufs, where=name)
        out[name] = gain * wet
    pairs = [("source1", "source2"), ("source1", "source3"), ("source2", "source3")]
    for bg in ("noise", "music"):
        for a, b in pairs:
            out[f"sep_{a[-1]}{b[-1]}_{bg}"] = out[a] + out[b] + out[bg]
    for s in ("source1", "source2", "source3"):
        out[f"enh_{s[-1]}_noise"] = out[s] + out["noise"]
    return out


# (label, container, subtype, scaled, bits, FLAC compression level)
FORMATS = [
    ("float32 WAV (today)", "wav", "FLOAT", False, None, None),
    ("16-bit FLAC + scale (yardstick)", "flac", "PCM_16", True, None, None),
    ("24-bit FLAC + scale, level 0", "flac", "PCM_24", True, None, 0.0),
    ("24-bit FLAC + scale, level 5 (default)", "flac", "PCM_24", True, None, None),
    ("24-bit FLAC + scale, level 8", "flac", "PCM_24", True, None, 1.0),
    ("20 bits in 24-bit FLAC + scale", "flac", "PCM_24", True, 20, None),
    ("18 bits in 24-bit FLAC + scale", "flac", "PCM_24", True, 18, None),
    ("24-bit WAV + scale", "wav", "PCM_24", True, None, None),
]


def measure(files: dict[str, np.ndarray], tmp: Path, fmt: tuple) -> dict[str, float]:
    import soundfile as sf

    from sonicspec.export.files import peak_scale, read_scale_tag, write_audio

    _, ext, subtype, scaled, bits, level = fmt
    size = enc = dec = 0.0
    worst_err, worst_snr = 0.0, np.inf
    for name, x in files.items():
        path = tmp / f"{name}.{ext}"
        t = time.process_time()
        scale = peak_scale(x, subtype, bits) if scaled else None
        write_audio(path, x, RATE, audio_format=ext, subtype=subtype, scale=scale, bits=bits,
                    compression_level=level)
        enc += time.process_time() - t
        size += path.stat().st_size
        t = time.process_time()
        y, _ = sf.read(str(path), dtype="float32")
        s = read_scale_tag(path) if scaled else None
        if s is not None:
            y = y * np.float32(s)
        dec += time.process_time() - t
        # The format's own error: decoded in float64 (the loader's float32 adds its rounding,
        # 2**-24 of each sample, as float32 WAV has).
        y, _ = sf.read(str(path), dtype="float64")
        err = np.abs(y * (s or 1.0) - x)
        worst_err = max(worst_err, float(err.max() / np.abs(x).max()))
        noise = float(np.sum(err**2))
        snr = np.inf if noise == 0 else 10 * np.log10(float(np.sum(x**2)) / noise)
        worst_snr = min(worst_snr, snr)
    seconds = sum(x.size for x in files.values()) / RATE
    return {"kb_s": size / seconds / 1000, "group_mb": size / 1e6, "enc": seconds / enc,
            "dec": seconds / dec, "err": worst_err, "snr": worst_snr}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="group length (SonicSet: 60)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        files = group(args.seconds, tmp / "corpora")
        peaks = {k: float(np.abs(v).max()) for k, v in files.items()}
        print(f"# python bench/bench_audio_format.py --seconds {args.seconds:g}")
        print(f"# {platform.python_version()}, {platform.machine()}; {len(files)} files of "
              f"{args.seconds:g} s; peaks {min(peaks.values()):.2f}…{max(peaks.values()):.2f} "
              f"(above 0 dBFS: {sum(p > 1 for p in peaks.values())} of {len(peaks)})")
        rows = [(f[0], measure(files, tmp, f)) for f in FORMATS]
        ref = next(r for label, r in rows if "yardstick" in label)["kb_s"]
        print("| format | kB/s per file | group MB (60 s) | × 16-bit FLAC | encode ×RT | "
              "decode ×RT | max error / peak | worst SNR dB |")
        print("|---|---|---|---|---|---|---|---|")
        for label, r in rows:
            per_group = r["group_mb"] * 60.0 / args.seconds
            err = "0" if r["err"] == 0 else f"{r['err']:.2e} (2^{np.log2(r['err']):.1f})"
            print(f"| {label} | {r['kb_s']:.1f} | {per_group:.1f} | {r['kb_s'] / ref:.2f} | "
                  f"{r['enc']:.0f} | {r['dec']:.0f} | {err} | {r['snr']:.1f} |")


if __name__ == "__main__":
    sys.exit(main())
