"""Stage ``export``: the dataset folder of every group in a shard.

Per group, under ``<output dir>/<split>/<index>/``: each reverberant source (``source1``…),
``noise`` and ``music``, the training targets (``source1_direct``…), the task mixtures
(``mixtures/sep_s1s2_noise``…), the RIRs if asked (``rirs/<track>/<point>.wav``, float32) and
``metadata.json`` in the SonicSet form — ``source1..N: {audio, start_end_points, words}``,
``noise``, ``music`` — extended with the speaker, trajectory, RIR points, microphone, gains,
acoustic figures and the content keys (typed:
:class:`~sonicspec.export.metadata.GroupMetadata`), and ``tracks.npz``, the 10 ms position
tracks that the metadata, the Lhotse manifests and the record reference
(:mod:`sonicspec.export.tracks`); with ``outputs.scale: per_file`` also ``audio_scales``
(each audio file, relative to the group's folder -> its scale: the signal is the decoded samples
times it). Every file is written atomically. The artifact records
the files (each with the SHA-256 of the bytes written, which ``checksums.sha256``, ``verify`` and
the next build check), the manifest entries and the metadata for the ``dataset`` stage.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sonicspec import artifacts
from sonicspec.acoustics.engine import capsule_facts
from sonicspec.acoustics.receivers.arrays import local_directions
from sonicspec.artifacts import (
    ArrangedGroup,
    GroupPlacement,
    MixGroup,
    RenderGroup,
    RirGroup,
    RirSource,
)
from sonicspec.artifacts.records import ExportData, ExportGroup, FileRecord, MetadataRef
from sonicspec.audio.arrange import Segment
from sonicspec.audio.augment import (
    GroupAugmentation,
    chain_files,
    draw_chain,
    parse_chain,
    read_impulse_response,
)
from sonicspec.export.checksums import file_record
from sonicspec.export.files import peak_scale, write_audio
from sonicspec.export.manifests import RecordingEntry, SupervisionEntry
from sonicspec.export.metadata import (
    BackgroundTrack,
    CapsulesRecord,
    GroupMetadata,
    ImageSourceOrder,
    Loudness,
    MixtureRecord,
    RirTail,
    SpeechTrack,
    TrackReference,
)
from sonicspec.export.tracks import TrackFile
from sonicspec.plan.params import ExportParams
from sonicspec.stages.context import JobContext
from sonicspec.stages.motion import Timeline, Walk, group_speech, timeline


class _GroupWriter:
    """Writes one group's files and keeps the manifest rows."""

    def __init__(self, out: Path, folder: Path, group: str, params: ExportParams) -> None:
        self.out, self.folder, self.group = out, folder, group
        self.outputs = params.outputs
        self.rate = params.sample_rate_hz
        self.files: list[FileRecord] = []
        self.recordings: list[dict[str, Any]] = []
        self.rec_ids: dict[str, str] = {}
        self.scales: dict[str, float] = {}
        """File (relative to the group's folder) -> scale, with outputs.scale per_file."""

    def audio(self, kind: str, name: str, x: np.ndarray, *, float_wav: bool = False,
              custom: dict[str, Any] | None = None) -> str:
        ext = "wav" if float_wav else self.outputs.audio_format
        subtype = "FLOAT" if float_wav else self.outputs.subtype
        path = self.folder / f"{name}.{ext}"
        # outputs.scale per_file: the file peaks just under full scale and its scale (the
        # signal is the decoded samples times it) goes in the file's tag, the record, the
        # Lhotse recording and metadata.json's audio_scales; float files keep any level.
        scaled = self.outputs.scale == "per_file" and subtype != "FLOAT"
        scale = peak_scale(x, subtype, self.outputs.bits) if scaled else None
        write_audio(path, x, self.rate, audio_format=ext, subtype=subtype, scale=scale,
                    bits=self.outputs.bits if scaled else None)
        if self.outputs.scale == "per_file":
            self.scales[path.relative_to(self.folder).as_posix()] = 1.0 if scale is None else scale
        rel = path.relative_to(self.out).as_posix()
        x2 = np.atleast_2d(x)
        self.files.append(file_record(self.out, path, kind=kind, name=name,
                                      channels=int(x2.shape[0]), num_samples=int(x2.shape[1]),
                                      sample_rate_hz=self.rate,
                                      scale=float(scale) if scaled else None))
        if not float_wav:
            rec_id = f"{self.group.replace('/', '_')}_{name.replace('/', '_')}"
            self.rec_ids[name] = rec_id
            self.recordings.append(RecordingEntry(rec_id, rel, self.rate, int(x2.shape[1]),
                                                  int(x2.shape[0]), custom,
                                                  scale).to_lhotse())
        return rel


# Position labels every 10 ms (issue 18: localisation, tracking and activity need <= 10 ms).
TRACK_HOP_S = 0.01


def position_track(line: Timeline, rate: int) -> tuple[float, dict[str, np.ndarray]]:
    """Where a source is every ``TRACK_HOP_S`` from t = 0 over the whole clip (held before and
    after its walk), read from the same timeline the renderer used, with its azimuth,
    elevation and distance in the microphone's frame (where the microphone is and faces
    then): the hop (s) and the arrays (:class:`~sonicspec.export.tracks.TrackFile` rounds
    them to 0.1 mm and 0.01°)."""
    hop = max(1, round(TRACK_HOP_S * rate))
    index = line.index[::hop]
    positions = line.at(line.source_m, index)
    mic = line.at(line.mic_m, index)
    yaw = line.at(line.yaw_deg, index) if line.mic_moves else float(line.yaw_deg[0])
    azimuth, elevation, distance = local_directions(positions - mic, yaw, line.pitch_deg)
    return hop / rate, {"positions_m": positions, "azimuth_deg": azimuth,
                        "elevation_deg": elevation, "distance_m": distance}


def microphone_track(line: Timeline, rate: int) -> tuple[float, dict[str, np.ndarray]]:
    """Where the microphone is (and faces) every ``TRACK_HOP_S``, from any source's
    timeline of its group (they share the microphone's walk)."""
    hop = max(1, round(TRACK_HOP_S * rate))
    index = line.index[::hop]
    track = {"positions_m": line.at(line.mic_m, index)}
    if line.mic_moves:
        track["yaw_deg"] = (line.at(line.yaw_deg, index) + 180.0) % 360.0 - 180.0
    return hop / rate, track


def _order(source: RirSource) -> ImageSourceOrder | None:
    """The image-source order a source's RIRs asked and reached (None from a rir artifact
    written before it was recorded)."""
    if source.image_source_order is None or source.image_source_order_asked is None:
        return None
    return ImageSourceOrder(asked=source.image_source_order_asked,
                            reached=source.image_source_order,
                            stopped=source.image_source_order_stopped)


def capsules_record(microphone) -> CapsulesRecord | None:
    """What ``metadata.json`` says of the microphone's capsules
    (:func:`~sonicspec.acoustics.engine.capsule_facts`); None for omni capsules in free
    field, whose records keep their bytes."""
    facts = capsule_facts(microphone.model_dump(mode="json"))
    if facts is None:
        return None
    return CapsulesRecord.model_validate(facts)


def export_group(out: Path, params: ExportParams, arrays: dict[str, np.ndarray],
                 render: RenderGroup, mix: MixGroup, arrange: ArrangedGroup,
                 placement: GroupPlacement, rir: RirGroup, rir_arrays: dict[str, Any],
                 keys: dict[str, str], walk: Walk,
                 backgrounds: dict[str, Any] | None = None,
                 augmentation: GroupAugmentation | None = None) -> ExportGroup:
    """Write one group's folder; its record for ``dataset``. ``backgrounds``: the render's
    diffuse background fields by role (recorded in the metadata); ``augmentation``: the
    group's draw of the spec's device and channel effects."""
    group = render.group
    split, index = group.split("/")
    w = _GroupWriter(out, out / split / index, group, params)
    outputs = params.outputs
    gains = mix.gains
    tracks = {t.name: t for t in render.tracks}
    arranged = {t.name: t for t in arrange.tracks}
    track_file = TrackFile(out, w.folder)
    # A PCM file without a per-file scale holds [-1, 1]: the augmented signal is cut there.
    full_scale = outputs.scale != "per_file" and outputs.subtype != "FLOAT"

    def clean(x: np.ndarray) -> np.ndarray:
        """A track or training target: through the effects marked ``targets``, if any."""
        if augmentation is None or not augmentation.touches_targets:
            return x
        return augmentation.apply(x, w.rate, target=True, full_scale=full_scale)[0]
    entries: dict[str, SpeechTrack | BackgroundTrack] = {}
    spoken: dict[str, tuple[str, list[Segment]]] = {}
    speech = group_speech(arrange.tracks)
    for name, track in tracks.items():
        role = track.role
        a = arranged[name]
        field = (backgrounds or {}).get(role)
        # a background heard only as a diffuse field: its point source was not traced
        traced = field is None or field.diffuse_fraction < 1.0
        rir_source = rir.source(name) if traced else None
        signal = gains[name] * np.asarray(arrays[track.arrays["reverberant"]], dtype=np.float64)
        geometry = placement.source(name)
        line = timeline(geometry, a.segment_list(), placement, walk, speech,
                        render.clip_samples, w.rate)
        hop_s, values = position_track(line, w.rate)
        if "facing_yaw_deg" in track.arrays:  # a directional source: where it faced
            facing = np.asarray(arrays[track.arrays["facing_yaw_deg"]], dtype=np.float64)
            values["yaw_deg"] = (facing + 180.0) % 360.0 - 180.0
        track_labels = track_file.add(name, hop_s, values)
        if (outputs.sources and role == "speech") or (outputs.background and role != "speech"):
            audio_rel = w.audio(role, name, clean(signal), custom={"track": track_labels})
        else:
            audio_rel = None
        for kind in ("dry", "direct", "early"):
            if f"{name}_{kind}" in gains:
                w.audio(f"{role}_{kind}", f"{name}_{kind}",
                        clean(gains[f"{name}_{kind}"] * np.asarray(arrays[track.arrays[kind]],
                                                                   dtype=np.float64)))
        if outputs.rirs and rir_source is not None:
            stack = np.asarray(rir_arrays[rir_source.array])
            for j in range(stack.shape[0]):
                w.audio("rir", f"rirs/{name}/{j:03d}", stack[j], float_wav=True)
        segs = a.segment_list()
        common: dict[str, Any] = {
            "audio": [a.files[s.id].path for s in segs],
            "start_end_points": [(s.start, s.end) for s in segs],
            "file": audio_rel,
            "rir_points_m": ([tuple(p) for p in geometry.rir_points_m] if traced else []),
            **({"t30_s": rir_source.t30_s, "drr_db": rir_source.drr_db,
                "direct_path": rir_source.direct,
                "rir_tail": RirTail(**rir_source.tail.to_dict()),
                "image_source_order": _order(rir_source)} if rir_source is not None else {}),
            "loudness": Loudness(**mix.components[name].model_dump()),
            "track": TrackReference(**track_labels),
        }
        if role == "speech":
            entries[name] = SpeechTrack(
                **common, words=[s.text for s in segs], speaker=a.speaker,
                trajectory_m=[tuple(p) for p in geometry.path_m],
                path_length_m=geometry.path_length_m)
            spoken[name] = (a.speaker, segs)
        else:
            heard = ({"field": field.field, "diffuse_fraction": field.diffuse_fraction}
                     if field is not None else {})
            entries[name] = BackgroundTrack(**common, position_m=tuple(geometry.rir_points_m[0]),
                                            **heard)
    mixtures = []
    if outputs.mixtures:
        for m in mix.mixtures:
            total = sum(gains[c] * np.asarray(arrays[tracks[c].arrays["reverberant"]],
                                              dtype=np.float64) for c in m.components)
            measured = None
            if augmentation is not None:
                total, measured = augmentation.apply(total, w.rate, target=False,
                                                     full_scale=full_scale)
            rel = w.audio("mixture", f"mixtures/{m.name}", total)
            mixtures.append(MixtureRecord(**m.model_dump(mode="json"), file=rel,
                                          augmentation=measured))
    mic_ref = TrackReference(**track_file.add("microphone", *microphone_track(line, w.rate)))
    track_file.write()
    w.files.append(file_record(out, track_file.path, kind="tracks", name="tracks"))
    speech_entries = {n: e for n, e in entries.items() if isinstance(e, SpeechTrack)}
    metadata = GroupMetadata(
        group=group, split=split, scene_id=params.scene_id, mic_m=tuple(placement.mic_m),
        floor=placement.floor_index, sample_rate_hz=w.rate,
        num_samples=render.clip_samples, mixtures=mixtures,
        group_gain_db=mix.group_gain_db, keys=keys, microphone_track=mic_ref,
        noise=entries.get("noise"), music=entries.get("music"), **speech_entries,
        audio_scales=w.scales or None, capsules=capsules_record(walk.microphone),
        augmentation=augmentation.draw if augmentation is not None else None)
    if outputs.metadata:
        metadata.write(w.folder / "metadata.json")
        w.files.append(file_record(out, w.folder / "metadata.json", kind="metadata",
                                   name="metadata"))
    # A supervision per utterance on every recording it is heard in: its source's own file
    # and each mixture that contains the source.
    rows = []
    for name, (speaker, segs) in spoken.items():
        heard_in = [name] + [f"mixtures/{m.name}" for m in mixtures if name in m.components]
        for rec_name in heard_in:
            if rec_name not in w.rec_ids:
                continue
            rec = w.rec_ids[rec_name]
            # Unique across the split: a mixture holds several sources' utterances.
            stem = rec if rec_name == name else f"{rec}_{name}"
            rows.extend(SupervisionEntry(f"{stem}_{k}", rec, seg.start, seg.end, w.rate,
                                         seg.text, speaker).to_lhotse()
                        for k, seg in enumerate(segs))
    return ExportGroup(
        group=group, split=split, scene_id=params.scene_id,
        metadata=MetadataRef(path=f"{split}/{index}/metadata.json" if outputs.metadata
                             else None),
        files=w.files, recordings=w.recordings, supervisions=rows,
        duration_s=render.clip_samples / w.rate)


def run(ctx: JobContext) -> None:
    params: ExportParams = ctx.params
    out = Path(ctx.plan.output_dir)
    mix = artifacts.read(ctx, "mix").groups
    render_art = ctx.input("render")
    render = artifacts.decode("render", render_art.data, ctx.job.label)
    rir_art = ctx.input("rir")
    rir = artifacts.decode("rir", rir_art.data, ctx.job.label)
    arrange = artifacts.read(ctx, "arrange").groups
    placements = artifacts.read(ctx, "placement").groups
    keys = {step: ctx.input_keys(step)[0]
            for step in ("placement", "arrange", "rir", "render", "mix")}
    microphone = ctx.input_params("rir").microphone
    render_params = ctx.input_params("render")
    walk = Walk(render_params.speed_m_s, render_params.walk_span, microphone)
    chain = parse_chain(params.augmentation) if params.augmentation is not None else None
    paths = dict(ctx.job.paths)
    responses = {name: read_impulse_response(paths.get(name, name), params.sample_rate_hz,
                                             where=f"augmentation impulse_response {name!r}")
                 for name in (chain_files(chain) if chain else [])}
    groups = []
    for r, m, arr, placement, rir_group in zip(render.groups, mix, arrange, placements,
                                               rir.groups, strict=True):
        # One draw per group, from the spec seed and the group (its own stream: the mix
        # step's draws are untouched).
        aug = (GroupAugmentation(draw_chain(chain, ctx.rng("augment", r.group)), responses)
               if chain else None)
        groups.append(export_group(out, params, render_art.arrays, r, m, arr, placement,
                                   rir_group, rir_art.arrays, {**keys, "export": ctx.job.key},
                                   walk, render_params.backgrounds, aug))
    ctx.write({"file_count": np.array([sum(len(g.files) for g in groups)], dtype=np.int64)},
              artifacts.encode("export", ExportData(groups=groups)))
