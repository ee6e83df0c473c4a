"""Builds several test files share: made once per test session, even across pytest-xdist
workers (the first worker to ask builds under a file lock; the others wait for it and read the
same folder).

A shared folder is read-only for the tests: a test that damages, edits or rebuilds copies it
first (``shutil.copytree(folder, tmp_path / ..., symlinks=True)``; a copied build works where it
is copied, as ``test_pipeline_trust``'s ``copy`` fixture shows).
"""

from __future__ import annotations

import fcntl
import io
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from build_cases import build_digest, plan_for, write_spec

# The test files that take longest, longest first (measured with `--durations=0`, summed per
# file by bench/bench_test_durations.py). CI runs `--dist loadfile --no-loadscope-reorder`:
# each file on one worker, files handed out in collection order, so these start first and no
# long file is left to run alone at the end (xdist's default order, most tests first, put
# the long build files with few tests last). Files not named keep their collection order.
SLOW_FIRST: list[str] = [
    "test_pipeline_trust.py",  # builds the shared demo (conftest's demo_reference) ...
    "test_dataload.py",  # ... while the other worker builds the dataload dataset
    "test_trust_round2.py",
    "test_pipeline_build.py",
    "test_audio_scale.py",
    "test_report_browser.py",
    "test_pipeline_capsules.py",
    "test_pipeline_augment.py",
    "test_pipeline_motion.py",
    "test_sonicset_realistic.py",
    "test_sonicset_preset.py",
    "test_docs.py",
]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: files stay whole


def shared_folder(factory: pytest.TempPathFactory, name: str,
                  make: Callable[[Path], None]) -> Path:
    """``make(folder)`` run once per session (across xdist workers): the folder it filled.

    A make that fails leaves no done marker, so the next worker to ask tries again and fails
    with its own error (no test reads a half-built folder)."""
    root = factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above each worker's popen-gwN
    folder, done = root / f"shared-{name}", root / f"shared-{name}.done"
    with open(root / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not done.exists():
                shutil.rmtree(folder, ignore_errors=True)  # an earlier attempt that failed
                folder.mkdir()
                make(folder)
                done.touch()
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return folder


def _build_demo(folder: Path) -> None:
    from sonicspec.stages.workflow import build

    plan = plan_for(write_spec(folder))
    assert build(plan, cores=2, stream=io.StringIO()).code == 0


@pytest.fixture(scope="session")
def demo_reference(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """The cut-down demo of ``build_cases.write_spec`` built once through Snakemake (its folder:
    ``demo.yaml``, the store and the dataset folder under ``out/``) and its digests. Read-only:
    copy it before changing anything."""
    folder = shared_folder(tmp_path_factory, "demo", _build_demo)
    return folder, build_digest(plan_for(folder / "demo.yaml"))


def _build_dataload(folder: Path) -> None:
    from dataload_cases import build_dataset

    build_dataset(folder)


@pytest.fixture(scope="session")
def dataload_reference(tmp_path_factory) -> Path:
    """The small dataset of ``dataload_cases.build_dataset`` built once (its folder:
    ``demo.yaml``, the store and ``out/demo`` with its exports beside it). Read-only: copy it
    before changing anything."""
    return shared_folder(tmp_path_factory, "dataload", _build_dataload)
