"""Batched workflows (sonicspec.plan.batches, sonicspec.stages.batch): what Snakemake sees of a
big plan is bounded, every job is in exactly one batch, a batch reads only its excerpt.

The bytes of a batched build against an unbatched one: tests/test_pipeline_build.py.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from sonicspec.errors import CompileError
from sonicspec.plan.batches import (
    AUTO_MIN_JOBS,
    AUTO_TARGET,
    BATCHED_STEPS,
    auto_shards_per_batch,
    batch_plan,
    shard_chains,
)
from sonicspec.plan.model import STEP_BY_NAME, Job, Plan
from sonicspec.stages.batch import marker_path, read_batch, refresh_markers, write_layout
from sonicspec.stages.workflow import (
    BatchedWorkflowPlan,
    WorkflowPlan,
    failed_job_messages,
    failed_jobs,
    snakemake_command,
)


def synthetic_plan(folder: Path, shards: int, scenes: int = 3) -> Plan:
    """A plan shaped like a compiled one: a corpus, per scene a mesh and navigation, per shard
    the six shard steps wired as compile_spec wires them, one dataset job."""
    corpus = Job("corpus", {"role": "speech"}, (), "corpus speech")
    jobs = [corpus]
    scene = []
    for s in range(scenes):
        mesh = Job("mesh", {"scene": s}, (), f"mesh s{s}")
        nav = Job("navigation", {"scene": s}, (mesh.key,), f"navigation s{s}")
        jobs += [mesh, nav]
        scene.append((mesh, nav))
    exports = []
    for n in range(shards):
        mesh, nav = scene[n % scenes]
        tag = f"train/s{n % scenes}#{n}"
        placement = Job("placement", {"shard": n}, (nav.key,), f"placement {tag}")
        arrange = Job("arrange", {"shard": n}, (corpus.key,), f"arrange {tag}")
        rir = Job("rir", {"shard": n}, (mesh.key, placement.key), f"rir {tag}")
        render = Job("render", {"shard": n}, (rir.key, arrange.key, placement.key, corpus.key),
                     f"render {tag}")
        mix = Job("mix", {"shard": n}, (render.key,), f"mix {tag}")
        export = Job("export", {"shard": n},
                     (mix.key, render.key, rir.key, arrange.key, placement.key), f"export {tag}")
        jobs += [placement, arrange, rir, render, mix, export]
        exports.append(export.key)
    jobs.append(Job("dataset", {"name": "t"}, (corpus.key, *exports), "dataset"))
    return Plan("t", 1, str(folder / "store"), str(folder / "out"), "0" * 64, tuple(jobs))


def _dry_run_counts(plan: Plan, plan_path: Path, layout: Path
                    ) -> tuple[dict[str, int], subprocess.CompletedProcess]:
    """Snakemake's dry run of a batched plan: its job counts per rule."""
    Path(plan.store_dir).mkdir(parents=True, exist_ok=True)
    cmd = snakemake_command(plan_path, plan, cores=1, profile=None, dry_run=True, layout=layout)
    done = subprocess.run(cmd, cwd=plan.store_dir, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    counts = {}
    for line in (done.stdout + done.stderr).splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[1].isdigit():
            counts[parts[0]] = int(parts[1])
    return counts, done


def test_every_shard_job_is_in_exactly_one_batch(tmp_path: Path) -> None:
    plan = synthetic_plan(tmp_path, shards=10)
    chains = shard_chains(plan)
    assert len(chains) == 10 and all(len(c) == 6 for c in chains)
    batches = batch_plan(plan, 4)
    assert [len(b.members) for b in batches] == [24, 24, 12]
    members = [k for b in batches for k in b.members]
    shard_jobs = [j.key for j in plan.jobs if j.step in BATCHED_STEPS]
    assert members == shard_jobs  # each once, in plan order
    inside = set(members)
    outside = {j.key for j in plan.jobs if j.step not in BATCHED_STEPS}
    for batch in batches:
        assert set(batch.inputs) <= outside and not set(batch.inputs) & inside
        # members run one at a time: the largest step's request, not their sum
        assert batch.mem_mb == max(STEP_BY_NAME[s].mem_mb for s in BATCHED_STEPS)
    assert batches[0].label == "batch train/s0#0 .. train/s0#3"
    assert batch_plan(plan, 0) == []
    with pytest.raises(CompileError, match="shards per batch"):
        batch_plan(plan, -1)
    # the key names the member set: another grouping is another batch
    assert {b.key for b in batch_plan(plan, 5)}.isdisjoint(b.key for b in batches)


def test_a_large_plan_shows_snakemake_a_bounded_job_count(tmp_path: Path) -> None:
    """Past AUTO_MIN_JOBS, a build batches by itself: Snakemake sees about AUTO_TARGET batches
    however many shards, plus the scene, corpus and dataset jobs."""
    shards = AUTO_MIN_JOBS // 6 + 1_000
    plan = synthetic_plan(tmp_path, shards=shards)
    assert len(plan.jobs) > AUTO_MIN_JOBS
    assert auto_shards_per_batch(synthetic_plan(tmp_path, shards=100)) == 0
    n = auto_shards_per_batch(plan)
    assert n == -(-shards // AUTO_TARGET) == 2
    batches = batch_plan(plan, n)
    assert len(batches) <= AUTO_TARGET
    plan_path = plan.write(tmp_path / "plan.json")
    layout_path = write_layout(plan, plan_path, batches, tmp_path / "layout.json")
    workflow = WorkflowPlan.load(plan_path, layout_path)
    assert isinstance(workflow, BatchedWorkflowPlan)
    scene_jobs = 1 + 2 * 3 + 1
    assert len(workflow.layout.units) == len(batches) + scene_jobs < len(plan.jobs) / 10
    # the dataset's inputs are the batches' markers; it is the one final artifact
    dataset = plan.jobs[-1]
    assert workflow.final_artifacts() == [workflow.artifact("dataset", dataset.key)]
    inputs = workflow.layout.units[dataset.key]["inputs"]
    assert len(inputs) == len(batches) + 1
    assert inputs[1:] == [str(marker_path(plan.store_dir, b.key)) for b in batches]
    assert read_batch(layout_path, batches[7].key)["members"] == list(batches[7].members)


def test_a_batch_reads_its_excerpt_of_the_plan(tmp_path: Path) -> None:
    plan = synthetic_plan(tmp_path, shards=6)
    path = plan.write(tmp_path / "plan.json")
    batch = batch_plan(plan, 2)[1]
    part = Plan.read_jobs(path, batch.members)
    keys = [j.key for j in part.jobs]
    assert set(keys) == set(batch.members) | set(batch.inputs)
    assert keys[-len(batch.members):] == list(batch.members)
    with pytest.raises(CompileError, match="no job with key 000000000000"):
        Plan.read_jobs(path, [batch.members[0], "0" * 64])


def test_markers_follow_the_store(tmp_path: Path) -> None:
    plan = synthetic_plan(tmp_path, shards=4)
    batches = batch_plan(plan, 2)
    first, second = batches
    stale = marker_path(plan.store_dir, second.key)
    stale.parent.mkdir(parents=True)
    stale.write_text("{}")
    assert refresh_markers(plan.store_dir, batches, set(first.members)) == 1
    assert marker_path(plan.store_dir, first.key).is_file()  # complete: no job needed
    assert not stale.exists()  # a member missing: the batch runs again


def test_a_failed_batch_names_its_failed_member(tmp_path: Path) -> None:
    plan = synthetic_plan(tmp_path, shards=2)
    batch = batch_plan(plan, 2)[0]
    rir = next(j for j in plan.jobs if j.step == "rir")
    member_log = tmp_path / "store" / "logs" / "rir" / rir.key[:2] / f"{rir.key}.log"
    member_log.parent.mkdir(parents=True)
    member_log.write_text("INFO starting\nERROR rir train/s0#0: the mesh leaks\n")
    batch_log = tmp_path / "store" / "logs" / "batch" / batch.key[:2] / f"{batch.key}.log"
    batch_log.parent.mkdir(parents=True)
    batch_log.write_text(f"2026 ERROR job failed: {rir.key} rir train/s0#0 log: {member_log}\n")
    snakemake_log = (f"Error in rule batch:\n    jobid: 3\n    log: {batch_log} (check log "
                     "file(s) for error details)\n")
    assert failed_jobs(snakemake_log, plan) == ["rir train/s0#0"]
    (message,) = failed_job_messages(snakemake_log, plan)
    assert message.startswith(f"rir train/s0#0 ({rir.key[:12]}) failed")
    assert "the mesh leaks" in message


def test_snakemake_runs_batches_not_shard_jobs(tmp_path: Path) -> None:
    """Snakemake's own dry run of a batched plan: one job per batch, none per shard step."""
    plan = synthetic_plan(tmp_path, shards=12)
    plan_path = plan.write(tmp_path / "plan.json")
    layout = write_layout(plan, plan_path, batch_plan(plan, 4), tmp_path / "layout.json")
    counts, done = _dry_run_counts(plan, plan_path, layout)
    assert counts == {"batch": 3, "corpus": 1, "dataset": 1, "mesh": 3, "navigation": 3,
                      "all": 1, "total": 12}, done.stdout[-2000:]


def test_snakemake_runs_only_the_batches_without_their_marker(tmp_path: Path) -> None:
    """Markers the build wrote (no Snakemake records for them, as after an unbatched build)
    count as done: Snakemake runs the one batch missing a member, and the dataset."""
    plan = synthetic_plan(tmp_path, shards=12)
    batches = batch_plan(plan, 4)
    workflow_files = []
    for job in plan.jobs:
        if job.step not in BATCHED_STEPS and job.step != "dataset":
            path = Path(WorkflowPlan(plan, tmp_path / "plan.json").artifact(job.step, job.key))
            path.parent.mkdir(parents=True)
            path.write_text("{}")
            workflow_files.append(path)
    present = {k for b in batches for k in b.members} - {batches[1].members[3]}
    assert refresh_markers(plan.store_dir, batches, present) == 2
    plan_path = plan.write(tmp_path / "plan.json")
    layout = write_layout(plan, plan_path, batches, tmp_path / "layout.json")
    counts, done = _dry_run_counts(plan, plan_path, layout)
    assert counts == {"batch": 1, "dataset": 1, "all": 1, "total": 3}, done.stdout[-2000:]
