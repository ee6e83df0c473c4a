"""Where a source and the microphone are at every sample of a group's clip.

One function, :func:`timeline`, read by the three steps that must agree on it: ``rir`` (which
points it traces), ``render`` (which RIR or path it renders when) and ``export`` (the position
labels). A source walks its RIR points while its speech plays (or over the clip, or at the
trajectory's speed: :func:`~sonicspec.audio.render.walk_index`).

A static microphone: the RIR points are the source's own, and the timeline is the source's
walk. A moving microphone (issue 18): its walk is timed the same way over the group (its
``span``: the clip, or the speech of all the group's speakers), and the RIR points become
*pairs* — the source's and the microphone's positions at the samples where either of them
reaches one of its own RIR points (and where a walk starts or stops). Between two pairs both
move linearly, so the timeline's fractional pair index gives both positions exactly as the
two walks do; neither moves more than its own ``rir_spacing_m`` from one pair to the next.
A microphone with ``facing: walk`` turns to its horizontal direction of travel (its heading,
linear between its points), ``yaw_deg`` added.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sonicspec.acoustics.moving.delays import read_at
from sonicspec.artifacts import GroupPlacement, SourcePlacement
from sonicspec.audio.arrange import Segment, speech_span, walk_window
from sonicspec.audio.render import walk_index
from sonicspec.geometry.navigation import cumulative_length
from sonicspec.spec.trajectory import StaticTrajectorySpec


@dataclass(frozen=True)
class Walk:
    """How the sources and the microphone walk: the source trajectory's ``speed_m_s``
    (None: a walk spans ``span``) and the spec's microphone model."""

    speed_m_s: float | None
    span: str
    microphone: object

    @property
    def mic_moves(self) -> bool:
        return not isinstance(self.microphone.trajectory, StaticTrajectorySpec)


@dataclass(frozen=True, eq=False)
class Timeline:
    """A source's RIR points (pairs, with a moving microphone) and when it is where.

    Attributes
    ----------
    index : (T,) float
        Fractional index into the points at every sample of the clip.
    source_m : (P, 3) float
        The source at each point.
    mic_m : (P, 3) float
        The microphone (array or head centre) at each point.
    yaw_deg : (P,) float
        Where the microphone faces at each point (unwrapped: linear interpolation between
        points is its turn).
    pitch_deg : float
    """

    index: np.ndarray
    source_m: np.ndarray
    mic_m: np.ndarray
    yaw_deg: np.ndarray
    pitch_deg: float
    mic_moves: bool

    def __len__(self) -> int:
        return len(self.source_m)

    def at(self, values: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
        """``values`` (one row per point) read at fractional ``index`` (default: every
        sample), linear between points."""
        return read_at(values, self.index if index is None else index)


def mic_walk_index(placement: GroupPlacement, walk: Walk, speech: Sequence[Segment],
                   clip_samples: int, rate: int) -> np.ndarray:
    """The microphone's fractional index into its own RIR points at every sample."""
    if not walk.mic_moves:
        return np.zeros(clip_samples)
    trajectory = walk.microphone.trajectory
    points = np.asarray(placement.mic_path_m, dtype=np.float64)
    window = (0, clip_samples) if trajectory.span == "clip" else speech_span(speech)
    return walk_index(cumulative_length(points), clip_samples, window, trajectory.speed_m_s,
                      rate)


def headings_deg(points_m: np.ndarray) -> np.ndarray:
    """The horizontal direction of travel at each point of a polyline, degrees (atan2 of
    the chord through its neighbours; one-sided at the ends), unwrapped."""
    p = np.asarray(points_m, dtype=np.float64)
    if len(p) < 2:
        return np.zeros(len(p))
    ahead = np.concatenate([p[1:], p[-1:]]) - np.concatenate([p[:1], p[:-1]])
    return np.degrees(np.unwrap(np.arctan2(ahead[:, 1], ahead[:, 0])))


def _breaks(index: np.ndarray) -> np.ndarray:
    """Samples where a walk's index reaches a new point, or starts or stops moving."""
    whole = np.floor(index + 1e-9)
    crossing = np.flatnonzero(np.diff(whole) != 0) + 1
    slope = np.diff(index)
    kink = np.flatnonzero(np.abs(np.diff(slope)) > 1e-9) + 1
    return np.concatenate([crossing, kink])


def timeline(source: SourcePlacement, segments: Sequence[Segment], placement: GroupPlacement,
             walk: Walk, speech: Sequence[Segment], clip_samples: int, rate: int) -> Timeline:
    """A source's timeline in its group (module docstring); ``segments``: the source's
    own, ``speech``: every speech segment of the group (a microphone walking over the
    group's speech)."""
    points = np.asarray(source.rir_points_m, dtype=np.float64)
    mic = walk.microphone
    s_index = walk_index(source.rir_points_distance_m, clip_samples,
                         walk_window(walk.span, segments, clip_samples), walk.speed_m_s, rate)
    if not walk.mic_moves:
        return Timeline(s_index, points, np.repeat(np.asarray(placement.mic_m)[None], len(points),
                                                   axis=0),
                        np.full(len(points), float(mic.yaw_deg)), float(mic.pitch_deg), False)
    m_index = mic_walk_index(placement, walk, speech, clip_samples, rate)
    at = np.unique(np.concatenate([[0, clip_samples - 1], _breaks(s_index), _breaks(m_index)]))
    at = at[(at >= 0) & (at < clip_samples)]
    mic_points = np.asarray(placement.mic_path_m, dtype=np.float64)
    source_m = read_at(points, s_index[at])
    mic_m = read_at(mic_points, m_index[at])
    # Two pairs at one place (both stand between them) are both kept, so the index keeps
    # time; the rir step traces each place once.
    yaw = np.full(len(at), float(mic.yaw_deg))
    if mic.trajectory.facing == "walk":
        yaw += read_at(headings_deg(mic_points), m_index[at])
    index = (np.interp(np.arange(clip_samples), at, np.arange(len(at), dtype=np.float64))
             if len(at) > 1 else np.zeros(clip_samples))
    return Timeline(index, source_m, mic_m, yaw, float(mic.pitch_deg), True)


def group_speech(tracks) -> list[Segment]:
    """Every speech segment of a group's arranged tracks."""
    return [seg for t in tracks if t.role == "speech" for seg in t.segment_list()]
