"""The dataset step streams (issue 27): its memory does not grow with the groups, its outputs are
what the whole-in-memory step wrote, and a failure leaves no half file under a final name.

The inputs are synthetic export records of SonicSet-preset groups
(:mod:`sonicspec.testing.scale`; ``bench/bench_scale.py`` measures the same at 10^2–10^4).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sonicspec.artifacts.records import FileRecord
from sonicspec.errors import StageError
from sonicspec.export.checksums import checksums_text, file_record
from sonicspec.export.manifests import csv_text, jsonl
from sonicspec.plan.model import Plan
from sonicspec.stages import dataset as dataset_stage
from sonicspec.stages import run_job
from sonicspec.store import ArtifactStore
from sonicspec.testing.scale import measure_dataset_job, write_dataset_inputs


def _whole_in_memory(plan: Plan, key: str) -> dict[str, str]:
    """The manifests and checksums as the step wrote them before it streamed (346f31f): every
    record at once, sorted by group, each file one string."""
    store = ArtifactStore(plan.store_dir)
    job = plan.by_key()[key]
    exports = [store.read_data("export", k) for k in job.inputs]
    groups = sorted((g for e in exports for g in e["groups"]), key=lambda g: g["group"])
    by_split: dict[str, list] = {}
    for g in groups:
        by_split.setdefault(g["split"], []).append(g)
    out = {}
    for split, items in sorted(by_split.items()):
        out[f"manifests/{split}_recordings.jsonl"] = jsonl(
            [r for g in items for r in g["recordings"]])
        out[f"manifests/{split}_supervisions.jsonl"] = jsonl(
            [s for g in items for s in g["supervisions"]])
        out[f"manifests/{split}.csv"] = csv_text(
            [dict(f, split=split, group=g["group"]) for g in items for f in g["files"]],
            dataset_stage.CSV_COLUMNS)
    out["groups"] = [{"group": g["group"], "split": g["split"], "scene_id": g["scene_id"],
                      "metadata": g["metadata"]} for g in groups]
    out["files"] = [f for g in groups for f in g["files"]]
    out["hours"] = round(sum(g["duration_s"] for g in groups) / 3600.0, 6)
    return out


def test_streamed_outputs_are_what_the_whole_in_memory_step_wrote(tmp_path: Path) -> None:
    plan_file, key = write_dataset_inputs(tmp_path, 23, groups_per_shard=4)
    plan = Plan.read(plan_file)
    assert run_job(plan, key)
    out = Path(plan.output_dir)
    expected = _whole_in_memory(plan, key)
    for rel in ("manifests/train_recordings.jsonl", "manifests/train_supervisions.jsonl",
                "manifests/train.csv"):
        assert (out / rel).read_text() == expected[rel], rel
    summary = json.loads((out / "dataset.json").read_text())
    assert summary["groups"] == expected["groups"]  # in group order, shards interleaved
    assert [g["group"] for g in summary["groups"]] == [f"train/{i:06d}" for i in range(23)]
    assert summary["splits"] == {"train": {"groups": 23, "files": len(expected["files"]),
                                           "audio_hours": expected["hours"]}}
    assert summary["manifests"] == ["manifests/train_recordings.jsonl",
                                    "manifests/train_supervisions.jsonl", "manifests/train.csv"]
    own = [file_record(out, out / rel) for rel in [*summary["manifests"], "dataset.json"]]
    recorded = [FileRecord.model_validate(f) for f in expected["files"]]
    assert (out / "checksums.sha256").read_text() == checksums_text(recorded + own)
    assert not [p for p in out.rglob("*") if ".tmp-" in p.name]
    assert not [p for p in Path(plan.store_dir).iterdir() if p.name.startswith(".tmp-")]


def test_a_failure_midway_leaves_no_half_file(tmp_path: Path, monkeypatch) -> None:
    plan_file, key = write_dataset_inputs(tmp_path, 6, groups_per_shard=2)
    plan = Plan.read(plan_file)
    calls = []

    def failing(item):
        calls.append(item)
        if len(calls) > 40:
            raise OSError(28, "No space left on device")
        return json.dumps(item, sort_keys=True) + "\n"

    monkeypatch.setattr(dataset_stage, "jsonl_line", failing)
    with pytest.raises(StageError, match="dataset"):
        run_job(plan, key)
    out = Path(plan.output_dir)
    assert len(calls) > 40
    assert not out.exists() or not [p for p in out.rglob("*") if p.is_file()]


def test_an_export_record_that_does_not_read_names_its_group(tmp_path: Path) -> None:
    plan_file, key = write_dataset_inputs(tmp_path, 4, groups_per_shard=2)
    plan = Plan.read(plan_file)
    store = ArtifactStore(plan.store_dir)
    export_key = next(k for k in plan.by_key()[key].inputs if store.exists("export", k))
    art = store.read("export", export_key)
    data = json.loads(json.dumps(art.data))
    del data["groups"][1]["duration_s"]
    store.remove("export", export_key)
    store.write("export", export_key, art.arrays, data=data, params={})
    group = data["groups"][1]["group"]
    with pytest.raises(StageError, match=rf"group {group} does not read \(duration_s: Field "
                                         r"required\)"):
        run_job(plan, key)


@pytest.mark.slow
def test_peak_memory_at_ten_times_the_groups_is_within_one_and_a_half_times(
        tmp_path: Path) -> None:
    """A bench-backed bound (``bench/bench_scale.py --only dataset``), not a timing: the peak
    RSS of the dataset job's process on 200 groups is within 1.5x of that on 20 (before it
    streamed: +15.6 MB per group, 3 GB more at 200)."""
    peaks = {}
    for n in (20, 200):
        plan_file, key = write_dataset_inputs(tmp_path / str(n), n)
        peaks[n] = measure_dataset_job(plan_file, key)["peak_rss_mb"]
        assert json.loads((tmp_path / str(n) / "out" / "dataset.json").read_text())[
            "splits"]["train"]["groups"] == n
    assert peaks[200] <= 1.5 * peaks[20], peaks
