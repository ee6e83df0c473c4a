"""Batches: the jobs of whole shards run as one Snakemake job, for plans too big for its DAG.

Snakemake's cost is per job it sees (bench/RESULTS.md, "Snakemake's DAG at 10^5 and 10^6
groups": 1.4 ms and 25 kB per job on a quiet machine, 9 ms under load), so a plan of 10^6
groups (375k jobs at 16 groups per shard) would take minutes and gigabytes before its first
job. A batch is a run of consecutive shards: their placement, arrange, rir, render, mix and
export jobs (a shard's jobs need only each other and the scene/corpus jobs), run in order by
one ``sonicspec batch`` process. The plan and every job's key are unchanged: a batch is only
how jobs are handed to Snakemake, so the store and dataset bytes are those of unbatched jobs
(tests/test_pipeline_build.py builds both ways).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from sonicspec.errors import CompileError
from sonicspec.hashing import canonical_json, sha256_hex
from sonicspec.plan.model import STEP_BY_NAME, Job, Plan

BATCHED_STEPS = ("placement", "arrange", "rir", "render", "mix", "export")
"""The per-shard steps; corpus, mesh, navigation (per scene) and dataset stay single jobs."""

AUTO_MIN_JOBS = 20_000
"""Plans with more jobs than this are batched unless told otherwise (Snakemake's DAG for
20,000 jobs: ~30 s and ~0.5 GB quiet, minutes under load)."""

AUTO_TARGET = 4_000
"""How many batches an automatically batched plan aims at (~6 s of DAG on a quiet machine)."""


@dataclass(frozen=True)
class Batch:
    """Consecutive shards' jobs, run in plan order by one Snakemake job."""

    key: str
    """Names the batch: the digest of its members' keys (a new member set is a new batch)."""
    members: tuple[str, ...]
    inputs: tuple[str, ...]
    """Keys of the jobs outside the batch that its members need (scene and corpus jobs)."""
    label: str
    mem_mb: int
    """The largest member step's request: members run one after another in one process."""
    runtime_min: int
    """The members' runtimes summed."""


def shard_chains(plan: Plan) -> list[list[Job]]:
    """The batched steps' jobs in groups closed under their inputs (one group per shard in a
    compiled plan), in plan order."""
    parent: dict[str, str] = {}

    def find(k: str) -> str:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    jobs = [j for j in plan.jobs if j.step in BATCHED_STEPS]
    for job in jobs:
        parent[job.key] = job.key
    for job in jobs:
        for k in job.inputs:
            if k in parent:
                a, b = find(job.key), find(k)
                if a != b:
                    parent[a] = b
    chains: dict[str, list[Job]] = {}
    for job in jobs:
        chains.setdefault(find(job.key), []).append(job)
    return list(chains.values())


def auto_shards_per_batch(plan: Plan, chains: Sequence[Sequence[Job]] | None = None) -> int:
    """0 (no batches) for plans of up to :data:`AUTO_MIN_JOBS` jobs; else the shards per batch
    that bring the batches to about :data:`AUTO_TARGET`."""
    if len(plan.jobs) <= AUTO_MIN_JOBS:
        return 0
    count = len(chains) if chains is not None else len(shard_chains(plan))
    return max(1, math.ceil(count / AUTO_TARGET))


def batch_plan(plan: Plan, shards_per_batch: int) -> list[Batch]:
    """The plan's shards in batches of ``shards_per_batch`` (consecutive in plan order, so a
    batch's shards share a scene where they can). Empty for 0 (no batching)."""
    if shards_per_batch < 0:
        raise CompileError(f"shards per batch: expected 0 (no batches) or more, got "
                           f"{shards_per_batch}")
    if shards_per_batch == 0:
        return []
    chains = shard_chains(plan)
    out = []
    for first in range(0, len(chains), shards_per_batch):
        members = [j for chain in chains[first: first + shards_per_batch] for j in chain]
        inside = {j.key for j in members}
        inputs = list(dict.fromkeys(k for j in members for k in j.inputs if k not in inside))
        keys = tuple(j.key for j in members)
        steps = {j.step for j in members}
        label = members[0].label.split(" ", 1)[-1]
        if len(chains[first: first + shards_per_batch]) > 1:
            label += f" .. {members[-1].label.split(' ', 1)[-1]}"
        out.append(Batch(
            key=sha256_hex(canonical_json(["batch", list(keys)])),
            members=keys,
            inputs=tuple(inputs),
            label=f"batch {label}",
            mem_mb=max(STEP_BY_NAME[s].mem_mb for s in steps),
            runtime_min=sum(STEP_BY_NAME[j.step].runtime_min for j in members),
        ))
    return out
