"""Driving Snakemake: the plan as the workflow sees it, and `sonicspec build` with progress.

The Snakefile (``workflow/Snakefile``) is generic: it asks :class:`WorkflowPlan` for the steps,
the input artifacts of a job and the output pattern of a step. Rerun decisions come from the
content keys in the output paths and params, never from file times (``--rerun-triggers params
input``).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import sonicspec
from sonicspec.errors import SonicspecError
from sonicspec.plan.model import STEPS, Plan, Step
from sonicspec.store import ArtifactStore


def workflow_dir() -> Path:
    """The ``workflow/`` folder of the source tree this package runs from."""
    here = Path(sonicspec.__file__).resolve().parent.parent / "workflow"
    if not (here / "Snakefile").is_file():
        raise SonicspecError(
            f"workflow: expected {here / 'Snakefile'}; `sonicspec build` runs from a source "
            "checkout installed with `pip install -e .`"
        )
    return here


class WorkflowPlan:
    """The plan as the Snakefile sees it (paths and patterns only)."""

    def __init__(self, plan: Plan, path: Path) -> None:
        self.plan = plan
        self.path = str(path)
        self.store_dir = plan.store_dir
        self._jobs = plan.by_key()

    @classmethod
    def load(cls, path: str | Path) -> WorkflowPlan:
        return cls(Plan.read(Path(path)), Path(path))

    def steps(self) -> list[Step]:
        present = {j.step for j in self.plan.jobs}
        return [s for s in STEPS if s.name in present]

    def artifact(self, step: str, key: str) -> str:
        """The file that stands for an artifact: its group's ``zarr.json``.

        It appears with the rest of the group in one rename, so its presence means the whole
        artifact is there; naming a file (not the folder) keeps Snakemake from writing its
        timestamp marker into the Zarr group.
        """
        return f"{self.store_dir}/{step}/{key[:2]}/{key}.zarr/zarr.json"

    def output_pattern(self, step: str) -> str:
        return f"{self.store_dir}/{step}/{{pre}}/{{key}}.zarr/zarr.json"

    def log_pattern(self, step: str) -> str:
        return f"{self.store_dir}/logs/{step}/{{pre}}/{{key}}.log"

    def benchmark_pattern(self, step: str) -> str:
        return f"{self.store_dir}/benchmarks/{step}/{{pre}}/{{key}}.tsv"

    def inputs_of(self, wildcards: Any) -> list[str]:
        job = self._jobs[wildcards.key]
        return [self.artifact(self._jobs[k].step, k) for k in job.inputs]

    def final_artifacts(self) -> list[str]:
        """Artifacts nothing else consumes: building them builds everything."""
        consumed = {k for j in self.plan.jobs for k in j.inputs}
        return [self.artifact(j.step, j.key) for j in self.plan.jobs if j.key not in consumed]


@dataclass(frozen=True)
class StepProgress:
    step: str
    done: int
    total: int


def progress(plan: Plan, store: ArtifactStore) -> list[StepProgress]:
    """Jobs done (artifact present) and planned, per step."""
    out = []
    for step, jobs in plan.by_step().items():
        if jobs:
            present = store.present(step, (j.key for j in jobs))
            done = sum(j.key in present for j in jobs)
            out.append(StepProgress(step, done, len(jobs)))
    return out


def format_progress(steps: list[StepProgress], elapsed_s: float, start_done: int) -> str:
    done = sum(s.done for s in steps)
    total = sum(s.total for s in steps)
    parts = [f"{s.step} {s.done}/{s.total}" for s in steps if s.done < s.total or s.total]
    eta = ""
    made = done - start_done
    if 0 < made and done < total:
        eta = f", ETA {_clock((total - done) * elapsed_s / made)}"
    return f"[{_clock(elapsed_s)}] {done}/{total} jobs ({'; '.join(parts)}){eta}"


def _clock(seconds: float) -> str:
    seconds = round(seconds)
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


def snakemake_command(
    plan_path: Path,
    plan: Plan,
    *,
    cores: int,
    profile: Path | None,
    dry_run: bool,
    extra: list[str] | None = None,
) -> list[str]:
    wf = workflow_dir()
    cmd = [
        sys.executable,
        "-m",
        "snakemake",
        "--snakefile",
        str(wf / "Snakefile"),
        "--directory",
        plan.store_dir,
        "--config",
        f"plan={plan_path}",
        "--rerun-triggers",
        "params",
        "input",
        "--rerun-incomplete",
        "--nolock",
    ]
    if profile is not None:
        cmd += ["--profile", str(Path(profile).resolve())]
    else:
        cmd += ["--cores", str(cores), "--keep-going"]
    if profile is not None and cores:
        cmd += ["--cores", str(cores)]
    if dry_run:
        cmd += ["--dry-run", "--quiet", "rules"]
    return cmd + list(extra or [])


_FAILED_LOG = re.compile(r"log: (\S+\.log)")


def failed_job_messages(snakemake_log: str, plan: Plan) -> list[str]:
    """For each failed job in Snakemake's output: the job's label and its last log lines."""
    jobs = plan.by_key()
    out = []
    for block in snakemake_log.split("Error in rule ")[1:]:
        match = _FAILED_LOG.search(block)
        if match is None:
            continue
        log_path = Path(match.group(1).rstrip(","))
        if not log_path.is_absolute():
            log_path = Path(plan.store_dir) / log_path
        key = log_path.stem
        label = jobs[key].label if key in jobs else key[:12]
        tail = ""
        if log_path.is_file():
            lines = [x for x in log_path.read_text(errors="replace").splitlines() if x.strip()]
            tail = "\n    ".join(lines[-3:])
        out.append(f"{label} ({key[:12]}) failed; its log {log_path}:\n    {tail}")
    return out


def run_build(
    plan: Plan,
    *,
    cores: int = 1,
    profile: Path | None = None,
    dry_run: bool = False,
    stream: TextIO = sys.stderr,
    poll_s: float = 1.0,
    on_start: Callable[[subprocess.Popen], None] | None = None,
    snakemake_args: list[str] | None = None,
) -> int:
    """Run the plan through Snakemake, printing progress; returns Snakemake's exit code."""
    store = ArtifactStore(plan.store_dir)
    Path(plan.store_dir).mkdir(parents=True, exist_ok=True)
    removed = store.clean_stale_temp()
    if removed:
        print(f"removed {removed} unfinished artifact(s) left by an interrupted build", file=stream)
    plan_path = plan.write(Path(plan.store_dir) / "plans" / f"{plan.digest}.json")
    cmd = snakemake_command(plan_path, plan, cores=cores, profile=profile, dry_run=dry_run,
                            extra=snakemake_args)
    log_dir = Path(plan.store_dir) / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    log_path = log_dir / f"snakemake-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    start = time.monotonic()
    start_done = sum(p.done for p in progress(plan, store))
    with open(log_path, "w") as log:
        log.write("$ " + " ".join(shlex.quote(c) for c in cmd) + "\n")
        log.flush()
        proc = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=plan.store_dir
        )
        if on_start is not None:
            on_start(proc)
        last = ""
        while proc.poll() is None:
            time.sleep(poll_s)
            if not dry_run:
                steps = progress(plan, store)
                counts = repr([(p.step, p.done) for p in steps])
                if counts != last:
                    print(
                        format_progress(steps, time.monotonic() - start, start_done),
                        file=stream,
                        flush=True,
                    )
                    last = counts
    text = log_path.read_text(errors="replace")
    if dry_run:
        print(text.split("\n", 1)[1] if "\n" in text else text, file=stream)
    elif proc.returncode == 0:
        print(
            format_progress(progress(plan, store), time.monotonic() - start, start_done),
            file=stream,
        )
    else:
        for message in failed_job_messages(text, plan):
            print(message, file=stream)
        print(f"build failed; Snakemake's log: {log_path}", file=stream)
    return proc.returncode
