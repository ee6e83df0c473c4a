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
Alias ``test`` = every benchmark split present (``--task`` then picks separation or
enhancement).

The raw released folders (the "train folder", ``val.rar`` and ``test.rar`` downloads, written
by ``SonicSim-SonicSet/SonicSet.py``) are read too, as groups to mix from::

    <root>/train|val|test/<scene>/<spk1>-<spk2>-<spk3>/
        moving_audio_1.wav, moving_audio_2.wav, moving_audio_3.wav   the moving talkers
        noise_audio.wav, music_audio.wav    (or noise.wav, music.wav) the static backgrounds
        json_data.json    source1..3: audio, start_end_points, words; noise, music

Each such folder is one group ``<split>/<scene>/<speakers>`` with tracks ``source1``…
``source3`` (``start_end_points`` and ``words`` from ``json_data.json``), ``noise`` and
``music``, and the mixtures the released test generator draws from, summed as saved (no
file): ``sep_s<i>s<j>_<noise|music>`` for each pair of talkers and ``enh_s<i>_<noise|music>``
for each talker. The loader's dynamic mixing (the ``sonicsim`` preset) re-draws them the way
the released training loader does. Point the reader at the folder holding the split folders
(``SonicSet/scene_datasets/mp3d``), or at one of them.
"""

from __future__ import annotations

import re
from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item, mixture
from sonicspec.dataload.formats.plain import leaves

NAME = "sonicset"
_SPLIT = re.compile(r"^(enh-)?test-(noise|music|all)$")
RAW_SPLITS = ("train", "val", "test")
TALKERS = ("moving_audio_1.wav", "moving_audio_2.wav", "moving_audio_3.wav")
BACKGROUNDS = {"noise": ("noise_audio.wav", "noise.wav"),
               "music": ("music_audio.wav", "music.wav")}


def _splits(root: Path) -> list[Path]:
    if _SPLIT.match(root.name):
        return [root]
    if not root.is_dir():
        return []
    return sorted((p for p in root.iterdir() if p.is_dir() and _SPLIT.match(p.name)),
                  key=lambda p: p.name)


def _raw_groups(split: Path) -> list[Path]:
    """The ``<scene>/<speakers>`` folders of a raw split holding the first talker."""
    return sorted(p.parent for p in split.glob(f"*/*/{TALKERS[0]}"))


def _raw_splits(root: Path) -> list[Path]:
    if root.name in RAW_SPLITS and _raw_groups(root):
        return [root]
    return [root / s for s in RAW_SPLITS if _raw_groups(root / s)]


def detect(root: Path) -> bool:
    return bool(_splits(root)) or bool(_raw_splits(root))


def _raw_item(base: Path, folder: Path, split: str) -> Item:
    rel = folder.relative_to(base).as_posix()
    names = {p.name for p in folder.iterdir()}
    tracks = {f"source{k + 1}": f"{rel}/{t}" for k, t in enumerate(TALKERS)}
    for bg, files in BACKGROUNDS.items():
        found = next((f for f in files if f in names), None)
        if found is None:
            raise DatasetError(f"{folder}: no {' or '.join(files)}; the released SonicSet "
                               f"layout has the {bg} track beside the talkers")
        tracks[bg] = f"{rel}/{found}"
    mixes = []
    for bg in BACKGROUNDS:
        for i, j in ((1, 2), (1, 3), (2, 3)):
            mixes.append(mixture(f"sep_s{i}s{j}_{bg}", "", [f"source{i}", f"source{j}"],
                                 [f"source{i}", f"source{j}", bg]))
        for i in (1, 2, 3):
            mixes.append(mixture(f"enh_s{i}_{bg}", "", [f"source{i}"], [f"source{i}", bg]))
    for m in mixes:
        del m["file"]  # summed from its components as saved
    return Item(rel, tracks, tuple(mixes), {"track_info_file": f"{rel}/json_data.json"})


def open_folder(root: Path) -> ExternalFolder:
    from sonicspec.dataload.formats.plain import item

    splits = _splits(root)
    raw = _raw_splits(root)
    if not splits and not raw:
        raise DatasetError(f"{root}: no test-noise/, test-music/, enh-test-noise/ or "
                           "enh-test-music/ (the benchmarks), nor train|val|test/<scene>/"
                           f"<speakers>/{TALKERS[0]} (the raw folders); expected the released "
                           "SonicSet layout")
    base = (splits or raw)[0].parent
    items: dict[str, list[Item]] = {}
    for split in raw:
        for folder in _raw_groups(split):
            items.setdefault(split.name, []).append(_raw_item(base, folder, split.name))
    for split in splits:
        for folder, names in leaves(split):
            if "mix.wav" not in names:
                continue
            items.setdefault(split.name, []).append(
                item(base, folder, names, split.name, "SonicSet", clean=("clean",)))
        if split.name not in items:
            raise DatasetError(f"{split}: no <background>-<speakers>/<scene>/<group>/mix.wav; "
                               "expected the released SonicSet benchmark layout")
    bench = tuple(s.name for s in splits)
    return ExternalFolder(base, NAME, items, aliases={"test": bench} if bench else {})
