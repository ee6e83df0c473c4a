"""Benchmark (issue 22): `sonicspec report` on a 2,000-group synthetic dataset, time and size.

Writes a dataset folder of metadata only (``sonicspec.testing.datasets``: dataset.json and a
metadata.json per group in the exported form, SonicSet-shaped by default: 60 s groups, three
moving speakers, noise and music, each with its 10 ms position track, ~3.4 MB of JSON per
group), then runs ``sonicspec report`` on it in a child process twice (the first run reads the
metadata from disk, the second mostly from the page cache) and prints, per run: wall time,
the time the report states of itself, peak memory (the child's maximum RSS from ``os.wait4``),
the page's size and the group pages' size. There is no store, so no RIRs: the group pages
have a floor plan and audio links, the scenes have no walls.

Reproduce:
    python bench/bench_report.py                      # ~10 min to write 7 GB, then ~1 min
    python bench/bench_report.py --duration 10        # demo-sized groups (~0.6 MB each)
    python bench/bench_report.py --dir /tmp/ds --keep # keep the dataset for another run
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _write_part(args: tuple[str, dict[str, int], int, float, int, int]) -> None:
    """Write one worker's share of the groups (every ``step``-th from ``first``)."""
    import json

    from sonicspec.testing.datasets import synthetic_metadata

    root, groups, scenes, duration, first, step = args
    k = 0
    for s, (split, count) in enumerate(groups.items()):
        for i in range(count):
            if k % step == first:
                group = f"{split}/{i:06d}"
                meta = synthetic_metadata(group, f"scene{s * scenes + i % scenes:02d}", 7,
                                          duration_s=duration)
                folder = Path(root) / group
                folder.mkdir(parents=True, exist_ok=True)
                (folder / "metadata.json").write_text(
                    json.dumps(meta, indent=2, sort_keys=True, ensure_ascii=False) + "\n")
            k += 1


def write_dataset(root: Path, groups: dict[str, int], duration: float, scenes: int = 3) -> None:
    """The synthetic dataset, its groups written by two processes (the JSON encoder with
    indentation is pure Python: ~0.2 s a 60 s group)."""
    from sonicspec.testing.datasets import write_synthetic_dataset

    write_synthetic_dataset(root, {s: 0 for s in groups}, scenes=scenes, duration_s=duration)
    workers = 2
    with multiprocessing.Pool(workers) as pool:
        pool.map(_write_part, [(str(root), groups, scenes, duration, w, workers)
                               for w in range(workers)])
    # dataset.json with every group (written last, as a build does)
    import json

    summary = json.loads((root / "dataset.json").read_text())
    summary["groups"] = [{"group": f"{split}/{i:06d}", "split": split,
                          "scene_id": f"scene{s * scenes + i % scenes:02d}",
                          "metadata": {"path": f"{split}/{i:06d}/metadata.json"}}
                         for s, (split, n) in enumerate(groups.items()) for i in range(n)]
    summary["spec"]["splits"] = {s: {"groups": n} for s, n in groups.items()}
    summary["splits"] = {s: {"groups": n, "files": 0, "audio_hours": n * duration / 3600}
                         for s, n in groups.items()}
    (root / "dataset.json").write_text(json.dumps(summary, indent=2))


def run_report(root: Path) -> dict[str, float]:
    out = root / "report.html"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "sonicspec.cli", "report", str(root)],
                            env=env, stdout=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    line = proc.stdout.read().strip()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"sonicspec report failed: {line}")
    stated = float(out.read_text().split('id="report-seconds">')[1].split("<")[0])
    pages = sum(p.stat().st_size for p in (root / "report_files" / "groups").glob("*.html"))
    return {"wall_s": wall, "stated_s": stated, "rss_mb": usage.ru_maxrss / 1024,
            "page_mb": out.stat().st_size / 1e6, "pages_mb": pages / 1e6,
            "pages": len(list((root / "report_files" / "groups").glob("*.html")))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--groups", type=int, default=2000)
    parser.add_argument("--duration", type=float, default=60.0, help="seconds per group")
    parser.add_argument("--dir", type=Path, help="dataset folder (reused if it has the groups)")
    parser.add_argument("--keep", action="store_true", help="keep the dataset folder")
    args = parser.parse_args()
    n = args.groups
    groups = {"train": n - 2 * (n // 10), "val": n // 10, "test": n // 10}
    root = args.dir or Path(tempfile.mkdtemp(prefix="sonicspec-bench-report-")) / "ds"
    existing = len(list(root.glob("*/*/metadata.json"))) if root.is_dir() else 0
    if existing != n:
        if root.exists():
            shutil.rmtree(root)
        start = time.perf_counter()
        write_dataset(root, groups, args.duration)
        print(f"wrote {n} groups of {args.duration:g} s in {time.perf_counter() - start:.0f} s")
    size = sum(p.stat().st_size for p in root.glob("*/*/metadata.json"))
    print(f"{root}: {n} groups ({groups}), metadata {size / 1e9:.2f} GB "
          f"({size / n / 1e6:.2f} MB a group); {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}")
    print("\n| run | wall s | stated by the page s | peak RSS MB | page MB | group pages | "
          "their MB |\n|---|---|---|---|---|---|---|")
    for run in ("first", "second"):
        r = run_report(root)
        print(f"| {run} | {r['wall_s']:.1f} | {r['stated_s']:.1f} | {r['rss_mb']:.0f} | "
              f"{r['page_mb']:.2f} | {r['pages']} | {r['pages_mb']:.2f} |")
    print(f"\n$ python bench/bench_report.py --groups {n} --duration {args.duration:g}")
    if not args.keep and args.dir is None:
        shutil.rmtree(root.parent)


if __name__ == "__main__":
    main()
