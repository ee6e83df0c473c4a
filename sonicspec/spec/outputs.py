"""Outputs: where the dataset and the artifact store go, and in which form."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel


class ReportSpec(SpecModel):
    """The HTML report a build writes at the end (``sonicspec report`` makes it any time)."""

    enabled: bool = Field(
        False,
        description="After a successful build, write report.html (and its folder of group "
        "pages, report_files/) at the top of the dataset folder: the spec, the plan summary, "
        "build facts, distributions per split aggregated from the groups' metadata, floor "
        "plans per scene, a sortable group table and warnings. Needs matplotlib and jinja2: "
        "pip install 'sonicspec[report]'. The report is not part of the dataset's content: "
        "it is not in checksums.sha256, and changing these fields reruns only the dataset "
        "step (its dataset.json records the spec), no export.",
    )
    group_pages: int = Field(
        100,
        ge=0,
        le=100_000,
        description="At most this many groups get a page of their own (floor plan, RIR and "
        "energy decay curves, audio players), drawn with the spec's seed and spread over "
        "splits and scenes; per-band T30, EDT and C50 are computed from these groups' RIRs. "
        "Bounds the report's time and size on big datasets.",
    )


Manifest = Literal["lhotse", "csv", "huggingface", "webdataset"]


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
    scale: Literal["none", "per_file"] = Field(
        "none",
        description="'per_file': each PCM file is peak-normalised to just under full scale "
        "and its scale recorded (metadata.json's audio_scales, the file's comment tag "
        "sonicspec_scale=<scale>, the Lhotse recording's Volume transform); the signal is the "
        "decoded samples times the scale, so levels above 0 dBFS (mixture.loudness."
        "peak_limit_dbfs: null) are kept without float WAV. sonicspec's loader, evaluate and "
        "exports apply it. 'none': samples as they are (levels must stay within full scale). "
        "FLOAT files are never scaled.",
    )
    bits: int | None = Field(
        None,
        ge=16,
        le=24,
        description="With scale: per_file, the precision of the samples, bits relative to "
        "the file's peak (the error is at most 2^-bits of the peak); the bits below are "
        "zero, which FLAC stores for free. null: the subtype's (16 or 24). The sonicset "
        "presets use PCM_24 with 18 bits: 1.19x the size of 16-bit FLAC, 24 bits costs 1.76x "
        "(bench/RESULTS.md, issue 27).",
    )
    sources: bool = Field(True, description="Write each reverberant source track.")
    background: bool = Field(True, description="Write the reverberant noise and music tracks.")
    mixtures: bool = Field(True, description="Write the task mixtures.")
    rirs: bool = Field(False, description="Write the RIRs used, as float32 WAV.")
    metadata: bool = Field(True, description="Write a metadata JSON per group (SonicSet form).")
    manifests: list[Manifest] = Field(
        default_factory=list,
        description="Manifests written per split in the dataset folder ('lhotse', 'csv'), and "
        "exports written beside it after the build, rewritten only where groups changed: "
        "'huggingface' (Parquet shards with Audio columns, <dir>-huggingface/, "
        "datasets.load_dataset reads it) and 'webdataset' (tar shards, <dir>-webdataset/); "
        "the exports need pip install 'sonicspec[export]'.",
    )
    report: ReportSpec = Field(
        default_factory=ReportSpec, description="The HTML report of the built dataset."
    )
    groups_per_shard: int = Field(
        4, ge=1, le=10_000, description="Groups handled by one pipeline job (keeps the DAG small)."
    )
