"""Stage ``dataset``: ``dataset.json``, the manifests and ``checksums.sha256``, from every export
job's record."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sonicspec import __version__
from sonicspec.atomic import write_text
from sonicspec.export.checksums import CHECKSUMS_NAME, file_record, write_checksums
from sonicspec.export.files import write_json
from sonicspec.export.manifests import csv_text, jsonl
from sonicspec.plan.params import DatasetParams
from sonicspec.stages.context import JobContext
from sonicspec.stages.corpus import corpus_role

CSV_COLUMNS = ("split", "group", "kind", "name", "path", "channels", "num_samples",
               "sample_rate_hz")


def run(ctx: JobContext) -> None:
    params: DatasetParams = ctx.params
    out = Path(ctx.plan.output_dir)
    exports: list[dict[str, Any]] = ctx.input_data("export")
    groups = sorted((g for e in exports for g in e["groups"]), key=lambda g: g["group"])
    files_written: list[str] = []
    by_split: dict[str, list[dict[str, Any]]] = {}
    for g in groups:
        by_split.setdefault(g["split"], []).append(g)
    for split, items in sorted(by_split.items()):
        recordings = [r for g in items for r in g["recordings"]]
        supervisions = [s for g in items for s in g["supervisions"]]
        if "lhotse" in params.manifests:
            for name, rows in (("recordings", recordings), ("supervisions", supervisions)):
                path = out / "manifests" / f"{split}_{name}.jsonl"
                write_text(path, jsonl(rows))
                files_written.append(str(path.relative_to(out)))
        if "csv" in params.manifests:
            rows = [dict(f, split=split, group=g["group"]) for g in items for f in g["files"]]
            path = out / "manifests" / f"{split}.csv"
            scaled = params.spec.outputs.scale == "per_file"  # a column: the file's scale
            write_text(path, csv_text(rows, (*CSV_COLUMNS, "scale") if scaled else CSV_COLUMNS))
            files_written.append(str(path.relative_to(out)))
    counts = {split: {"groups": len(items),
                      "files": sum(len(g["files"]) for g in items),
                      "audio_hours": round(sum(g["duration_s"] for g in items) / 3600.0, 6)}
              for split, items in sorted(by_split.items())}
    jobs = ctx.plan.by_key()
    skipped = {corpus_role(jobs[k]): ctx.store.read_data("corpus", k).get("skipped", [])
               for k in ctx.input_keys("corpus")}
    spec = params.spec.model_dump(mode="json")
    summary = {
        "corpus_files_skipped": {role: {"count": len(files), "files": files}
                                 for role, files in sorted(skipped.items())},
        "name": params.spec.name,
        "description": params.spec.description,
        "sonicspec_version": __version__,
        "spec_version": params.spec.sonicspec,
        "spec": spec,
        "splits": counts,
        "groups": [{"group": g["group"], "split": g["split"], "scene_id": g["scene_id"],
                    "metadata": g["metadata"]} for g in groups],
        "manifests": files_written,
    }
    write_json(out / "dataset.json", summary)
    own = [file_record(out, out / rel) for rel in [*files_written, "dataset.json"]]
    write_checksums(out, [f for g in groups for f in g["files"]] + own)
    ctx.write({"group_count": np.array([len(groups)], dtype=np.int64)},
              {"dataset_json": "dataset.json", "manifests": files_written,
               "splits": counts, "files": [*own, file_record(out, out / CHECKSUMS_NAME)]})
