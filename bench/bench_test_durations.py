"""The test suite's time per file, from the log of a pytest run with ``--durations=0``.

``--dist loadfile`` runs each test file on one worker, so the longest file bounds the suite's
wall time however many workers there are; this prints each file's total (setup + call +
teardown of its tests), the share of the sum, and the summary line of the run.

    nice -n 10 python -m pytest -n 2 --dist loadfile --durations=0 -q -p no:cacheprovider \\
        > /tmp/durations.txt 2>&1
    python bench/bench_test_durations.py /tmp/durations.txt [--top 25]
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
