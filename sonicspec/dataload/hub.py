"""Exports of a built dataset folder for Hugging Face ``datasets`` and ``webdataset``.

Both hold one record per group: every audio file of the group as written (the FLAC or WAV
bytes themselves, so the samples are the folder's), and its metadata. Groups go in shards of
``groups_per_shard``; a shard's name carries the content key of what it holds (the split, its
groups and the SHA-256 of their files from ``checksums.sha256``, and the export's format
version), so a second export writes only the shards whose groups changed and removes the
shards nothing refers to any more.

* ``huggingface``: ``<out>/data/<split>-<key>.parquet``, the layout ``datasets`` reads as a
  dataset with one split per file prefix: ``datasets.load_dataset("<out>")``. Audio columns
  are ``datasets.Audio`` features (``{"bytes", "path"}``); the metadata is in columns
  (``group``, ``split``, ``scene_id``, ``sample_rate_hz``, ``num_samples``, ``speakers``,
  ``transcripts``, ``t30_s``, ``drr_db``), whole as JSON (``metadata``) and the group's
  ``tracks.npz`` as bytes (``tracks``; ``numpy.load(io.BytesIO(row["tracks"]))``).
* ``webdataset``: ``<out>/<split>-<key>.tar``; each group a sample keyed by its id
  (``train/000000``) with members ``<key>.<track>.flac`` (``source1``, ``noise``,
  ``source1_dry``, a mixture's name such as ``sep_s1s2_noise``), ``<key>.metadata.json`` and
  ``<key>.tracks.npz``.
  Tar members carry no time or owner, so the same groups give the same bytes.

A dataset built with ``outputs.scale: per_file`` keeps each file's scale with it: the audio
bytes are the files' own (each carries its ``sonicspec_scale=`` comment tag), and each record
adds ``audio_scales`` (record name -> scale; a Parquet struct column, a ``<key>.scales.json``
member): multiply a decoded audio column by its scale for the signal's level.
"""

from __future__ import annotations

import io
import json
import tarfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sonicspec.atomic import atomic_path, write_text
from sonicspec.dataload.folder import DatasetError, DatasetFolder, Group
from sonicspec.export.checksums import read_checksums
from sonicspec.export.tracks import is_reference
from sonicspec.hashing import canonical_json, sha256_hex

FORMATS = ("huggingface", "webdataset")
REQUIRES = {"huggingface": ("datasets", "pyarrow"), "webdataset": ("webdataset",)}
"""The modules each export needs (to write it, or for a reader to read it)."""
FORMAT_VERSION = 2
"""2: the group's ``tracks.npz`` is in each record (metadata version 2 references it)."""
STATE_NAME = ".sonicspec-export.json"
_INSTALL = {"huggingface": "pip install 'sonicspec[export]' (datasets)",
            "webdataset": "pip install 'sonicspec[export]' (webdataset)"}


def group_files(group: Group) -> dict[str, str]:
    """``record name -> path`` (relative to the folder) of every audio file of a group:
    tracks, stems and mixtures, in a fixed order."""
    out: dict[str, str] = {}
    for name in (*group.speakers, *group.backgrounds):
        entry = group.metadata[name]
        if entry.get("file"):
            out[name] = entry["file"]
        for stem in ("dry", "direct", "early"):
            for ext in (".flac", ".wav"):
                rel = f"{group.id}/{name}_{stem}{ext}"
                if (group.root / rel).is_file():
                    out[f"{name}_{stem}"] = rel
    for m in group.mixtures():
        if m.get("file"):
            out[m["name"]] = m["file"]
    return out


def group_extras(group: Group) -> dict[str, str]:
    """``record name -> path`` of a group's non-audio files: ``metadata`` and, for a dataset
    whose metadata references it, ``tracks`` (the ``tracks.npz``)."""
    out = {"metadata": f"{group.id}/metadata.json"}
    ref = group.metadata.get("microphone_track")
    if is_reference(ref):
        out["tracks"] = ref["file"]
    return out


def _shards(folder: DatasetFolder, split: str, per_shard: int,
            sums: dict[str, str]) -> Iterator[tuple[str, list[Group]]]:
    groups = folder.groups(split)
    for i in range(0, len(groups), per_shard):
        chunk = groups[i:i + per_shard]
        content = []
        for g in chunk:
            files = {**group_files(g), **group_extras(g)}
            missing = [rel for rel in files.values() if rel not in sums]
            if missing:
                raise DatasetError(f"{folder.root}: {missing[0]} is not in checksums.sha256 "
                                   "(an unfinished or edited build?); run `sonicspec verify`")
            content.append([g.id, sorted((n, sums[rel]) for n, rel in files.items())])
        key = sha256_hex(canonical_json({"version": FORMAT_VERSION, "split": split,
                                         "groups": content}))
        yield key[:16], chunk


def _row(group: Group, files: dict[str, str]) -> dict[str, Any]:
    meta = group.metadata
    speakers = group.speakers
    tracks = group_extras(group).get("tracks")
    row: dict[str, Any] = {
        "group": group.id, "split": group.split, "scene_id": meta.get("scene_id"),
        "sample_rate_hz": group.sample_rate_hz, "num_samples": group.num_samples,
        "speakers": [str(meta[s].get("speaker")) for s in speakers],
        "transcripts": [" ".join(meta[s].get("words", [])) for s in speakers],
        "t30_s": [meta[s].get("t30_s") for s in speakers],
        "drr_db": [meta[s].get("drr_db") for s in speakers],
        "metadata": json.dumps(meta, sort_keys=True),
        "tracks": (group.root / tracks).read_bytes() if tracks else None,
    }
    for name, rel in files.items():
        row[name] = {"bytes": (group.root / rel).read_bytes(), "path": rel}
    scales = audio_scales(group, files)
    if scales is not None:
        row["audio_scales"] = scales
    return row


def audio_scales(group: Group, files: dict[str, str]) -> dict[str, float] | None:
    """Record name -> scale of a group built with ``outputs.scale: per_file`` (None for one
    built without: its files are at their level)."""
    if group.metadata.get("audio_scales") is None:
        return None
    return {name: group.scale(rel) for name, rel in files.items()}


def _write_parquet(path: Path, groups: list[Group]) -> None:
    try:
        import datasets
    except ImportError:
        raise DatasetError(f"the huggingface export needs datasets; {_INSTALL['huggingface']}"
                           ) from None
    names = list(group_files(groups[0]))
    rows = []
    for g in groups:
        files = group_files(g)
        if list(files) != names:
            raise DatasetError(f"group {g.id}: audio files {sorted(files)} differ from group "
                               f"{groups[0].id}'s {sorted(names)}; one table needs the same "
                               "columns")
        rows.append(_row(g, files))
    scaled = "audio_scales" in rows[0]
    if any(("audio_scales" in r) != scaled for r in rows):
        raise DatasetError(f"groups {groups[0].id}…{groups[-1].id}: some record audio_scales "
                           "and some do not; one table needs the same columns (rebuild)")
    features = datasets.Features({
        "group": datasets.Value("string"), "split": datasets.Value("string"),
        "scene_id": datasets.Value("string"), "sample_rate_hz": datasets.Value("int64"),
        "num_samples": datasets.Value("int64"),
        "speakers": datasets.Sequence(datasets.Value("string")),
        "transcripts": datasets.Sequence(datasets.Value("string")),
        "t30_s": datasets.Sequence(datasets.Value("float64")),
        "drr_db": datasets.Sequence(datasets.Value("float64")),
        "metadata": datasets.Value("string"),
        "tracks": datasets.Value("binary"),
        **{n: datasets.Audio(sampling_rate=groups[0].sample_rate_hz, decode=True)
           for n in names},
        **({"audio_scales": {n: datasets.Value("float64") for n in names}} if scaled else {})})
    # The table is made with pyarrow against the features' own Arrow schema (which carries
    # them in its "huggingface" metadata, as datasets writes Parquet): datasets' encoder would
    # need torchcodec to pass FLAC bytes through unchanged.
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist(rows, schema=features.arrow_schema)
    with atomic_path(path) as tmp:
        pq.write_table(table, str(tmp))


def _write_tar(path: Path, groups: list[Group]) -> None:
    with atomic_path(path) as tmp, tarfile.open(tmp, "w", format=tarfile.USTAR_FORMAT) as tar:
        for g in groups:
            members = [(f"{name}{Path(rel).suffix}", (g.root / rel).read_bytes())
                       for name, rel in group_files(g).items()]
            members += [(Path(rel).name, (g.root / rel).read_bytes())
                        for rel in group_extras(g).values()]
            scales = audio_scales(g, group_files(g))
            if scales is not None:
                members.append(("scales.json", (json.dumps(scales, sort_keys=True)
                                                + "\n").encode()))
            for ext, data in members:
                info = tarfile.TarInfo(f"{g.id}.{ext}")
                info.size, info.mtime, info.mode = len(data), 0, 0o644
                info.uid = info.gid = 0
                info.uname = info.gname = ""
                tar.addfile(info, io.BytesIO(data))


def export(root: str | Path, out: str | Path, fmt: str, *, splits: list[str] | None = None,
           groups_per_shard: int = 64) -> dict[str, Any]:
    """Export a dataset folder as ``fmt`` (``huggingface`` or ``webdataset``) into ``out``.

    Returns ``{"written": [...], "kept": [...], "removed": [...]}`` (shard paths relative to
    ``out``).
    """
    if fmt not in FORMATS:
        raise DatasetError(f"format: expected one of {list(FORMATS)}, got {fmt!r}")
    if groups_per_shard < 1:
        raise DatasetError(f"groups_per_shard: expected >= 1, got {groups_per_shard}")
    if fmt == "webdataset":
        try:  # not needed to write a tar, but a reader will want it: say so now
            import webdataset  # noqa: F401
        except ImportError:
            raise DatasetError(f"the webdataset export needs webdataset; "
                               f"{_INSTALL['webdataset']}") from None
    folder = DatasetFolder(root)
    out = Path(out).resolve()
    if out == folder.root.resolve() or folder.root.resolve() in out.parents:
        raise DatasetError(f"{out}: inside the dataset folder {folder.root}; export beside it "
                           "(the folder holds what the build wrote, nothing else)")
    state_path = out / STATE_NAME
    if out.exists() and any(out.iterdir()) and not state_path.is_file():
        raise DatasetError(f"{out}: not empty and not an export folder (no {STATE_NAME}); "
                           "choose an empty or new folder")
    previous = json.loads(state_path.read_text()) if state_path.is_file() else {}
    if previous and previous.get("format") != fmt:
        raise DatasetError(f"{out}: holds a {previous.get('format')} export; choose another "
                           f"folder for {fmt}")
    sums = read_checksums(folder.root)
    chosen = splits or folder.splits
    wanted: list[tuple[str, list[Group]]] = []
    for split in chosen:
        for key, chunk in _shards(folder, split, groups_per_shard, sums):
            rel = (f"data/{split}-{key}.parquet" if fmt == "huggingface"
                   else f"{split}-{key}.tar")
            wanted.append((rel, chunk))
    written, kept = [], []
    for rel, chunk in wanted:
        path = out / rel
        if path.is_file():
            kept.append(rel)
            continue
        (_write_parquet if fmt == "huggingface" else _write_tar)(path, chunk)
        written.append(rel)
    names = {rel for rel, _ in wanted}
    removed = sorted(r for r in previous.get("shards", []) if r not in names)
    for rel in removed:
        (out / rel).unlink(missing_ok=True)
    write_text(state_path, json.dumps(
        {"format": fmt, "version": FORMAT_VERSION, "dataset": str(folder.root.resolve()),
         "splits": chosen, "shards": sorted(names)}, indent=2, sort_keys=True) + "\n")
    return {"written": written, "kept": kept, "removed": removed}
