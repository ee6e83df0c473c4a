"""Corpora: where speech, noise and music come from, and which part feeds which split."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel, SplitName

DEFAULT_SHARES_TEXT = (
    " Left out: SonicSet's 7:2:1 (train:val:test) renormalised over the spec's splits "
    "(train and test only: 0.875 and 0.125)."
)


class LibriSpeechCorpusSpec(SpecModel):
    """LibriSpeech layout: ``<root>/<subset>/<speaker>/<chapter>/*.flac`` + ``*.trans.txt``."""

    kind: Literal["librispeech"] = Field(description="Corpus type.")
    root: str = Field(
        min_length=1, description="Folder holding the subsets, relative to the spec file."
    )
    subsets: dict[SplitName, list[str]] = Field(
        default_factory=lambda: {
            "train": ["train-clean-360"],
            "val": ["dev-clean"],
            "test": ["test-clean"],
        },
        description="Subsets (folder names) that feed each split; speakers never cross splits.",
    )


class FolderCorpusSpec(SpecModel):
    """Any folder of audio files; speakers are the first-level sub-folders (speech only)."""

    kind: Literal["folder"] = Field(description="Corpus type.")
    root: str = Field(min_length=1, description="Folder of audio files, relative to the spec file.")
    extensions: list[str] = Field(
        default_factory=lambda: [".flac", ".wav"],
        min_length=1,
        description="File endings read (case-insensitive).",
    )
    split_ratios: dict[SplitName, float] | None = Field(
        None,
        description="Share of files (speech: of speakers) per split; shares of the spec's "
        "splits must sum to 1." + DEFAULT_SHARES_TEXT,
    )


class GeneratedSpeechSpec(SpecModel):
    """Speech synthesised offline with espeak-ng into the LibriSpeech layout (demo and tests)."""

    kind: Literal["generated"] = Field(description="Corpus type.")
    speakers_per_split: int = Field(4, ge=1, le=100, description="Voices per split.")
    utterances_per_speaker: int = Field(6, ge=1, le=200, description="Sentences per voice.")


class Fsd50kCorpusSpec(SpecModel):
    """FSD50K layout: ``FSD50K.dev_audio``, ``FSD50K.eval_audio``, ``FSD50K.ground_truth``."""

    kind: Literal["fsd50k"] = Field(description="Corpus type.")
    root: str = Field(min_length=1, description="Folder holding the FSD50K folders.")
    split_ratios: dict[SplitName, float] | None = Field(
        None,
        description="Share of clips per split; shares of the spec's splits must sum to 1."
        + DEFAULT_SHARES_TEXT,
    )
    exclude_labels: list[str] = Field(
        default_factory=lambda: ["Speech", "Human_voice", "Singing", "Music"],
        description="Clips carrying any of these labels are left out (keeps noise free of speech).",
    )


class FmaCorpusSpec(SpecModel):
    """FMA layout: ``fma_<size>/<nnn>/<track>.mp3`` and ``fma_metadata/tracks.csv``."""

    kind: Literal["fma"] = Field(description="Corpus type.")
    root: str = Field(min_length=1, description="Folder holding fma_<size> and fma_metadata.")
    size: Literal["small", "medium", "large", "full"] = Field(
        "small", description="Which FMA audio folder to read."
    )
    split_ratios: dict[SplitName, float] | None = Field(
        None,
        description="Share of tracks per split; shares of the spec's splits must sum to 1."
        + DEFAULT_SHARES_TEXT,
    )
    instrumental_only: bool = Field(
        True, description="Keep only tracks whose genres include Instrumental (no vocals)."
    )


class GeneratedNoiseSpec(SpecModel):
    """Noise or music synthesised offline (demo and tests)."""

    kind: Literal["generated"] = Field(description="Corpus type.")
    clips_per_split: int = Field(12, ge=1, le=1000, description="Clips per split.")
    clip_duration_s: float = Field(4.0, gt=0, le=600, description="Length of each clip, seconds.")


SpeechCorpusSpec = Annotated[
    LibriSpeechCorpusSpec | FolderCorpusSpec | GeneratedSpeechSpec, Field(discriminator="kind")
]
NoiseCorpusSpec = Annotated[
    Fsd50kCorpusSpec | FolderCorpusSpec | GeneratedNoiseSpec, Field(discriminator="kind")
]
MusicCorpusSpec = Annotated[
    FmaCorpusSpec | FolderCorpusSpec | GeneratedNoiseSpec, Field(discriminator="kind")
]


class CorporaSpec(SpecModel):
    """The three kinds of dry material; noise and music are optional."""

    speech: SpeechCorpusSpec = Field(description="Speech corpus.")
    noise: NoiseCorpusSpec | None = Field(None, description="Environmental noise corpus.")
    music: MusicCorpusSpec | None = Field(None, description="Music corpus.")
    cache_dir: str = Field(
        ".sonicspec-cache",
        description="Where corpus indexes and generated corpora are kept, relative to the "
        "spec file.",
    )
