"""Readers of external dataset layouts, so the loader and ``sonicspec evaluate`` score a model
on a public test set as on a sonicspec dataset.

One module per layout, each with ``NAME``, ``detect(root)`` and ``open_folder(root)``
(its docstring names the layout's source): :mod:`.sonicset` (the released SonicSet
benchmarks), :mod:`.librimix`, :mod:`.lrs2mix`, :mod:`.wham` (WHAM! and WHAMR!),
:mod:`.voicebank` (VoiceBank-DEMAND), :mod:`.dns` (the DNS Challenge synthetic test sets) and
:mod:`.plain` (mixture + references). :func:`open_dataset` picks one by name, or by the
folder's layout: a folder with ``dataset.json`` is a sonicspec dataset.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

from sonicspec.dataload.folder import DatasetError, DatasetFolder
from sonicspec.dataload.formats import dns, librimix, lrs2mix, plain, sonicset, voicebank, wham
from sonicspec.dataload.formats.base import ExternalFolder

READERS: dict[str, ModuleType] = {m.NAME: m for m in (
    sonicset, librimix, wham, lrs2mix, voicebank, dns, plain)}
"""The readers in detection order (plain last: it takes any mixture + references tree)."""
FORMATS = ("auto", "sonicspec", *READERS)


def detect(root: str | Path) -> str:
    """The name of the layout of ``root`` (``sonicspec`` for a built dataset)."""
    path = Path(root)
    if not path.is_dir():
        raise DatasetError(f"{path}: no such folder")
    if (path / "dataset.json").is_file():
        return "sonicspec"
    for name, reader in READERS.items():
        if reader.detect(path):
            return name
    raise DatasetError(f"{path / 'dataset.json'}: missing; expected a dataset folder built "
                       "by `sonicspec build` (its outputs.dir) or a test set in one of the "
                       f"layouts {list(READERS)} (give --format to be told what it lacks)")


def open_dataset(root: str | Path, format: str | None = None
                 ) -> DatasetFolder | ExternalFolder:
    """The dataset at ``root`` in layout ``format`` (``None`` or ``"auto"``: detected)."""
    name = detect(root) if format in (None, "auto") else format
    if name == "sonicspec":
        return DatasetFolder(root)
    if name not in READERS:
        raise DatasetError(f"format: expected one of {list(FORMATS)}, got {name!r}")
    path = Path(root)
    if not path.is_dir():
        raise DatasetError(f"{path}: no such folder")
    return READERS[name].open_folder(path)


__all__ = ["FORMATS", "READERS", "ExternalFolder", "detect", "open_dataset"]
