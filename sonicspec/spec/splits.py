"""Dataset splits: how many groups each split has and which scenes it may use."""

from __future__ import annotations

from pydantic import Field

from sonicspec.spec.base import SpecModel

MAX_GROUPS = 1_000_000
"""Most groups per split and in all splits together: 10^6 groups of 60 s are 16,700 hours of
audio, and their plan has 1.5 million jobs (20 s and 1.3 GB to compile, a 1.4 GB plan file;
bench/RESULTS.md, issue 16)."""


class SplitSpec(SpecModel):
    """One split (train, val, test, ...); splits never share a scene."""

    groups: int = Field(
        ge=1,
        le=MAX_GROUPS,
        description="Mixture groups (clips) in this split; at most 1,000,000 per split and in "
        "all splits together (SonicSet has 19,034 training groups).",
    )
    scenes: list[str] = Field(
        min_length=1,
        description="Scene ids or glob patterns over scene ids (e.g. 'mp3d/*') this split "
        "draws from.",
    )
    scene_count: int | None = Field(
        None,
        ge=1,
        description="Take this many of the matched scenes (a seeded choice; splits are filled in "
        "the order written and never share a scene). Null: all matched scenes.",
    )
