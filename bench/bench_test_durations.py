"""The test suite's time per file, from the log of a pytest run with ``--durations=0``.

``--dist loadfile`` runs each test file on one worker, so the longest file bounds the suite's
wall time however many workers there are; this prints each file's total (setup + call +
teardown of its tests), the share of the sum, and the summary line of the run.

    nice -n 10 python -m pytest -n 2 --dist loadfile --durations=0 -q -p no:cacheprovider \\
        > /tmp/durations.txt 2>&1
    python bench/bench_test_durations.py /tmp/durations.txt [--top 25] [--workers 2]

``--workers N`` also estimates the wall time of N workers taking files greedily (a worker that
runs out takes the next file: the shape of xdist's loadfile scheduling) in three orders: the
order xdist uses by default (most tests first), the longest file first, and the order of
``tests/conftest.py``'s ``SLOW_FIRST`` list. An estimate from the run's own per-file seconds:
files that shared one build (conftest's session builds) are counted as they ran.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import defaultdict
from pathlib import Path

LINE = re.compile(r"^\s*([0-9.]+)s\s+(setup|call|teardown)\s+(\S+?\.py)::")
SUMMARY = re.compile(r"^=* ?\d+ (passed|failed)\b.* in ([0-9.]+)s")


def per_file(text: str) -> tuple[dict[str, float], int, str | None]:
    """Seconds per test file, the number of duration lines read, and the summary line."""
    totals: dict[str, float] = defaultdict(float)
    lines = 0
    summary = None
    for line in text.splitlines():
        found = LINE.match(line)
        if found:
            totals[found.group(3)] += float(found.group(1))
            lines += 1
        elif SUMMARY.match(line):
            summary = line.strip("= ")
    return dict(totals), lines, summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path, help="the output of pytest --durations=0")
    parser.add_argument("--top", type=int, default=25, help="files to list (default 25)")
    parser.add_argument("--workers", type=int, default=0,
                        help="estimate the wall time of this many workers (default: no)")
    args = parser.parse_args(argv)
    totals, lines, summary = per_file(args.log.read_text(errors="replace"))
    if not lines:
        print(f"{args.log}: no duration lines (was pytest run with --durations=0?)",
              file=sys.stderr)
        return 2
    whole = sum(totals.values())
    print(f"{args.log}: {lines} duration lines, {len(totals)} files, "
          f"sum {whole:.0f} s; run: {summary or 'no summary line'}")
    print(f"{'seconds':>8} {'share':>6}  file")
    for name, seconds in sorted(totals.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"{seconds:8.1f} {seconds / whole:6.1%}  {name}")
    if args.workers:
        print(f"estimated wall time on {args.workers} workers, files taken greedily in order:")
        counts = _test_counts()
        collected = [f for f in counts if f in totals] + [f for f in totals if f not in counts]
        orders = {
            "most tests first (xdist's default)": sorted(
                collected, key=lambda f: -counts.get(f, 0)),
            "longest first": sorted(collected, key=lambda f: -totals[f]),
            "conftest SLOW_FIRST, then the rest as collected": _slow_first(collected),
        }
        for name, order in orders.items():
            print(f"  {greedy(order, totals, args.workers):7.0f} s  {name}")
        print(f"  {whole / args.workers:7.0f} s  the bound: sum / workers")
    return 0


def greedy(order: list[str], seconds: dict[str, float], workers: int) -> float:
    """When the last of ``workers`` finishes if each, once free, takes the next file."""
    free = [0.0] * workers
    for name in order:
        i = free.index(min(free))
        free[i] += seconds[name]
    return max(free)


def _test_counts() -> dict[str, int]:
    """Tests per file, as collected here (xdist's default order sorts files by this)."""
    import subprocess

    out = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                          "-p", "no:cacheprovider"], capture_output=True, text=True).stdout
    counts: dict[str, int] = defaultdict(int)
    for line in out.splitlines():
        if "::" in line:
            counts[line.split("::")[0]] += 1
    return dict(counts)


def _slow_first(files: list[str]) -> list[str]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from conftest import SLOW_FIRST

    rank = {name: i for i, name in enumerate(SLOW_FIRST)}
    return sorted(files, key=lambda f: rank.get(Path(f).name, len(rank)))


if __name__ == "__main__":
    sys.exit(main())
