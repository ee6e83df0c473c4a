"""Before a build runs: find what is damaged or missing, and clear the way to remake it.

A build trusts nothing it has not checked. For every job of the plan whose artifact is in the store
it checks the artifact (digest of its arrays, re-read only when its files moved since the last
check, see :mod:`sonicspec.stages.checked`), and for the ``export`` and ``dataset`` jobs every file
they wrote into the dataset folder (SHA-256 recorded when written; re-hashed only when its size or
time moved; the list of those files is read from the artifact only when the artifact moved, see
:class:`~sonicspec.stages.checked.CheckCache`). A damaged artifact, a missing or changed dataset
file, or a deleted artifact whose consumers are still there, sends that job and every job
downstream of it back to the queue: their artifacts are removed, so Snakemake (which reruns exactly
the jobs whose output is missing) makes them again, with the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonicspec import artifacts
from sonicspec.artifacts.records import DatasetData, ExportData, FileRecord
from sonicspec.errors import StageError, StoreError
from sonicspec.export.checksums import (
    CHECKSUMS_NAME,
    DATASET_MARKER,
    read_checksums,
    read_marker,
    verify_dataset,
)
from sonicspec.hashing import file_sha256
from sonicspec.plan.model import Job, Plan
from sonicspec.stages.checked import CheckCache
from sonicspec.store import ArtifactStore

FILE_STEPS = ("export", "dataset")


@dataclass(frozen=True)
class Finding:
    """Something a build found damaged or missing (and will remake)."""

    job: Job
    problem: str

    def format(self) -> str:
        return f"{self.job.label} ({self.job.key[:12]}): {self.problem}"


@dataclass
class CheckReport:
    findings: list[Finding] = field(default_factory=list)
    removed: list[Job] = field(default_factory=list)
    """Artifacts removed so the build remakes them (the damaged ones and what follows)."""
    artifacts_checked: int = 0
    artifacts_verified: int = 0
    files_checked: int = 0
    files_hashed: int = 0
    records_read: int = 0
    """``export``/``dataset`` artifacts whose JSON was read for the files they record (the
    others' lists came from the check cache)."""


def present_keys(plan: Plan, store: ArtifactStore) -> set[str]:
    """Keys of the plan's jobs whose artifacts are in the store."""
    return {k for step, jobs in plan.by_step().items() if jobs
            for k in store.present(step, (j.key for j in jobs))}


def written_files(step: str, data: Any, where: str = "") -> Iterator[FileRecord]:
    """The dataset-folder files an ``export`` or ``dataset`` artifact (its data) records;
    :class:`~sonicspec.errors.StageError` if the data does not read as the step's model."""
    if step == "export":
        export: ExportData = artifacts.decode(step, data, where)
        for group in export.groups:
            yield from group.files
    elif step == "dataset":
        dataset: DatasetData = artifacts.decode(step, data, where)
        yield from dataset.files


def _file_problem(out: Path, record: FileRecord, cache: CheckCache,
                  report: CheckReport) -> str | None:
    if record.sha256 is None:
        return None
    path = out / record.path
    report.files_checked += 1
    try:
        st = path.stat()
    except FileNotFoundError:
        return f"dataset file {record.path} is missing"
    if cache.file_ok(path, st, record.sha256):
        return None
    report.files_hashed += 1
    if record.bytes not in (None, st.st_size) or file_sha256(path) != record.sha256:
        cache.forget_file(path)
        return f"dataset file {record.path} differs from what the build wrote"
    cache.mark_file(path, st, record.sha256)
    return None


def check_existing(plan: Plan, store: ArtifactStore, cache: CheckCache, *, repair: bool = True,
                   tick: Callable[[str], None] | None = None) -> CheckReport:
    """Check what the plan already has; with ``repair``, remove what must be made again."""
    report = CheckReport()
    present = present_keys(plan, store)
    bad: dict[str, str] = {}
    out = Path(plan.output_dir)
    for n, job in enumerate(plan.jobs):
        if tick is not None and n % 200 == 0:
            tick(f"checking the store and the dataset folder: {n}/{len(plan.jobs)} jobs")
        if job.key not in present:
            continue
        report.artifacts_checked += 1
        fingerprint = store.fingerprint(job.step, job.key)
        if not cache.artifact_ok(job.key, fingerprint):
            report.artifacts_verified += 1
            problem = store.verify_one(job.step, job.key)
            if problem is not None:
                bad[job.key] = f"store artifact damaged: {problem.problem}"
                continue
            cache.mark_artifact(job.key, fingerprint)
        if job.step in FILE_STEPS:
            # The files it wrote, from the cache while the artifact is unchanged: reading its
            # JSON costs megabytes per group.
            records = cache.written(job.key, fingerprint)
            if records is None:
                report.records_read += 1
                try:
                    records = cache.mark_written(
                        job.key, fingerprint,
                        written_files(job.step, store.read_data(job.step, job.key), job.label))
                except StageError as exc:
                    bad[job.key] = f"store artifact's record does not read: {exc}"
                    continue
            for record in records:
                problem = _file_problem(out, record, cache, report)
                if problem is not None:
                    bad[job.key] = problem
                    break
    # A missing artifact whose consumers exist (deleted by hand) and every damaged one send
    # themselves and everything downstream back to the queue.
    consumers: dict[str, list[str]] = {}
    for job in plan.jobs:
        for k in job.inputs:
            consumers.setdefault(k, []).append(job.key)
    jobs = plan.by_key()
    for job in plan.jobs:
        if job.key not in present and any(c in present for c in consumers.get(job.key, ())):
            bad.setdefault(job.key, "store artifact missing (deleted?) while the jobs that "
                                    "use it are there")
    rerun: set[str] = set()
    stack = list(bad)
    while stack:
        key = stack.pop()
        if key not in rerun:
            rerun.add(key)
            stack.extend(consumers.get(key, ()))
    order = {k: i for i, k in enumerate(jobs)}
    report.findings = [Finding(jobs[k], bad[k]) for k in sorted(bad, key=order.__getitem__)]
    report.removed = [j for j in plan.jobs if j.key in rerun and j.key in present]
    if repair:
        for job in report.removed:
            store.remove(job.step, job.key)
    return report


def record_written(plan: Plan, store: ArtifactStore, cache: CheckCache,
                   keys: set[str]) -> list[str]:
    """After a build: remember the artifacts and files its jobs (``keys``) just wrote as sound,
    so the next build does not re-read them; returns the files those jobs recorded that are
    not there. (Every other job's files were checked before the build ran.)"""
    out = Path(plan.output_dir)
    missing = []
    for job in plan.jobs:
        if job.key not in keys or not store.exists(job.step, job.key):
            continue
        fingerprint = store.fingerprint(job.step, job.key)
        cache.mark_artifact(job.key, fingerprint)
        if job.step in FILE_STEPS:
            records = list(written_files(job.step, store.read_data(job.step, job.key),
                                         job.label))
            cache.mark_written(job.key, fingerprint, records)
            for record in records:
                path = out / record.path
                if not path.is_file():
                    missing.append(record.path)
                elif record.sha256 is not None:
                    cache.mark_file(path, path.stat(), record.sha256)
    return missing


def verify_dataset_folder(out: Path, cache: CheckCache | None = None) -> tuple[int, list[str]]:
    """Every file of a dataset folder against ``checksums.sha256``, and that list against the
    records in the store that built it (the dataset artifact the marker names and its export
    inputs); (files checked, problems). With ``cache`` (the store's, under its lock), the files
    found damaged are forgotten there, so the next build re-hashes and repairs them even if
    their size and time were kept."""
    count, problems = verify_dataset(out)
    if cache is not None and problems:
        cache.forget_files([out / p.path for p in problems] + [out / CHECKSUMS_NAME])
    lines = [p.format() for p in problems]
    marker = read_marker(out)
    if "store" not in marker or "dataset_key" not in marker:
        return count, lines  # made before markers named their store: the checksums only
    store = ArtifactStore(out / marker["store"])
    key = marker["dataset_key"]
    if not store.exists("dataset", key):
        lines.append(f"{DATASET_MARKER}: names dataset {key[:12]} in store {store.root}, which "
                     "does not have it (an unfinished build, or the store was moved)")
        return count, lines
    try:
        listed = read_checksums(out)
    except StoreError:
        return count, lines
    try:
        recorded = list(written_files("dataset", store.read_data("dataset", key)))
        for k in store.read("dataset", key).provenance["input_keys"]:
            if store.exists("export", k):  # (the others are corpora)
                recorded += written_files("export", store.read_data("export", k))
    except StageError as exc:
        lines.append(f"{DATASET_MARKER}: the store's record of what the build wrote does not "
                     f"read ({exc})")
        return count, lines
    for r in recorded:
        if r.path == CHECKSUMS_NAME:
            continue
        if listed.get(r.path) != r.sha256:
            if cache is not None:
                cache.forget_files([out / r.path, out / CHECKSUMS_NAME])
            lines.append(f"{r.path}: {CHECKSUMS_NAME} disagrees with the store's record of "
                         "what the build wrote")
    return count, lines
