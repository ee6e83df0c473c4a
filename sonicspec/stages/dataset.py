"""Stage ``dataset``: ``dataset.json``, the manifests and ``checksums.sha256``, from every export
job's record — streamed, one group at a time.

Memory does not grow with the dataset (DESIGN.md §6, "every step streams"): the export
records are read one at a time and each group's record is copied as one line into a spool
file (an unlinked temporary file in the store, gone when the job ends, however it ends),
remembering only where each group's line starts. The groups are then read back in group
order (shards of different scenes interleave in it) and every output is written as it goes:
the Lhotse JSONL and CSV manifests of each split, ``dataset.json`` (its per-group list one
line per group) and the checksum lines of the groups' files, spooled again and merged with
the dataset's own files at the end. Each file is written under a temporary name beside it and
renamed into place when complete (:func:`sonicspec.atomic.open_atomic`).
"""

from __future__ import annotations

import itertools
import json
import tempfile
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import IO, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from sonicspec import __version__, artifacts
from sonicspec.artifacts.records import DatasetData, ExportGroup, SplitCount
from sonicspec.atomic import open_atomic
from sonicspec.errors import StageError
from sonicspec.export.checksums import (
    CHECKSUMS_NAME,
    checksum_line,
    file_record,
    write_checksums_merged,
)
from sonicspec.export.manifests import csv_writer, jsonl_line
from sonicspec.plan.params import DatasetParams
from sonicspec.stages.context import JobContext
from sonicspec.stages.corpus import corpus_role

CSV_COLUMNS = ("split", "group", "kind", "name", "path", "channels", "num_samples",
               "sample_rate_hz")


def _compact(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False)


class _GroupId(BaseModel):
    """An export group record's id (the rest is read when the group is written)."""

    model_config = ConfigDict(extra="ignore")
    group: str


class _Shard(BaseModel):
    groups: list[dict[str, Any]]


def _spool_groups(ctx: JobContext, spool: IO[bytes]) -> list[tuple[str, int]]:
    """Every export record's groups as lines of ``spool``; ``(group id, offset)`` in group
    order."""
    index: list[tuple[str, int]] = []
    keys = ctx.input_keys("export")
    for n, key in enumerate(keys):
        ctx.progress(f"reading export records: {n}/{len(keys)}")
        # checked as it is read back (one group at a time); here only the group ids are read
        raw = _Shard.model_validate(ctx.store.read_data("export", key))
        for g in raw.groups:
            index.append((_GroupId.model_validate(g).group, spool.tell()))
            spool.write(_compact(g).encode("utf-8") + b"\n")
    index.sort()
    for (a, _), (b, _) in itertools.pairwise(index):
        if a == b:
            raise StageError(f"{ctx.job.label}: group {a} is in two export records",
                             ctx.job.key)
    return index


def _groups(ctx: JobContext, spool: IO[bytes], index: list[tuple[str, int]]
            ) -> Iterator[ExportGroup]:
    for group, offset in index:
        spool.seek(offset)
        try:
            yield ExportGroup.model_validate_json(spool.readline())
        except ValidationError as err:
            raise StageError(f"{ctx.job.label}: the export record of group {group} does not "
                             f"read ({artifacts.first_error(err)}); was it made by another "
                             "sonicspec version?", ctx.job.key) from None


class _SplitWriters:
    """The manifest files of the splits, opened as each split's first group comes."""

    def __init__(self, out: Path, stack: ExitStack, manifests: tuple[str, ...],
                 columns: tuple[str, ...]) -> None:
        self.out, self.stack, self.manifests, self.columns = out, stack, manifests, columns
        self.split: str | None = None
        self.files: dict[str, IO[str]] = {}
        self.csv: Any = None
        self.written: list[str] = []

    def _open(self, rel: str) -> IO[str]:
        self.written.append(rel)
        return self.stack.enter_context(open_atomic(self.out / rel))

    def group(self, g: ExportGroup) -> None:
        split = g.split
        if split != self.split:
            self.split = split
            if "lhotse" in self.manifests:
                for name in ("recordings", "supervisions"):
                    self.files[name] = self._open(f"manifests/{split}_{name}.jsonl")
            if "csv" in self.manifests:
                self.csv = csv_writer(self._open(f"manifests/{split}.csv"), self.columns)
        if "lhotse" in self.manifests:
            self.files["recordings"].writelines(jsonl_line(r) for r in g.recordings)
            self.files["supervisions"].writelines(jsonl_line(s) for s in g.supervisions)
        if "csv" in self.manifests:
            self.csv.writerows(dict(f.model_dump(mode="json"), split=split, group=g.group)
                               for f in g.files)


def run(ctx: JobContext) -> None:
    params: DatasetParams = ctx.params
    out = Path(ctx.plan.output_dir)
    jobs = ctx.plan.by_key()
    skipped = {corpus_role(jobs[k]): ctx.store.read_data("corpus", k).get("skipped", [])
               for k in ctx.input_keys("corpus")}
    # dataset.json's keys in sorted order: "groups" streams, what follows it is known after.
    head = {
        "corpus_files_skipped": {role: {"count": len(files), "files": files}
                                 for role, files in sorted(skipped.items())},
        "description": params.spec.description,
    }
    counts: dict[str, list[int]] = {}  # split -> [groups, files]
    seconds: dict[str, float] = {}
    last_path = ""
    scratch = Path(ctx.plan.store_dir)
    scratch.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryFile(dir=scratch, prefix=".tmp-dataset-") as spool, \
            tempfile.TemporaryFile("w+", dir=scratch, prefix=".tmp-checksums-",
                                   encoding="utf-8", newline="\n") as sums:
        index = _spool_groups(ctx, spool)
        with ExitStack() as stack:
            scaled = params.spec.outputs.scale == "per_file"  # a column: the file's scale
            writers = _SplitWriters(out, stack, tuple(params.manifests),
                                    (*CSV_COLUMNS, "scale") if scaled else CSV_COLUMNS)
            summary = stack.enter_context(open_atomic(out / "dataset.json"))
            summary.write(_compact(head)[:-1] + ',"groups":[')
            for n, g in enumerate(_groups(ctx, spool, index)):
                if n % 1000 == 0:
                    ctx.progress(f"writing manifests: {n}/{len(index)} groups")
                writers.group(g)
                summary.write(("\n" if n == 0 else ",\n") + _compact(
                    {"group": g.group, "split": g.split, "scene_id": g.scene_id,
                     "metadata": g.metadata.model_dump(mode="json")}))
                c = counts.setdefault(g.split, [0, 0])
                c[0] += 1
                c[1] += len(g.files)
                seconds[g.split] = seconds.get(g.split, 0.0) + g.duration_s
                for record in sorted(g.files, key=lambda r: r.path):
                    if record.path <= last_path:
                        raise StageError(f"{ctx.job.label}: file {record.path} comes "
                                         f"after {last_path} in group order; group ids must "
                                         "not be prefixes of one another", ctx.job.key)
                    last_path = record.path
                    sums.write(checksum_line(record))
            # The same sum in the same (group) order as before: the same rounding.
            splits = {split: SplitCount(groups=c[0], files=c[1],
                                        audio_hours=round(seconds[split] / 3600.0, 6))
                      for split, c in sorted(counts.items())}
            files_written = writers.written
            tail = {"manifests": files_written, "name": params.spec.name,
                    "sonicspec_version": __version__,
                    "spec": params.spec.model_dump(mode="json"),
                    "spec_version": params.spec.sonicspec,
                    "splits": {k: v.model_dump(mode="json") for k, v in splits.items()}}
            summary.write(("\n" if index else "") + "]," + _compact(tail)[1:] + "\n")
        own = [file_record(out, out / rel) for rel in [*files_written, "dataset.json"]]
        sums.seek(0)
        write_checksums_merged(out, sums, own)
    ctx.write({"group_count": np.array([len(index)], dtype=np.int64)},
              artifacts.encode("dataset", DatasetData(
                  dataset_json="dataset.json", manifests=files_written, splits=splits,
                  files=[*own, file_record(out, out / CHECKSUMS_NAME)])))
