"""What a spec needs on disk and is not there yet: for ``plan --summary`` and the errors that
meet absent data, one line per missing source saying what to download and where to put it.

The layouts are the readers' (``sonicspec.audio.corpora`` and the ``matterport`` mesh format);
paths are relative to the spec's folder, as the spec writes them.
"""

from __future__ import annotations

import glob
from pathlib import Path

from sonicspec.spec.dataset import DatasetSpec

# Where each kind of data comes from and how its folder must look (the readers' layouts).
LAYOUTS: dict[str, str] = {
    "matterport": (
        "Matterport3D (https://niessner.github.io/Matterport/: the terms of use, then "
        "download_mp.py --task habitat for the .glb files): one folder per building, "
        "{root}/<building id>/<building id>.glb; each building becomes a scene "
        "mp3d/<building id>"),
    "mesh": "mesh files (glb, gltf, obj, ply) matching {glob}",
    "librispeech": (
        "LibriSpeech (https://www.openslr.org/12: {subsets}): unpack so that "
        "{root}/<subset>/<speaker>/<chapter>/<speaker>-<chapter>-<nnnn>.flac and "
        "<speaker>-<chapter>.trans.txt exist"),
    "fsd50k": (
        "FSD50K (https://zenodo.org/record/4060432): {root}/FSD50K.dev_audio/<fname>.wav, "
        "{root}/FSD50K.eval_audio/<fname>.wav and {root}/FSD50K.ground_truth/dev.csv, "
        "eval.csv"),
    "fma": (
        "FMA (https://github.com/mdeff/fma: fma_{size}.zip and fma_metadata.zip): "
        "{root}/fma_{size}/<nnn>/<track id>.mp3 and {root}/fma_metadata/tracks.csv"),
    "folder": "a folder of audio files ({extensions}) at {root}",
}


def missing_data(spec: DatasetSpec, base_dir: Path) -> list[str]:
    """One line per data source of ``spec`` that is absent under ``base_dir`` (the spec's
    folder): a mesh glob that matches no file, a corpus root that is not a folder. Empty when
    everything the spec reads is there (or it reads nothing: procedural scenes, generated
    corpora)."""
    base = Path(base_dir)
    out: list[str] = []
    for k, scene in enumerate(spec.scenes):
        pattern = getattr(scene, "path", None)
        if scene.kind != "mesh" or not pattern:
            continue
        if glob.glob(str(base / pattern)):
            continue
        if getattr(scene, "format", None) == "matterport":
            root = pattern.split("*")[0].rstrip("/") or "."
            what = LAYOUTS["matterport"].format(root=root)
        else:
            what = LAYOUTS["mesh"].format(glob=pattern)
        out.append(f"scenes[{k}] ({scene.id}): no file matches {pattern!r} under {base}; "
                   f"download {what}")
    for role in ("speech", "noise", "music"):
        corpus = getattr(spec.corpora, role, None)
        root = getattr(corpus, "root", None)
        if corpus is None or root is None or (base / root).is_dir():
            continue
        fields = {"root": root, "size": getattr(corpus, "size", "full"),
                  "extensions": ", ".join(getattr(corpus, "extensions", []) or []),
                  "subsets": ", ".join(sorted({s for subs in (getattr(corpus, "subsets", None)
                                                              or {}).values() for s in subs}))}
        what = LAYOUTS.get(corpus.kind, "{root}").format(**fields)
        out.append(f"corpora.{role} ({corpus.kind}): no folder {base / root}; download {what}")
    return out
