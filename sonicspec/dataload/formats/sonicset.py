"""The released SonicSet v1 test benchmarks (JusperLee/SonicSim: the "sep-benchmark" and
"enh-benchmark" downloads of its README, written by ``separation/generate_fixed_test.py`` and
``enhancement/generate_fixed_test.py`` from the raw ``test`` folder).

Layout (16 kHz; one folder per fixed mixture)::

    <root>/
        test-noise/noise-0-1/<scene>/<group>/mix.wav, s1.wav, s2.wav   separation, speakers
        test-music/music-0-2/<scene>/<group>/...                       0,1 / 0,2 / 1,2 of 3,
                                                                       with noise or music
        enh-test-noise/noise-0/<scene>/<group>/mix.wav, clean.wav      enhancement, speaker
        enh-test-music/music-2/<scene>/<group>/...                     0 / 1 / 2

(The released loaders read them as ``<split>/<background>-<speakers>/<scene>/<group>``.) Each
split folder present is a split; each folder holding ``mix.wav`` is one group
``<split>/<background>-<speakers>/<scene>/<group>`` with tracks ``source1``… (``s<k>.wav``,
or ``clean.wav``) and one mixture ``mix`` (separation with two references, enhancement with
one). The background was mixed in and not saved (``components_complete: false``).
Alias ``test`` = every split present (``--task`` then picks separation or enhancement).
Point the reader at the folder holding the split folders, or at one of them.
"""

from __future__ import annotations

import re
from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item
from sonicspec.dataload.formats.plain import leaves

NAME = "sonicset"
_SPLIT = re.compile(r"^(enh-)?test-(noise|music|all)$")


def _splits(root: Path) -> list[Path]:
    if _SPLIT.match(root.name):
        return [root]
    if not root.is_dir():
        return []
    return sorted((p for p in root.iterdir() if p.is_dir() and _SPLIT.match(p.name)),
                  key=lambda p: p.name)


def detect(root: Path) -> bool:
    return bool(_splits(root))


def open_folder(root: Path) -> ExternalFolder:
    from sonicspec.dataload.formats.plain import item

    splits = _splits(root)
    if not splits:
        raise DatasetError(f"{root}: no test-noise/, test-music/, enh-test-noise/ or "
                           "enh-test-music/; expected the released SonicSet benchmark folder")
    base = splits[0].parent
    items: dict[str, list[Item]] = {}
    for split in splits:
        for folder, names in leaves(split):
            if "mix.wav" not in names:
                continue
            items.setdefault(split.name, []).append(
                item(base, folder, names, split.name, "SonicSet", clean=("clean",)))
        if split.name not in items:
            raise DatasetError(f"{split}: no <background>-<speakers>/<scene>/<group>/mix.wav; "
                               "expected the released SonicSet benchmark layout")
    return ExternalFolder(base, NAME, items, aliases={"test": tuple(items)})
