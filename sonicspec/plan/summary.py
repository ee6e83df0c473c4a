"""What a spec asks for, in numbers, before anything runs.

The summary counts what the spec fixes statically (groups, tracks, audio hours) and estimates
what depends on placement (RIR points per moving source, from the middle of the travel-distance
range and the RIR spacing). Estimates are labelled as such.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from sonicspec.spec.checks import scene_matches
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.microphone import channel_count
from sonicspec.spec.trajectory import StaticTrajectorySpec


@dataclass(frozen=True)
class SplitSummary:
    name: str
    groups: int
    scenes: tuple[str, ...]
    scene_count: int | None
    speech_tracks: int
    audio_hours: float
    rir_points_estimate: int


@dataclass(frozen=True)
class SpecSummary:
    name: str
    sample_rate_hz: int
    channels: int
    microphone: str
    trajectory: str
    splits: tuple[SplitSummary, ...]
    rir_points_per_source_estimate: int
    mixtures_per_group: int

    @property
    def groups(self) -> int:
        return sum(s.groups for s in self.splits)

    @property
    def audio_hours(self) -> float:
        return sum(s.audio_hours for s in self.splits)

    @property
    def rir_points_estimate(self) -> int:
        return sum(s.rir_points_estimate for s in self.splits)

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(
            groups=self.groups,
            audio_hours=self.audio_hours,
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


def summarize(spec: DatasetSpec) -> SpecSummary:
    """Counts and estimates for ``spec`` (see the module docstring)."""
    traj = spec.trajectory
    if isinstance(traj, StaticTrajectorySpec):
        per_source = 1
    else:
        travel = sum(spec.placement.source_travel_distance_m) / 2
        per_source = math.ceil(travel / traj.rir_spacing_m) + 1
    static_points = int(spec.corpora.noise is not None) + int(spec.corpora.music is not None)
    splits = []
    for name, split in spec.splits.items():
        scenes = sorted({m for p in split.scenes for m in scene_matches(p, spec)})
        tracks = split.groups * spec.mixture.speakers
        splits.append(
            SplitSummary(
                name=name,
                groups=split.groups,
                scenes=tuple(scenes),
                scene_count=split.scene_count,
                speech_tracks=tracks,
                audio_hours=split.groups * spec.mixture.duration_s / 3600.0,
                rir_points_estimate=tracks * per_source + split.groups * static_points,
            )
        )
    return SpecSummary(
        name=spec.name,
        sample_rate_hz=spec.sample_rate_hz,
        channels=channel_count(spec.microphone),
        microphone=spec.microphone.kind,
        trajectory=traj.kind,
        splits=tuple(splits),
        rir_points_per_source_estimate=per_source,
        mixtures_per_group=_mixtures_per_group(spec),
    )


def format_summary(s: SpecSummary) -> str:
    """A short table a person reads in a terminal."""
    lines = [
        f"dataset {s.name}: {s.groups} groups, {s.audio_hours:.2f} h of audio at "
        f"{s.sample_rate_hz} Hz, {s.channels}-channel {s.microphone} microphone",
        f"sources move: {s.trajectory}; about {s.rir_points_per_source_estimate} RIR points "
        f"per moving source (estimate); {s.mixtures_per_group} mixtures per group",
        f"{'split':<10} {'groups':>7} {'tracks':>7} {'hours':>8} {'RIRs (est.)':>12}  scenes",
    ]
    for sp in s.splits:
        scenes = ", ".join(sp.scenes)
        if sp.scene_count is not None:
            scenes = f"{sp.scene_count} of {scenes}"
        lines.append(
            f"{sp.name:<10} {sp.groups:>7} {sp.speech_tracks:>7} "
            f"{sp.audio_hours:>8.2f} {sp.rir_points_estimate:>12}  {scenes}"
        )
    lines.append(
        f"{'total':<10} {s.groups:>7} {sum(x.speech_tracks for x in s.splits):>7} "
        f"{s.audio_hours:>8.2f} {s.rir_points_estimate:>12}"
    )
    return "\n".join(lines)
