"""Dataset splits: how many groups each split has and which scenes it may use."""

from __future__ import annotations

from pydantic import Field

from sonicspec.spec.base import SpecModel


class SplitSpec(SpecModel):
    """One split (train, val, test, ...); splits never share a scene."""

    groups: int = Field(ge=1, le=10_000_000, description="Mixture groups (clips) in this split.")
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
