"""VoiceBank-DEMAND (Valentini-Botinhao et al., "Noisy speech database for training speech
enhancement algorithms and TTS models", University of Edinburgh DataShare, 2017,
doi:10.7488/ds/2117), as the DataShare zips unpack.

Layout (48 kHz as released; the 16 kHz copies most papers use keep the names)::

    <root>/
        clean_testset_wav/p232_001.wav        noisy_testset_wav/p232_001.wav
        clean_trainset_28spk_wav/p226_001.wav noisy_trainset_28spk_wav/p226_001.wav
        clean_trainset_56spk_wav/...          noisy_trainset_56spk_wav/...

A ``noisy_<set>_wav`` file and the ``clean_<set>_wav`` file of the same name are one group
``<split>/<name>`` (splits ``test``, ``train_28spk``, ``train_56spk``; alias ``train`` =
``train_28spk``): track ``source1`` (the clean speech) and one enhancement mixture ``noisy``.
The noise itself is not released, so the mixture's components list only the speech
(``components_complete: false``): such items are read as written, not re-mixed.
"""

from __future__ import annotations

import re
from pathlib import Path

from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats.base import ExternalFolder, Item, mixture, wavs

NAME = "voicebank"
_NOISY = re.compile(r"^noisy_(?P<set>testset|trainset_\d+spk)_wav$")


def _split(set_name: str) -> str:
    return "test" if set_name == "testset" else set_name.replace("trainset", "train")


def detect(root: Path) -> bool:
    return root.is_dir() and any(_NOISY.match(p.name) for p in root.iterdir() if p.is_dir())


def open_folder(root: Path) -> ExternalFolder:
    sets = sorted(m.group("set") for p in root.iterdir() if p.is_dir()
                  and (m := _NOISY.match(p.name))) if root.is_dir() else []
    if not sets:
        raise DatasetError(f"{root}: no noisy_testset_wav/ (or noisy_trainset_*spk_wav/); "
                           "expected a VoiceBank-DEMAND folder")
    items: dict[str, list[Item]] = {}
    for name in sets:
        clean = root / f"clean_{name}_wav"
        if not clean.is_dir():
            raise DatasetError(f"{clean}: missing; the VoiceBank-DEMAND layout pairs "
                               f"noisy_{name}_wav/ with it")
        split = _split(name)
        for path in wavs(root / f"noisy_{name}_wav"):
            m = mixture("noisy", f"noisy_{name}_wav/{path.name}", ["source1"], ["source1"])
            m["components_complete"] = False
            items.setdefault(split, []).append(Item(
                f"{split}/{path.stem}", {"source1": f"clean_{name}_wav/{path.name}"}, (m,)))
    return ExternalFolder(root, NAME, items, aliases={"train": ("train_28spk",)})
