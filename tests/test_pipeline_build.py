"""Builds through Snakemake: identical bytes twice, resume after a kill, verify, SLURM.

Each build is the demo spec cut down (4 groups in 3 shards, a cheaper tracer), end to end:
corpora generated with espeak-ng, RIRs, rendering, mixing, export and manifests.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sonicspec.plan.compile import compile_spec
from sonicspec.plan.model import Plan
from sonicspec.spec import load_spec
from sonicspec.stages import STAGES
from sonicspec.stages.workflow import run_build
from sonicspec.store import ArtifactStore

ROOT = Path(__file__).resolve().parents[1]


def write_spec(tmp: Path) -> Path:
    """The demo spec, smaller and with a cheaper tracer (the machinery, not the physics, is
    under test)."""
    text = (ROOT / "specs" / "demo.yaml").read_text()
    for old, new in (("rays: 4000", "rays: 600"), ("max_rir_length_s: 1.0",
                                                   "max_rir_length_s: 0.4"),
                     ("train: {groups: 4,", "train: {groups: 2,"),
                     ("speakers_per_split: 3, utterances_per_speaker: 4",
                      "speakers_per_split: 2, utterances_per_speaker: 2")):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp / "demo.yaml"
    path.write_text(text)
    return path


def plan_for(spec: Path) -> Plan:
    plan = compile_spec(load_spec(spec))
    assert {j.step for j in plan.jobs} <= set(STAGES)
    return plan


def store_digest(store: Path) -> dict[str, str]:
    """SHA-256 of every artifact file (logs, benchmarks, plans and Snakemake state excluded)."""
    out = {}
    for p in sorted(store.rglob("*")):
        rel = p.relative_to(store)
        if p.is_file() and rel.parts[0] not in ("logs", "benchmarks", "plans", ".snakemake",
                                                "cache"):
            out[str(rel)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def build_digest(plan: Plan) -> dict[str, str]:
    """Digests of the store's artifacts and of every file of the dataset folder."""
    out = {f"store/{k}": v for k, v in store_digest(Path(plan.store_dir)).items()}
    folder = Path(plan.output_dir)
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            out[f"out/{p.relative_to(folder)}"] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[Plan, dict[str, str]]:
    """One finished build of the test spec and its digests, shared by the tests below."""
    folder = tmp_path_factory.mktemp("reference")
    plan = plan_for(write_spec(folder))
    assert run_build(plan, cores=2) == 0
    return plan, build_digest(plan)


def test_two_builds_from_empty_stores_are_byte_identical(reference, tmp_path: Path) -> None:
    plan = plan_for(write_spec(tmp_path))
    assert run_build(plan, cores=2) == 0
    assert ArtifactStore(plan.store_dir).verify({j.key: j.step for j in plan.jobs}) == []
    digest = build_digest(plan)
    assert digest == reference[1]
    out = [k for k in digest if k.startswith("out/")]
    # 4 groups x (2 sources, noise, music, 3 mixtures, metadata), dataset.json, 6 manifests.
    assert len(out) == 4 * 8 + 1 + 6, out


def test_killed_build_resumes_to_the_same_result(reference, tmp_path: Path) -> None:
    expected = reference[1]
    killed = tmp_path / "killed"
    killed.mkdir()
    plan = plan_for(write_spec(killed))
    store = ArtifactStore(plan.store_dir)
    procs: list[subprocess.Popen] = []

    def kill_when_some_done(proc: subprocess.Popen) -> None:
        procs.append(proc)

    import threading

    def killer() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            done = sum(store.exists(j.step, j.key) for j in plan.jobs)
            if 0 < done < len(plan.jobs) and procs:
                procs[0].send_signal(signal.SIGKILL)
                subprocess.run(["pkill", "-9", "-f", f"sonicspec job --plan {plan.store_dir}"],
                               check=False)
                return
            time.sleep(0.05)

    thread = threading.Thread(target=killer)
    thread.start()
    code = run_build(plan, cores=1, poll_s=0.2, on_start=kill_when_some_done)
    thread.join()
    assert code != 0
    done = sum(store.exists(j.step, j.key) for j in plan.jobs)
    assert 0 < done < len(plan.jobs)
    assert store.verify() == [] or all("temporary" in p.problem for p in store.verify())
    assert run_build(plan, cores=1) == 0
    assert store.temp_folders() == []
    assert build_digest(plan) == expected
    leftovers = [p for p in Path(plan.output_dir).rglob(".*tmp*")]
    assert leftovers == []


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
