"""SonicSet's inputs in their real layouts, as small as they can be, for the preset's tests.

``specs/sonicset.yaml`` reads ``data/mp3d/<building>/<building>.glb`` (with the
``_semantic.ply`` and ``.house`` beside it), ``data/LibriSpeech/<subset>/<speaker>/<chapter>/``,
``data/FSD50K`` and ``data/fma``. :func:`write_sonicset_inputs` writes all of them under one
folder: every scan is the same one-room Matterport fixture under its own id (hard links, so 90
scans cost one), and every speaker reads the same few synthetic utterances (hard links again),
so the paper's 921 / 40 / 40 speakers take a second to lay out.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from sonicspec.audio.generated import file_rng, normalise, voiced, write_audio_file
from sonicspec.testing.corpora import write_fma, write_fsd50k
from sonicspec.testing.meshes import write_matterport_scene
from sonicspec.units import seconds_to_samples

PAPER_SPEAKERS = {"train-clean-360": 921, "dev-clean": 40, "test-clean": 40}
"""LibriSpeech's speakers in the subsets SonicSet uses (train / val / test)."""


def _link(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)
    except OSError:  # a file system without hard links
        shutil.copyfile(src, dst)


def write_scans(root: Path, scene_ids: Sequence[str]) -> list[Path]:
    """``<root>/<id>/<id>.glb``, ``<id>_semantic.ply`` and ``<id>.house`` for every id: the
    one-room Matterport fixture (:func:`write_matterport_scene`) under each name."""
    root = Path(root)
    first = write_matterport_scene(root / scene_ids[0], scene_ids[0])
    out = [first.glb]
    for sid in scene_ids[1:]:
        folder = root / sid
        folder.mkdir(parents=True, exist_ok=True)
        _link(first.glb, folder / f"{sid}.glb")
        _link(first.semantic_ply, folder / f"{sid}_semantic.ply")
        (folder / f"{sid}.house").write_text(
            first.house.read_text(encoding="ascii").replace(scene_ids[0], sid), encoding="ascii")
        out.append(folder / f"{sid}.glb")
    return out


def write_speaker_folders(root: Path, subsets: Mapping[str, int], *, utterances: int = 5,
                          utterance_s: float = 8.0, seed: int = 0,
                          sample_rate_hz: int = 16000) -> dict[str, list[str]]:
    """A LibriSpeech-layout corpus with ``subsets[name]`` speakers in each subset (ids unique
    across subsets): one chapter each, ``utterances`` FLAC files of synthetic voice
    (``utterance_s`` long) shared by hard links, and the chapter's ``.trans.txt``.
    Returns subset -> speaker ids."""
    root = Path(root)
    pool = root / ".pool"
    pool.mkdir(parents=True, exist_ok=True)
    n = seconds_to_samples(utterance_s, sample_rate_hz)
    voices = []
    for k in range(utterances):
        path = pool / f"u{k}.flac"
        if not path.is_file():
            x = normalise(voiced(n, sample_rate_hz, file_rng(seed, "utterance", k)), 0.5)
            write_audio_file(path, x.astype(np.float32), sample_rate_hz, "FLAC", "PCM_16")
        voices.append(path)
    out: dict[str, list[str]] = {}
    speaker = 100
    for subset in sorted(subsets):
        out[subset] = []
        for _ in range(int(subsets[subset])):
            chapter = root / subset / str(speaker) / "1000"
            chapter.mkdir(parents=True, exist_ok=True)
            lines = []
            for k, src in enumerate(voices):
                uid = f"{speaker}-1000-{k:04d}"
                _link(src, chapter / f"{uid}.flac")
                lines.append(f"{uid} A SENTENCE THE FIXTURE SPEAKS NUMBER {k}")
            (chapter / f"{speaker}-1000.trans.txt").write_text("\n".join(lines) + "\n")
            out[subset].append(str(speaker))
            speaker += 1
    shutil.rmtree(pool)
    return out


def write_sonicset_inputs(data: Path, scene_ids: Sequence[str],
                          speakers: Mapping[str, int] = PAPER_SPEAKERS, *, seed: int = 0,
                          noise_clips: tuple[int, int] = (14, 6), music_tracks: int = 12
                          ) -> Path:
    """Everything ``specs/sonicset.yaml`` reads, under ``data`` (the spec's ``data/``)."""
    data = Path(data)
    write_scans(data / "mp3d", scene_ids)
    write_speaker_folders(data / "LibriSpeech", speakers, seed=seed)
    write_fsd50k(data / "FSD50K", *noise_clips, clip_duration_s=6.0, seed=seed + 1,
                 sample_rate_hz=16000)
    write_fma(data / "fma", music_tracks, size="large", clip_duration_s=8.0, seed=seed + 2,
              sample_rate_hz=16000)
    return data
