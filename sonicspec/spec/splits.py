"""Dataset splits: how many groups each split has and which scenes it may use."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel

MAX_GROUPS = 1_000_000
"""Most groups per split and in all splits together: 10^6 groups of 60 s are 16,700 hours of
audio, and their plan has 1.5 million jobs (20 s and 1.3 GB to compile, a 1.4 GB plan file;
bench/RESULTS.md, issue 16)."""

EACH_SPEAKER_PER_SCENE = "each_speaker_per_scene"
"""The composition rule of SonicSet's generation scripts: in every scene of the split, every
speaker of the split once, in groups of ``mixture.speakers``."""


class SplitSpec(SpecModel):
    """One split (train, val, test, ...); splits never share a scene."""

    groups: Annotated[int, Field(ge=1, le=MAX_GROUPS)] | Literal["each_speaker_per_scene"] = Field(
        description="Mixture groups (clips) in this split: a number, spread evenly over the "
        "split's scenes, each group drawing its speakers at random; or "
        "'each_speaker_per_scene': in every scene of the split, every speaker of the split's "
        "speech once, in groups of mixture.speakers (a seeded shuffle per scene), so a scene "
        "has floor(speakers / mixture.speakers) groups and the remaining speakers (fewer than "
        "mixture.speakers) sit that scene out, as SonicSet's generation scripts do (921 "
        "speakers in groups of 3 over 62 scenes: 19,034 groups). At most 1,000,000 per split "
        "and in all splits together.",
    )
    scenes: list[str] = Field(
        min_length=1,
        description="Scene ids or glob patterns over scene ids (e.g. 'mp3d/*') this split "
        "draws from. Listing ids without a scene_count pins the split's scenes (e.g. a "
        "paper's scene lists); an id may appear once, in one split.",
    )
    scene_count: int | None = Field(
        None,
        ge=1,
        description="Take this many of the matched scenes (a seeded choice; splits are filled in "
        "the order written and never share a scene). Null: all matched scenes.",
    )
