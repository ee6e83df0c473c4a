"""Word and character error rates of estimates, with a Whisper model the user holds.

Nothing is downloaded: ``sonicspec evaluate --asr-model PATH`` names either a faster-whisper
model folder (a CTranslate2 conversion: ``model.bin``, ``config.json``, the tokenizer; run by
``faster_whisper``) or an openai-whisper checkpoint file (``medium.en.pt``; run by
``whisper``). Each estimate is transcribed whole at 16 kHz, in English, with each package's
default decoding.

Both the reference and the transcript go through Whisper's English text normaliser (the
``whisper_normalizer`` package's ``EnglishTextNormalizer``, MIT: the normaliser of
openai-whisper's ``whisper/normalizers`` without its PyTorch dependency; spellings
British -> American, numbers written as digits, punctuation and fillers dropped), then
``jiwer`` counts word (and character) substitutions, deletions and insertions. A row's ``wer``
is its errors over its reference's words; a summary's is the pooled errors over the pooled
words (the corpus WER), not the mean of the rows'.

References: a sonicspec dataset's (and the released SonicSet's) metadata has each talker's
transcript (``words``, a clip's text each); any other set, or a dataset without them, takes
a ``--transcripts`` file: UTF-8 lines ``<group id>/<target><TAB><text>`` (the group id as
``evaluate`` names it, e.g. ``test/000003/source1``; a one-target group may leave out
``/<target>``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.dataload.folder import DatasetError, Group
from sonicspec.dataload.mos import RATE_HZ, file_record

COLUMNS = ("wer", "cer")
COUNTS = {"wer": ("word_errors", "ref_words"), "cer": ("char_errors", "ref_chars")}
_INSTALL = "pip install 'sonicspec[asr]'"
CT2_FILES = ("model.bin", "config.json")


def _need(module: str, what: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise DatasetError(f"the {module} package is needed for {what}; {_INSTALL}") from None


def normaliser() -> Callable[[str], str]:
    """Whisper's English text normaliser."""
    english = _need("whisper_normalizer.english", "WER (Whisper's text normaliser)")
    return english.EnglishTextNormalizer()


def error_counts(reference: str, hypothesis: str,
                 normalise: Callable[[str], str] | None = None) -> dict[str, Any]:
    """``wer``, ``cer`` and their counts of one utterance, both texts normalised first.

    A reference with no words after normalising has no error rate: :class:`DatasetError`.
    """
    jiwer = _need("jiwer", "WER")
    norm = normalise or normaliser()
    ref, hyp = norm(reference).strip(), norm(hypothesis).strip()
    if not ref:
        raise DatasetError(f"WER: the reference {reference!r} has no words after Whisper's "
                           "normaliser; expected a transcript")
    words = jiwer.process_words(ref, hyp)
    chars = jiwer.process_characters(ref, hyp)
    n_words = words.hits + words.substitutions + words.deletions
    n_chars = chars.hits + chars.substitutions + chars.deletions
    w_err = words.substitutions + words.deletions + words.insertions
    c_err = chars.substitutions + chars.deletions + chars.insertions
    return {"wer": w_err / n_words, "cer": c_err / n_chars, "word_errors": w_err,
            "ref_words": n_words, "char_errors": c_err, "ref_chars": n_chars,
            "reference": ref, "transcript": hyp}


@dataclass
class Transcriber:
    """A speech recogniser: ``transcribe(audio at 16 kHz) -> text``, the files it came from
    (path, bytes, SHA-256) and its kind."""

    kind: str
    transcribe: Callable[[np.ndarray], str]
    files: list[dict[str, Any]] = field(default_factory=list)

    def __call__(self, audio: np.ndarray, rate: int) -> str:
        x = np.asarray(audio, dtype=np.float64)
        if rate != RATE_HZ:
            from scipy.signal import resample_poly

            g = math.gcd(int(rate), RATE_HZ)
            x = resample_poly(x, RATE_HZ // g, int(rate) // g)
        return str(self.transcribe(x.astype(np.float32)))


def open_transcriber(path: str | Path, *, language: str = "en") -> Transcriber:
    """A faster-whisper model folder or an openai-whisper checkpoint file, checked."""
    p = Path(path)
    if p.is_dir():
        missing = [n for n in CT2_FILES if not (p / n).is_file()]
        if missing:
            raise DatasetError(f"--asr-model {p}: missing {', '.join(missing)}; expected a "
                               "faster-whisper (CTranslate2) model folder (model.bin, "
                               "config.json, tokenizer.json) or an openai-whisper .pt file")
        fw = _need("faster_whisper", f"--asr-model {p} (a faster-whisper model folder)")
        try:
            model = fw.WhisperModel(str(p), device="cpu", compute_type="int8",
                                    local_files_only=True)
        except Exception as exc:  # CTranslate2 raises RuntimeError / ValueError / OSError
            raise DatasetError(f"--asr-model {p}: faster-whisper cannot load it: "
                               f"{str(exc).splitlines()[0][:200]}") from None

        def run(x: np.ndarray) -> str:
            segments, _ = model.transcribe(x, language=language)
            return " ".join(s.text.strip() for s in segments)

        files = [file_record(f) for f in sorted(p.iterdir()) if f.is_file()]
        return Transcriber("faster-whisper", run, files)
    if p.is_file():
        if p.suffix != ".pt":
            raise DatasetError(f"--asr-model {p}: expected a faster-whisper model folder or "
                               f"an openai-whisper checkpoint (.pt), got a {p.suffix or 'bare'}"
                               " file")
        whisper = _need("whisper", f"--asr-model {p} (an openai-whisper checkpoint)")
        try:
            model = whisper.load_model(str(p), device="cpu")
        except Exception as exc:  # torch.load raises many kinds
            raise DatasetError(f"--asr-model {p}: openai-whisper cannot load it: "
                               f"{str(exc).splitlines()[0][:200]}") from None

        def run_pt(x: np.ndarray) -> str:
            return str(model.transcribe(x, language=language, fp16=False)["text"])

        return Transcriber("openai-whisper", run_pt, [file_record(p)])
    raise DatasetError(f"--asr-model {p}: no such file or folder; expected a faster-whisper "
                       "model folder or an openai-whisper .pt file (nothing is downloaded)")


def read_transcripts(path: str | Path) -> dict[str, str]:
    """A ``--transcripts`` file: ``<key><TAB><text>`` lines (blank lines skipped)."""
    p = Path(path)
    if not p.is_file():
        raise DatasetError(f"--transcripts {p}: no such file")
    out: dict[str, str] = {}
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise DatasetError(f"--transcripts {p}: not UTF-8 text (byte {exc.start})") from None
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        key, sep, text = line.partition("\t")
        if not sep or not key.strip():
            raise DatasetError(f"--transcripts {p}:{n}: expected '<group id>/<target><TAB>"
                               f"<text>', got {line[:80]!r}")
        if key.strip() in out:
            raise DatasetError(f"--transcripts {p}:{n}: {key.strip()!r} is given twice")
        out[key.strip()] = text.strip()
    return out


def reference_text(group: Group, target: str, n_targets: int,
                   transcripts: Mapping[str, str] | None) -> str:
    """What ``target`` of ``group`` says: the ``--transcripts`` entry, else its metadata's
    ``words``; :class:`DatasetError` naming the group and target when neither has it."""
    if transcripts is not None:
        for key in (f"{group.id}/{target}", *((group.id,) if n_targets == 1 else ())):
            if key in transcripts:
                return transcripts[key]
    words = (group.metadata.get(target) or {}).get("words")
    if words:
        return " ".join(str(w) for w in words)
    where = "the --transcripts file" if transcripts is not None else "no --transcripts file"
    raise DatasetError(f"group {group.id}: no transcript for {target} (its metadata has no "
                       f"words, and {where} has no line '{group.id}/{target}<TAB>...'); WER "
                       "needs what each target says")
