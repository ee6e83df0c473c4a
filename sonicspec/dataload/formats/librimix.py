"""LibriMix (Libri2Mix, Libri3Mix) as its recipe writes it.

Source of the layout: JorisCos/LibriMix, ``generate_librimix.sh`` and
``scripts/create_librimix_from_metadata.py`` (Cosentino et al., "LibriMix: An Open-Source
Dataset for Generalizable Speech Separation", 2020). One variant (sample rate and mode) is one
folder::

    Libri2Mix/wav8k/min/                      (wav8k | wav16k, min | max)
        metadata/mixture_<split>_<type>.csv   (split: train-360, train-100, dev, test;
                                               type: mix_clean, mix_both, mix_single)
        <split>/mix_clean/<mixture_ID>.wav    s1 + s2 (+ s3)
        <split>/mix_both/<mixture_ID>.wav     the sources + noise
        <split>/mix_single/<mixture_ID>.wav   s1 + noise
        <split>/s1/, s2/, (s3/), noise/       the references, same names

The CSVs have the columns ``mixture_ID, mixture_path, source_1_path, …, source_K_path,
[noise_path,] length`` (``noise_path`` for mix_both and mix_single, one source for
mix_single; ``length`` in samples). Their paths are the generating machine's, so they are
read as ``<split>/<folder>/<file>`` under the variant folder (a moved copy reads the same).
Point the reader at the variant folder, or at ``Libri2Mix`` when it holds only one variant.

Each ``mixture_ID`` is one group ``<split>/<mixture_ID>``: tracks ``source1``… and ``noise``;
mixtures named after their type — ``mix_clean`` and ``mix_both`` (separation, every source),
``mix_single`` (enhancement, ``source1``). Aliases: ``val`` = dev; ``train`` = both train
sets.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item, mixture, need_dir, pick_variant

NAME = "librimix"
TYPES = ("mix_clean", "mix_both", "mix_single")
_CSV = re.compile(r"^mixture_(?P<split>.+)_(?P<type>mix_clean|mix_both|mix_single)\.csv$")


def detect(root: Path) -> bool:
    try:
        base = pick_variant(root, "LibriMix", "metadata")
    except DatasetError:
        return False
    return any(_CSV.match(p.name) for p in (base / "metadata").glob("mixture_*.csv"))


def _local(path: str, split: str, folder: str) -> str:
    """A CSV path as ``<split>/<folder>/<file>`` under the variant folder."""
    name = Path(path.replace("\\", "/")).name
    return f"{split}/{folder}/{name}"


def open_folder(root: Path) -> ExternalFolder:
    base = pick_variant(root, "LibriMix", "metadata")
    meta = need_dir(base / "metadata", "LibriMix", "the metadata CSVs")
    tables = sorted((m.group("split"), m.group("type"), p) for p in meta.glob("*.csv")
                    if (m := _CSV.match(p.name)))
    if not tables:
        raise DatasetError(f"{meta}: no mixture_<split>_<mix_clean|mix_both|mix_single>.csv; "
                           "expected the LibriMix recipe's metadata folder")
    tracks_of: dict[str, dict[str, str]] = {}
    mixtures_of: dict[str, list[dict]] = {}
    length_of: dict[str, str] = {}
    for split, kind, path in tables:
        folder = base / split / kind
        if not folder.is_dir():
            continue  # the recipe was run without this type: its CSV is still written
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            cols = reader.fieldnames or []
            for col in ("mixture_ID", "mixture_path", "source_1_path", "length"):
                if col not in cols:
                    raise DatasetError(f"{path}: no column {col!r}; expected the LibriMix "
                                       f"columns mixture_ID, mixture_path, source_1_path…, "
                                       f"length, got {cols}")
            sources = sorted((c for c in cols if re.fullmatch(r"source_\d+_path", c)),
                             key=lambda c: int(c.split("_")[1]))
            for n, row in enumerate(reader, start=2):
                mid = row["mixture_ID"]
                gid = f"{split}/{mid}"
                tracks = tracks_of.setdefault(gid, {})
                length = length_of.setdefault(gid, row["length"])
                names = []
                for col in sources:
                    k = int(col.split("_")[1])
                    tracks[f"source{k}"] = _local(row[col], split, f"s{k}")
                    names.append(f"source{k}")
                components = list(names)
                if row.get("noise_path"):
                    tracks["noise"] = _local(row["noise_path"], split, "noise")
                    components.append("noise")
                if row["length"] != length:
                    raise DatasetError(f"{path}: line {n}: length {row['length']} of {mid}, "
                                       f"another table says {length}")
                mixtures_of.setdefault(gid, []).append(mixture(
                    kind, _local(row["mixture_path"], split, kind), names, components,
                    task="enhancement" if kind == "mix_single" else "separation"))
    if not tracks_of:
        raise DatasetError(f"{base}: the metadata names splits "
                           f"{sorted({s for s, _, _ in tables})} but none of their "
                           f"{'/'.join(TYPES)} folders exist (e.g. "
                           f"{base / tables[0][0] / tables[0][1]})")
    items: dict[str, list[Item]] = {}
    for gid, tracks in tracks_of.items():
        try:
            expected = int(length_of[gid])
        except ValueError:
            raise DatasetError(f"{base / 'metadata'}: length of {gid}: expected a sample "
                               f"count, got {length_of[gid]!r}") from None
        items.setdefault(gid.split("/")[0], []).append(
            Item(gid, tracks, tuple(mixtures_of[gid]), {"expected_num_samples": expected}))
    rate = 8000 if "wav8k" in base.parts else 16000 if "wav16k" in base.parts else None
    return ExternalFolder(base, NAME, items,
                          aliases={"val": ("dev",), "train": ("train-360", "train-100")},
                          info={"variant": "/".join(base.parts[-2:]), "rate_hint_hz": rate})
