"""The spec's source directivity as the rir and render steps use it: each role's pattern
(a SOFA set read from the job's files) and the role of a track."""

from __future__ import annotations

from collections.abc import Mapping

from sonicspec.acoustics.directivity import DirectivityPattern, pattern_by_name
from sonicspec.acoustics.engine import load_source_directivity
from sonicspec.errors import StageError
from sonicspec.spec.directivity import SourcesDirectivitySpec


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
