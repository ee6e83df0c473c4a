"""LRS2-2Mix as released with TDANet / CTCNet (Li et al., "An efficient encoder-decoder
architecture with top-down attention for speech separation", ICLR 2023; the archive on
JusperLee's Hugging Face page and the TDANet README).

Layout (16 kHz, 2 s mixtures, 20 000 / 5 000 / 3 000 items)::

    LRS2-2Mix/                 (or its wav16k/min folder, as unpacked)
        tr/ cv/ tt/
            mix/<name>.wav     s1 + s2
            s1/<name>.wav
            s2/<name>.wav

Each name is one group ``<split>/<name>`` with tracks ``source1``, ``source2`` and one
separation mixture ``mix``. Aliases: ``train`` = tr, ``val`` = cv, ``test`` = tt.
"""

from __future__ import annotations

from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item, mixture, pick_variant, wavs

NAME = "lrs2mix"
SPLITS = ("tr", "cv", "tt")


def _base(root: Path) -> Path:
    for split in SPLITS:
        try:
            base = pick_variant(root, "LRS2-2Mix", f"{split}/mix")
        except DatasetError:
            continue
        return base
    raise DatasetError(f"{root}: no tr|cv|tt/mix/ here nor under wav8k|wav16k/min|max; "
                       "expected an LRS2-2Mix folder")


def detect(root: Path) -> bool:
    try:
        base = _base(root)
    except DatasetError:
        return False
    return any((base / s / "s1").is_dir() for s in SPLITS)


def open_folder(root: Path) -> ExternalFolder:
    base = _base(root)
    items: dict[str, list[Item]] = {}
    for split in SPLITS:
        if not (base / split / "mix").is_dir():
            continue
        refs = sorted((d.name for d in (base / split).iterdir()
                       if d.is_dir() and d.name[:1] == "s" and d.name[1:].isdigit()),
                      key=lambda d: int(d[1:]))
        if not refs:
            raise DatasetError(f"{base / split}: mix/ but no s1/, s2/; expected the "
                               "LRS2-2Mix references beside the mixtures")
        for path in wavs(base / split / "mix"):
            tracks = {f"source{r[1:]}": f"{split}/{r}/{path.name}" for r in refs}
            items.setdefault(split, []).append(Item(
                f"{split}/{path.stem}", tracks,
                (mixture("mix", f"{split}/mix/{path.name}", list(tracks), list(tracks)),)))
    return ExternalFolder(base, NAME, items,
                          aliases={"train": ("tr",), "val": ("cv",), "test": ("tt",)})
