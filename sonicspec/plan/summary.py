"""What a spec asks for, in numbers, before anything runs.

The summary counts what the spec fixes (groups, speech tracks, audio hours) and estimates
what depends on placement (RIR points per moving source, from the middle of the travel-distance
range and the RIR spacing). Estimates are labelled as such. Given the split layouts
(:func:`sonicspec.plan.compile.split_layouts`: scene globs expanded, speaker folders counted) it
also gives the scenes and speakers of each split and the size of splits composed per speaker
and scene (``groups: each_speaker_per_scene``), which the spec alone does not fix.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Protocol

from sonicspec.spec.checks import scene_matches
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.microphone import channel_count
from sonicspec.spec.trajectory import StaticTrajectorySpec


class Layout(Protocol):
    """A split's size once its scenes and speakers are known (``compile.SplitLayout``)."""

    scenes: tuple[str, ...]
    groups: int
    speakers: int | None


@dataclass(frozen=True)
class SplitSummary:
    name: str
    groups: int | None  # None: composed per speaker and scene, and not counted
    scenes: tuple[str, ...]
    scene_count: int | None
    scenes_used: int | None
    """Concrete scenes the split uses (None if not counted)."""
    speakers: int | None
    """Speakers of the split (counted for splits composed per speaker and scene)."""
    speech_tracks: int | None
    """Speech tracks (a moving trajectory each, unless sources are static)."""
    audio_hours: float | None
    """Hours of mixture audio: groups x mixture.duration_s."""
    track_hours: float | None
    """Hours of speech tracks: speech tracks x mixture.duration_s."""
    rir_points_estimate: int | None


@dataclass(frozen=True)
class SpecSummary:
    name: str
    sample_rate_hz: int
    channels: int
    microphone: str
    trajectory: str
    microphone_motion: str | None
    """How a moving microphone walks (None: it stays put)."""
    splits: tuple[SplitSummary, ...]
    rir_points_per_source_estimate: int
    mixtures_per_group: int

    def _total(self, field: str) -> float | None:
        values = [getattr(s, field) for s in self.splits]
        return None if any(v is None for v in values) else sum(values)

    @property
    def groups(self) -> int | None:
        return self._total("groups")  # type: ignore[return-value]

    @property
    def audio_hours(self) -> float | None:
        return self._total("audio_hours")

    @property
    def rir_points_estimate(self) -> int | None:
        return self._total("rir_points_estimate")  # type: ignore[return-value]

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(
            groups=self.groups,
            audio_hours=self.audio_hours,
            speech_tracks=self._total("speech_tracks"),
            track_hours=self._total("track_hours"),
            rir_points_estimate=self.rir_points_estimate,
        )
        return d


def _mixtures_per_group(spec: DatasetSpec) -> int:
    count = 0
    for task in spec.mixture.tasks:
        if task.kind == "separation":
            count += math.comb(spec.mixture.speakers, task.speakers)
        else:
            count += spec.mixture.speakers
    return count


def summarize(spec: DatasetSpec, layouts: Mapping[str, Layout] | None = None) -> SpecSummary:
    """Counts and estimates for ``spec`` (see the module docstring); ``layouts``: every
    split's layout, when the scenes and corpora were read."""
    traj = spec.trajectory
    if isinstance(traj, StaticTrajectorySpec):
        per_source = 1
    else:
        travel = sum(spec.placement.source_travel_distance_m) / 2
        per_source = math.ceil(travel / traj.rir_spacing_m) + 1
    static_points = int(spec.corpora.noise is not None) + int(spec.corpora.music is not None)
    mic_traj = spec.microphone.trajectory
    mic_motion = None
    if not isinstance(mic_traj, StaticTrajectorySpec):
        # RIRs at pairs: about the source's points plus the microphone's, for every source
        # (a static one too).
        ends = ([mic_traj.start_m, mic_traj.end_m] if mic_traj.kind == "line"
                else mic_traj.points_m)
        walk = sum(math.dist(a, b) for a, b in itertools.pairwise(ends))
        mic_points = math.ceil(walk / mic_traj.rir_spacing_m) + 1
        per_source += mic_points
        static_points *= 1 + mic_points
        mic_motion = f"{mic_traj.kind}, {walk:.1f} m, facing {mic_traj.facing}"
    duration_h = spec.mixture.duration_s / 3600.0
    splits = []
    for name, split in spec.splits.items():
        scenes = sorted({m for p in split.scenes for m in scene_matches(p, spec)})
        layout = layouts[name] if layouts is not None else None
        groups = layout.groups if layout is not None else (
            split.groups if isinstance(split.groups, int) else None)
        tracks = None if groups is None else groups * spec.mixture.speakers
        splits.append(
            SplitSummary(
                name=name,
                groups=groups,
                scenes=tuple(scenes),
                scene_count=split.scene_count,
                scenes_used=None if layout is None else len(layout.scenes),
                speakers=None if layout is None else layout.speakers,
                speech_tracks=tracks,
                audio_hours=None if groups is None else groups * duration_h,
                track_hours=None if tracks is None else tracks * duration_h,
                rir_points_estimate=(None if groups is None or tracks is None
                                     else tracks * per_source + groups * static_points),
            )
        )
    return SpecSummary(
        name=spec.name,
        sample_rate_hz=spec.sample_rate_hz,
        channels=channel_count(spec.microphone),
        microphone=spec.microphone.kind,
        trajectory=traj.kind,
        microphone_motion=mic_motion,
        splits=tuple(splits),
        rir_points_per_source_estimate=per_source,
        mixtures_per_group=_mixtures_per_group(spec),
    )


def _n(value: int | None) -> str:
    return "?" if value is None else f"{value:,}"


def _h(value: float | None) -> str:
    return "?" if value is None else f"{value:,.2f}"


def format_summary(s: SpecSummary) -> str:
    """A short table a person reads in a terminal: per split the scenes, speakers, groups,
    speech tracks (one moving trajectory each when sources move), hours of mixtures and hours
    of speech tracks; ``?`` where the scenes or corpora were not read."""
    head = (f"{s.groups:,} groups, {s.audio_hours:.2f} h of audio" if s.groups is not None
            else "groups counted per speaker and scene (the corpus is needed)")
    lines = [
        f"dataset {s.name}: {head} at {s.sample_rate_hz} Hz, {s.channels}-channel "
        f"{s.microphone} microphone" + (f" moving ({s.microphone_motion})"
                                        if s.microphone_motion else ""),
        f"sources move: {s.trajectory}; about {s.rir_points_per_source_estimate} RIR points "
        f"per moving source (estimate{'; pairs with the microphone' * bool(s.microphone_motion)}"
        f"); {s.mixtures_per_group} mixtures per group",
        f"{'split':<10} {'scenes':>6} {'speakers':>8} {'groups':>8} {'tracks':>8} "
        f"{'hours':>8} {'track h':>8} {'RIRs (est.)':>12}  scenes from",
    ]
    for sp in s.splits:
        scenes = ", ".join(sp.scenes)
        if sp.scene_count is not None:
            scenes = f"{sp.scene_count} of {scenes}"
        lines.append(
            f"{sp.name:<10} {_n(sp.scenes_used):>6} {_n(sp.speakers):>8} {_n(sp.groups):>8} "
            f"{_n(sp.speech_tracks):>8} {_h(sp.audio_hours):>8} {_h(sp.track_hours):>8} "
            f"{_n(sp.rir_points_estimate):>12}  {scenes}"
        )
    d = s.to_dict()
    used = [x.scenes_used for x in s.splits]
    speakers = [x.speakers for x in s.splits]
    lines.append(
        f"{'total':<10} {_n(None if None in used else sum(used)):>6} "  # type: ignore[arg-type]
        f"{_n(None if None in speakers else sum(speakers)):>8} "  # type: ignore[arg-type]
        f"{_n(s.groups):>8} {_n(d['speech_tracks']):>8} {_h(s.audio_hours):>8} "
        f"{_h(d['track_hours']):>8} {_n(s.rir_points_estimate):>12}"
    )
    return "\n".join(lines)
