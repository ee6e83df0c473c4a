"""Stage ``corpus``: index a corpus (generating it first for the ``generated`` kind).

The index (every usable file with its split, speaker, length and words; paths relative to the
corpus root, so the artifact is the same wherever the corpus lives) is the artifact; it is
stored as one compressed JSON array so a 100 000-utterance corpus does not bloat the group's
metadata. A second copy is cached beside the corpus in the spec's ``cache_dir``, so a cleaned
store re-indexes without re-reading every file header. Files that cannot be used are logged by
name as warnings and listed in the artifact (``skipped``: path below the root and the reason;
:func:`skipped_files` reads them back for a plan).
"""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from sonicspec import artifacts
from sonicspec.audio.corpora import (
    CorpusIndex,
    cached_index,
    index_fma,
    index_folder,
    index_fsd50k,
    index_librispeech,
    index_split_folders,
)
from sonicspec.errors import CorpusError, SonicspecError
from sonicspec.plan.model import Job, Plan
from sonicspec.plan.params import CorpusParams, read_params
from sonicspec.shares import split_shares
from sonicspec.spec.corpora import (
    FmaCorpusSpec,
    Fsd50kCorpusSpec,
    GeneratedNoiseSpec,
    GeneratedSpeechSpec,
    LibriSpeechCorpusSpec,
)
from sonicspec.stages.context import JobContext
from sonicspec.store import ArtifactStore

log = logging.getLogger("sonicspec.stages.corpus")


def _generated(params: CorpusParams, cache: Path, key: str) -> CorpusIndex:
    from sonicspec.audio.generated import generate_background_corpus, generate_speech_corpus

    corpus, role, splits = params.corpus, params.role, list(params.splits)
    root = cache / "generated" / f"{role}-{key[:16]}"
    if isinstance(corpus, GeneratedSpeechSpec):
        subsets = generate_speech_corpus(root, splits, corpus.speakers_per_split,
                                         corpus.utterances_per_speaker, seed=params.seed)
        return index_librispeech(root, subsets)
    generate_background_corpus(root, role, splits, corpus.clips_per_split,
                               corpus.clip_duration_s, seed=params.seed,
                               sample_rate_hz=params.sample_rate_hz)
    return index_split_folders(root, splits)


def corpus_shares(ratios: dict[str, float] | None, splits: list[str], role: str
                  ) -> dict[str, float]:
    """The shares a ratio-split corpus gives the spec's splits (:func:`split_shares`)."""
    try:
        return split_shares(ratios, splits)
    except SonicspecError as err:
        raise CorpusError(f"corpora.{role}.split_ratios: {err}") from None


def build_index(params: CorpusParams, paths: dict[str, str], key: str,
                rng: np.random.Generator) -> CorpusIndex:
    """The index a corpus job describes (its folder from ``paths``, ratio splits from ``rng``)."""
    corpus, role, splits = params.corpus, params.role, list(params.splits)
    if isinstance(corpus, GeneratedSpeechSpec | GeneratedNoiseSpec):
        return _generated(params, Path(paths["cache"]), key)
    root = Path(paths["root"])
    if isinstance(corpus, LibriSpeechCorpusSpec):
        return index_librispeech(root, {s: v for s, v in corpus.subsets.items() if s in splits})
    ratios = corpus_shares(corpus.split_ratios, splits, role)
    if isinstance(corpus, Fsd50kCorpusSpec):
        return index_fsd50k(root, ratios, corpus.exclude_labels, rng)
    if isinstance(corpus, FmaCorpusSpec):
        return index_fma(root, corpus.size, ratios, corpus.instrumental_only, rng)
    return index_folder(root, corpus.extensions, ratios, rng, by_speaker=role == "speech")


def corpus_role(job: Job) -> str:
    """Which corpus a corpus job indexes: ``speech``, ``noise`` or ``music``."""
    return read_params("corpus", job.params, job.label).role


def corpus_root(job: Job) -> Path:
    """The folder a corpus job's item paths are relative to."""
    if "root" in job.paths:
        return Path(job.paths["root"])
    return Path(job.paths["cache"]) / "generated" / f"{corpus_role(job)}-{job.key[:16]}"


def corpus_roots(ctx: JobContext) -> dict[str, Path]:
    """Role -> root of every corpus a job reads."""
    jobs = ctx.plan.by_key()
    return {corpus_role(jobs[k]): corpus_root(jobs[k]) for k in ctx.input_keys("corpus")}


def _portable(index: CorpusIndex, root: Path) -> CorpusIndex:
    """Item paths relative to the corpus root, so the artifact does not depend on where the
    corpus (or the spec) lives and two machines store the same bytes."""
    prefix = str(root).rstrip("/") + "/"
    items = tuple(replace(i, path=os.path.relpath(i.path, root)) for i in index.items)
    skipped = tuple((os.path.relpath(p, root), r) for p, r in index.skipped)
    return CorpusIndex(index.kind, items, tuple(p.replace(prefix, "") for p in index.problems),
                       skipped)


def run(ctx: JobContext) -> None:
    params: CorpusParams = ctx.params
    cache = Path(ctx.job.paths["cache"])
    rng = ctx.rng("corpus", params.role)
    root = corpus_root(ctx.job)
    index = cached_index(
        cache / "index" / f"{params.role}-{ctx.job.key}.json",
        lambda: _portable(build_index(params, dict(ctx.job.paths), ctx.job.key, rng), root))
    for problem in index.problems:
        log.warning("corpora.%s: %s", params.role, problem)
    counts = {}
    for split in params.splits:
        items = index.split(split)
        counts[split] = {"items": len(items), "speakers": len(index.speakers(split)),
                         "hours": round(sum(i.duration_s for i in items) / 3600.0, 6)}
    ctx.write(artifacts.corpus_index_arrays(index),
              {"role": params.role, "kind": params.corpus.kind,
               "splits": counts, "problems": list(index.problems),
               "skipped": [{"path": p, "reason": r} for p, r in index.skipped]})


def skipped_files(plan: Plan, store: ArtifactStore) -> dict[str, list[dict[str, str]]]:
    """Role -> the files its corpus index left out, ``{"path", "reason"}`` each (path relative
    to the corpus root), for every corpus job of ``plan`` already in ``store``.

    For the build summary and dataset.json: a corrupt file is skipped with a warning in the
    corpus job's log, and this is where it is counted.
    """
    out: dict[str, list[dict[str, str]]] = {}
    for job in plan.by_step()["corpus"]:
        if store.exists("corpus", job.key):
            data = store.read_data("corpus", job.key)
            out[corpus_role(job)] = [dict(s) for s in data.get("skipped", ())]
    return out
