"""Benchmark (issue 21): the loader's throughput against decoding alone, and evaluate's cost.

Builds the pipeline tests' cut-down demo (three speakers per group, 30 s groups) twice into
one temporary folder, once with FLAC and once with WAV (the second build reuses the store:
only the export differs), then:

- decoding alone: the soundfile reads a 3 s separation item needs at the least (two target
  crops and the noise crop at random places), crops per second;
- the loader, ``SonicspecDataset(..., "separation")``, 3 s crops: static (the built mixture)
  and dynamic mixing (the ``paper`` preset), with 0, 1 and 2 workers. Workers are
  ``torch.utils.data.DataLoader`` workers (batch size 8) when torch imports, otherwise a
  ``multiprocessing`` pool sharding batches the way DataLoader does; the table says which
  (torch runs on one thread, as in DataLoader's workers);
- ``evaluate``: the mixture copied as the estimates (one method), every metric, and without
  PESQ and STOI; seconds per group-hour of mixtures scored (a group-hour: one hour of one
  mixture with its targets).

Reproduce:
    python bench/bench_data.py                 # about 6 min on 2 cores
    python bench/bench_data.py --items 240     # quicker; worker start-up then weighs in
"""

from __future__ import annotations

import argparse
import multiprocessing
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def build(tmp: Path, audio_format: str) -> Path:
    from build_cases import plan_for, write_spec

    from sonicspec.stages.workflow import run_build

    spec = write_spec(tmp)
    text = spec.read_text()
    for old, new in (("speakers_per_split: 2,", "speakers_per_split: 3,"),
                     ("  speakers: 2\n", "  speakers: 3\n"),
                     ("duration_s: 10.0", "duration_s: 30.0"),
                     ("utterances_per_speaker: [1, 2]", "utterances_per_speaker: [2, 3]"),
                     ("audio_format: flac", f"audio_format: {audio_format}"),
                     ("dir: out/demo", f"dir: out/demo-{audio_format}")):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp / f"bench-{audio_format}.yaml"
    path.write_text(text)
    plan = plan_for(path)
    if run_build(plan, cores=2) != 0:
        raise SystemExit(f"the {audio_format} build failed")
    return Path(plan.output_dir)


def decode_only(root: Path, n: int) -> float:
    """Crops per second: two targets and the noise, 3 s each, at random places."""
    import soundfile as sf

    from sonicspec.dataload import DatasetFolder

    groups = DatasetFolder(root).groups("train")
    rng = np.random.default_rng(0)
    length = 3 * 16000
    t = time.perf_counter()
    for i in range(n):
        g = groups[i % len(groups)]
        for name in ("source1", "source2", "noise"):
            start = int(rng.integers(0, g.num_samples - length))
            sf.read(str(g.track_path(name)), start=start, stop=start + length, dtype="float32")
    return n / (time.perf_counter() - t)


def _items(args: tuple[str, str, list[int]]) -> int:
    from sonicspec.dataload import MixingConfig, SonicspecDataset

    root, mode, indices = args
    config = "paper" if mode == "dynamic" else MixingConfig(dynamic=False, crop_s=3.0)
    ds = SonicspecDataset(root, "train", "separation", config=config)
    for k, i in enumerate(indices):
        ds.item(i % len(ds), epoch=k // len(ds))
    return len(indices)


def loader_rate(root: Path, mode: str, workers: int, n: int) -> tuple[float, str]:
    """Items (3 s crops) per second with ``workers`` workers."""
    try:
        import torch
        from torch.utils.data import DataLoader, Dataset
    except ImportError:
        DataLoader = None
    from sonicspec.dataload import MixingConfig, SonicspecDataset

    config = "paper" if mode == "dynamic" else MixingConfig(dynamic=False, crop_s=3.0)
    if DataLoader is not None:
        # DataLoader's workers run torch on one thread; the main process would use every
        # core's intra-op thread for collation, which on 2 busy cores made the 0-worker case
        # 3x slower than 1 worker. Load as the workers do.
        torch.set_num_threads(1)
        base = SonicspecDataset(root, "train", "separation", config=config)

        class Repeat(Dataset):  # n items cycling over the split, a new epoch each round
            def __len__(self) -> int:
                return n

            def __getitem__(self, i: int):
                return base.item(i % len(base), epoch=i // len(base))

        loader = DataLoader(Repeat(), batch_size=8, num_workers=workers)
        t = time.perf_counter()
        count = sum(len(b["mixture"]) for b in loader)
        return count / (time.perf_counter() - t), "torch DataLoader"
    batches = [list(range(i, min(i + 8, n))) for i in range(0, n, 8)]
    t = time.perf_counter()
    if workers == 0:
        count = sum(_items((str(root), mode, b)) for b in batches)
    else:
        shards = [[i for j, b in enumerate(batches) if j % workers == w for i in b]
                  for w in range(workers)]
        with multiprocessing.get_context("fork").Pool(workers) as pool:
            count = sum(pool.map(_items, [(str(root), mode, s) for s in shards]))
    return count / (time.perf_counter() - t), "multiprocessing pool"


def evaluate_cost(root: Path, tmp: Path, metrics: list[str]) -> tuple[float, float]:
    """(seconds, group-hours) to score the mixture itself as the estimates."""
    import soundfile as sf

    from sonicspec.dataload import DatasetFolder
    from sonicspec.dataload.evaluate import evaluate

    est = tmp / "estimates"
    hours = 0.0
    for split in ("test", "val"):
        for g in DatasetFolder(root).groups(split):
            for m in g.mixtures("separation"):
                x = g.read(m["file"])[0]
                (est / g.id).mkdir(parents=True, exist_ok=True)
                sf.write(str(est / g.id / f"{m['name']}.wav"),
                         np.stack([x] * len(m["targets"]), axis=1), g.sample_rate_hz,
                         subtype="FLOAT")
    t = time.perf_counter()
    for split in ("test", "val"):
        rows = evaluate(root, split, "separation", estimates=est, metrics=metrics)
        hours += len({(r["group"], r["mixture"]) for r in rows}) * 30.0 / 3600.0
    return time.perf_counter() - t, hours


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--items", type=int, default=1000, help="items per measurement")
    args = parser.parse_args()
    print(f"python {platform.python_version()}, {multiprocessing.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        t = time.perf_counter()
        roots = {fmt: build(tmp, fmt) for fmt in ("flac", "wav")}
        print(f"builds: {time.perf_counter() - t:.0f} s")
        print("\n| format | decoding alone | loader | workers | crops/s | vs decoding | via |")
        print("|---|---|---|---|---|---|---|")
        for fmt, root in roots.items():
            base = decode_only(root, args.items)
            for mode in ("static", "dynamic"):
                for workers in (0, 1, 2):
                    rate, via = loader_rate(root, mode, workers, args.items)
                    print(f"| {fmt} | {base:.0f}/s | {mode} | {workers} | {rate:.0f} | "
                          f"{rate / base:.2f} | {via} |")
        for label, metrics in (("all metrics", None),
                               ("SI-SNR(i), SDR(i)", ["si_snr", "si_snri", "sdr", "sdri"])):
            from sonicspec.audio.metrics import METRICS

            seconds, hours = evaluate_cost(roots["flac"], tmp / label.replace(" ", "_"),
                                           list(metrics or METRICS))
            print(f"evaluate ({label}): {seconds:.1f} s for {hours:.4f} group-hours = "
                  f"{seconds / hours / 60:.1f} min per group-hour")


if __name__ == "__main__":
    main()
