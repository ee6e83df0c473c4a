"""A build's check before it runs, and the head's events, without a build (issue 27): unchanged
artifacts are recognised from fingerprints without reading their JSON, and what moved is read
and checked as before."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from sonicspec.plan.model import Job, Plan
from sonicspec.stages.checked import CheckCache
from sonicspec.stages.context import finished_dir, mark_finished
from sonicspec.stages.repair import check_existing
from sonicspec.stages.workflow import take_finished
from sonicspec.store import ArtifactStore


def built(tmp_path: Path) -> tuple[Plan, ArtifactStore, Path]:
    """A placement and an export artifact; the export records one dataset file."""
    placement = Job("placement", {"groups": ["train/0"]}, (), "placement 0")
    export = Job("export", {"groups": ["train/0"]}, (placement.key,), "export train/0")
    plan = Plan("t", 1, str(tmp_path / "store"), str(tmp_path / "out"), "0" * 64,
                (placement, export))
    store = ArtifactStore(plan.store_dir)
    body = b"audio" * 100
    out = Path(plan.output_dir)
    (out / "train").mkdir(parents=True)
    (out / "train" / "0.flac").write_bytes(body)
    record = {"path": "train/0.flac", "bytes": len(body),
              "sha256": hashlib.sha256(body).hexdigest()}
    store.write("placement", placement.key, {"mic": np.zeros(3)})
    store.write("export", export.key, {"peak": np.ones(1)},
                data={"groups": [{"id": "train/0", "files": [record], "tracks": [0.5] * 100}]})
    return plan, store, out


def check(plan: Plan, store: ArtifactStore):
    cache = CheckCache.of_store(plan.store_dir)
    report = check_existing(plan, store, cache)
    cache.save()
    return report


def test_an_unchanged_store_is_checked_without_reading_any_artifact(tmp_path: Path) -> None:
    plan, store, _ = built(tmp_path)
    first = check(plan, store)
    assert (first.artifacts_verified, first.records_read, first.files_hashed) == (2, 1, 1)
    cache_file = CheckCache.of_store(plan.store_dir).path
    written = cache_file.stat().st_mtime_ns
    again = check(plan, store)
    assert again.findings == []
    assert (again.artifacts_verified, again.records_read, again.files_hashed) == (0, 0, 0)
    assert again.files_checked == 1
    assert cache_file.stat().st_mtime_ns == written  # nothing changed: not rewritten


def test_a_changed_dataset_file_is_found_from_the_cached_records(tmp_path: Path) -> None:
    plan, store, out = built(tmp_path)
    check(plan, store)
    path = out / "train" / "0.flac"
    st = path.stat()
    path.write_bytes(b"AUDIO" * 100)  # same size, other bytes
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    report = check(plan, store)
    assert report.records_read == 0
    assert [f.problem for f in report.findings] == [
        "dataset file train/0.flac differs from what the build wrote"]
    assert not store.exists("export", plan.jobs[1].key)  # removed, to be made again


def test_an_artifact_that_moved_is_read_again(tmp_path: Path) -> None:
    plan, store, _ = built(tmp_path)
    check(plan, store)
    meta = store.path("export", plan.jobs[1].key) / "zarr.json"
    st = meta.stat()
    os.utime(meta, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    report = check(plan, store)
    assert (report.artifacts_verified, report.records_read) == (1, 1)
    assert report.findings == []


def test_the_head_takes_each_finished_job_once(tmp_path: Path) -> None:
    keys = [f"{n:064x}" for n in range(3)]
    assert take_finished(finished_dir(tmp_path)) == []  # no folder yet
    for key in keys:
        mark_finished(tmp_path, key)
    assert sorted(take_finished(finished_dir(tmp_path))) == keys
    assert take_finished(finished_dir(tmp_path)) == []
    mark_finished(tmp_path, keys[0])
    assert take_finished(finished_dir(tmp_path)) == [keys[0]]
