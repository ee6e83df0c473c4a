"""Stage ``arrange``: which utterances and clips each group's tracks play, and when.

Each group draws from its own generator (spec seed, step, group id): its speakers from the
split's speakers without replacement, then each track's clips (:mod:`sonicspec.audio.arrange`).
Lengths are counted at the dataset's rate, as the render stage will resample the files.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

from sonicspec import artifacts
from sonicspec.artifacts import speech_track_name
from sonicspec.audio.arrange import Clip, arrange_background, arrange_speech
from sonicspec.audio.corpora import CorpusIndex, CorpusItem
from sonicspec.errors import AudioError, CorpusError
from sonicspec.hashing import rng_for
from sonicspec.plan.params import ArrangeParams
from sonicspec.stages.context import JobContext
from sonicspec.stages.corpus import corpus_role
from sonicspec.units import seconds_to_samples


def resampled_length(num_samples: int, from_hz: int, to_hz: int) -> int:
    """Samples after polyphase resampling from ``from_hz`` to ``to_hz`` (``resample_poly``)."""
    ratio = Fraction(to_hz, from_hz)
    return -((-num_samples * ratio.numerator) // ratio.denominator)


def _clip(item: CorpusItem, rate: int) -> Clip:
    return Clip(item.id, resampled_length(item.num_samples, item.sample_rate_hz, rate),
                item.text, item.speaker)


def _files(items: list[CorpusItem], segments) -> dict[str, dict[str, Any]]:
    by_id = {i.id: i for i in items}
    return {s.id: {"path": by_id[s.id].path, "sample_rate_hz": by_id[s.id].sample_rate_hz,
                   "speaker": by_id[s.id].speaker} for s in segments}


def scene_speakers(names: list[str], params: ArrangeParams, seed: int) -> list[list[str]]:
    """Per group of a shard composed per speaker and scene, its speakers: slot ``j`` takes
    run ``j`` of ``mixture.speakers`` names of the scene's shuffle of ``names`` (seeded by the
    spec seed, the split and the scene), so a scene's groups use every speaker at most once.
    """
    comp = params.composition
    if comp is None:
        raise ValueError("scene_speakers: the shard is not composed per speaker and scene")
    if len(names) != comp.speakers:
        raise CorpusError(
            f"corpora.speech: split '{params.split}' has {len(names)} usable speakers in the "
            f"corpus index but the plan counted {comp.speakers} speaker folders "
            "(splits.*.groups: each_speaker_per_scene); a speaker whose every file was "
            "skipped is not in the index: fix or remove its folder and plan again")
    k = params.mixture.speakers
    order = rng_for(seed, "scene-speakers", params.split, comp.scene_id).permutation(len(names))
    return [[names[i] for i in order[j * k:(j + 1) * k]] for j in comp.slots]


def arrange_group(indexes: dict[str, CorpusIndex], params: ArrangeParams, group: str,
                  rng: np.random.Generator, speakers: list[str] | None = None
                  ) -> dict[str, Any]:
    """The tracks of one group as JSON data: name, role, speaker, segments, files (paths
    relative to the corpus root of the track's role). ``speakers``: the group's speakers
    (a split composed per speaker and scene); None draws them from ``rng``."""
    mix = params.mixture
    rate = params.sample_rate_hz
    split = params.split
    clip_samples = seconds_to_samples(mix.duration_s, rate)
    speech = indexes["speech"]
    speech.require_speakers(split, mix.speakers, "corpora.speech")
    by_speaker = speech.speakers(split)
    names = sorted(by_speaker)
    if speakers is None:
        chosen = [names[i] for i in rng.choice(len(names), mix.speakers, replace=False)]
    else:
        chosen = speakers
    tracks = []
    for k, speaker in enumerate(chosen):
        items = by_speaker[speaker]
        try:
            segments = arrange_speech(
                [_clip(i, rate) for i in items], clip_samples, mix.utterances_per_speaker,
                mix.utterance_gap_s, rate, rng,
                where=f"group {group} source{k + 1} (speaker {speaker})")
        except AudioError as err:
            raise AudioError(f"{err} (the clip is mixture.duration_s, the gaps "
                             "mixture.utterance_gap_s)") from None
        tracks.append({"name": speech_track_name(k), "role": "speech", "speaker": speaker,
                       "segments": [s.to_dict() for s in segments],
                       "files": _files(items, segments)})
    background = {"noise": (mix.noise_clips, mix.noise_gap_s),
                  "music": (mix.music_clips, mix.music_gap_s)}
    for role, (clips, gaps) in background.items():
        if role not in indexes or clips[1] == 0:
            continue
        items = indexes[role].split(split)
        indexes[role].require_items(split, 1, f"corpora.{role}")
        segments = arrange_background([_clip(i, rate) for i in items], clip_samples,
                                      clips, gaps, rate, rng, where=f"group {group} {role}")
        if segments:
            tracks.append({"name": role, "role": role, "speaker": "",
                           "segments": [s.to_dict() for s in segments],
                           "files": _files(items, segments)})
    return {"group": group, "clip_samples": clip_samples, "tracks": tracks}


def run(ctx: JobContext) -> None:
    jobs = ctx.plan.by_key()
    indexes: dict[str, CorpusIndex] = {}
    for key in ctx.input_keys("corpus"):
        indexes[corpus_role(jobs[key])] = artifacts.read_corpus_index(
            ctx.store.read("corpus", key).arrays)
    params: ArrangeParams = ctx.params
    if params.composition is None:
        chosen: list[list[str] | None] = [None] * len(params.groups)
    else:
        chosen = list(scene_speakers(sorted(indexes["speech"].speakers(params.split)), params,
                                     params.seed))
    groups = [arrange_group(indexes, params, g, ctx.rng("arrange", g), c)
              for g, c in zip(params.groups, chosen, strict=True)]
    ctx.write({"group_count": np.array([len(groups)], dtype=np.int64)},
              artifacts.encode("arrange", {"groups": groups}))
