"""Builds through Snakemake: identical bytes twice, verify, SLURM (kills and other faults:
test_pipeline_trust.py).

Each build is the demo spec cut down (4 groups in 3 shards, a cheaper tracer), end to end:
corpora generated with espeak-ng, RIRs, rendering, mixing, export and manifests.
"""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from build_cases import ROOT, build_digest, plan_for, write_spec

from sonicspec.plan.model import Plan
from sonicspec.stages.workflow import build, run_build
from sonicspec.store import ArtifactStore


@pytest.fixture(scope="module")
def reference(demo_reference) -> tuple[Plan, dict[str, str]]:
    """One finished build of the test spec and its digests (conftest's, made once per session
    by another process or this one), shared by the tests below; read-only."""
    folder, digest = demo_reference
    return plan_for(folder / "demo.yaml"), digest


def test_two_builds_from_empty_stores_are_byte_identical(reference, tmp_path: Path) -> None:
    plan = plan_for(write_spec(tmp_path))
    assert run_build(plan, cores=2) == 0
    assert ArtifactStore(plan.store_dir).verify({j.key: j.step for j in plan.jobs}) == []
    digest = build_digest(plan)
    assert digest == reference[1]
    out = [k for k in digest if k.startswith("out/")]
    # 4 groups x (2 sources, noise, music, 3 mixtures, metadata, tracks), dataset.json,
    # 6 manifests, checksums.sha256 and the folder's marker.
    assert len(out) == 4 * 9 + 1 + 6 + 2, out


def test_verify_command_catches_a_damaged_artifact(reference, tmp_path: Path) -> None:
    plan = reference[0]
    shutil.copytree(plan.store_dir, tmp_path / "store")
    store = ArtifactStore(tmp_path / "store")
    job = next(j for j in plan.jobs if j.step == "mesh")
    chunk = next(p for p in (store.path("mesh", job.key) / "vertices").rglob("*")
                 if p.is_file() and p.name != "zarr.json")
    chunk.write_bytes(chunk.read_bytes()[:-7])
    result = subprocess.run([sys.executable, "-m", "sonicspec.cli", "verify", str(store.root)],
                            capture_output=True, text=True)
    assert result.returncode == 1
    assert f"mesh {job.key}" in result.stderr and "1 problem" in result.stderr


@pytest.mark.skipif(os.geteuid() != 0, reason="the test SLURM cluster needs root")
def test_slurm_build_gives_the_same_bytes(reference, tmp_path: Path) -> None:
    from sonicspec.testing.slurm import SlurmUnavailable, single_node_slurm

    expected = reference[1]
    cluster = tmp_path / "cluster"
    cluster.mkdir()
    plan = plan_for(write_spec(cluster))
    try:
        with single_node_slurm(tmp_path / "slurm"):
            code = run_build(plan, cores=2, profile=ROOT / "workflow/profiles/slurm",
                             snakemake_args=["--slurm-init-seconds-before-status-checks", "2",
                                             "--seconds-between-status-checks", "2",
                                             "--latency-wait", "5"])
    except SlurmUnavailable as exc:
        pytest.skip(str(exc))
    assert code == 0
    assert build_digest(plan) == expected
    # The profile groups jobs (several per SLURM job): the bytes are those of ungrouped jobs.
    log = max((Path(plan.store_dir) / "logs").glob("snakemake-*.log")).read_text()
    assert "Group job rir" in log and "Group job shard" in log, log[-3000:]
    submitted = log.count("submitted with SLURM jobid")
    assert 0 < submitted < len(plan.jobs), submitted


@pytest.mark.skipif(os.geteuid() != 0, reason="the test SLURM cluster needs root")
def test_slurm_batched_build_gives_the_same_bytes(reference, tmp_path: Path) -> None:
    """Batches through the SLURM profile (its groups name rules a batched build still has):
    one SLURM job per batch, the bytes of a local unbatched build."""
    from sonicspec.testing.slurm import SlurmUnavailable, single_node_slurm

    cluster = tmp_path / "cluster"
    cluster.mkdir()
    plan = plan_for(write_spec(cluster))
    try:
        with single_node_slurm(tmp_path / "slurm"):
            result = build(plan, cores=2, profile=ROOT / "workflow/profiles/slurm",
                           shards_per_batch=2, stream=io.StringIO(),
                           snakemake_args=["--slurm-init-seconds-before-status-checks", "2",
                                           "--seconds-between-status-checks", "2",
                                           "--latency-wait", "5"])
    except SlurmUnavailable as exc:
        pytest.skip(str(exc))
    assert result.code == 0
    assert _without_markers(build_digest(plan)) == reference[1]
    assert result.jobs_run == len(plan.jobs)
    log = max((Path(plan.store_dir) / "logs").glob("snakemake-*.log")).read_text()
    assert "rule batch:" in log and "rule render:" not in log, log[-3000:]


def test_a_cold_numba_cache_elsewhere_builds_the_same_bytes(reference, tmp_path: Path,
                                                            monkeypatch) -> None:
    """The kernels' cache goes where SONICSPEC_NUMBA_CACHE_DIR says, is compiled there once
    before the jobs (the warm stamp), and the bytes do not change."""
    import sonicspec
    from sonicspec.stages.warm import _stamp

    cache = tmp_path / "numba"
    monkeypatch.setenv("SONICSPEC_NUMBA_CACHE_DIR", str(cache))
    assert sonicspec.numba_cache_dir() == str(cache)
    source = Path(sonicspec.__file__).parent
    before = {p: p.stat().st_mtime_ns for p in source.rglob("*.nbi")}
    folder = tmp_path / "cold"
    folder.mkdir()
    plan = plan_for(write_spec(folder))
    assert run_build(plan, cores=2) == 0
    assert build_digest(plan) == reference[1]
    assert _stamp().is_file() and _stamp().parent == cache
    assert list(cache.rglob("*.nbi")), "nothing compiled into the redirected cache"
    assert {p: p.stat().st_mtime_ns for p in source.rglob("*.nbi")} == before


def _without_markers(digest: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in digest.items() if not k.startswith("store/batches/")}


def test_batched_build_gives_the_same_bytes_and_resumes(reference, tmp_path: Path) -> None:
    """Shards run in batches (one Snakemake job per batch): the same artifacts and dataset
    bytes as one Snakemake job per step and shard; a batch missing a member runs again and
    makes only what is missing."""
    plan = plan_for(write_spec(tmp_path))
    stream = io.StringIO()
    result = build(plan, cores=2, shards_per_batch=2, stream=stream)
    assert result.code == 0, stream.getvalue()[-3000:]
    shards = len(plan.by_step()["export"])
    batches = -(-shards // 2)
    assert f"batched: {batches} Snakemake jobs of 2 shards each (0 complete)" in stream.getvalue()
    # every job counted as run, the batches' members from their finished markers
    assert result.jobs_run == len(plan.jobs), result.ran
    log = max((Path(plan.store_dir) / "logs").glob("snakemake-*.log")).read_text()
    assert log.count("rule batch:") == batches and "rule render:" not in log, log[-3000:]
    digest = build_digest(plan)
    assert _without_markers(digest) == reference[1]
    assert len(digest) - len(_without_markers(digest)) == batches
    # A render lost: its shard's batch runs again, remaking it and what follows from it only.
    render = plan.by_step()["render"][-1]
    ArtifactStore(plan.store_dir).remove("render", render.key)
    stream = io.StringIO()
    again = build(plan, cores=2, shards_per_batch=2, stream=stream)
    assert again.code == 0, stream.getvalue()[-3000:]
    assert f"({batches - 1} complete)" in stream.getvalue()
    assert {s: n for s, n in again.ran.items() if n} == {
        "render": 1, "mix": 1, "export": 1, "dataset": 1}, again.ran
    assert _without_markers(build_digest(plan)) == reference[1]
