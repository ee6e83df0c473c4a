"""WHAM! and WHAMR! as their scripts write them.

Source of the layout: the WHAM! and WHAMR! generation scripts (``create_wham_from_scratch.py``
of wham_scripts and whamr_scripts, wham.whisper.ai; Wichern et al., Interspeech 2019;
Maciejewski et al., ICASSP 2020). One variant (rate and mode) is one folder::

    wham_mix/wav8k/min/                 (wav8k | wav16k, min | max)
        tr/ cv/ tt/
            mix_clean/<name>.wav        s1 + s2
            mix_both/<name>.wav         s1 + s2 + noise
            mix_single/<name>.wav       s1 + noise
            s1/ s2/ noise/              the references, same names

    whamr/wav8k/min/tt/                 (WHAMR!: every mixture and source twice)
            mix_{clean,both,single}_{anechoic,reverb}/<name>.wav
            s1_anechoic/ s2_anechoic/   the sources without reverb, aligned with the
            s1_reverb/ s2_reverb/       reverberant ones
            noise/

File names are the wsj0-2mix ones (``<utt1>_<gain1>_<utt2>_<gain2>.wav``). Each name is one
group ``<split>/<name>`` with tracks ``source1``, ``source2``, ``noise``; mixtures named
after their folder: ``mix_clean`` / ``mix_both`` separation, ``mix_single`` enhancement of
``source1``. WHAMR!: ``source1`` and ``source2`` are the anechoic sources (the targets of
WHAMR!'s separate-and-dereverberate task) and ``source1_reverb``, ``source2_reverb`` the
reverberant ones; a ``*_reverb`` mixture's components are the reverberant sources, its targets
the anechoic ones. Point the reader at the variant folder, or at the top folder when it holds
one variant. Aliases: ``train`` = tr, ``val`` = cv, ``test`` = tt.
"""

from __future__ import annotations

from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import (
    ExternalFolder,
    Item,
    mixture,
    pick_variant,
    subdirs,
    wavs,
)

NAME = "wham"
SPLITS = ("tr", "cv", "tt")
ALIASES = {"train": ("tr",), "val": ("cv",), "test": ("tt",)}
KINDS = ("mix_clean", "mix_both", "mix_single")


def _split_dir(root: Path) -> str | None:
    return next((s for s in SPLITS if (root / s).is_dir()
                 and any(d.name.startswith(KINDS) for d in subdirs(root / s))), None)


def _base(root: Path) -> Path:
    for split in SPLITS:
        try:
            return pick_variant(root, "WHAM!", split)
        except DatasetError:
            continue
    raise DatasetError(f"{root}: no tr/, cv/ or tt/ here nor under wav8k|wav16k/min|max; "
                       "expected a WHAM! or WHAMR! folder")


def detect(root: Path) -> bool:
    try:
        return _split_dir(_base(root)) is not None
    except DatasetError:
        return False


def open_folder(root: Path) -> ExternalFolder:
    base = _base(root)
    if _split_dir(base) is None:
        raise DatasetError(f"{base}: no mix_clean/, mix_both/ or mix_single/ (or their "
                           "_anechoic/_reverb forms) under tr/, cv/ or tt/; expected a WHAM! "
                           "or WHAMR! folder")
    reverb = any(d.name.endswith(("_reverb", "_anechoic"))
                 for s in SPLITS for d in subdirs(base / s))
    items: dict[str, list[Item]] = {}
    for split in SPLITS:
        folders = [d.name for d in subdirs(base / split) if d.name.startswith(KINDS)]
        if not folders:
            continue
        names: dict[str, None] = {}
        for folder in folders:
            names.update(dict.fromkeys(p.name for p in wavs(base / split / folder)))
        for name in names:
            items.setdefault(split, []).append(
                _item(split, name, folders, reverb))
    kind = "WHAMR!" if reverb else "WHAM!"
    return ExternalFolder(base, NAME, items, aliases=ALIASES,
                          info={"variant": "/".join(base.parts[-2:]), "corpus": kind})


def _item(split: str, name: str, folders: list[str], reverb: bool) -> Item:
    def at(folder: str) -> str:
        return f"{split}/{folder}/{name}"

    tracks: dict[str, str] = {}
    if reverb:
        for k in (1, 2):
            tracks[f"source{k}"] = at(f"s{k}_anechoic")
            tracks[f"source{k}_reverb"] = at(f"s{k}_reverb")
    else:
        tracks.update({"source1": at("s1"), "source2": at("s2")})
    mixes = []
    for folder in folders:
        kind = next(k for k in KINDS if folder.startswith(k))
        suffix = "_reverb" if folder.endswith("_reverb") else ""
        targets = ["source1"] if kind == "mix_single" else ["source1", "source2"]
        components = [f"{t}{suffix}" for t in targets]
        if kind != "mix_clean":
            tracks["noise"] = at("noise")
            components.append("noise")
        mixes.append(mixture(folder, at(folder), targets, components))
    # The references only a mixture present needs: WHAMR!'s reverberant sources, or s2.
    used = {c for m in mixes for c in (*m["components"], *m["targets"])}
    tracks = {k: v for k, v in tracks.items() if k in used}
    return Item(f"{split}/{Path(name).stem}", tracks, tuple(mixes))
