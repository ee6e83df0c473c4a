"""Preflight: what a build would meet late, found before it starts (issue 16).

``sonicspec validate --check-files``, ``sonicspec plan`` and the start of ``sonicspec build``
run :func:`preflight` on a loaded spec: the files the spec names exist; meshes load through
the mesh stage's own reader; every corpus folder holds audio that the corpus readers' probe
can open; the optional packages and programs the spec's features need are installed. Each
finding is a :class:`~sonicspec.spec.load.Problem` at its place in the spec file, with the fix.

Not a stage: no store, no plan. Heavy modules are imported inside the checks, so commands
that only ask :func:`module_available` stay quick.
"""

from __future__ import annotations

import glob
import importlib.util
import shutil
import warnings
from collections.abc import Callable, Iterable, Iterator
from itertools import islice
from pathlib import Path
from typing import Any

from sonicspec.spec.checks import check_files
from sonicspec.spec.corpora import (
    FmaCorpusSpec,
    FolderCorpusSpec,
    Fsd50kCorpusSpec,
    LibriSpeechCorpusSpec,
)
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.load import LoadedSpec, Problem
from sonicspec.spec.scene import MeshObstacleSpec, MeshSceneSpec
from sonicspec.spec.validate import locate_in_file

PROBE_FILES = 20
"""Files opened per corpus folder at most, until one reads: a folder whose first 20 audio
files are all unreadable is reported (the corpus stage would skip every one of them)."""

PLOT_NEEDS = "--plot needs matplotlib: pip install 'sonicspec[plot]'"
"""What ``scene inspect --plot`` and ``rir --plot`` say, before any work, without matplotlib."""


def module_available(name: str) -> bool:
    """True if the Python package ``name`` is installed (tests replace this to fake one
    missing)."""
    return importlib.util.find_spec(name) is not None


def program_available(name: str) -> bool:
    """True if the program ``name`` is on the PATH (tests replace this to fake one missing)."""
    return shutil.which(name) is not None


def mp3_readable() -> bool:
    """True if this libsndfile reads MP3 (1.1 and later; FMA's tracks are MP3)."""
    import soundfile as sf

    return "MP3" in sf.available_formats()


def preflight(loaded: LoadedSpec) -> list[Problem]:
    """Every problem a build of ``loaded`` would meet in its files, corpora and environment.

    Errors and warnings, located in the spec file and sorted, like
    :func:`~sonicspec.spec.validate_file`'s; the build should not start while any is an
    error. Meshes are read in full (a glob of scans takes as long as reading them once).
    """
    spec, base = loaded.spec, Path(loaded.base_dir)
    problems = check_files(spec, base)
    missing = {p.path for p in problems if p.severity == "error"}
    problems += _requirements(spec)
    problems += _meshes(spec, base, missing)
    problems += _corpora(spec, base, missing)
    return locate_in_file(problems, loaded.source)


def _err(path: tuple, message: str) -> Problem:
    return Problem(tuple(path), message)


# --- packages and programs ---------------------------------------------------------------


def _requirements(spec: DatasetSpec) -> list[Problem]:
    out = []
    hrtf = getattr(spec.microphone, "hrtf", None)
    if hrtf is not None and hrtf.kind == "sofa" and not module_available("sofar"):
        out.append(_err(("microphone", "hrtf", "kind"),
                        "expected the sofar package to read a SOFA HRTF, got none installed; "
                        "pip install 'sonicspec[sofa]'"))
    if spec.corpora.speech.kind == "generated" and not program_available("espeak-ng"):
        out.append(_err(("corpora", "speech", "kind"),
                        "expected espeak-ng on the PATH to generate speech, got none; "
                        "apt-get install espeak-ng (or use a librispeech or folder corpus)"))
    if isinstance(spec.corpora.music, FmaCorpusSpec) and not mp3_readable():
        import soundfile as sf

        out.append(_err(("corpora", "music", "kind"),
                        "expected a libsndfile that reads MP3 (FMA's tracks are MP3), got "
                        f"libsndfile {sf.__libsndfile_version__} without it; "
                        "pip install -U soundfile (its wheels bring libsndfile 1.1 or later)"))
    return out


# --- meshes --------------------------------------------------------------------------------


def _read(path: tuple, what: str, read: Callable[[], Any]) -> list[Problem]:
    """Problems of ``read()``: its error, or the warnings it raised (e.g. PLY labels lost)."""
    from sonicspec.errors import SonicspecError, SonicspecWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        try:
            read()
        except SonicspecError as exc:
            return [_err(path, str(exc))]
        except Exception as exc:  # a corrupt file can trip any reader
            return [_err(path, f"{what}: expected a readable mesh, got {type(exc).__name__}: "
                               f"{exc}; is the file corrupt or truncated?")]
    return [Problem(tuple(path), str(w.message), severity="warning") for w in caught
            if issubclass(w.category, SonicspecWarning)]


def _meshes(spec: DatasetSpec, base: Path, missing: set[tuple]) -> list[Problem]:
    if not any(isinstance(s, MeshSceneSpec) or any(isinstance(o, MeshObstacleSpec)
                                                   for o in s.obstacles) for s in spec.scenes):
        return []
    from sonicspec.artifacts.scenes import load_scan
    from sonicspec.errors import CompileError
    from sonicspec.geometry.io import load_mesh
    from sonicspec.plan.compile import FileDigests, SceneEntry, scene_jobs
    from sonicspec.plan.params import read_params

    out: list[Problem] = []
    for i, scene in enumerate(spec.scenes):
        for j, ob in enumerate(scene.obstacles):
            where = ("scenes", i, "obstacles", j, "path")
            if isinstance(ob, MeshObstacleSpec) and where not in missing:
                file = base / ob.path
                out += _read(where, str(file), lambda file=file: load_mesh(file))
        where = ("scenes", i, "path")
        if not isinstance(scene, MeshSceneSpec) or where in missing:
            continue
        files = ([Path(p) for p in sorted(glob.glob(str(base / scene.path)))
                  if Path(p).is_file()] if glob.has_magic(scene.path) else [base / scene.path])
        digests = FileDigests()
        for file in files:
            entry = SceneEntry(f"{scene.id}/{file.stem}" if glob.has_magic(scene.path)
                               else scene.id, i, file)
            try:
                ((_, job, _),) = scene_jobs(spec, [entry], base, digests)
            except CompileError as exc:
                out.append(_err(where, str(exc).removeprefix(f"scenes[{i}]: ")))
                continue
            params = read_params("mesh", job.params, job.label)
            out += _read(where, str(file),
                         lambda params=params, job=job: load_scan(
                             params.scene, dict(job.paths), obj_labels=params.obj_labels))
    return out


# --- corpora -------------------------------------------------------------------------------


def _corpus_folders(corpus: Any, root: Path, splits: Iterable[str]
                    ) -> Iterator[tuple[tuple[str, ...], Path, set[str]]]:
    """(spec path, folder, file endings) of every folder a corpus reader reads audio from."""
    from sonicspec.audio.corpora import normalise_extensions

    if isinstance(corpus, LibriSpeechCorpusSpec):
        for split in splits:
            for sub in corpus.subsets.get(split, ()):
                yield ("subsets", split), root / sub, {".flac"}
    elif isinstance(corpus, Fsd50kCorpusSpec):
        for part in ("FSD50K.dev_audio", "FSD50K.eval_audio"):
            yield ("root",), root / part, {".wav"}
    elif isinstance(corpus, FmaCorpusSpec):
        yield ("size",), root / f"fma_{corpus.size}", {".mp3"}
    elif isinstance(corpus, FolderCorpusSpec):
        yield ("root",), root, normalise_extensions(corpus.extensions)


def _corpora(spec: DatasetSpec, base: Path, missing: set[tuple]) -> list[Problem]:
    from sonicspec.audio.corpora import audio_files, probe_audio

    out: list[Problem] = []
    for role in ("speech", "noise", "music"):
        corpus = getattr(spec.corpora, role)
        if corpus is None or not hasattr(corpus, "root") or ("corpora", role, "root") in missing:
            continue
        if isinstance(corpus, FmaCorpusSpec) and not mp3_readable():
            continue  # reported by _requirements
        # The readers pool the folders of one spec path (FSD50K's dev and eval, a split's
        # LibriSpeech subsets): only a path with no readable file at all fails the build.
        unreadable: dict[tuple, list[str]] = {}
        readable: set[tuple] = set()
        for sub, folder, endings in _corpus_folders(corpus, base / corpus.root, spec.splits):
            where = ("corpora", role, *sub)
            if not folder.is_dir() or where in readable:
                continue  # a missing folder is check_files' to name
            tried = []
            for file in islice(audio_files(folder, endings), PROBE_FILES):
                probe = probe_audio(file)
                if not isinstance(probe, str):
                    readable.add(where)
                    break
                tried.append(f"{file}: {probe}")
            else:
                if not tried:
                    why = (f"expected audio files ending in {', '.join(sorted(endings))} in "
                           f"'{folder}', got none")
                else:
                    first = "" if len(tried) == 1 else f"the first {len(tried)}, e.g. "
                    why = (f"expected readable audio files in '{folder}', got none readable "
                           f"among {first}{tried[0]}; the corpus stage would skip them all")
                unreadable.setdefault(where, []).append(why)
        for where, whys in unreadable.items():
            if where not in readable:
                out += [_err(where, why) for why in whys]
    return out
