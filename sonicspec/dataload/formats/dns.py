"""The DNS Challenge synthetic test sets (Reddy et al., "The INTERSPEECH 2020 Deep Noise
Suppression Challenge", 2020; microsoft/DNS-Challenge, ``datasets/test_set/synthetic``).

Layout (16 kHz, 150 clips of 10 s per condition)::

    test_set/synthetic/               (point at test_set, synthetic or one condition)
        no_reverb/
            clean/clean_fileid_0.wav
            noisy/clnsp102_traffic_248091_3_snr0_tl-21_fileid_0.wav
        with_reverb/
            clean/clean_fileid_0.wav  (the reverberant speech: the with_reverb target)
            noisy/..._fileid_0.wav

A noisy file and the clean file of the same ``fileid_<N>`` are one group
``<condition>/fileid_<N>``: track ``source1`` (the clean file) and one enhancement mixture
``noisy``. Splits ``no_reverb`` and ``with_reverb``; alias ``test`` = both. The noise is not
released alone (``components_complete: false``: items are read as written).
"""

from __future__ import annotations

import re
from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item, mixture, wavs

NAME = "dns"
CONDITIONS = ("no_reverb", "with_reverb")
_FILEID = re.compile(r"fileid_(\d+)\.(wav|flac)$", re.IGNORECASE)


def _conditions(root: Path) -> dict[str, Path]:
    for base in (root / "synthetic", root):
        found = {c: base / c for c in CONDITIONS if (base / c / "noisy").is_dir()}
        if found:
            return found
    if (root / "noisy").is_dir() and (root / "clean").is_dir():
        return {root.name if root.name in CONDITIONS else "test": root}
    return {}


def detect(root: Path) -> bool:
    return bool(_conditions(root))


def open_folder(root: Path) -> ExternalFolder:
    conditions = _conditions(root)
    if not conditions:
        raise DatasetError(f"{root}: no synthetic/no_reverb|with_reverb/noisy/ here; expected "
                           "a DNS Challenge test_set folder")
    top = min((p.parent for p in conditions.values()), key=lambda p: len(p.parts))
    items: dict[str, list[Item]] = {}
    for split, folder in conditions.items():
        if not (folder / "clean").is_dir():
            raise DatasetError(f"{folder / 'clean'}: missing; the DNS test set pairs "
                               f"{folder / 'noisy'} with it")
        for path in wavs(folder / "noisy"):
            m = _FILEID.search(path.name)
            if m is None:
                raise DatasetError(f"{path}: no fileid_<N> in its name; expected the DNS "
                                   "test set's <...>_fileid_<N>.wav")
            here = folder.relative_to(top).as_posix() if folder != top else "."
            prefix = "" if here == "." else f"{here}/"
            mix = mixture("noisy", f"{prefix}noisy/{path.name}", ["source1"], ["source1"])
            mix["components_complete"] = False
            items.setdefault(split, []).append(Item(
                f"{split}/fileid_{m.group(1)}",
                {"source1": f"{prefix}clean/clean_fileid_{m.group(1)}{path.suffix}"}, (mix,)))
    return ExternalFolder(top, NAME, items, aliases={"test": tuple(conditions)})
