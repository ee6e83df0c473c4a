"""Benchmark (issue 31): what reading an external test set costs before any audio is scored.

A Libri2Mix test set of the real size (3,000 mixtures; wav8k/min with mix_clean, mix_both,
mix_single, s1, s2, noise and the recipe's three metadata CSVs) is written with short files
(0.25 s: the reader reads headers, not samples, so the length does not matter), then:

- ``detect``: recognising the layout from the folder;
- ``index``: ``open_dataset`` (the CSVs read, the items listed; no audio opened);
- ``groups``: every group opened (each file checked to exist, its header read for rate and
  length: six files per mixture ID), per group and in all;
- ``oracle``: ``evaluate(..., oracle=True, metrics=["si_snr", "si_snri"],
  mixtures=["mix_both"])`` on the whole set (count: score rows, two methods x two targets).

CPU seconds (getrusage, this process) are printed beside wall times, since the machine is
shared.

Reproduce:
    python bench/bench_readers.py                 # 3,000 mixtures
    python bench/bench_readers.py --items 300     # quicker
"""

from __future__ import annotations

import argparse
import csv
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import soundfile as sf


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def write_librimix(root: Path, items: int, n: int = 2000) -> Path:
    base = root / "Libri2Mix" / "wav8k" / "min"
    rng = np.random.default_rng(0)
    rows = {"mix_clean": [], "mix_both": [], "mix_single": []}
    for i in range(items):
        mid = f"{1000 + i}-1-0000_{5000 + i}-2-0001"
        s1, s2, noise = 0.1 * rng.standard_normal((3, n))
        for folder, x in (("s1", s1), ("s2", s2), ("noise", noise), ("mix_clean", s1 + s2),
                          ("mix_both", s1 + s2 + noise), ("mix_single", s1 + noise)):
            path = base / "test" / folder / f"{mid}.wav"
            path.parent.mkdir(parents=True, exist_ok=True)
            sf.write(str(path), x, 8000, subtype="PCM_16")
        p = f"/elsewhere/Libri2Mix/wav8k/min/test/{{}}/{mid}.wav"
        rows["mix_clean"].append([mid, p.format("mix_clean"), p.format("s1"), p.format("s2"),
                                  n])
        rows["mix_both"].append([mid, p.format("mix_both"), p.format("s1"), p.format("s2"),
                                 p.format("noise"), n])
        rows["mix_single"].append([mid, p.format("mix_single"), p.format("s1"),
                                   p.format("noise"), n])
    heads = {"mix_clean": ["mixture_ID", "mixture_path", "source_1_path", "source_2_path",
                           "length"],
             "mix_both": ["mixture_ID", "mixture_path", "source_1_path", "source_2_path",
                          "noise_path", "length"],
             "mix_single": ["mixture_ID", "mixture_path", "source_1_path", "noise_path",
                            "length"]}
    (base / "metadata").mkdir(parents=True)
    for kind, head in heads.items():
        with (base / "metadata" / f"mixture_test_{kind}.csv").open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(head)
            w.writerows(rows[kind])
    return root / "Libri2Mix"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=3000)
    args = ap.parse_args()
    from sonicspec.dataload.evaluate import evaluate
    from sonicspec.dataload.formats import detect, open_dataset

    with tempfile.TemporaryDirectory() as tmp:
        t0, c0 = time.perf_counter(), _cpu()
        root = write_librimix(Path(tmp), args.items)
        print(f"wrote {args.items} mixture IDs x 6 files: {time.perf_counter() - t0:.1f} s")
        figures = []
        t0, c0 = time.perf_counter(), _cpu()
        name = detect(root)
        figures.append(("detect", time.perf_counter() - t0, _cpu() - c0, 1))
        t0, c0 = time.perf_counter(), _cpu()
        folder = open_dataset(root)
        figures.append(("index", time.perf_counter() - t0, _cpu() - c0, 1))
        t0, c0 = time.perf_counter(), _cpu()
        groups = folder.groups("test")
        figures.append(("groups", time.perf_counter() - t0, _cpu() - c0, len(groups)))
        t0, c0 = time.perf_counter(), _cpu()
        rows = evaluate(root, "test", "separation", oracle=True,
                        metrics=["si_snr", "si_snri"], mixtures=["mix_both"])
        n_rows = len(rows)
        figures.append(("oracle (whole set, 2 methods)", time.perf_counter() - t0,
                        _cpu() - c0, n_rows))
        if name != "librimix":
            raise SystemExit(f"detected {name!r}, expected librimix")
    print(f"Libri2Mix test, {args.items} mixture IDs (python {sys.version.split()[0]})")
    print("| step | wall s | CPU s | count | CPU ms each |")
    print("|---|---|---|---|---|")
    for step, wall, cpu, count in figures:
        print(f"| {step} | {wall:.2f} | {cpu:.2f} | {count} | {1000 * cpu / count:.2f} |")
    print("command: python bench/bench_readers.py" + (f" --items {args.items}"
                                                      if args.items != 3000 else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
