"""Benchmark (issue 20): planning the SonicSet presets at the paper's size.

Lays out SonicSet's inputs in their real layouts (``sonicspec.testing.sonicset``: 90
Matterport scans under the released scripts' building ids, LibriSpeech with 921 / 40 / 40
speakers, small FSD50K and FMA) in a temporary folder, copies ``specs/sonicset.yaml`` and
``specs/sonicset_release.yaml`` beside them, and measures, each in its own child process:

- ``sonicspec plan SPEC --summary``: the paper's table (lists scan files and speaker folders);
- ``sonicspec plan SPEC``: the whole command (preflight, compile with every scan hashed, what
  the store holds);
- ``compile_spec``: loading the spec and compiling the plan (wall time inside the child).

Wall times only: this script's own process holds the fixture writer's imports, which a
forked child's ``ru_maxrss`` would count (``/usr/bin/time -f %M`` on the commands gives their
memory: 55 MB for ``plan --summary``, 131 MB for ``plan``).

Reproduce:
    python bench/bench_plan_sonicset.py            # about 20 s on 2 cores
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

COMPILE = """
import sys, time
from sonicspec.plan.compile import compile_spec
from sonicspec.spec import load_spec
t = time.perf_counter()
plan = compile_spec(load_spec(sys.argv[1]), cache=False)
print(f"{time.perf_counter() - t:.3f} {len(plan.jobs)}")
"""


def run(args: list[str], cwd: Path) -> tuple[float, str]:
    """(wall s, stdout) of one child process."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t = time.perf_counter()
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed: {done.stderr}")
    return wall, done.stdout


def main() -> None:
    sys.path.insert(0, str(ROOT))
    from sonicspec.spec import validate_text
    from sonicspec.testing.sonicset import PAPER_SPEAKERS, write_sonicset_inputs

    with tempfile.TemporaryDirectory(prefix="bench-sonicset-") as tmp:
        folder = Path(tmp)
        release = (ROOT / "specs" / "sonicset_release.yaml").read_text()
        loaded, _ = validate_text(release, str(folder / "r.yaml"), folder)
        ids = [s.split("/")[1] for split in loaded.spec.splits.values() for s in split.scenes]
        t = time.perf_counter()
        write_sonicset_inputs(folder / "data", ids, PAPER_SPEAKERS)
        print(f"inputs laid out in {time.perf_counter() - t:.1f} s (90 scans, "
              f"{sum(PAPER_SPEAKERS.values())} speakers)")
        print("| spec | measured | wall s | jobs |")
        print("|---|---|---|---|")
        for name in ("sonicset.yaml", "sonicset_release.yaml"):
            (folder / name).write_text((ROOT / "specs" / name).read_text())
            py = sys.executable
            wall, _ = run([py, "-m", "sonicspec.cli", "plan", name, "--summary"], folder)
            print(f"| {name} | sonicspec plan --summary | {wall:.2f} | |")
            wall, out = run([py, "-c", COMPILE, name], folder)
            inner, jobs = out.split()
            print(f"| {name} | compile_spec (load + compile; child wall {wall:.2f} s) | "
                  f"{float(inner):.2f} | {int(jobs):,} |")
            wall, _ = run([py, "-m", "sonicspec.cli", "plan", name], folder)
            print(f"| {name} | sonicspec plan | {wall:.2f} | |")
    print(f"\ncommand: python bench/{Path(__file__).name}")


if __name__ == "__main__":
    main()
