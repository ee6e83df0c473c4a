"""The demo's generated corpora (``kind: generated``): real-layout folders of deterministic audio.

Speech comes from espeak-ng (real English sentences, one voice, pitch and speed per speaker) in
the LibriSpeech layout; noise and music are synthesised (coloured noise, hum, clicks, knocks;
notes and chords with envelopes) into one folder per split. The corpus step generates them
into its cache and indexes them like any other corpus (:mod:`sonicspec.audio.corpora`); the
test fixtures in ``sonicspec.testing.corpora`` write FSD50K, FMA and plain-folder layouts from
the same synthesis.

Everything is deterministic for the seed: each file draws from its own
``numpy.random.Generator`` keyed by (seed, corpus, file), so no global RNG is touched and adding
a split or a file leaves the others as they were.

Every file is written to a dot-file beside its target and renamed into place, and a root is
finished by writing ``.complete`` (the parameters and the files written) last. A call whose
root already holds a ``.complete`` with the same parameters returns at once; an interrupted
run has no marker, so the next call writes everything again (same bytes).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import soundfile as sf
from scipy.signal import lfilter

from sonicspec.atomic import atomic_path, write_text
from sonicspec.audio.corpora import resample
from sonicspec.errors import CorpusError
from sonicspec.units import seconds_to_samples, seconds_to_samples_floor

GENERATOR_VERSION = 1
"""Bump when a writer's output changes, so existing generated roots are written again."""
MARKER = ".complete"


# Harvard sentences (IEEE Recommended Practice for Speech Quality Measurements, 1969): real,
# phonetically balanced English, the classic material for speech tests.
SENTENCES = (
    "The birch canoe slid on the smooth planks.",
    "Glue the sheet to the dark blue background.",
    "It's easy to tell the depth of a well.",
    "These days a chicken leg is a rare dish.",
    "Rice is often served in round bowls.",
    "The juice of lemons makes fine punch.",
    "The box was thrown beside the parked truck.",
    "The hogs were fed chopped corn and garbage.",
    "Four hours of steady work faced us.",
    "A large size in stockings is hard to sell.",
    "The boy was there when the sun rose.",
    "A rod is used to catch pink salmon.",
    "The source of the huge river is the clear spring.",
    "Kick the ball straight and follow through.",
    "Help the woman get back to her feet.",
    "A pot of tea helps to pass the evening.",
    "Smoky fires lack flame and heat.",
    "The soft cushion broke the man's fall.",
    "The salt breeze came across from the sea.",
    "The girl at the booth sold fifty bonds.",
    "The small pup gnawed a hole in the sock.",
    "The fish twisted and turned on the bent hook.",
    "Press the pants and sew a button on the vest.",
    "The swan dive was far short of perfect.",
    "The beauty of the view stunned the young boy.",
    "Two blue fish swam in the tank.",
    "Her purse was full of useless trash.",
    "The colt reared and threw the tall rider.",
    "It snowed, rained, and hailed the same morning.",
    "Read verse out loud for pleasure.",
    "Hoist the load to your left shoulder.",
    "Take the winding path to reach the lake.",
    "Note closely the size of the gas tank.",
    "Wipe the grease off his dirty face.",
    "Mend the coat before you go out.",
    "The wrist was badly strained and hung limp.",
    "The stray cat gave birth to kittens.",
    "The young girl gave no clear response.",
    "The meal was cooked before the bell rang.",
    "What joy there is in living.",
)


# espeak-ng accents and voice variants that ship with every espeak-ng >= 1.49.
_ACCENTS = ("en-us", "en", "en-gb-scotland", "en-029", "en-gb-x-rp")
_VARIANTS = ("m1", "m2", "m3", "m4", "m7", "f1", "f2", "f3", "f4", "f5")

NOISE_KINDS = ("rain", "wind", "fan", "engine", "clock", "knock", "speech", "music")
"""What :func:`noise_clip` synthesises (speech- and music-like kinds included)."""

BACKGROUND_NOISE_KINDS = ("rain", "wind", "fan", "engine", "clock", "knock")


# --------------------------------------------------------------------------------------------
# Plumbing


def espeak_available() -> bool:
    """True if the ``espeak-ng`` program is on the PATH."""
    return shutil.which("espeak-ng") is not None


def file_rng(seed: int, *words: str | int) -> np.random.Generator:
    """A generator of its own for each (seed, words): files do not share random streams."""
    keys = [w if isinstance(w, int) else zlib.crc32(str(w).encode()) for w in words]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed), *keys])))


def generate_once(root: Path, params: Mapping[str, Any],
                  generate: Callable[[Path], list[str]]) -> Path:
    """Run ``generate(root)`` unless ``root/.complete`` records the same parameters.

    ``generate`` returns the files it wrote (relative paths). A root generated before with
    other parameters loses the files the old marker lists and the new ones are written.
    """
    root = Path(root)
    params = json.loads(json.dumps({**params, "generator": GENERATOR_VERSION}, sort_keys=True))
    marker = root / MARKER
    old: dict[str, Any] | None = None
    try:
        old = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        old = None
    if isinstance(old, dict) and old.get("params") == params:
        return root
    marker.unlink(missing_ok=True)  # from here on the root does not look complete
    root.mkdir(parents=True, exist_ok=True)
    written = set(generate(root))
    if isinstance(old, dict):
        for rel in old.get("files", ()):
            if rel not in written:
                _remove_generated(root, Path(rel))
    text = json.dumps({"params": params, "files": sorted(written)}, indent=1, sort_keys=True)
    write_text(marker, text)
    return root


def _remove_generated(root: Path, rel: Path) -> None:
    """Delete a file an earlier generation wrote, and the folders it leaves empty."""
    path = root / rel
    if path.is_file():
        path.unlink()
    for parent in path.parents:
        if parent == root or root not in parent.parents:
            break
        try:
            parent.rmdir()
        except OSError:
            break


def write_audio_file(path: Path, x: np.ndarray, sample_rate_hz: int, fmt: str,
                     subtype: str) -> None:
    """Atomic soundfile write (x is (T,) or (T, C))."""
    with atomic_path(path) as tmp:
        sf.write(str(tmp), x, sample_rate_hz, format=fmt, subtype=subtype)


def normalise(x: np.ndarray, peak: float) -> np.ndarray:
    m = float(np.max(np.abs(x)))
    return x * (peak / m) if m > 0 else x


def check_positive(**values: float) -> None:
    for name, v in values.items():
        if not v > 0:
            raise CorpusError(f"{name}: expected > 0, got {v}")


# --------------------------------------------------------------------------------------------
# Speech (espeak-ng)


def transcript_words(sentence: str) -> str:
    """LibriSpeech's transcript style: upper case, no punctuation but apostrophes."""
    return " ".join(re.sub(r"[^A-Z' ]+", " ", sentence.upper()).split())


def _espeak(text: str, voice: str, pitch: int, speed: int, workdir: Path
            ) -> tuple[np.ndarray, int]:
    if not espeak_available():
        raise CorpusError("espeak-ng not found; install it with apt-get install espeak-ng")
    wav = workdir / "utterance.wav"
    cmd = ["espeak-ng", "-w", str(wav), "-v", voice, "-p", str(pitch), "-s", str(speed), text]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    except (OSError, subprocess.TimeoutExpired) as err:
        raise CorpusError(f"espeak-ng: expected to synthesise {text!r}, got {err}") from err
    if done.returncode != 0 or not wav.is_file():
        raise CorpusError(f"espeak-ng (voice {voice}): expected a WAV file, got exit code "
                          f"{done.returncode}: {done.stderr.strip()[:300]}")
    x, rate = sf.read(str(wav), dtype="float64", always_2d=True)
    return x.mean(axis=1), int(rate)


def write_librispeech(root: Path, subsets: Mapping[str, int], utterances_per_speaker: int, *,
                      seed: int = 0, sample_rate_hz: int = 16000) -> Path:
    """A LibriSpeech-layout corpus of espeak-ng speech; ``subsets`` maps name -> speakers.

    ``<root>/<subset>/<speaker>/<chapter>/<speaker>-<chapter>-<nnnn>.flac`` (16-bit FLAC at
    ``sample_rate_hz``) and ``<speaker>-<chapter>.trans.txt``. Each speaker has a voice,
    pitch, speed and level of its own and reads Harvard sentences (a speaker with more than
    five utterances gets two chapters); speaker ids are unique across subsets.
    """
    if not subsets or any(int(n) < 1 for n in subsets.values()):
        raise CorpusError(f"subsets: expected subset names with >= 1 speaker each, got "
                          f"{dict(subsets)}")
    check_positive(utterances_per_speaker=utterances_per_speaker,
                   sample_rate_hz=sample_rate_hz)
    if not espeak_available():
        raise CorpusError("espeak-ng not found; install it with apt-get install espeak-ng")
    params = {"kind": "librispeech", "subsets": dict(sorted(subsets.items())),
              "utterances_per_speaker": int(utterances_per_speaker), "seed": int(seed),
              "sample_rate_hz": int(sample_rate_hz)}

    def generate(root: Path) -> list[str]:
        rng = file_rng(seed, "librispeech")
        total = sum(int(n) for n in subsets.values())
        speaker_ids = rng.choice(np.arange(100, 10000), size=total, replace=False)
        chapter_ids = rng.choice(np.arange(10000, 400000), size=2 * total, replace=False)
        written: list[str] = []
        k = 0
        with tempfile.TemporaryDirectory(prefix=".espeak-", dir=root) as work:
            for subset in sorted(subsets):
                for _ in range(int(subsets[subset])):
                    written += _write_speaker(root, subset, int(speaker_ids[k]),
                                              [int(c) for c in chapter_ids[2 * k: 2 * k + 2]],
                                              int(utterances_per_speaker),
                                              file_rng(seed, "librispeech-speaker", k),
                                              int(sample_rate_hz), Path(work))
                    k += 1
        return written

    return generate_once(Path(root), params, generate)


def _write_speaker(root: Path, subset: str, speaker: int, chapters: list[int],
                   utterances: int, rng: np.random.Generator, sample_rate_hz: int,
                   work: Path) -> list[str]:
    voice = f"{_ACCENTS[rng.integers(len(_ACCENTS))]}+{_VARIANTS[rng.integers(len(_VARIANTS))]}"
    pitch = int(rng.integers(25, 76))
    speed = int(rng.integers(140, 186))
    level = float(rng.uniform(0.3, 0.7))
    order = np.concatenate([rng.permutation(len(SENTENCES))
                            for _ in range(-(-utterances // len(SENTENCES)))])
    n_chapters = 1 if utterances <= 5 else 2
    written: list[str] = []
    for c in range(n_chapters):
        chapter = chapters[c]
        folder = root / subset / str(speaker) / str(chapter)
        lines = []
        for n, u in enumerate(range(c, utterances, n_chapters)):
            sentence = SENTENCES[int(order[u])]
            uid = f"{speaker}-{chapter}-{n:04d}"
            x, rate = _espeak(sentence, voice, pitch, speed, work)
            x = normalise(resample(x, rate, sample_rate_hz), level)
            path = folder / f"{uid}.flac"
            write_audio_file(path, x, sample_rate_hz, "FLAC", "PCM_16")
            written.append(path.relative_to(root).as_posix())
            lines.append(f"{uid} {transcript_words(sentence)}\n")
        trans = folder / f"{speaker}-{chapter}.trans.txt"
        write_text(trans, "".join(lines))
        written.append(trans.relative_to(root).as_posix())
    return written


# --------------------------------------------------------------------------------------------
# Noise synthesis


def _coloured_noise(n: int, fs: int, rng: np.random.Generator, exponent: float,
                    f_low: float = 30.0) -> np.ndarray:
    """Noise with power spectral density ∝ 1/f^exponent above ``f_low`` (0 white, 1 pink)."""
    spec = rng.standard_normal(n // 2 + 1) + 1j * rng.standard_normal(n // 2 + 1)
    f = np.fft.rfftfreq(n, 1 / fs)
    gain = np.where(f >= f_low, np.maximum(f, f_low) ** (-exponent / 2), 0.0)
    return np.fft.irfft(spec * gain, n)


def _decaying_tone(n: int, fs: int, freq: float, decay_s: float) -> np.ndarray:
    t = np.arange(n) / fs
    return np.sin(2 * np.pi * freq * t) * np.exp(-t / decay_s)


def _add_at(out: np.ndarray, start: int, x: np.ndarray) -> None:
    stop = min(out.size, start + x.size)
    if stop > start:
        out[start:stop] += x[: stop - start]


def _harmonics(f0: np.ndarray | float, n: int, fs: int, count: int, tilt: float
               ) -> np.ndarray:
    """Sum of harmonics of a (possibly gliding) fundamental, amplitudes k^-tilt, below Nyquist."""
    f0 = np.asarray(f0, dtype=np.float64)
    if f0.ndim == 0:
        phase = 2 * np.pi * float(f0) / fs * np.arange(n)
        top = float(f0)
    else:
        phase = 2 * np.pi * np.cumsum(f0) / fs
        top = float(f0.max()) if f0.size else 0.0
    out = np.zeros(n)
    # sin(kθ) = 2 cos θ · sin((k−1)θ) − sin((k−2)θ): one sine and cosine for all harmonics
    s_prev, s_k, two_cos = np.zeros(n), np.sin(phase), 2 * np.cos(phase)
    for k in range(1, count + 1):
        if k * top >= 0.45 * fs:
            break
        out += s_k / k**tilt
        s_prev, s_k = s_k, two_cos * s_k - s_prev
    return out


def _resonator(x: np.ndarray, fs: int, freq: float, bandwidth: float) -> np.ndarray:
    """Two-pole resonance (a formant or a body mode)."""
    r = np.exp(-np.pi * bandwidth / fs)
    a = [1.0, -2 * r * np.cos(2 * np.pi * freq / fs), r * r]
    return lfilter([1 - r], a, x)


def voiced(n: int, fs: int, rng: np.random.Generator) -> np.ndarray:
    """Speech-like sound: a gliding glottal buzz through two formants, in syllables."""
    t_points = np.linspace(0, n, 6)
    f0 = np.interp(np.arange(n), t_points, rng.uniform(90, 240) * rng.uniform(0.8, 1.25, 6))
    buzz = _harmonics(f0, n, fs, 30, 1.0)
    voice = (_resonator(buzz, fs, rng.uniform(400, 800), 80)
             + 0.6 * _resonator(buzz, fs, rng.uniform(1000, 2200), 120))
    env = np.zeros(n)
    pos = seconds_to_samples_floor(rng.uniform(0.02, 0.1), fs)
    while pos < n:
        length = seconds_to_samples_floor(rng.uniform(0.12, 0.3), fs)
        _add_at(env, pos, np.hanning(length))
        pos += length + seconds_to_samples_floor(rng.uniform(0.02, 0.15), fs)
    return voice * env


def noise_clip(kind: str, n: int, fs: int, rng: np.random.Generator) -> np.ndarray:
    """One synthesised clip standing in for an FSD50K class."""
    t = np.arange(n) / fs
    if kind == "rain":
        x = 0.4 * _coloured_noise(n, fs, rng, 1.0, 200.0)
        x /= np.max(np.abs(x))
        drops = np.zeros(n)
        for start in rng.integers(0, n, size=int(rng.uniform(20, 60) * n / fs)):
            _add_at(drops, int(start),
                    rng.uniform(0.2, 1) * _decaying_tone(seconds_to_samples_floor(0.02, fs), fs,
                                                         rng.uniform(2000, 6000), 0.003))
        return x + drops
    if kind == "wind":
        lfo = 0.6 + 0.4 * np.sin(2 * np.pi * rng.uniform(0.1, 0.4) * t + rng.uniform(0, 6.3))
        return _coloured_noise(n, fs, rng, 2.0, 40.0) * lfo
    if kind == "fan":
        hum = _harmonics(rng.uniform(40, 120), n, fs, 8, 1.2)
        return hum / np.max(np.abs(hum)) + 2.0 * normalise(
            _coloured_noise(n, fs, rng, 1.0, 100.0), 0.25)
    if kind == "engine":
        f0 = rng.uniform(25, 60) * (1 + 0.05 * np.sin(2 * np.pi * 0.3 * t))
        x = _harmonics(f0, n, fs, 20, 0.8)
        x *= 1 + 0.3 * np.sin(2 * np.pi * 4 * f0.mean() * t)
        return normalise(x, 1) + normalise(_coloured_noise(n, fs, rng, 2.0, 30.0), 0.3)
    if kind == "clock":
        x = 0.002 * rng.standard_normal(n)
        period = rng.choice([0.5, 1.0])
        freq = rng.uniform(2500, 4500)
        for i, start in enumerate(np.arange(rng.uniform(0, period), n / fs, period)):
            tick = _decaying_tone(seconds_to_samples_floor(0.03, fs), fs,
                                  freq * (1.0 if i % 2 else 0.8), 0.004)
            _add_at(x, seconds_to_samples_floor(start, fs), tick)
        return x
    if kind == "knock":
        x = 0.002 * rng.standard_normal(n)
        mode = rng.uniform(120, 300)
        for group in np.arange(rng.uniform(0.1, 0.5), n / fs - 0.5, rng.uniform(1.2, 2.0)):
            for k in range(int(rng.integers(2, 5))):
                hit = _decaying_tone(seconds_to_samples_floor(0.15, fs), fs, mode, 0.03)
                click = seconds_to_samples_floor(0.003, fs)
                hit[:click] += rng.standard_normal(click)
                _add_at(x, seconds_to_samples_floor(group + 0.18 * k, fs), hit)
        return x
    if kind == "speech":
        return voiced(n, fs, rng)
    if kind == "music":
        return music(n, fs, rng, vocals=False)
    raise CorpusError(f"noise kind: expected one of {', '.join(NOISE_KINDS)}, got {kind!r}")


# --------------------------------------------------------------------------------------------
# Music synthesis

_MAJOR = (0, 2, 4, 5, 7, 9, 11)


_MINOR = (0, 2, 3, 5, 7, 8, 10)


def _midi_hz(note: float) -> float:
    return 440.0 * 2 ** ((note - 69) / 12)


def _note(freq: float, length: int, fs: int, attack_s: float, decay_s: float, tilt: float
          ) -> np.ndarray:
    t = np.arange(length) / fs
    env = np.minimum(1.0, t / attack_s) * np.exp(-t / decay_s)
    fade = min(length, seconds_to_samples_floor(0.01, fs))
    env[-fade:] *= np.linspace(1, 0, fade)
    return _harmonics(freq, length, fs, 8, tilt) * env


def music(n: int, fs: int, rng: np.random.Generator, *, vocals: bool) -> np.ndarray:
    """Chords, bass and a plucked melody in one key and tempo; optional sung line."""
    beat = 60.0 / rng.uniform(80, 140)
    tonic = 48 + int(rng.integers(0, 12))
    scale = _MAJOR if rng.random() < 0.5 else _MINOR
    out = np.zeros(n)
    bar = seconds_to_samples_floor(4 * beat, fs)
    for start in range(0, n, bar):
        degree = int(rng.choice([0, 3, 4, 5]))
        for step in (0, 2, 4):  # triad on the degree
            idx = degree + step
            note = tonic + 12 + scale[idx % 7] + 12 * (idx // 7)
            _add_at(out, start, 0.25 * _note(_midi_hz(note), bar, fs, 0.08, 3.0, 2.0))
        for b in range(4):
            bass = _note(_midi_hz(tonic - 12 + scale[degree]),
                         seconds_to_samples_floor(beat, fs), fs, 0.005, 0.4, 1.5)
            _add_at(out, start + seconds_to_samples_floor(b * beat, fs), 0.4 * bass)
    half = seconds_to_samples_floor(beat / 2, fs)  # beat / 2 is exact: the same as beat * fs / 2
    melody = []
    for start in range(0, n, half):
        if rng.random() < 0.75:
            note = tonic + 24 + scale[int(rng.integers(7))]
            melody.append((start, note))
            _add_at(out, start, 0.3 * _note(_midi_hz(note), 2 * half, fs, 0.003, 0.25, 1.0))
    if vocals and melody:
        f0 = np.zeros(n)
        for start, note in melody:
            f0[start:] = _midi_hz(note - 12)
        f0 *= 1 + 0.01 * np.sin(2 * np.pi * 5.5 * np.arange(n) / fs)  # vibrato
        buzz = _harmonics(np.maximum(f0, 80.0), n, fs, 25, 1.0)
        sung = _resonator(buzz, fs, 700, 90) + 0.5 * _resonator(buzz, fs, 1200, 110)
        out += 0.8 * normalise(sung, 1.0) * (f0 > 0)
    return out


# --------------------------------------------------------------------------------------------
# Generated corpora for specs (``kind: generated``)


def _check_splits(splits: Sequence[str]) -> list[str]:
    names = [str(s) for s in splits]
    if not names or len(set(names)) != len(names) or any(not s or "/" in s for s in names):
        raise CorpusError(f"splits: expected distinct non-empty names, got {names}")
    return names


def generate_speech_corpus(root: Path, splits: Sequence[str], speakers_per_split: int,
                           utterances_per_speaker: int, *, seed: int) -> dict[str, list[str]]:
    """espeak-ng speech in the LibriSpeech layout, one subset ``generated-<split>`` per split.

    Returns the split -> subsets mapping to give :func:`~sonicspec.audio.corpora.
    index_librispeech`; speakers are distinct across splits.
    """
    names = _check_splits(splits)
    subsets = {f"generated-{s}": int(speakers_per_split) for s in names}
    write_librispeech(Path(root), subsets, utterances_per_speaker, seed=seed)
    return {s: [f"generated-{s}"] for s in names}


def generate_background_corpus(root: Path, role: str, splits: Sequence[str],
                               clips_per_split: int, clip_duration_s: float, *, seed: int,
                               sample_rate_hz: int = 16000) -> dict[str, list[str]]:
    """Synthesised noise or music clips, ``<root>/<split>/<role>-<nnnn>.flac``.

    ``role`` is ``noise`` (rain, wind, fan, engine, clock, knock) or ``music`` (instrumental).
    Returns split -> item ids (``train/noise-0000`` …), the ids
    :func:`~sonicspec.audio.corpora.index_split_folders` gives the same files.
    """
    if role not in ("noise", "music"):
        raise CorpusError(f"role: expected noise or music, got {role!r}")
    names = _check_splits(splits)
    check_positive(clips_per_split=clips_per_split, clip_duration_s=clip_duration_s,
                   sample_rate_hz=sample_rate_hz)
    ids = {s: [f"{s}/{role}-{i:04d}" for i in range(int(clips_per_split))] for s in names}
    params = {"kind": "background", "role": role, "splits": names,
              "clips_per_split": int(clips_per_split),
              "clip_duration_s": float(clip_duration_s), "seed": int(seed),
              "sample_rate_hz": int(sample_rate_hz)}

    def generate(root: Path) -> list[str]:
        n = seconds_to_samples(clip_duration_s, sample_rate_hz)
        written: list[str] = []
        for split in names:
            for i, uid in enumerate(ids[split]):
                rng = file_rng(seed, role, split, i)
                if role == "noise":
                    kind = BACKGROUND_NOISE_KINDS[int(rng.integers(len(BACKGROUND_NOISE_KINDS)))]
                    x = noise_clip(kind, n, sample_rate_hz, rng)
                else:
                    x = music(n, sample_rate_hz, rng, vocals=False)
                path = root / f"{uid}.flac"
                write_audio_file(path, normalise(x, float(rng.uniform(0.3, 0.8))),
                                 sample_rate_hz, "FLAC", "PCM_16")
                written.append(path.relative_to(root).as_posix())
        return written

    generate_once(Path(root), params, generate)
    return ids
