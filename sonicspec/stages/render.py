"""Stage ``render``: every track of every group through its RIRs at the microphone.

A track's dry signal is assembled from its clips (resampled to the dataset rate), then
rendered through the RIRs along its source's path (:func:`sonicspec.audio.render.render_moving`
with the spec's interpolation). A speech source walks its path while its utterances play (the
speed is set so the path spans them, as in the recipe, unless the trajectory gives one); noise
and music are static. The output is cut to the clip: ``(channels, clip samples)`` float32.

Optional training targets, rendered with the same path: ``direct`` (each RIR cut just after
its direct sound) and ``early`` (cut 50 ms after it). The dry track is always stored (mono,
small): the mixer may normalise on it, and the ``dry`` target exports it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.audio.arrange import Segment, assemble, speech_span
from sonicspec.audio.corpora import load_audio
from sonicspec.audio.render import render_moving, split_rir, walk_index
from sonicspec.errors import StageError
from sonicspec.stages.context import JobContext
from sonicspec.stages.corpus import corpus_roots


class _AudioCache:
    """Each corpus file read and resampled once per job."""

    def __init__(self, rate: int) -> None:
        self.rate = rate
        self._audio: dict[str, np.ndarray] = {}

    def clip(self, path: str, length: int) -> np.ndarray:
        if path not in self._audio:
            self._audio[path] = load_audio(path, self.rate)
        x = self._audio[path]
        # Polyphase resampling gives ceil(n * up / down) samples; keep exactly that many.
        return x[:length] if x.size >= length else np.pad(x, (0, length - x.size))


def _source_geometry(placement: dict[str, Any], name: str) -> dict[str, Any]:
    if name.startswith("source"):
        return placement["speech"][int(name[len("source"):]) - 1]
    return placement[name]


def track_audio(track: dict[str, Any], segments: list[Segment], cache: _AudioCache,
                corpus_root: Path) -> dict[str, np.ndarray]:
    """Each clip of a track, once, as long as its longest use needs.

    A clip can be used twice in one track (a small corpus split), the second use cut at the
    clip's end: keeping the last use's length (as before) made the first use fail.
    """
    need: dict[str, int] = {}
    for seg in segments:
        need[seg.id] = max(need.get(seg.id, 0), seg.offset + seg.end - seg.start)
    return {sid: cache.clip(str(corpus_root / track["files"][sid]["path"]), n)
            for sid, n in need.items()}


def render_track(track: dict[str, Any], rirs: np.ndarray, source: dict[str, Any],
                 mic_m: np.ndarray, params: dict[str, Any], cache: _AudioCache,
                 clip_samples: int, corpus_root: Path) -> dict[str, np.ndarray]:
    """``{"reverberant", "dry", and any targets}`` arrays of one track."""
    rate = params["sample_rate_hz"]
    segments = [Segment.from_dict(s) for s in track["segments"]]
    dry = assemble(segments, track_audio(track, segments, cache, corpus_root), clip_samples)
    points = np.asarray(source["rir_points_m"], dtype=np.float64)
    if len(points) != rirs.shape[0]:
        raise StageError(f"track {track['name']}: {len(points)} RIR points in the placement but "
                         f"{rirs.shape[0]} RIRs")
    position = walk_index(source["rir_points_distance_m"], clip_samples, speech_span(segments),
                          params["speed_m_s"], rate)
    method = params["interpolation"]
    out = {"dry": dry[None, :].astype(np.float32),
           "reverberant": render_moving(dry, rirs, position, method)[:, :clip_samples]
           .astype(np.float32)}
    wanted = [t for t in ("direct", "early") if t in params["targets"]]
    if wanted:
        distance = np.linalg.norm(points - mic_m[None, :], axis=1)
        delays = distance / params["speed_of_sound_m_s"] * rate
        direct, early = split_rir(rirs, delays, rate)
        for name, h in (("direct", direct), ("early", early)):
            if name in wanted:
                out[name] = render_moving(dry, h, position, method)[:, :clip_samples].astype(
                    np.float32)
    return out


def run(ctx: JobContext) -> None:
    params = ctx.params
    arrange = ctx.input_data("arrange")[0]["groups"]
    placements = ctx.input_data("placement")[0]["groups"]
    rir_art = ctx.input("rir")
    cache = _AudioCache(params["sample_rate_hz"])
    roots = corpus_roots(ctx)
    arrays: dict[str, np.ndarray] = {}
    groups = []
    for g, (arr, placement, rir_group) in enumerate(
            zip(arrange, placements, rir_art.data["groups"], strict=True)):
        if not arr["group"] == placement["group"] == rir_group["group"]:
            raise StageError(f"{ctx.job.label}: inputs disagree on group order "
                             f"({arr['group']}, {placement['group']}, {rir_group['group']})")
        rir_by_name = {s["name"]: s for s in rir_group["sources"]}
        mic = np.asarray(placement["mic_m"], dtype=np.float64)
        tracks = []
        for n, track in enumerate(arr["tracks"]):
            ctx.progress(f"group {g + 1}/{len(arrange)}, track {n + 1}/{len(arr['tracks'])}")
            name = track["name"]
            if name not in rir_by_name:
                raise StageError(f"{ctx.job.label}: group {arr['group']} has no RIRs for "
                                 f"track {name}")
            rirs = np.asarray(rir_art.arrays[rir_by_name[name]["array"]], dtype=np.float64)
            signals = render_track(track, rirs, _source_geometry(placement, name), mic, params,
                                   cache, arr["clip_samples"], roots[track["role"]])
            keys = {}
            for kind, x in signals.items():
                key = f"g{g}_{name}_{kind}"
                arrays[key] = x
                keys[kind] = key
            tracks.append({"name": name, "role": track["role"], "arrays": keys,
                           "channels": int(signals["reverberant"].shape[0])})
        groups.append({"group": arr["group"], "clip_samples": arr["clip_samples"],
                       "tracks": tracks})
    ctx.write(arrays, {"groups": groups, "sample_rate_hz": params["sample_rate_hz"]})
