"""A build's check before it runs, and the head's events, without a build (issue 27): unchanged
artifacts are recognised from fingerprints without reading their JSON, and what moved is read
and checked as before."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from sonicspec.artifacts.records import FileRecord
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
                data={"groups": [{"group": "train/0", "split": "train", "scene_id": "room",
                                  "metadata": {"path": None}, "files": [record],
                                  "recordings": [{"tracks": [0.5] * 100}],
                                  "supervisions": [], "duration_s": 1.0}]})
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


def test_an_export_record_that_does_not_read_is_made_again(tmp_path: Path) -> None:
    plan, store, _ = built(tmp_path)
    export = plan.jobs[1]
    store.remove("export", export.key)
    store.write("export", export.key, {"peak": np.ones(1)},
                data={"groups": [{"group": "train/0", "files": [{"path": "train/0.flac",
                                                                 "size": 500}]}]})
    report = check(plan, store)
    assert [f.job.key for f in report.findings] == [export.key]
    assert "export artifact does not read" in report.findings[0].problem
    assert not store.exists("export", export.key)


def test_checked_json_reads_and_writes_back_the_same_bytes(tmp_path: Path) -> None:
    plan, store, _ = built(tmp_path)
    check(plan, store)
    cache_file = CheckCache.of_store(plan.store_dir).path
    before = cache_file.read_bytes()
    assert b'"written"' in before and b'"train/0.flac",500,' in before
    cache = CheckCache.of_store(plan.store_dir)
    cache._dirty = True  # force the write
    cache.save()
    assert cache_file.read_bytes() == before
    cache_file.write_text('{"artifacts": {"k": 3}, "files": {}}')  # not this version's: reset
    assert CheckCache.of_store(plan.store_dir).artifact_ok("k", "3") is False


def test_a_file_record_leaves_out_what_it_does_not_carry() -> None:
    own = FileRecord(path="dataset.json", sha256="0" * 64, bytes=12)
    assert own.model_dump(mode="json") == {"path": "dataset.json", "sha256": "0" * 64,
                                           "bytes": 12}
    audio = {"kind": "speech", "name": "source1", "path": "train/0/source1.flac",
             "sha256": "1" * 64, "bytes": 9, "channels": 2, "num_samples": 16000,
             "sample_rate_hz": 16000, "scale": 0.25}
    assert FileRecord.model_validate(audio).model_dump(mode="json") == audio
    with pytest.raises(ValidationError, match="size"):
        FileRecord.model_validate({"path": "a.flac", "size": 3})
