"""Stage ``render``: every track of every group through its RIRs at the microphone.

A track's dry signal is assembled from its clips (resampled to the dataset rate), then
rendered along its source's path. A speech source walks its path while its utterances play
(the speed is set so the path spans them, as in the recipe, unless the trajectory gives one);
noise and music are static. The output is cut to the clip: ``(channels, clip samples)``
float32.

``interpolation: paths``: the direct sound and every image-source path are rendered as
time-varying delays from the source's position at each emission
(:func:`sonicspec.acoustics.moving.delays.render_paths`), and the late part of the RIRs (the
RIRs less those paths) is crossfaded between RIR points. Otherwise the whole RIRs are blended
(:func:`sonicspec.audio.render.render_moving` with the spec's interpolation).

Optional training targets, rendered with the same path: ``direct`` (each RIR cut just after
its direct sound; with ``paths``, the direct path alone) and ``early`` (cut 50 ms after it;
with ``paths``, the paths arriving within 50 ms of the direct sound and the late part's first
50 ms). The dry track is always stored (mono, small): the mixer may normalise on it, and the
``dry`` target exports it.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from sonicspec import artifacts
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.directivity import SourceDirectivity, yaw_per_sample
from sonicspec.acoustics.engine import (
    SimulationSettings,
    array_offsets,
    direction_responses,
    load_hrirs,
    microphone_capsules,
    receiver_aperture_m,
    sphere_head,
)
from sonicspec.acoustics.moving.delays import PathSet, Receiver, render_paths
from sonicspec.acoustics.receivers.arrays import rotation
from sonicspec.acoustics.receivers.diffuse import (
    direction_count,
    isotropic_directions,
    isotropic_roots,
    render_isotropic,
)
from sonicspec.acoustics.receivers.hrtf import SphereHead, ear_axes
from sonicspec.artifacts import (
    ArrangedTrack,
    RenderData,
    RenderedTrack,
    RenderGroup,
)
from sonicspec.audio.arrange import Segment, assemble
from sonicspec.audio.corpora import load_audio
from sonicspec.audio.mix import measurement_channels
from sonicspec.audio.render import EARLY_MS, render_moving, split_rir
from sonicspec.errors import StageError
from sonicspec.plan.params import RenderParams
from sonicspec.spec.microphone import SofaHrtfSpec
from sonicspec.spec.mixture import BackgroundFieldSpec
from sonicspec.stages.context import JobContext
from sonicspec.stages.corpus import corpus_roots
from sonicspec.stages.directivity import facing_frames, source_patterns
from sonicspec.stages.motion import Timeline, Walk, group_speech, timeline


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


def track_audio(track: ArrangedTrack, segments: list[Segment], cache: _AudioCache,
                corpus_root: Path) -> dict[str, np.ndarray]:
    """Each clip of a track, once, as long as its longest use needs.

    A clip can be used twice in one track (a small corpus split), the second use cut at the
    clip's end: keeping the last use's length (as before) made the first use fail.
    """
    need: dict[str, int] = {}
    for seg in segments:
        need[seg.id] = max(need.get(seg.id, 0), seg.offset + seg.end - seg.start)
    return {sid: cache.clip(str(corpus_root / track.files[sid].path), n)
            for sid, n in need.items()}


def track_dry(track: ArrangedTrack, cache: _AudioCache, clip_samples: int,
              corpus_root: Path) -> np.ndarray:
    """A track's dry signal: its clips assembled on the clip's timeline, ``(clip,)``."""
    segments = track.segment_list()
    return assemble(segments, track_audio(track, segments, cache, corpus_root), clip_samples)


def render_track(track: ArrangedTrack, rirs: np.ndarray, line: Timeline,
                 params: RenderParams, cache: _AudioCache, clip_samples: int,
                 corpus_root: Path,
                 paths: tuple[PathSet, np.ndarray, OctaveFilterBank, Receiver] | None = None,
                 source: SourceDirectivity | None = None) -> dict[str, np.ndarray]:
    """``{"reverberant", "dry", and any targets}`` arrays of one track heard along its
    ``line`` (:func:`sonicspec.stages.motion.timeline`: its RIR points and when it is
    where). ``paths``: the source's exact early paths, its late RIRs and their bands
    (``interpolation: paths``); a static source heard by a static microphone is heard through
    its RIR, as its paths and late part sum to it, unless it turns its head. ``source``: a
    directional source's pattern and its yaw at every sample, for its paths."""
    rate = params.sample_rate_hz
    dry = track_dry(track, cache, clip_samples, corpus_root)
    points = line.source_m
    if len(points) != rirs.shape[0]:
        raise StageError(f"track {track.name}: {len(points)} RIR points in the placement but "
                         f"{rirs.shape[0]} RIRs")
    position = line.index
    wanted = [t for t in ("direct", "early") if t in params.targets]
    distance = np.linalg.norm(points - line.mic_m, axis=1)
    delays = distance / params.speed_of_sound_m_s * rate
    out = {"dry": dry[None, :].astype(np.float32)}
    turns = source is not None and source.yaw_deg.ndim and np.ptp(source.yaw_deg) > 0
    if len(points) == 1 and not turns:  # a static source: its RIR is its paths
        paths = None
    if paths is None:  # one RIR is one convolution, whichever blend
        method = "sample_crossfade" if params.interpolation == "paths" else params.interpolation
        out["reverberant"] = render_moving(dry, rirs, position, method)[:, :clip_samples]
        if wanted:
            direct, early = split_rir(rirs, delays, rate)
            for name, h in (("direct", direct), ("early", early)):
                if name in wanted:
                    out[name] = render_moving(dry, h, position, method)[:, :clip_samples]
    else:
        found, late, bank, receiver = paths

        def heard(subset: PathSet) -> np.ndarray:
            return render_paths(dry, position, points, subset, bank, n_out=clip_samples,
                                speed_of_sound_m_s=params.speed_of_sound_m_s,
                                receiver=receiver, source=source)

        tail = render_moving(dry, late, position, "sample_crossfade")[:, :clip_samples]
        out["reverberant"] = heard(found) + tail
        if "direct" in wanted:
            out["direct"] = heard(found.select(found.order == 0))
        if "early" in wanted:  # paths within 50 ms of the direct sound, and the tail's start
            _, early_tail = split_rir(late, delays, rate)
            out["early"] = (heard(_within(found, points, line.mic_m, EARLY_MS / 1000.0,
                                          params.speed_of_sound_m_s))
                            + render_moving(dry, early_tail, position,
                                            "sample_crossfade")[:, :clip_samples])
    return {k: v.astype(np.float32) for k, v in out.items()}


def path_receiver(microphone, center_m, line: Timeline | None = None, hrirs=None,
                  sample_rate_hz: float | None = None) -> Receiver:
    """The receiver :func:`render_paths` renders for a spec's microphone at ``center_m``,
    or moving and turning along ``line`` (a moving microphone's timeline); ``hrirs``: the
    loaded set of a SOFA HRTF (rendered at ``sample_rate_hz``)."""
    if isinstance(getattr(microphone, "hrtf", None), SofaHrtfSpec):
        if hrirs is None or sample_rate_hz is None:
            raise StageError("microphone.hrtf: a SOFA HRTF needs its HRIR set and the rate")
        hset = hrirs.resampled(sample_rate_hz)
        frame = ({"mic_track_m": line.mic_m, "yaw_deg": line.yaw_deg}
                 if line is not None and line.mic_moves else {"yaw_deg": microphone.yaw_deg})
        return Receiver("hrir", hrirs=hset, hrir_radius_rad=hrir_radius(hrirs),
                        pitch_deg=microphone.pitch_deg, **frame)
    capsules = _capsule_receiver(microphone, center_m, line)
    if capsules is not None:
        return capsules
    if line is not None and line.mic_moves:
        moving = {"mic_track_m": line.mic_m, "yaw_deg": line.yaw_deg,
                  "pitch_deg": line.pitch_deg}
        mic = microphone.model_dump(mode="json")
        if microphone.kind == "ambisonics":
            return Receiver("ambisonics", order=microphone.order, **moving)
        if microphone.kind == "mono":
            return Receiver(**moving)
        if microphone.kind == "binaural":  # its own frame: turned by the timeline's yaw
            head = sphere_head(mic)
            return Receiver("sphere_head", head=head, ear_axes=ear_axes(head, 0.0, 0.0),
                            **moving)
        return Receiver("array", offsets_m=array_offsets({**mic, "yaw_deg": 0.0,
                                                          "pitch_deg": 0.0}), **moving)
    if microphone.kind == "ambisonics":
        return Receiver("ambisonics", order=microphone.order,
                        center_m=np.asarray(center_m, dtype=np.float64),
                        yaw_deg=microphone.yaw_deg, pitch_deg=microphone.pitch_deg)
    if microphone.kind == "mono":
        return Receiver()
    if microphone.kind == "binaural":  # the sphere head (SOFA sets: above)
        mic = microphone.model_dump(mode="json")
        head = sphere_head(mic)
        return Receiver("sphere_head", head=head, center_m=np.asarray(center_m, dtype=float),
                        ear_axes=ear_axes(head, microphone.yaw_deg, microphone.pitch_deg))
    return Receiver("array", offsets_m=array_offsets(microphone.model_dump(mode="json")),
                    center_m=np.asarray(center_m, dtype=np.float64))


def _capsule_receiver(microphone, center_m, line: Timeline | None) -> Receiver | None:
    """The receiver of a device or of directional capsules (None for the others, which
    :func:`path_receiver` builds as before): capsules on a rigid sphere as the sphere head's
    ears, free-field ones as an array whose capsules weight each path by their pattern.
    Static: offsets and axes in the scene's frame; moving: in the microphone's own frame,
    turned along ``line``."""
    mic = microphone.model_dump(mode="json")
    capsules = microphone_capsules(mic)
    if capsules is None or (capsules.omni and microphone.kind != "device"):
        return None
    if line is not None and line.mic_moves:
        where = {"mic_track_m": line.mic_m, "yaw_deg": line.yaw_deg,
                 "pitch_deg": line.pitch_deg}
    else:
        where = {"center_m": np.asarray(center_m, dtype=np.float64)}
        capsules = capsules.rotated(rotation(microphone.yaw_deg, microphone.pitch_deg))
    if capsules.sphere_radius_m is not None:
        return Receiver("sphere_head", head=SphereHead(head_radius_m=capsules.sphere_radius_m),
                        ear_axes=capsules.axes, **where)
    directional = {} if capsules.omni else {"capsule_axes": capsules.axes,
                                            "capsule_alphas": capsules.alphas}
    return Receiver("array", offsets_m=capsules.offsets_m, **directional, **where)


#: A SOFA set's HRIRs are blended over this many times its covering angle (so every
#: direction has at least one measurement within the blend).
HRIR_RADIUS_FACTOR = 1.25


@functools.lru_cache(maxsize=4)
def hrir_radius(hrirs) -> float:
    """The angle a SOFA set's HRIRs are blended over (:data:`HRIR_RADIUS_FACTOR` times its
    covering angle), radians."""
    from sonicspec.acoustics.receivers.hrtf import covering_angle_rad

    return HRIR_RADIUS_FACTOR * covering_angle_rad(hrirs)


def _within(paths: PathSet, points: np.ndarray, mic_m: np.ndarray, window_s: float,
            speed_of_sound_m_s: float) -> PathSet:
    """``paths`` kept only at the points where they arrive within ``window_s`` of the direct
    sound's delay (a path that crosses the limit between two points fades there); ``points``
    and ``mic_m``: the source and the microphone at each RIR point (the microphone's images
    move with it, by the paths' isometries)."""
    points, mic_m = paths.on_points(points), paths.on_points(mic_m)
    direct_s = np.linalg.norm(points - mic_m, axis=1) / speed_of_sound_m_s
    if paths.isometries is not None:
        images = (np.einsum("kij,nj->kni", paths.isometries[:, :, :3], mic_m)
                  + paths.isometries[:, None, :, 3])
    else:
        images = np.broadcast_to(paths.images_m[:, None, :], (len(paths), len(points), 3))
    length = np.linalg.norm(points[None, :, :] - images, axis=2)
    if paths.lengths_m is not None:  # paths bent round an edge: their own lengths
        edge = np.isnan(paths.images_m[:, 0])
        length[edge] = np.nan_to_num(paths.lengths_m[edge], nan=np.inf)
    inside = (length / speed_of_sound_m_s - direct_s[None, :]) <= window_s
    return paths.with_weights(paths.weights * inside[:, :, None])


class _Diffuse:
    """A job's diffuse backgrounds (``mixture.noise_field`` / ``music_field``): the
    receiver's mixing matrices per field, computed once from its per-direction responses
    (:func:`~sonicspec.acoustics.engine.direction_responses`, through the receiver's own
    early-part synthesis), and the blend with the point source."""

    def __init__(self, ctx: JobContext, microphone, hrirs) -> None:
        rir_params = ctx.input_params("rir")
        self.settings = SimulationSettings.from_spec(
            rir_params.acoustics.model_dump(mode="json"), rir_params.sample_rate_hz,
            rir_params.speed_of_sound_m_s)
        self.mic = microphone.model_dump(mode="json")
        self.hrirs = hrirs
        self.binaural = microphone.kind == "binaural"
        self.targets = ctx.params.targets
        self._roots: dict[str, np.ndarray] = {}

    def roots(self, field: str) -> np.ndarray:
        if field not in self._roots:
            s = self.settings
            n = direction_count(field, receiver_aperture_m(self.mic), s.sample_rate_hz,
                                s.speed_of_sound_m_s)
            responses = direction_responses(isotropic_directions(field, n), s, self.mic,
                                            self.hrirs)
            self._roots[field] = isotropic_roots(responses, s.sample_rate_hz)
        return self._roots[field]

    def render(self, spec: BackgroundFieldSpec, point: dict[str, np.ndarray],
               rng: np.random.Generator) -> dict[str, np.ndarray]:
        """The track's signals with its ``reverberant`` part (and any targets) diffuse by
        ``spec.diffuse_fraction`` of its power: ``√f D + √(1 − f) g P``, ``g`` bringing the
        point part ``P`` to the diffuse part's power ``D`` on the channels loudness is
        measured on; ``direct``/``early`` targets keep only the point part's share."""
        dry = point["dry"][0].astype(np.float64)
        diffuse = render_isotropic(dry, self.roots(spec.diffuse), rng)
        f = spec.diffuse_fraction
        out = {"dry": point["dry"]}
        if f >= 1.0:
            out["reverberant"] = diffuse.astype(np.float32)
            for kind in ("direct", "early"):
                if kind in self.targets:
                    out[kind] = np.zeros_like(out["reverberant"])
            return out
        reverberant = point["reverberant"].astype(np.float64)
        p_point = float(np.mean(measurement_channels(reverberant, self.binaural) ** 2))
        p_diffuse = float(np.mean(measurement_channels(diffuse, self.binaural) ** 2))
        g = math.sqrt(p_diffuse / p_point) if p_point > 0 else 0.0
        w = math.sqrt(1.0 - f) * g
        out["reverberant"] = (math.sqrt(f) * diffuse + w * reverberant).astype(np.float32)
        for kind in ("direct", "early"):
            if kind in point:
                out[kind] = (w * point[kind]).astype(np.float32)
        return out


def run(ctx: JobContext) -> None:
    params: RenderParams = ctx.params
    arrange = artifacts.read(ctx, "arrange").groups
    placements = artifacts.read(ctx, "placement").groups
    rir_art = ctx.input("rir")
    rir = artifacts.decode("rir", rir_art.data, ctx.job.label)
    cache = _AudioCache(params.sample_rate_hz)
    roots = corpus_roots(ctx)
    bank = OctaveFilterBank(rir.sample_rate_hz, tuple(rir.bands_hz))
    microphone = ctx.input_params("rir").microphone
    walk = Walk(params.speed_m_s, params.walk_span, microphone)
    hrirs = load_hrirs(ctx.job.paths["hrtf"]) if "hrtf" in ctx.job.paths else None
    directivity = getattr(ctx.input_params("rir"), "directivity", None)
    patterns = (source_patterns(directivity, ctx.job.paths, bank.bands_hz)
                if params.interpolation == "paths" else {})
    diffuse: _Diffuse | None = None
    arrays: dict[str, np.ndarray] = {}
    groups = []
    for g, (arr, placement, rir_group) in enumerate(
            zip(arrange, placements, rir.groups, strict=True)):
        if not arr.group == placement.group == rir_group.group:
            raise StageError(f"{ctx.job.label}: inputs disagree on group order "
                             f"({arr.group}, {placement.group}, {rir_group.group})")
        speech = group_speech(arr.tracks)
        tracks = []
        for n, track in enumerate(arr.tracks):
            ctx.progress(f"group {g + 1}/{len(arrange)}, track {n + 1}/{len(arr.tracks)}")
            entry = rir_group.source(track.name)
            rirs = np.asarray(rir_art.arrays[entry.array], dtype=np.float64)
            line = timeline(placement.source(track.name), track.segment_list(), placement,
                            walk, speech, arr.clip_samples, params.sample_rate_hz)
            paths = None
            if params.interpolation == "paths":
                if entry.paths is None:
                    raise StageError(f"{ctx.job.label}: interpolation 'paths' but the RIRs of "
                                     f"group {arr.group} {track.name} hold no early paths")
                paths = (artifacts.read_path_set(rir_art.arrays, entry.paths),
                         np.asarray(rir_art.arrays[f"{entry.paths}_late"], dtype=np.float64),
                         bank, path_receiver(microphone, placement.mic_m, line, hrirs,
                                             params.sample_rate_hz))
            source, facing = None, None
            if directivity is not None and not directivity.role(track.role).is_omni:
                d = directivity.role(track.role)
                # head turns are rendered along the paths; RIRs at points face as the spec says
                rng = (ctx.rng("head_turn", ctx.job.key, arr.group, track.name)
                       if params.interpolation == "paths" else None)
                hop, facing = facing_frames(d, line, placement.mic_m, params.sample_rate_hz,
                                            rng)
                if track.role in patterns:
                    source = SourceDirectivity(patterns[track.role],
                                               yaw_per_sample(facing, hop, line.index.size),
                                               d.pitch_deg)
            field = (params.backgrounds or {}).get(track.role)
            if field is not None and field.diffuse_fraction >= 1.0:
                # The point source is not heard: its dry track is all the diffuse field needs.
                signals = {"dry": track_dry(track, cache, arr.clip_samples,
                                            roots[track.role])[None, :].astype(np.float32)}
            else:
                signals = render_track(track, rirs, line, params, cache, arr.clip_samples,
                                       roots[track.role], paths, source)
            if field is not None:
                if diffuse is None:
                    diffuse = _Diffuse(ctx, microphone, hrirs)
                signals = diffuse.render(field, signals, ctx.rng("render", "diffuse",
                                                                 arr.group, track.name))
            keys = {}
            for kind, x in signals.items():
                key = f"g{g}_{track.name}_{kind}"
                arrays[key] = x
                keys[kind] = key
            if facing is not None:  # a directional source: where it faced, every 10 ms
                key = f"g{g}_{track.name}_facing_yaw_deg"
                arrays[key] = facing.astype(np.float32)
                keys["facing_yaw_deg"] = key
            tracks.append(RenderedTrack(name=track.name, role=track.role, arrays=keys,
                                        channels=int(signals["reverberant"].shape[0])))
        groups.append(RenderGroup(group=arr.group, clip_samples=arr.clip_samples,
                                  tracks=tracks))
    ctx.write(arrays, artifacts.encode("render", RenderData(
        groups=groups, sample_rate_hz=params.sample_rate_hz)))
