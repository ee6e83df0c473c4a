"""Batched workflows: the layout file Snakemake reads, the batch markers, ``sonicspec batch``.

A batched build (:mod:`sonicspec.plan.batches`) shows Snakemake the scene and corpus jobs, the
dataset job and one job per batch of shards. It reads a compact *layout* file written by the
head (one unit per line: rule, key, input files, resources), not the plan: a plan of 10^6
groups takes minutes to read and re-hash, its layout a second.

A batch's output is a marker, ``<store>/batches/<pre>/<key>.json`` (its members' keys),
written once every member's artifact is in the store. The head keeps markers true to the
store before Snakemake starts (:func:`refresh_markers`): a batch with a member missing loses
its marker and runs again, skipping the members already made (``run_job`` does).
"""

from __future__ import annotations

import json
import logging
import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from sonicspec.atomic import atomic_path
from sonicspec.errors import CompileError, SonicspecError
from sonicspec.plan.batches import Batch
from sonicspec.plan.model import STEP_BY_NAME, Plan

LAYOUT_FORMAT = "sonicspec-workflow-layout"
BATCH_RULE = "batch"
FAILED_LINE = "job failed: "

log = logging.getLogger("sonicspec.stages")


def marker_path(store_dir: str | Path, key: str) -> Path:
    """The file that stands for a finished batch."""
    return Path(store_dir) / "batches" / key[:2] / f"{key}.json"


def job_log_path(store_dir: str | Path, step: str, key: str) -> Path:
    """A job's log (the workflow's ``log:`` pattern, also for the members of a batch)."""
    return Path(store_dir) / "logs" / step / key[:2] / f"{key}.log"


def artifact_file(store_dir: str, step: str, key: str) -> str:
    """The file that stands for an artifact (see ``WorkflowPlan.artifact``)."""
    return f"{store_dir}/{step}/{key[:2]}/{key}.zarr/zarr.json"


def write_layout(plan: Plan, plan_path: Path, batches: Sequence[Batch], path: Path) -> Path:
    """The layout of a batched workflow (module docstring), atomically, one unit per line."""
    in_batch = {k: b for b in batches for k in b.members}
    step_of = {j.key: j.step for j in plan.jobs}

    def file_of(key: str) -> str:
        batch = in_batch.get(key)
        if batch is not None:
            return str(marker_path(plan.store_dir, batch.key))
        return artifact_file(plan.store_dir, step_of[key], key)

    header = {"format": LAYOUT_FORMAT, "version": 1, "plan": str(plan_path),
              "store_dir": plan.store_dir,
              "steps": [s for s in STEP_BY_NAME if s in set(step_of.values())]}
    emitted: set[str] = set()
    with atomic_path(path) as tmp, tmp.open("w") as fh:
        fh.write(json.dumps(header, sort_keys=True) + "\n")
        for job in plan.jobs:
            batch = in_batch.get(job.key)
            if batch is None:
                inputs = list(dict.fromkeys(file_of(k) for k in job.inputs))
                unit = {"rule": job.step, "key": job.key, "inputs": inputs}
            elif batch.key in emitted:
                continue
            else:
                emitted.add(batch.key)
                unit = {"rule": BATCH_RULE, "key": batch.key, "label": batch.label,
                        "inputs": list(dict.fromkeys(file_of(k) for k in batch.inputs)),
                        "members": list(batch.members), "mem_mb": batch.mem_mb,
                        "runtime_min": batch.runtime_min}
            fh.write(json.dumps(unit) + "\n")
    return path


@dataclass(frozen=True)
class Layout:
    """A layout file as read (:func:`read_layout`)."""

    plan_path: str
    store_dir: str
    steps: list[str]
    units: dict[str, dict]
    """Key -> the unit's line (rule, inputs; members and resources for a batch)."""


def read_layout(path: str | Path) -> Layout:
    try:
        with open(path) as fh:
            header = json.loads(fh.readline())
            if header.get("format") != LAYOUT_FORMAT or header.get("version") != 1:
                raise CompileError(f"layout file {path}: not a sonicspec workflow layout "
                                   "(version 1)")
            units = {}
            for line in fh:
                unit = json.loads(line)
                units[unit["key"]] = unit
    except FileNotFoundError:
        raise CompileError(f"layout file {path}: does not exist") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise CompileError(f"layout file {path}: unreadable ({exc})") from exc
    return Layout(header["plan"], header["store_dir"], header["steps"], units)


def read_batch(path: str | Path, key: str) -> dict:
    """One batch's line of a layout file, found without parsing the others."""
    tag = f'"key": "{key}"'
    try:
        with open(path) as fh:
            fh.readline()
            for line in fh:
                if tag in line:
                    unit = json.loads(line)
                    if unit["key"] == key and unit["rule"] == BATCH_RULE:
                        return unit
    except FileNotFoundError:
        raise CompileError(f"layout file {path}: does not exist") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise CompileError(f"layout file {path}: unreadable ({exc})") from exc
    raise CompileError(f"layout file {path}: no batch with key {key[:12]}")


def refresh_markers(store_dir: str | Path, batches: Sequence[Batch], present: set[str]) -> int:
    """Make each batch's marker say whether all its members are in the store: written where
    they are (no job needed), removed where one is not (the batch runs again). Returns how
    many batches are complete. One ``stat`` per batch."""
    complete = 0
    for batch in batches:
        path = marker_path(store_dir, batch.key)
        if all(k in present for k in batch.members):
            complete += 1
            if not path.is_file():
                _write_marker(path, batch.members)
        else:
            path.unlink(missing_ok=True)
    return complete


def _write_marker(path: Path, members: Sequence[str]) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps({"members": list(members)}) + "\n")


def _run_member(plan: Plan, key: str, log_path: Path) -> bool:
    """Run one member job with its output in ``log_path``; True if it made its artifact.

    In a forked child where the system has ``fork`` (POSIX): the batch's process imported the
    stages once, each job starts from that state in milliseconds (no 1 s Python start, no
    re-import) and its memory is returned when it ends, so a batch's peak is its largest job's,
    not what many jobs leave behind (bench/bench_rule_memory.py measures both ways). A member
    killed (out of memory, a signal) fails alone. Elsewhere: in this process.
    """
    from sonicspec.stages import run_job

    log_path.parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    if not hasattr(os, "fork"):
        with _output_to(log_path):
            try:
                run_job(plan, key)
                return True
            except SonicspecError as exc:
                log.error("%s", exc)
                return False
    pid = os.fork()
    if pid == 0:  # the member job: never returns
        code = 1
        try:
            fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            os.close(fd)
            run_job(plan, key)
            code = 0
        except SonicspecError as exc:
            log.error("%s", exc)
        except BaseException:
            log.exception("%s: the job's process failed", key[:12])
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    code = os.waitstatus_to_exitcode(status)
    if code < 0:
        with open(log_path, "a") as fh:
            fh.write(f"the job's process was killed by signal {-code} "
                     f"({_signal_name(-code)})\n")
    return code == 0


def _signal_name(number: int) -> str:
    import signal

    try:
        return signal.Signals(number).name
    except ValueError:
        return "unknown"


@contextmanager
def _output_to(path: Path) -> Iterator[None]:
    """Send this process's stdout and stderr (file descriptors 1 and 2, so the libraries'
    output too) to ``path`` for the duration: a member job's log, as ``sonicspec job``
    writes it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(path, "w") as fh:
            os.dup2(fh.fileno(), 1)
            os.dup2(fh.fileno(), 2)
            try:
                yield
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os.dup2(saved[0], 1)
                os.dup2(saved[1], 2)
    finally:
        for fd in saved:
            os.close(fd)


def run_batch(plan_path: str | Path, layout_path: str | Path, key: str) -> list[str]:
    """Run a batch's member jobs in plan order (each in a forked child, :func:`_run_member`),
    each logging to its own job log; keep going past a failure with the members that do not
    need it. Writes the batch's marker when every member is made. Returns the failed members'
    keys (also logged as ``job failed: KEY LABEL log: PATH`` lines, which the head reads)."""
    from sonicspec.stages import stage_function

    unit = read_batch(layout_path, key)
    members = unit["members"]
    plan = Plan.read_jobs(Path(plan_path), members)
    jobs = plan.by_key()
    for step in dict.fromkeys(jobs[k].step for k in members):
        stage_function(step)  # imported once, before the forks
    failed: list[str] = []
    blocked: set[str] = set()
    for member in members:
        job = jobs[member]
        log_path = job_log_path(plan.store_dir, job.step, member)
        needs = [k for k in job.inputs if k in blocked]
        if needs:
            blocked.add(member)
            log.error("%s (%s): not run, it needs %s, which failed", job.label, member[:12],
                      jobs[needs[0]].label)
            continue
        if not _run_member(plan, member, log_path):
            failed.append(member)
            blocked.add(member)
            log.error("%s%s %s log: %s", FAILED_LINE, member, job.label, log_path)
    if not failed and not blocked:
        _write_marker(marker_path(plan.store_dir, key), members)
    return failed
