"""A plain "mixture + references" folder: the layout for any set that has none of its own
(a real recorded set, a set made by another tool).

Layout::

    <root>/<split>/<item>/              (the item may be nested: <split>/<a>/<b>/)
        mixture.wav   (or mix.wav)      the input
        s1.wav, s2.wav, …               the references, one per speaker (separation)
        clean.wav                       or one reference (enhancement)
        noise.wav                       optional: the background, when it is known

Every folder under a split that holds a mixture file is one group ``<split>/<item path>``:
tracks ``source1``… (``s<k>`` or ``clean``) and ``noise``, one mixture named after the file
(``mixture`` or ``mix``): separation with two or more references, enhancement with one. With
``noise.wav`` the components are the references and the noise; without it the mixture's
background is unknown (``components_complete: false``: items are read as written). FLAC
files are read the same way (``mixture.flac``).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item, mixture

NAME = "plain"
MIXTURES = ("mixture", "mix")
EXTENSIONS = (".wav", ".flac")
_SOURCE = re.compile(r"^s(\d+)$")


def _mixture_file(names: set[str]) -> str | None:
    return next((f"{m}{e}" for m in MIXTURES for e in EXTENSIONS if f"{m}{e}" in names), None)


def leaves(root: Path) -> Iterator[tuple[Path, set[str]]]:
    """Each folder under ``root`` holding a mixture file, with its file names, sorted."""
    for here, dirs, files in os.walk(root):
        dirs.sort()
        names = set(files)
        if _mixture_file(names):
            yield Path(here), names


def item(root: Path, folder: Path, names: set[str], split: str, layout: str,
         clean: tuple[str, ...] = ("clean",)) -> Item:
    """The item of one folder: its mixture, references and (optional) noise."""
    mix_file = _mixture_file(names)
    if mix_file is None:
        raise DatasetError(f"{folder}: no mixture.wav or mix.wav; the {layout} layout puts "
                           "one in each item's folder")
    rel = folder.relative_to(root).as_posix()
    stems = {Path(n).stem: n for n in sorted(names) if Path(n).suffix.lower() in EXTENSIONS}
    sources = sorted((int(m.group(1)), n) for s, n in stems.items()
                     if (m := _SOURCE.match(s)))
    tracks = {f"source{k}": f"{rel}/{n}" for k, n in sources}
    if not tracks:
        one = next((stems[c] for c in clean if c in stems), None)
        if one is None:
            raise DatasetError(f"{folder}: {mix_file} but no reference (s1.wav, s2.wav, … or "
                               f"{' / '.join(c + '.wav' for c in clean)}); the {layout} "
                               "layout needs one beside each mixture")
        tracks["source1"] = f"{rel}/{one}"
    if [k for k, _ in sources] != list(range(1, len(sources) + 1)):
        raise DatasetError(f"{folder}: references {[n for _, n in sources]}; expected s1 … "
                           f"s{len(sources)} with none missing")
    targets = list(tracks)
    components = list(targets)
    if "noise" in stems:
        tracks["noise"] = f"{rel}/{stems['noise']}"
        components.append("noise")
    m = mixture(Path(mix_file).stem, f"{rel}/{mix_file}", targets, components)
    if "noise" not in stems:
        m["components_complete"] = False
    return Item(f"{rel}", tracks, (m,))


def detect(root: Path) -> bool:
    return any(True for split in _splits(root) for _ in leaves(split))


def _splits(root: Path) -> list[Path]:
    if not root.is_dir():
        return []
    return sorted((p for p in root.iterdir() if p.is_dir()), key=lambda p: p.name)


def open_folder(root: Path) -> ExternalFolder:
    items: dict[str, list[Item]] = {}
    for split in _splits(root):
        for folder, names in leaves(split):
            if folder == split:
                raise DatasetError(f"{folder}: a mixture directly in the split folder; the "
                                   "plain layout puts each item in its own folder: "
                                   "<root>/<split>/<item>/mixture.wav")
            items.setdefault(split.name, []).append(item(root, folder, names, split.name,
                                                         "plain"))
    if not items:
        raise DatasetError(f"{root}: no <split>/<item>/mixture.wav (or mix.wav); expected a "
                           "plain mixture + references folder")
    return ExternalFolder(root, NAME, items)
