"""What every reader of an external layout shares: an index of items, read lazily as groups.

A reader lists a folder's items once (folder names and CSV rows, no audio) as :class:`Item` s;
:class:`ExternalFolder` turns an item into a :class:`~sonicspec.dataload.folder.Group` the
first time it is asked for, with the metadata a built sonicspec dataset would have: speech
tracks ``source1``…, a ``noise`` track where the layout has one, extra references under
their own names (``source1_reverb``), ``sample_rate_hz``, ``num_samples`` and the
``mixtures`` (``name``, ``task``, ``components``, ``targets``, ``file``). Every file path is
relative to the layout's root, so the loader and ``sonicspec evaluate`` read an external set
exactly as they read a sonicspec dataset.

Opening a group checks its files: each must exist (the error names the file and the layout
that expects it) and all must share the first mixture's rate and length.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonicspec.dataload.folder import DatasetError, Group


@dataclass(frozen=True)
class Item:
    """One item of a layout: its group id (``<split>/<name>``), its tracks (name -> file
    relative to the root) and its mixtures (``name``, ``task``, ``components``, ``targets``,
    ``file``)."""

    id: str
    tracks: dict[str, str]
    mixtures: tuple[dict[str, Any], ...]
    extra: dict[str, Any] = field(default_factory=dict)


def mixture(name: str, file: str, targets: Sequence[str], components: Sequence[str],
            task: str | None = None) -> dict[str, Any]:
    """A mixture record; the task is enhancement for one target, separation for more."""
    return {"name": name, "task": task or ("enhancement" if len(targets) == 1
                                           else "separation"),
            "components": list(components), "targets": list(targets), "file": file}


def subdirs(path: Path) -> list[Path]:
    """The folders inside ``path``, sorted by name (none when it is not a folder)."""
    if not path.is_dir():
        return []
    return sorted((p for p in path.iterdir() if p.is_dir()), key=lambda p: p.name)


def wavs(path: Path) -> list[Path]:
    """The ``.wav`` / ``.flac`` files in a folder, sorted by name."""
    if not path.is_dir():
        return []
    return sorted((p for p in path.iterdir() if p.is_file()
                   and p.suffix.lower() in (".wav", ".flac")), key=lambda p: p.name)


def need_dir(path: Path, layout: str, what: str) -> Path:
    """``path`` if it is a folder, else a :class:`DatasetError` naming it."""
    if not path.is_dir():
        raise DatasetError(f"{path}: missing; the {layout} layout expects {what} here")
    return path


def pick_variant(root: Path, layout: str, marker: str) -> Path:
    """The ``wav8k|wav16k/min|max`` folder of a LibriMix or WHAM!-style tree (where
    ``marker`` is found), or ``root`` itself when it has ``marker``; an error listing the
    variants when there are several and naming what is missing when there is none."""
    if (root / marker).exists():
        return root
    found = [root / r / m for r in ("wav8k", "wav16k") for m in ("min", "max")
             if (root / r / m / marker).exists()]
    if len(found) == 1:
        return found[0]
    if not found:
        raise DatasetError(f"{root}: no {marker} here nor under wav8k|wav16k/min|max; "
                           f"expected a {layout} folder")
    raise DatasetError(f"{root}: holds {len(found)} {layout} variants "
                       f"({', '.join(str(p.relative_to(root)) for p in found)}); point at "
                       "one of them")


class ExternalFolder:
    """A dataset in an external layout, read like a built :class:`DatasetFolder`.

    ``items`` maps each split (its native name) to its items; ``aliases`` maps a common
    name (``test``) to the native splits it stands for (``tt``), so the same ``--split``
    works across layouts.
    """

    def __init__(self, root: Path, layout: str, items: dict[str, list[Item]],
                 aliases: dict[str, tuple[str, ...]] | None = None,
                 info: dict[str, Any] | None = None) -> None:
        self.root = Path(root)
        self.layout = layout
        self._items = {s: {i.id: i for i in v} for s, v in items.items() if v}
        if not self._items:
            raise DatasetError(f"{self.root}: no items found in the {layout} layout")
        self.aliases = {k: tuple(s for s in v if s in self._items)
                        for k, v in (aliases or {}).items()}
        self.aliases = {k: v for k, v in self.aliases.items() if v and k not in self._items}
        self.info = dict(info or {})
        self._groups: dict[str, Group] = {}

    @property
    def splits(self) -> list[str]:
        return sorted(self._items)

    def describe(self) -> dict[str, Any]:
        return {"format": self.layout, "root": str(self.root), "splits": self.splits,
                "aliases": {k: list(v) for k, v in self.aliases.items()}, **self.info}

    def _native(self, split: str) -> tuple[str, ...]:
        if split in self._items:
            return (split,)
        if split in self.aliases:
            return self.aliases[split]
        names = self.splits + sorted(self.aliases)
        raise DatasetError(f"{self.root}: split {split!r} not in this {self.layout} set; it "
                           f"has {names}")

    def group_ids(self, split: str) -> list[str]:
        return [g for s in self._native(split) for g in sorted(self._items[s])]

    def group(self, group_id: str) -> Group:
        if group_id not in self._groups:
            split = group_id.split("/")[0]
            item = self._items.get(split, {}).get(group_id)
            if item is None:
                raise DatasetError(f"{self.root}: no group {group_id!r}")
            self._groups[group_id] = Group(self.root, group_id, self._metadata(item))
        return self._groups[group_id]

    def groups(self, split: str) -> list[Group]:
        return [self.group(g) for g in self.group_ids(split)]

    def _metadata(self, item: Item) -> dict[str, Any]:
        import soundfile as sf

        files = dict(item.tracks)
        files.update({f"mixture {m['name']}": m["file"] for m in item.mixtures
                      if m.get("file")})
        rate = length = None
        first = None
        for name, file in _mixtures_first(files):
            path = self.root / file
            if not path.is_file():
                raise DatasetError(f"{path}: missing; the {self.layout} layout lists it as "
                                   f"{name} of {item.id}")
            try:
                info = sf.info(str(path))
            except (sf.LibsndfileError, RuntimeError, OSError) as exc:
                raise DatasetError(f"{path}: cannot read audio ({exc})") from None
            if first is None:
                first, rate, length = path, info.samplerate, info.frames
            elif info.samplerate != rate or info.frames != length:
                raise DatasetError(f"{path}: {info.frames} samples at {info.samplerate} Hz, "
                                   f"but {rel(self.root, first)} of {item.id} has {length} at "
                                   f"{rate} Hz; expected every file of an item to match")
        expected = item.extra.get("expected_num_samples")
        if expected is not None and expected != length:
            raise DatasetError(f"{first}: {length} samples, but the {self.layout} metadata "
                               f"gives {item.id} a length of {expected}")
        meta: dict[str, Any] = {"group": item.id, "split": item.id.split("/")[0],
                                "format": self.layout, "sample_rate_hz": rate,
                                "num_samples": length, **item.extra}
        for name, file in item.tracks.items():
            meta[name] = {"file": file}
        info_file = item.extra.get("track_info_file")
        if info_file is not None:
            for name, info in _track_info(self.root / info_file, self.layout).items():
                if name in meta and isinstance(info, dict):
                    meta[name].update({k: v for k, v in info.items() if k != "file"})
        meta.pop("track_info_file", None)
        meta["mixtures"] = [dict(m) for m in item.mixtures]
        return meta


def _track_info(path: Path, layout: str) -> dict[str, Any]:
    """A layout's per-item JSON of track facts (SonicSet's ``json_data.json``)."""
    import json

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(f"{path}: missing; the {layout} layout has one beside each "
                           "item's audio") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path}: unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: expected a JSON object of track -> facts, got "
                           f"{type(data).__name__}")
    return data


def _mixtures_first(files: dict[str, str]) -> Iterable[tuple[str, str]]:
    yield from ((k, v) for k, v in files.items() if k.startswith("mixture "))
    yield from ((k, v) for k, v in files.items() if not k.startswith("mixture "))


def rel(root: Path, path: Path) -> str:
    """``path`` relative to ``root``, with ``/`` separators."""
    return path.relative_to(root).as_posix()
