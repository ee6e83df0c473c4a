"""Tiny corpora in the real FSD50K, FMA and plain-folder layouts, for the tests.

The clips are synthesised by :mod:`sonicspec.audio.generated` (the demo's generated corpora,
which also writes the LibriSpeech layout from espeak-ng speech), with its determinism (one
random stream per file), atomic writes and ``.complete`` marker.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import soundfile as sf

from sonicspec.atomic import write_text
from sonicspec.audio.corpora import FMA_INSTRUMENTAL_GENRE_ID
from sonicspec.audio.generated import (
    check_positive,
    file_rng,
    generate_once,
    music,
    noise_clip,
    normalise,
    voiced,
    write_audio_file,
)
from sonicspec.errors import CorpusError
from sonicspec.units import seconds_to_samples, seconds_to_samples_floor

# Synthesised noise kinds and the FSD50K labels (with AudioSet mids) they stand in for. The
# speech- and music-labelled kinds exist so the label filter has something to remove.
_NOISE_LABELS = {
    "rain": ("Rain,Water", "/m/06mb1,/m/0838f"),
    "wind": ("Wind", "/m/03m9d0z"),
    "fan": ("Mechanical_fan,Mechanisms", "/m/02x984l,/t/dd00077"),
    "engine": ("Engine", "/m/02mk9"),
    "clock": ("Tick-tock,Clock", "/m/07qjznl,/m/01x3z"),
    "knock": ("Knock,Door", "/m/07r4wb8,/m/02dgv"),
    "speech": ("Male_speech_and_man_speaking,Speech,Human_voice", "/m/05zppz,/m/09x0r,/m/09l8g"),
    "music": ("Piano,Keyboard_(musical),Musical_instrument,Music",
              "/m/05r5c,/m/05148p4,/m/04szw,/m/04rlf"),
}


# FMA genres (genre_id, parent, title, top_level), a few of the real 163.
_FMA_GENRES = (
    (1235, 0, "Instrumental", 1235), (18, 1235, "Soundtrack", 1235), (12, 0, "Rock", 12),
    (10, 0, "Pop", 10), (15, 0, "Electronic", 15), (17, 0, "Folk", 17), (21, 0, "Hip-Hop", 21),
)


# tracks.csv columns, as the real file orders them: (group, field).
_FMA_COLUMNS = tuple(
    [("album", f) for f in ("comments", "date_created", "date_released", "engineer",
                            "favorites", "id", "information", "listens", "producer", "tags",
                            "title", "tracks", "type")]
    + [("artist", f) for f in ("active_year_begin", "active_year_end", "associated_labels",
                               "bio", "comments", "date_created", "favorites", "id",
                               "latitude", "location", "longitude", "members", "name",
                               "related_projects", "tags", "website", "wikipedia_page")]
    + [("set", f) for f in ("split", "subset")]
    + [("track", f) for f in ("bit_rate", "comments", "composer", "date_created",
                              "date_recorded", "duration", "favorites", "genre_top", "genres",
                              "genres_all", "information", "interest", "language_code",
                              "license", "listens", "lyricist", "number", "publisher", "tags",
                              "title")]
)


def mp3_writable() -> bool:
    """True if this libsndfile can write MP3 (libsndfile >= 1.1 with LAME)."""
    return "MP3" in sf.available_formats()


# --------------------------------------------------------------------------------------------
# FSD50K


def write_fsd50k(root: Path, dev_clips: int, eval_clips: int, *, clip_duration_s: float = 3.0,
                 seed: int = 0, sample_rate_hz: int = 44100) -> Path:
    """An FSD50K-layout corpus of synthesised clips (16-bit mono WAV, real label names).

    ``FSD50K.dev_audio/<fname>.wav``, ``FSD50K.eval_audio/<fname>.wav`` and
    ``FSD50K.ground_truth/{dev,eval}.csv``; kinds cycle through rain, wind, fan, engine,
    clock, knock, and speech- and music-labelled clips (for the label filter) in an order the
    seed shuffles.
    """
    if dev_clips < 0 or eval_clips < 0 or dev_clips + eval_clips == 0:
        raise CorpusError(f"dev_clips, eval_clips: expected >= 0 and not both 0, got "
                          f"{dev_clips}, {eval_clips}")
    check_positive(clip_duration_s=clip_duration_s, sample_rate_hz=sample_rate_hz)
    params = {"kind": "fsd50k", "dev_clips": int(dev_clips), "eval_clips": int(eval_clips),
              "clip_duration_s": float(clip_duration_s), "seed": int(seed),
              "sample_rate_hz": int(sample_rate_hz)}

    def generate(root: Path) -> list[str]:
        rng = file_rng(seed, "fsd50k")
        total = dev_clips + eval_clips
        fnames = rng.choice(np.arange(1, 450000), size=total, replace=False)
        kinds = list(_NOISE_LABELS)
        cycle = [kinds[i] for i in rng.permutation(len(kinds))]
        n = seconds_to_samples(clip_duration_s, sample_rate_hz)
        written: list[str] = []
        rows = {"dev": [], "eval": []}
        for i, fname in enumerate(int(f) for f in fnames):
            part = "dev" if i < dev_clips else "eval"
            kind = cycle[i % len(cycle)]
            clip_rng = file_rng(seed, "fsd50k-clip", i)
            x = normalise(noise_clip(kind, n, sample_rate_hz, clip_rng),
                          float(clip_rng.uniform(0.3, 0.8)))
            path = root / f"FSD50K.{part}_audio" / f"{fname}.wav"
            write_audio_file(path, x, sample_rate_hz, "WAV", "PCM_16")
            written.append(path.relative_to(root).as_posix())
            labels, mids = _NOISE_LABELS[kind]
            row = [str(fname), labels, mids]
            if part == "dev":
                row.append("val" if clip_rng.random() < 0.15 else "train")
            rows[part].append(row)
        for part, header in (("dev", ["fname", "labels", "mids", "split"]),
                             ("eval", ["fname", "labels", "mids"])):
            buf = io.StringIO()
            writer = csv.writer(buf, lineterminator="\n")
            writer.writerow(header)
            writer.writerows(rows[part])
            path = root / "FSD50K.ground_truth" / f"{part}.csv"
            write_text(path, buf.getvalue())
            written.append(path.relative_to(root).as_posix())
        return written

    return generate_once(Path(root), params, generate)


# --------------------------------------------------------------------------------------------
# FMA


def write_fma(root: Path, tracks: int, *, size: str = "small", clip_duration_s: float = 5.0,
              seed: int = 0, sample_rate_hz: int = 44100) -> Path:
    """An FMA-layout corpus of synthesised stereo MP3 music and its metadata.

    ``fma_<size>/<nnn>/<track:06d>.mp3``, ``fma_metadata/tracks.csv`` (the real three header
    rows and column order, an artist bio with a comma and a line break to exercise quoting)
    and ``fma_metadata/genres.csv``. Three tracks in five are Instrumental (one of them only
    through ``genres_all`` with an empty ``genre_top``, as FMA does for tracks of several top
    genres); the others carry a sung line.
    """
    if tracks < 1:
        raise CorpusError(f"tracks: expected >= 1, got {tracks}")
    check_positive(clip_duration_s=clip_duration_s, sample_rate_hz=sample_rate_hz)
    if not mp3_writable():
        raise CorpusError(f"MP3: expected a libsndfile that writes MP3 (>= 1.1), got "
                          f"{sf.__libsndfile_version__}; upgrade soundfile")
    params = {"kind": "fma", "tracks": int(tracks), "size": size,
              "clip_duration_s": float(clip_duration_s), "seed": int(seed),
              "sample_rate_hz": int(sample_rate_hz)}

    def generate(root: Path) -> list[str]:
        rng = file_rng(seed, "fma")
        ids = sorted(int(t) for t in rng.choice(np.arange(2, 155000), size=tracks,
                                                 replace=False))
        n = seconds_to_samples(clip_duration_s, sample_rate_hz)
        written: list[str] = []
        rows = []
        counts: dict[int, int] = {}
        # Kinds cycle in a shuffled order, so five tracks already hold every kind: plain
        # Instrumental, a sub-genre of it, Instrumental only through genres_all (several top
        # genres, empty genre_top) and two with vocals.
        kinds = ("instrumental", "soundtrack", "several", "vocal", "vocal")
        cycle = [kinds[k] for k in rng.permutation(len(kinds))]
        titles = {g[0]: g[2] for g in _FMA_GENRES}
        for i, track in enumerate(ids):
            track_rng = file_rng(seed, "fma-track", i)
            kind = cycle[i % len(cycle)]
            if kind == "instrumental":
                top, genres, genres_all = "Instrumental", [1235], [1235]
            elif kind == "soundtrack":
                top, genres, genres_all = "Instrumental", [18], [18, 1235]
            elif kind == "several":
                top, genres, genres_all = "", [1235, 15], [1235, 15]
            else:
                genre = int(track_rng.choice([12, 10, 17, 21]))
                top, genres, genres_all = titles[genre], [genre], [genre]
            for g in genres_all:
                counts[g] = counts.get(g, 0) + 1
            vocals = FMA_INSTRUMENTAL_GENRE_ID not in genres_all
            left = music(n, sample_rate_hz, track_rng, vocals=vocals)
            right = (np.roll(left, seconds_to_samples_floor(0.0004, sample_rate_hz))
                     * track_rng.uniform(0.8, 1.0))
            x = normalise(np.stack([left, right], axis=1), float(track_rng.uniform(0.4, 0.8)))
            path = root / f"fma_{size}" / f"{track // 1000:03d}" / f"{track:06d}.mp3"
            write_audio_file(path, x, sample_rate_hz, "MP3", "MPEG_LAYER_III")
            written.append(path.relative_to(root).as_posix())
            values = {
                ("album", "id"): str(1000 + i // 3), ("album", "title"): f"Album {i // 3}",
                ("album", "tracks"): "3", ("album", "type"): "Album",
                ("artist", "id"): str(500 + i // 3), ("artist", "name"): f"Artist {i // 3}",
                ("artist", "bio"): "<p>Plays guitar, sometimes keys.</p>\n<p>Tours often.</p>",
                ("set", "split"): "training", ("set", "subset"): size,
                ("track", "bit_rate"): "320000",
                ("track", "duration"): str(round(clip_duration_s)),
                ("track", "genre_top"): top,
                ("track", "genres"): "[" + ", ".join(map(str, genres)) + "]",
                ("track", "genres_all"): "[" + ", ".join(map(str, genres_all)) + "]",
                ("track", "license"): "Attribution-NonCommercial-ShareAlike 3.0 International",
                ("track", "number"): str(i % 3 + 1), ("track", "title"): f"Track {track}",
            }
            rows.append([str(track)] + [values.get(col, "") for col in _FMA_COLUMNS])
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow([""] + [group for group, _ in _FMA_COLUMNS])
        writer.writerow([""] + [field for _, field in _FMA_COLUMNS])
        writer.writerow(["track_id"] + [""] * len(_FMA_COLUMNS))
        writer.writerows(rows)
        path = root / "fma_metadata" / "tracks.csv"
        write_text(path, buf.getvalue())
        written.append(path.relative_to(root).as_posix())
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(["genre_id", "#tracks", "parent", "title", "top_level"])
        for genre, parent, title, top_level in _FMA_GENRES:
            writer.writerow([genre, counts.get(genre, 0), parent, title, top_level])
        path = root / "fma_metadata" / "genres.csv"
        write_text(path, buf.getvalue())
        written.append(path.relative_to(root).as_posix())
        return written

    return generate_once(Path(root), params, generate)


# --------------------------------------------------------------------------------------------
# Plain folders


def write_folder(root: Path, speakers: int, files_per_speaker: int, *, seed: int = 0) -> Path:
    """A folder corpus ``<root>/<speaker>/take<nn>.<wav|flac>`` of speech-like sounds.

    No espeak-ng needed: a gliding buzz through two formants, in syllables. Speakers use
    16, 22.05 or 48 kHz and alternate WAV and FLAC, so readers meet mixed rates and formats;
    ``<root>/README.txt`` is not audio and must be ignored.
    """
    check_positive(speakers=speakers, files_per_speaker=files_per_speaker)
    params = {"kind": "folder", "speakers": int(speakers),
              "files_per_speaker": int(files_per_speaker), "seed": int(seed)}

    def generate(root: Path) -> list[str]:
        written: list[str] = []
        for s in range(speakers):
            rate = (16000, 22050, 48000)[s % 3]
            for f in range(files_per_speaker):
                rng = file_rng(seed, "folder", s, f)
                x = normalise(voiced(seconds_to_samples(rng.uniform(1.0, 2.0), rate), rate, rng),
                              float(rng.uniform(0.3, 0.7)))
                ext, fmt = ((".flac", "FLAC"), (".wav", "WAV"))[f % 2]
                path = root / f"spk{s + 1:02d}" / f"take{f + 1:02d}{ext}"
                write_audio_file(path, x, rate, fmt, "PCM_16")
                written.append(path.relative_to(root).as_posix())
        path = root / "README.txt"
        write_text(path, "Generated speech-like test corpus; one folder per speaker.\n")
        written.append(path.relative_to(root).as_posix())
        return written

    return generate_once(Path(root), params, generate)
