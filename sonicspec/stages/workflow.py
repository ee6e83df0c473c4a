"""Driving Snakemake: the plan as the workflow sees it, and `sonicspec build` with progress.

The Snakefile (``workflow/Snakefile``) is generic: it asks :class:`WorkflowPlan` for the steps,
the input artifacts of a job and the output pattern of a step. Rerun decisions come from the
content keys in the output paths and params, never from file times (``--rerun-triggers params
input``).
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import sonicspec
from sonicspec.errors import SonicspecError
from sonicspec.export.checksums import (
    CHECKSUMS_NAME,
    claim_folder,
    read_checksums,
    unlisted_files,
)
from sonicspec.plan.batches import auto_shards_per_batch, batch_plan
from sonicspec.plan.model import STEPS, Job, Plan, Step
from sonicspec.plan.params import read_params
from sonicspec.stages.batch import (
    BATCH_RULE,
    FAILED_LINE,
    Layout,
    marker_path,
    read_layout,
    refresh_markers,
    write_layout,
)
from sonicspec.stages.checked import CheckCache
from sonicspec.stages.context import finished_dir, progress_path
from sonicspec.stages.repair import CheckReport, check_existing, present_keys, record_written
from sonicspec.stages.warm import STEPS_THAT_COMPILE, warm_once
from sonicspec.store import ArtifactStore
from sonicspec.store.lock import StoreLock, group_members


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

    batched = False

    @classmethod
    def load(cls, path: str | Path, layout: str | Path | None = None) -> WorkflowPlan:
        """The plan file's workflow; with ``layout``, the batched workflow that file describes
        (:class:`BatchedWorkflowPlan`; the plan itself is not read)."""
        if layout:
            return BatchedWorkflowPlan.read(layout)
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

    def job_command(self) -> str:
        """The shell command of every rule: the plan's path written in (Snakemake formats
        ``{params.key}`` and ``{log}``; braces of the path are escaped)."""
        plan = shlex.quote(self.path).replace("{", "{{").replace("}", "}}")
        return f"sonicspec job --plan {plan} {{params.key}} > {{log}} 2>&1"

    def benchmark_pattern(self, step: str) -> str:
        return f"{self.store_dir}/benchmarks/{step}/{{pre}}/{{key}}.tsv"

    def inputs_of(self, wildcards: Any) -> list[str]:
        job = self._jobs[wildcards.key]
        return [self.artifact(self._jobs[k].step, k) for k in job.inputs]

    def final_artifacts(self) -> list[str]:
        """Artifacts nothing else consumes: building them builds everything."""
        consumed = {k for j in self.plan.jobs for k in j.inputs}
        return [self.artifact(j.step, j.key) for j in self.plan.jobs if j.key not in consumed]


class BatchedWorkflowPlan(WorkflowPlan):
    """A batched plan as the Snakefile sees it (:mod:`sonicspec.stages.batch`): the scene,
    corpus and dataset jobs as steps, the shards' jobs as ``batch`` jobs, all read from the
    layout file."""

    batched = True

    def __init__(self, layout: Layout) -> None:
        self.path = layout.plan_path
        self.store_dir = layout.store_dir
        self.layout = layout
        self._layout_path = ""

    @classmethod
    def read(cls, path: str | Path) -> BatchedWorkflowPlan:
        out = cls(read_layout(path))
        out._layout_path = str(path)
        return out

    def steps(self) -> list[Step]:
        # Every step of the plan keeps its rule (profiles name them), used or not.
        return [s for s in STEPS if s.name in self.layout.steps]

    def inputs_of(self, wildcards: Any) -> list[str]:
        return self.layout.units[wildcards.key]["inputs"]

    def final_artifacts(self) -> list[str]:
        consumed = {f for u in self.layout.units.values() for f in u["inputs"]}
        out = []
        for key, unit in self.layout.units.items():
            path = (str(marker_path(self.store_dir, key)) if unit["rule"] == BATCH_RULE
                    else self.artifact(unit["rule"], key))
            if path not in consumed:
                out.append(path)
        return out

    def batch_pattern(self) -> str:
        return f"{self.store_dir}/batches/{{pre}}/{{key}}.json"

    def batch_log_pattern(self) -> str:
        return f"{self.store_dir}/logs/{BATCH_RULE}/{{pre}}/{{key}}.log"

    def batch_benchmark_pattern(self) -> str:
        return f"{self.store_dir}/benchmarks/{BATCH_RULE}/{{pre}}/{{key}}.tsv"

    def batch_command(self) -> str:
        """``sonicspec batch``'s command line (braces escaped as in :meth:`job_command`)."""
        plan = shlex.quote(self.path).replace("{", "{{").replace("}", "}}")
        layout = shlex.quote(self._layout_path).replace("{", "{{").replace("}", "}}")
        return f"sonicspec batch --plan {plan} --layout {layout} {{params.key}} > {{log}} 2>&1"

    def batch_mem_mb(self, wildcards: Any) -> int:
        return self.layout.units[wildcards.key]["mem_mb"]

    def batch_runtime(self, wildcards: Any) -> int:
        return self.layout.units[wildcards.key]["runtime_min"]


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
    layout: Path | None = None,
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
        *([f"layout={layout}"] if layout is not None else []),
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


def _failed_logs(snakemake_log: str, plan: Plan) -> list[Path]:
    """The logs of the failed jobs Snakemake names; for a failed batch, those of its failed
    members (its log lists them, ``sonicspec.stages.batch.run_batch``), or its own."""
    out = []
    for block in snakemake_log.split("Error in rule ")[1:]:
        match = _FAILED_LOG.search(block)
        if match is None:
            continue
        log_path = Path(match.group(1).rstrip(","))
        if not log_path.is_absolute():
            log_path = Path(plan.store_dir) / log_path
        members = []
        if block.startswith(BATCH_RULE + ":"):
            with contextlib.suppress(OSError):  # no log: the batch's own path is named
                members = [Path(line.split(" log: ", 1)[1].strip())
                           for line in log_path.read_text(errors="replace").splitlines()
                           if FAILED_LINE in line and " log: " in line]
        out += members or [log_path]
    return out


def failed_job_messages(snakemake_log: str, plan: Plan) -> list[str]:
    """For each failed job in Snakemake's output: the job's label and its last log lines."""
    jobs = plan.by_key()
    out = []
    for log_path in _failed_logs(snakemake_log, plan):
        key = log_path.stem
        label = jobs[key].label if key in jobs else key[:12]
        tail = ""
        if log_path.is_file():
            lines = [x for x in log_path.read_text(errors="replace").splitlines() if x.strip()]
            tail = "\n    ".join(lines[-3:])
        out.append(f"{label} ({key[:12]}) failed; its log {log_path}:\n    {tail}")
    return out


@dataclass
class BuildResult:
    """What a build did: Snakemake's exit code, the jobs it ran and what it repaired."""

    code: int
    ran: dict[str, int]
    """Jobs run, per step (from Snakemake's own log: what it executed)."""
    reused: int
    check: CheckReport
    elapsed_s: float
    warnings: list[str]
    skipped: dict[str, list[dict[str, str]]] = field(default_factory=dict)
    """Corpus files the indexes left out, by role (``stages.corpus.skipped_files``)."""
    missing_files: list[str] = field(default_factory=list)
    """Dataset files the jobs that ran recorded but that are not there after the build."""
    stray_files: list[str] = field(default_factory=list)
    """Files in the dataset folder that the finished dataset does not list."""
    failed: list[str] = field(default_factory=list)
    """Labels of the jobs that failed (from Snakemake's log)."""
    not_made: dict[str, int] = field(default_factory=dict)
    """Jobs whose artifacts are not in the store after the build, per step (the failed ones
    and those waiting on them)."""
    summary: str = ""

    @property
    def jobs_run(self) -> int:
        return sum(self.ran.values())


_EXECUTED_KEY = re.compile(r"^\s*wildcards: pre=[0-9a-f]{2}, key=([0-9a-f]{64})\s*$", re.M)
_WARNING_LINE = re.compile(r"\bWARNING\b|Warning: ")


def executed_keys(snakemake_log: str) -> set[str]:
    """Keys of the jobs Snakemake started (each job block names its wildcards)."""
    return set(_EXECUTED_KEY.findall(snakemake_log))


def job_warnings(plan: Plan, keys: set[str]) -> list[str]:
    """Warning lines in the logs of the jobs that ran, each with its job's label."""
    jobs = plan.by_key()
    out = []
    for key in sorted(keys, key=lambda k: jobs[k].label if k in jobs else k):
        if key not in jobs:
            continue
        log_path = Path(plan.store_dir) / "logs" / jobs[key].step / key[:2] / f"{key}.log"
        try:
            lines = log_path.read_text(errors="replace").splitlines()
        except OSError:
            continue
        out += [f"{jobs[key].label}: {line.strip()}" for line in lines
                if _WARNING_LINE.search(line)]
    return out


def _clear_progress(plan: Plan) -> None:
    """Remove the progress files a killed build's jobs left (a job still running somewhere,
    e.g. on a cluster node, writes its file again at its next step)."""
    folder = progress_path(plan.store_dir, "0" * 64).parent
    try:
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        if name.endswith(".txt"):
            with contextlib.suppress(OSError):
                (folder / name).unlink()


def _job_progress(plan: Plan, waiting: Mapping[str, Job] | Iterable[Job]) -> str:
    """What the running jobs say of themselves (``JobContext.progress``), briefly.

    Lists the progress folder, which holds a file only while its job runs, and opens at most
    two of the files: O(running jobs), however many wait.
    """
    if not isinstance(waiting, Mapping):
        waiting = {j.key: j for j in waiting}
    folder = progress_path(plan.store_dir, "0" * 64).parent
    try:
        names = os.listdir(folder)
    except OSError:
        return ""
    running = sorted((waiting[n[:-4]] for n in names
                      if n.endswith(".txt") and n[:-4] in waiting),
                     key=lambda j: (j.label, j.key))
    parts = []
    for job in running:
        if len(parts) == 2:
            break
        try:
            text = progress_path(plan.store_dir, job.key).read_text().strip()
        except OSError:
            continue
        parts.append(f"{job.label}: {text}")
    if not parts:
        return ""
    more = len(running) - len(parts) if len(parts) == 2 else 0
    return " | " + "; ".join(parts) + (f" (+{more} more)" if more > 0 else "")


def _hours(plan: Plan) -> tuple[int, float]:
    """Groups in the plan and the hours of audio they last (one track's length each)."""
    arranged = [read_params("arrange", j.params, j.label) for j in plan.jobs
                if j.step == "arrange"]
    groups = sum(len(p.groups) for p in arranged)
    seconds = sum(len(p.groups) * p.mixture.duration_s for p in arranged)
    return groups, seconds / 3600.0


def failed_jobs(snakemake_log: str, plan: Plan) -> list[str]:
    """Labels of the jobs Snakemake reports failed, in the plan's order."""
    keys = {p.stem for p in _failed_logs(snakemake_log, plan)}
    return [j.label for j in plan.jobs if j.key in keys]


def _failure_lines(plan: Plan, result: BuildResult) -> list[str]:
    """What a failed build did not make, so its summary cannot read as a success."""
    if result.failed:
        more = ", ..." if len(result.failed) > 3 else ""
        lines = [f"{len(result.failed)} job{'s' * (len(result.failed) != 1)} failed "
                 f"({', '.join(result.failed[:3])}{more}); the ends of their logs are above"]
    else:
        lines = [f"Snakemake stopped (exit code {result.code}) before the jobs finished; its "
                 "log is named above"]
    missing = sum(result.not_made.values())
    if missing:
        lines.append(f"not made: {missing} of {len(plan.jobs)} jobs ("
                     + ", ".join(f"{s} {n}" for s, n in result.not_made.items() if n)
                     + "): the failed ones and every job that needs them")
    if result.not_made.get("dataset") or result.not_made.get("export"):
        lines.append(f"dataset: NOT written: {plan.output_dir} is incomplete (what an earlier "
                     "build wrote there is unchanged); fix the cause and run the build again: "
                     "it resumes from what was made")
    return lines


def format_summary(plan: Plan, result: BuildResult) -> str:
    ran = ", ".join(f"{s} {n}" for s, n in result.ran.items() if n) or "none"
    groups, hours = _hours(plan)
    lines = [
        f"build {'finished' if result.code == 0 else 'FAILED'} in {_clock(result.elapsed_s)}: "
        f"{result.jobs_run} job{'s' * (result.jobs_run != 1)} run ({ran}), {result.reused} "
        f"reused from the store, {len(result.check.findings)} repaired",
        f"checked {result.check.artifacts_checked} artifacts ({result.check.artifacts_verified}"
        f" re-read) and {result.check.files_checked} dataset files "
        f"({result.check.files_hashed} re-hashed)",
    ]
    if result.code == 0:
        lines.append(f"dataset: {groups} groups, {hours:.3f} h of audio per track")
    else:
        lines += _failure_lines(plan, result)
    skipped = {role: files for role, files in result.skipped.items() if files}
    if skipped:
        lines.append("corpus files skipped (unreadable or unusable; listed in dataset.json): "
                     + ", ".join(f"{role} {len(files)} (first: {files[0]['path']}, "
                                 f"{files[0]['reason']})" for role, files in skipped.items()))
    if result.stray_files:
        lines.append(f"{len(result.stray_files)} file(s) in the dataset folder are not part of "
                     f"this dataset (first: {result.stray_files[0]}; left by an earlier build "
                     "of another spec, or added by hand): `sonicspec verify "
                     f"{plan.output_dir}` lists them")
    if result.warnings:
        lines.append(f"{len(result.warnings)} warning{'s' * (len(result.warnings) != 1)} in "
                     "the jobs' logs:")
        lines += [f"  {w}" for w in result.warnings[:10]]
        if len(result.warnings) > 10:
            lines.append(f"  ... and {len(result.warnings) - 10} more (the logs are in "
                         f"{Path(plan.store_dir) / 'logs'})")
    elif result.code == 0:
        lines.append("no warnings")
    return "\n".join(lines)


def build(
    plan: Plan,
    *,
    cores: int = 1,
    profile: Path | None = None,
    dry_run: bool = False,
    stream: TextIO | None = None,
    poll_s: float = 1.0,
    on_start: Callable[[subprocess.Popen], None] | None = None,
    snakemake_args: list[str] | None = None,
    shards_per_batch: int | None = None,
) -> BuildResult:
    """Run the plan through Snakemake: check and repair what exists, run exactly the jobs
    whose artifacts are missing, print progress and a summary.

    ``shards_per_batch``: show Snakemake one job per that many shards (their placement to
    export jobs, :mod:`sonicspec.plan.batches`) instead of one per step and shard; 0 never;
    None (the default) batches plans of more than 20,000 jobs, at about 4,000 batches. The
    jobs, their keys and bytes are the same either way.

    One build at a time per store (:class:`~sonicspec.store.lock.StoreLock`); the store and
    the dataset folder are claimed with their marker files first, so a build never writes into
    a folder that is not its own.
    """
    from sonicspec.stages.corpus import skipped_files  # reads audio libraries: only here

    stream = stream or sys.stderr  # at call time: a caller may have replaced sys.stderr
    store = ArtifactStore(plan.store_dir)
    out = Path(plan.output_dir)
    dataset_key = next((j.key for j in plan.jobs if j.step == "dataset"), None)
    claims = ((Path(plan.store_dir), "store", "outputs.store_dir", {}),
              (out, "dataset", "outputs.dir",
               {"store": os.path.relpath(plan.store_dir, out), "dataset_key": dataset_key}))
    for claim in claims:  # both checked before either is written
        claim_folder(*claim, write=False)
    claim_folder(*claims[0], write=not dry_run)
    with StoreLock(plan.store_dir) as lock, _signals_interrupt():
        if lock.stopped:
            print(lock.stopped, file=stream)
        claim_folder(*claims[1], write=not dry_run)
        start = time.monotonic()
        removed = store.clean_stale_temp()
        _clear_progress(plan)
        if removed:
            print(f"removed {removed} unfinished artifact(s) left by an interrupted build",
                  file=stream)
        cache = CheckCache.of_store(plan.store_dir)
        check = check_existing(plan, store, cache, repair=not dry_run,
                               tick=lambda s: print(s, file=stream, flush=True)
                               if len(plan.jobs) > 2000 else None)
        for finding in check.findings:
            print(f"{'would repair' if dry_run else 'repairing'}: {finding.format()}",
                  file=stream)
        if check.removed and not dry_run:
            print(f"removed {len(check.removed)} artifact(s) to remake them (the damaged ones "
                  "and the jobs that follow from them)", file=stream)
        cache.save()
        present = present_keys(plan, store)
        if not dry_run and len(present) == len(plan.jobs):
            # Nothing to make: Snakemake would spend its DAG (seconds per 10^4 jobs) to say so.
            code, log_text, made = 0, "", set()
            print(format_progress(progress(plan, store), time.monotonic() - start,
                                  len(present)), file=stream)
        else:
            if not dry_run and any(j.step in STEPS_THAT_COMPILE and j.key not in present
                                   for j in plan.jobs):
                warm_once(stream)  # before the first wave, not in every job of it
            code, log_text, made = _run_snakemake(
                plan, store, present, cores=cores, profile=profile, dry_run=dry_run,
                stream=stream, poll_s=poll_s, on_start=on_start, snakemake_args=snakemake_args,
                start=start, lock=lock, shards_per_batch=shards_per_batch)
        # A batch's members are not Snakemake jobs: their finished markers name them.
        ran_keys = (executed_keys(log_text) | made) & {j.key for j in plan.jobs}
        jobs = plan.by_key()
        ran = {s.name: 0 for s in STEPS}
        for key in ran_keys:
            ran[jobs[key].step] += 1
        missing: list[str] = []
        if not dry_run:
            missing = record_written(plan, store, cache, ran_keys)
            cache.save()
        result = BuildResult(code=code, ran=ran, reused=len(present - ran_keys), check=check,
                             elapsed_s=time.monotonic() - start,
                             warnings=job_warnings(plan, ran_keys),
                             skipped=skipped_files(plan, store), missing_files=missing)
        if not dry_run:
            if code == 0 and dataset_key is not None and (out / CHECKSUMS_NAME).is_file():
                result.stray_files = unlisted_files(out, read_checksums(out))
            if code != 0:
                result.failed = failed_jobs(log_text, plan)
                made = present_keys(plan, store)
                for job in plan.jobs:
                    if job.key not in made:
                        result.not_made[job.step] = result.not_made.get(job.step, 0) + 1
            result.summary = format_summary(plan, result)
            print(result.summary, file=stream)
        return result


def run_build(plan: Plan, **kwargs: Any) -> int:
    """:func:`build`, returning Snakemake's exit code."""
    return build(plan, **kwargs).code


def take_finished(folder: Path) -> list[str]:
    """Keys of the jobs that finished since the last call (their markers in ``folder``,
    deleted as they are read): O(new markers)."""
    keys = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return keys
    for entry in entries:
        if entry.name.endswith(".done"):
            keys.append(entry.name[: -len(".done")])
        with contextlib.suppress(OSError):  # another head took it: counted there
            os.unlink(entry.path)
    return keys


def _follow(plan: Plan, proc: subprocess.Popen, waiting: dict[str, Job], *, done: dict[str, int],
            totals: dict[str, int], finished: Path, dry_run: bool, stream: TextIO,
            poll_s: float, start: float, start_done: int) -> set[str]:
    """Print progress until Snakemake ends: counts from the finished-job markers (O(new
    markers) per poll, ``take_finished``), text from the running jobs' progress files.
    Returns the keys of the waiting jobs that finished."""
    last = ""
    made: set[str] = set()

    def count() -> None:
        for key in take_finished(finished):
            job = waiting.pop(key, None)
            if job is not None:
                done[job.step] += 1
                made.add(key)

    while proc.poll() is None:
        time.sleep(poll_s)
        if dry_run:
            continue
        count()
        steps = [StepProgress(step, done[step], totals[step]) for step in totals]
        line = format_progress(steps, time.monotonic() - start, start_done)
        line += _job_progress(plan, waiting)
        if line.split("] ", 1)[-1] != last:
            print(line, file=stream, flush=True)
            last = line.split("] ", 1)[-1]
    if not dry_run:
        count()  # the markers of the last jobs, left after the last poll
    return made


def _die_with_parent() -> Callable[[], None] | None:
    """For Popen's ``preexec_fn`` (Linux): the child is killed when the head dies, even by
    ``kill -9`` (``PR_SET_PDEATHSIG``). None elsewhere.

    SIGKILL, not SIGTERM: on SIGTERM Snakemake waits "gracefully" for its jobs, and was seen
    waiting for many minutes after they were gone. Its jobs finish what they write (atomically)
    and exit; the next build stops any still running (see :mod:`sonicspec.store.lock`)."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def arm() -> None:  # runs in the child between fork and exec: no allocation, no imports
        prctl(1, signal.SIGKILL)  # 1 = PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the head died before the line above
            os.kill(os.getpid(), signal.SIGKILL)

    return arm


def stop_group(proc: subprocess.Popen, grace_s: float = 10.0) -> None:
    """Stop Snakemake and every job of its process group: SIGTERM, then SIGKILL to what is
    still there after ``grace_s``."""
    pgid = proc.pid
    for sig, wait_s in ((signal.SIGTERM, grace_s), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            break
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            if proc.poll() is not None and not group_members(pgid):
                return
            time.sleep(0.05)
    proc.poll()


@contextmanager
def _signals_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP end a build like Ctrl-C does (``KeyboardInterrupt``), so it stops
    its Snakemake and jobs and releases the lock instead of dying with them running."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, _frame: object) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    old = {s: signal.signal(s, interrupt) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def _run_snakemake(plan: Plan, store: ArtifactStore, present: set[str], *, cores: int,
                   profile: Path | None, dry_run: bool, stream: TextIO, poll_s: float,
                   on_start: Callable[[subprocess.Popen], None] | None,
                   snakemake_args: list[str] | None, start: float,
                   lock: StoreLock | None = None,
                   shards_per_batch: int | None = None) -> tuple[int, str, set[str]]:
    plan_path = plan.write(Path(plan.store_dir) / "plans" / f"{plan.digest}.json")
    layout = None
    if shards_per_batch is None:
        shards_per_batch = auto_shards_per_batch(plan)
    batches = batch_plan(plan, shards_per_batch)
    if batches:
        layout = write_layout(plan, plan_path, batches, Path(plan.store_dir) / "plans" /
                              f"{plan.digest}-batches-{shards_per_batch}.json")
        complete = refresh_markers(plan.store_dir, batches, present)
        print(f"batched: {len(batches)} Snakemake jobs of {shards_per_batch} shard"
              f"{'s' * (shards_per_batch != 1)} each ({complete} complete) for the "
              f"{sum(len(b.members) for b in batches)} shard jobs", file=stream)
    cmd = snakemake_command(plan_path, plan, cores=cores, profile=profile, dry_run=dry_run,
                            extra=snakemake_args, layout=layout)
    log_dir = Path(plan.store_dir) / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    log_path = log_dir / f"snakemake-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    start_done = len(present)
    # Progress from events: each job that finishes leaves a marker (``mark_finished``); the
    # head counts and deletes the new ones. Every job still to run started without its
    # artifact (the check removed the ones to remake), so the counts only ever grow.
    done: dict[str, int] = {}
    totals: dict[str, int] = {}
    for step, jobs in plan.by_step().items():
        if jobs:
            totals[step] = len(jobs)
            done[step] = sum(j.key in present for j in jobs)
    waiting = {j.key: j for j in plan.jobs if j.key not in present}
    finished = finished_dir(plan.store_dir)
    take_finished(finished)  # markers left by an earlier, interrupted build
    with open(log_path, "w") as log:
        log.write("$ " + " ".join(shlex.quote(c) for c in cmd) + "\n")
        log.flush()
        # Snakemake and every job it starts form one process group (its own session, so a
        # Ctrl-C reaches the head, which stops the group); the lock records it. If the head
        # dies, the kernel kills Snakemake: no further job starts.
        proc = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=plan.store_dir,
            start_new_session=True, preexec_fn=_die_with_parent(),
        )
        try:
            if lock is not None:
                lock.set_group(proc.pid)
            if on_start is not None:
                on_start(proc)
            made = _follow(plan, proc, waiting, done=done, totals=totals, finished=finished,
                           dry_run=dry_run, stream=stream, poll_s=poll_s, start=start,
                           start_done=start_done)
        finally:
            # Interrupted, or Snakemake died and left its jobs running: stop them all.
            if proc.poll() is None or group_members(proc.pid):
                stop_group(proc)
    text = log_path.read_text(errors="replace")
    if dry_run:
        print(text.split("\n", 1)[1] if "\n" in text else text, file=stream)
    elif proc.returncode == 0:
        print(format_progress(progress(plan, store), time.monotonic() - start, start_done),
              file=stream)
    else:
        for message in failed_job_messages(text, plan):
            print(message, file=stream)
        print(f"build failed; Snakemake's log: {log_path}", file=stream)
    return proc.returncode, text, made
