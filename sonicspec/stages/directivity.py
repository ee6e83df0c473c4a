"""The spec's source directivity as the rir and render steps use it: each role's pattern
(a SOFA set read from the job's files), the role of a track, and where a source faces along
its timeline (every 10 ms, and at each RIR pair of a moving microphone)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from sonicspec.acoustics.directivity import (
    DirectivityPattern,
    facing_yaw_deg,
    head_turns_deg,
    pattern_by_name,
)
from sonicspec.acoustics.engine import load_source_directivity
from sonicspec.errors import StageError
from sonicspec.spec.directivity import DirectivitySpec, SourcesDirectivitySpec
from sonicspec.stages.motion import Timeline

#: Where a directional source faces is recorded every this many seconds (the position
#: tracks' hop, :data:`sonicspec.stages.export.TRACK_HOP_S`).
FACING_HOP_S = 0.01


def facing_frames(d: DirectivitySpec, line: Timeline, mic_m, rate: int,
                  rng: np.random.Generator | None) -> tuple[int, np.ndarray]:
    """Where a directional source faces every :data:`FACING_HOP_S` of the clip (frames read
    at the same samples as its position track), unwrapped degrees, with its head turns when
    ``rng`` is given: ``(hop in samples, yaw per frame)``. ``mic_m``: the static
    microphone; a moving one (``line.mic_moves``) is read from the timeline at each frame,
    so ``toward_mic`` (and a source that never walks, with ``walk``) faces where it is
    then."""
    hop = max(1, round(FACING_HOP_S * rate))
    positions = line.at(line.source_m, line.index[::hop])
    if line.mic_moves:
        mic_m = line.at(line.mic_m, line.index[::hop])
    yaw = facing_yaw_deg(positions, hop / rate, d.facing_rule, mic_m, d.facing_smoothing_s)
    if d.head_turn is not None and rng is not None:
        yaw = yaw + head_turns_deg(len(yaw), hop / rate, d.head_turn.std_deg,
                                   d.head_turn.time_constant_s, rng)
    return hop, yaw


def pair_yaws_deg(d: DirectivitySpec, line: Timeline, rate: int) -> np.ndarray:
    """Where a directional source faces at each pair of a moving microphone's timeline
    ``(P,)``, degrees: its :func:`facing_frames` (no head turns: those are rendered along
    the paths) read at the sample of each pair, linear between frames, so the RIRs at the
    pairs face as the render step's facing track does."""
    hop, frames = facing_frames(d, line, None, rate, None)
    at = np.interp(np.arange(len(line), dtype=np.float64), line.index,
                   np.arange(line.index.size, dtype=np.float64))  # the sample of each pair
    return np.interp(at, np.arange(len(frames)) * hop, frames)


def track_role(name: str) -> str:
    """The source role of a track name (``noise``, ``music``; the talkers ``source<k>``)."""
    return name if name in ("noise", "music") else "speech"


def source_patterns(directivity: SourcesDirectivitySpec | None, paths: Mapping[str, str],
                    bands_hz) -> dict[str, DirectivityPattern]:
    """The pattern of every role that is not omnidirectional; a SOFA set read from the job's
    ``directivity_<role>`` path."""
    out: dict[str, DirectivityPattern] = {}
    if directivity is None:
        return out
    for role in ("speech", "noise", "music"):
        d = directivity.role(role)
        if d.is_omni:
            continue
        if d.pattern == "sofa":
            key = f"directivity_{role}"
            if key not in paths:
                raise StageError(f"directivity.{role}: pattern sofa but the job has no "
                                 f"{key} file")
            out[role] = load_source_directivity(paths[key], bands_hz, d.sofa_path)
        else:
            out[role] = pattern_by_name(d.pattern)
    return out
