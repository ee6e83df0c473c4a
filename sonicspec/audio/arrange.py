"""Arrangement: which corpus clips play when, in one group's clip (DESIGN.md §4).

A speech track holds 3–5 *whole* utterances of one speaker, each preceded by a random gap; an
utterance is never cut and never runs past the clip end. A noise or music track holds 6–8
clips with gaps; background clips may be cut at the clip end (they carry no transcript).
Everything is in samples at the dataset's rate; the arrangement is a description (which file,
which span of it, where in the clip) that the render stage turns into audio.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sonicspec.errors import AudioError
from sonicspec.units import seconds_to_samples


@dataclass(frozen=True)
class Clip:
    """A corpus item as arrangement sees it: an id, its length at the dataset rate, words."""

    id: str
    num_samples: int
    text: str = ""
    speaker: str = ""


@dataclass(frozen=True)
class Segment:
    """One clip placed in a track: output samples ``[start, end)`` play the clip from
    ``offset`` (clip samples, at the dataset rate)."""

    id: str
    start: int
    end: int
    offset: int = 0
    text: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "start": self.start, "end": self.end, "offset": self.offset,
                "text": self.text}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Segment:
        return cls(d["id"], int(d["start"]), int(d["end"]), int(d.get("offset", 0)),
                   d.get("text", ""))


def _draw_int(rng: np.random.Generator, bounds: Sequence[int]) -> int:
    lo, hi = int(bounds[0]), int(bounds[1])
    return int(rng.integers(lo, hi + 1))


def _draw_samples(rng: np.random.Generator, bounds_s: Sequence[float], rate: int) -> int:
    lo, hi = float(bounds_s[0]), float(bounds_s[1])
    return (seconds_to_samples(rng.uniform(lo, hi), rate) if hi > lo
            else seconds_to_samples(lo, rate))


def arrange_speech(utterances: Sequence[Clip], clip_samples: int, count: Sequence[int],
                   gap_s: Sequence[float], sample_rate_hz: int, rng: np.random.Generator,
                   *, where: str = "speech track") -> list[Segment]:
    """Whole utterances of one speaker placed one after another with random gaps.

    Draws the number of utterances in ``count`` (inclusive) and a gap in ``gap_s`` before
    each. Utterances are taken in a random order; one that would run past the clip end is
    skipped for a shorter one that fits, and placing stops when none fits. Raises
    :class:`AudioError` when not even one utterance fits.
    """
    if clip_samples <= 0:
        raise AudioError(f"{where}: expected a clip of at least one sample, got {clip_samples}")
    if not utterances:
        raise AudioError(f"{where}: expected at least one utterance, got none")
    wanted = _draw_int(rng, count)
    order = [utterances[i] for i in rng.permutation(len(utterances))]
    cursor = 0
    out: list[Segment] = []
    while len(out) < wanted and order:
        gap = _draw_samples(rng, gap_s, sample_rate_hz)
        start = cursor + gap
        fit = next((u for u in order if start + u.num_samples <= clip_samples), None)
        if fit is None:
            break
        order.remove(fit)
        out.append(Segment(fit.id, start, start + fit.num_samples, 0, fit.text))
        cursor = start + fit.num_samples
    if not out:
        shortest = min(u.num_samples for u in utterances) / sample_rate_hz
        raise AudioError(
            f"{where}: no utterance fits in the {clip_samples / sample_rate_hz:g} s clip "
            f"(shortest {shortest:.2f} s after a gap drawn in {list(gap_s)} s); lengthen "
            "the clip or shorten the gaps")
    return out


def arrange_background(clips: Sequence[Clip], clip_samples: int, count: Sequence[int],
                       gap_s: Sequence[float], sample_rate_hz: int, rng: np.random.Generator,
                       *, where: str = "background track") -> list[Segment]:
    """Noise or music clips placed one after another with random gaps, the last one cut at
    the clip end. Clips are drawn without replacement while the corpus has them."""
    if clip_samples <= 0:
        raise AudioError(f"{where}: expected a clip of at least one sample, got {clip_samples}")
    wanted = _draw_int(rng, count)
    if wanted == 0:
        return []
    if not clips:
        raise AudioError(f"{where}: expected at least one clip in the corpus split, got none")
    pool: list[Clip] = []
    out: list[Segment] = []
    cursor = 0
    while len(out) < wanted:
        if not pool:
            pool = [clips[i] for i in rng.permutation(len(clips))]
        clip = pool.pop()
        start = cursor + _draw_samples(rng, gap_s, sample_rate_hz)
        if start >= clip_samples:
            break
        end = min(start + clip.num_samples, clip_samples)
        out.append(Segment(clip.id, start, end, 0, ""))
        cursor = end
    return out


def speech_span(segments: Sequence[Segment]) -> tuple[int, int] | None:
    """Samples from the first segment's start to the last one's end (None without any)."""
    return (segments[0].start, segments[-1].end) if segments else None


def walk_window(span: str, segments: Sequence[Segment], clip_samples: int
                ) -> tuple[int, int] | None:
    """The samples a moving source's walk spans: its speech (``"speech"``: from its first
    segment's start to its last one's end, None without any) or the whole clip
    (``"clip"``)."""
    if span == "clip":
        return (0, clip_samples)
    if span == "speech":
        return speech_span(segments)
    raise AudioError(f"span: expected 'speech' or 'clip', got {span!r}")


def assemble(segments: Sequence[Segment], audio: dict[str, np.ndarray], clip_samples: int
             ) -> np.ndarray:
    """The dry track ``(clip_samples,)`` of placed segments, from each clip's audio by id."""
    out = np.zeros(clip_samples)
    for seg in segments:
        try:
            x = audio[seg.id]
        except KeyError:
            raise AudioError(f"segment {seg.id!r}: its audio was not given") from None
        n = seg.end - seg.start
        piece = x[seg.offset:seg.offset + n]
        if piece.size != n:
            raise AudioError(f"segment {seg.id!r}: needs {n} samples from offset {seg.offset}, "
                             f"the clip has {x.size}")
        out[seg.start:seg.end] += piece
    return out
