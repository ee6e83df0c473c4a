"""Outputs: where the dataset and the artifact store go, and in which form."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel


class OutputsSpec(SpecModel):
    """Dataset folder layout and file formats."""

    dir: str = Field("out", min_length=1, description="Dataset folder, relative to the spec file.")
    store_dir: str = Field(
        "store",
        min_length=1,
        description="Content-hashed artifact store, relative to the spec file; may be shared "
        "between specs.",
    )
    allow_outside_spec_folder: bool = Field(
        False,
        description="Let dir and store_dir lie outside the spec file's folder (an absolute "
        "path or one through '..'). Off by default: a spec may come from someone else, and "
        "should not choose where on your disk it writes; `sonicspec build --output-dir DIR` "
        "(--store-dir DIR) choose a folder from the command line instead.",
    )
    audio_format: Literal["flac", "wav"] = Field("flac", description="Audio container.")
    subtype: Literal["PCM_16", "PCM_24", "FLOAT"] = Field(
        "PCM_16", description="Sample format (FLOAT only with wav)."
    )
    sources: bool = Field(True, description="Write each reverberant source track.")
    background: bool = Field(True, description="Write the reverberant noise and music tracks.")
    mixtures: bool = Field(True, description="Write the task mixtures.")
    rirs: bool = Field(False, description="Write the RIRs used, as float32 WAV.")
    metadata: bool = Field(True, description="Write a metadata JSON per group (SonicSet form).")
    manifests: list[Literal["lhotse", "csv"]] = Field(
        default_factory=list, description="Manifest formats written per split."
    )
    groups_per_shard: int = Field(
        4, ge=1, le=10_000, description="Groups handled by one pipeline job (keeps the DAG small)."
    )
