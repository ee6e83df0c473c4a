"""``sonicspec evaluate``: a model's outputs scored against a dataset's targets.

The dataset is a built sonicspec dataset or a public test set in its own layout
(:mod:`sonicspec.dataload.formats`). The estimates folder mirrors its groups: for each
mixture of the task, ``<estimates>/<group id>/<mixture name>.wav`` (or ``.flac``; a sonicspec
group id is ``<split>/<group index>``, an external set's is its own), as long as the
mixture, at its sample rate, with one channel per target (``k`` for separation of ``k``
speakers, one for enhancement). Targets and mixture are taken at the reference channel
(``channel``, default 0). Separation outputs are matched to the targets by the permutation
with the best mean SI-SNR over the whole clip, kept in every window. Each metric is then the
mean over 6 s windows every 3 s (:func:`sonicspec.audio.metrics.windows`).

``oracle``: the mixture itself as every estimate (SI-SNRi and SDRi are 0 by construction: the
baseline) and the targets themselves (the ceiling).

Bad estimates: a file with a NaN or an infinite sample is refused (naming the file, the first
such sample and its channel). A silent (all-zero) estimate is scored, not a crash: in the
windows where it is silent every metric is undefined (SI-SNR and SDR are 0 / 0, P.862 cannot
level silence), so they are left out of the means like windows of a silent target, and
counted per row (``silent_estimate``); ``sonicspec evaluate`` warns with the count, and a
target whose estimate is silent throughout has no scores ("-" in the table).

Metrics with a model the user holds are scored on the whole clip of each matched estimate,
not in windows: ``wer`` (with ``cer``; a transcriber, :mod:`sonicspec.dataload.asr`) and
``dnsmos`` (``dnsmos_sig``, ``dnsmos_bak``, ``dnsmos_ovrl``, ``dnsmos_p808``;
:mod:`sonicspec.dataload.mos`). :func:`expand_metrics` turns the names a user gives into the
columns.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.atomic import write_text
from sonicspec.audio.metrics import METRICS, best_permutation, windowed_scores
from sonicspec.dataload.folder import DatasetError, Group, read_audio
from sonicspec.dataload.loader import TASKS

AUDIO_EXTENSIONS = (".wav", ".flac")
# Names that stand for several columns; any column is a name too.
ALIASES: dict[str, tuple[str, ...]] = {
    "pesq": ("pesq_nb", "pesq_wb"),
    "wer": ("wer", "cer"),
    "dnsmos": ("dnsmos_sig", "dnsmos_bak", "dnsmos_ovrl", "dnsmos_p808"),
}
MODEL_COLUMNS = ("wer", "cer", *ALIASES["dnsmos"])
POOLED = {"wer": ("word_errors", "ref_words"), "cer": ("char_errors", "ref_chars")}


def expand_metrics(names: Sequence[str]) -> list[str]:
    """The columns ``names`` ask for (each name a column or an alias of several; commas
    separate names too), in order, once each."""
    known = [*METRICS, *MODEL_COLUMNS]
    out: list[str] = []
    for item in names:
        for name in (n.strip() for n in str(item).split(",")):
            if not name:
                continue
            cols = ALIASES.get(name, (name,))
            if cols[0] not in known:
                raise DatasetError(f"--metrics: expected names from "
                                   f"{[*METRICS, *ALIASES]}, got {name!r}")
            out.extend(c for c in cols if c not in out)
    if not out:
        raise DatasetError("--metrics: expected at least one name")
    return out


def score_models(row: dict[str, Any], estimate: np.ndarray, rate: int, columns: Sequence[str],
                 *, reference: str | None, transcriber: Any = None, normalise: Any = None,
                 mos: Mapping[str, Any] | None = None) -> None:
    """Add the model metrics of ``columns`` for one whole-clip estimate to ``row``."""
    from sonicspec.dataload.asr import error_counts

    if "wer" in columns or "cer" in columns:
        if not np.any(estimate):
            text = ""  # a silent estimate says nothing: every reference word is deleted
        else:
            text = transcriber(estimate, rate)
        counts = error_counts(reference or "", text, normalise)
        row.update({c: counts[c] for c in ("wer", "cer") if c in columns})
        row.update({k: counts[k] for k in ("word_errors", "ref_words", "char_errors",
                                           "ref_chars", "transcript")})
    for model in (mos or {}).values():
        wanted = [c for c in model.COLUMNS if c in columns]
        if wanted:
            scores = model(estimate, rate)
            row.update({c: scores[c] for c in wanted})


def check_models(columns: Sequence[str], transcriber: Any, mos: Mapping[str, Any] | None
                 ) -> None:
    """A clear error when a model metric is asked for without its model."""
    if ("wer" in columns or "cer" in columns) and transcriber is None:
        raise DatasetError("--metrics wer: give the speech recogniser with --asr-model PATH (a "
                           "faster-whisper model folder or an openai-whisper .pt file)")
    if any(c.startswith("dnsmos_") for c in columns) and "dnsmos" not in (mos or {}):
        raise DatasetError("--metrics dnsmos: give the DNSMOS model files with --dnsmos-dir "
                           "DIR (sig_bak_ovr.onnx and model_v8.onnx) or --dnsmos-dir speechmos")


def estimate_path(estimates: Path, group: Group, mixture: dict[str, Any]) -> Path:
    """The estimate file of a mixture; :class:`DatasetError` naming the group and the file
    when none is there."""
    base = estimates / group.id / mixture["name"]
    for ext in AUDIO_EXTENSIONS:
        if base.with_suffix(ext).is_file():
            return base.with_suffix(ext)
    raise DatasetError(f"group {group.id}: missing estimate {base}.wav (or .flac) for mixture "
                       f"{mixture['name']} ({len(mixture['targets'])} channel(s), one per "
                       "target)")


def read_estimate(path: Path, group: Group, mixture: dict[str, Any]) -> np.ndarray:
    """An estimate file, checked against its mixture: rate, length, one channel per target."""
    import soundfile as sf

    try:
        info = sf.info(str(path))
    except (sf.LibsndfileError, RuntimeError, OSError) as exc:
        raise DatasetError(f"group {group.id}: {path}: unreadable ({exc})") from None
    k = len(mixture["targets"])
    if info.samplerate != group.sample_rate_hz:
        raise DatasetError(f"group {group.id}: {path}: expected {group.sample_rate_hz} Hz, got "
                           f"{info.samplerate} Hz")
    if info.channels != k:
        raise DatasetError(f"group {group.id}: {path}: expected {k} channel(s) (one per target "
                           f"of {mixture['name']}), got {info.channels}")
    if info.frames != group.num_samples:
        raise DatasetError(f"group {group.id}: {path}: expected {group.num_samples} samples "
                           f"(the mixture's length), got {info.frames}")
    audio = read_audio(path).astype(np.float64)
    bad = ~np.isfinite(audio)
    if np.any(bad):
        chans, samples = np.nonzero(bad)
        first = int(np.argmin(samples))
        sample, chan = int(samples[first]), int(chans[first])
        raise DatasetError(f"group {group.id}: {path}: {int(bad.sum())} sample(s) are not "
                           f"finite (NaN or Inf; the first at sample {sample} of channel "
                           f"{chan}); expected finite audio (a model's output that diverged?)")
    return audio


def score_mixture(estimates: np.ndarray, targets: np.ndarray, mixture: np.ndarray,
                  rate: int, *, permute: bool, metrics: Sequence[str] = METRICS,
                  window_s: float = 6.0, hop_s: float = 3.0) -> list[dict[str, Any]]:
    """One row per target: its matched estimate's windowed scores."""
    perm = best_permutation(estimates, targets) if permute else tuple(range(len(targets)))
    rows = []
    for i, j in enumerate(perm):
        row = windowed_scores(estimates[j], targets[i], mixture, rate, metrics,
                              window_s, hop_s)
        rows.append({"estimate_channel": int(j), **row})
    return rows


def evaluate(root: str | Path, split: str, task: str, *, estimates: str | Path | None = None,
             oracle: bool = False, channel: int = 0, metrics: Sequence[str] = METRICS,
             window_s: float = 6.0, hop_s: float = 3.0, format: str | None = None,
             mixtures: Sequence[str] | None = None, transcriber: Any = None,
             transcripts: Mapping[str, str] | None = None,
             mos: Mapping[str, Any] | None = None) -> list[dict[str, Any]]:
    """Per-target score rows for every mixture of ``task`` in ``split``.

    ``root`` is a built dataset or a folder in an external layout
    (:mod:`sonicspec.dataload.formats`; ``format`` names it, else it is detected);
    ``mixtures`` keeps only the mixtures of those names (``mix_both``).
    Each row: ``method`` (``estimates``, ``oracle_mixture``, ``oracle_targets``), ``group``,
    ``mixture``, ``target``, ``estimate_channel`` and one column per metric.

    ``metrics`` are columns (:func:`expand_metrics`); ``wer``/``cer`` need ``transcriber``
    (:func:`sonicspec.dataload.asr.open_transcriber`) and each target's text (its metadata's
    ``words`` or ``transcripts``, keyed ``<group id>/<target>``); the ``dnsmos_*`` columns need
    ``mos["dnsmos"]`` (:func:`sonicspec.dataload.mos.open_mos`). With ``wer``, rows also carry
    the counts (``word_errors``, ``ref_words``, ``char_errors``, ``ref_chars``) and the
    normalised ``transcript``.
    """
    from sonicspec.dataload.formats import open_dataset

    if task not in TASKS:
        raise DatasetError(f"task: expected one of {list(TASKS)}, got {task!r}")
    unknown = [m for m in metrics if m not in (*METRICS, *MODEL_COLUMNS)]
    if unknown:
        raise DatasetError(f"metrics: expected columns from {[*METRICS, *MODEL_COLUMNS]}, got "
                           f"{unknown[0]!r}")
    check_models(metrics, transcriber, mos)
    windowed = [m for m in metrics if m in METRICS]
    asr = "wer" in metrics or "cer" in metrics
    normalise = None
    if asr:
        from sonicspec.dataload.asr import normaliser, reference_text

        normalise = normaliser()
    if estimates is None and not oracle:
        raise DatasetError("evaluate: give an estimates folder, --oracle, or both")
    est_root = Path(estimates) if estimates is not None else None
    if est_root is not None and not est_root.is_dir():
        raise DatasetError(f"{est_root}: no such estimates folder")
    folder = open_dataset(root, format)
    groups = folder.groups(split)
    todo = [(g, m) for g in groups for m in g.mixtures(task)]
    if not todo:
        raise DatasetError(f"{folder.root}: split {split!r} has no {task} mixtures")
    if mixtures is not None:
        names = sorted({m["name"] for _, m in todo})
        todo = [(g, m) for g, m in todo if m["name"] in mixtures]
        if not todo:
            raise DatasetError(f"{folder.root}: split {split!r} has no {task} mixture named "
                               f"{' or '.join(mixtures)}; its {task} mixtures are {names}")
    rows: list[dict[str, Any]] = []
    for group, m in todo:
        refs = ({t: reference_text(group, t, len(m["targets"]), transcripts)
                 for t in m["targets"]} if asr else {})
        chans = (channel,)
        targets = np.stack([group.read(t, channels=chans)[0] for t in m["targets"]]
                           ).astype(np.float64)
        mix = (group.read(m["file"], channels=chans)[0] if m.get("file") else
               sum(group.read(c, channels=chans)[0] for c in m["components"])
               ).astype(np.float64)
        runs: list[tuple[str, np.ndarray]] = []
        if est_root is not None:
            est = read_estimate(estimate_path(est_root, group, m), group, m)
            runs.append(("estimates", est))
        if oracle:
            runs.append(("oracle_mixture", np.stack([mix] * len(targets))))
            runs.append(("oracle_targets", targets.copy()))
        for method, est in runs:
            scored = score_mixture(est, targets, mix, group.sample_rate_hz,
                                   permute=task == "separation", metrics=windowed,
                                   window_s=window_s, hop_s=hop_s)
            for target, row in zip(m["targets"], scored, strict=True):
                score_models(row, est[row["estimate_channel"]], group.sample_rate_hz, metrics,
                             reference=refs.get(target), transcriber=transcriber,
                             normalise=normalise, mos=mos)
                rows.append({"method": method, "group": group.id, "mixture": m["name"],
                             "target": target, **row})
    return rows


def _mean(values: list[float]) -> float | None:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(finite)) if finite else None


def _aggregate(rows: list[dict[str, Any]], column: str) -> float | None:
    """A column's mean over rows; WER and CER pooled (errors over reference words/chars)."""
    if column in POOLED:
        errors, total = POOLED[column]
        n = sum(r.get(total) or 0 for r in rows)
        return sum(r.get(errors) or 0 for r in rows) / n if n else None
    return _mean([r.get(column) for r in rows])


def summarise(rows: list[dict[str, Any]], metrics: Sequence[str] = METRICS) -> dict[str, Any]:
    """Means per method, and per method and group (WER and CER: pooled errors over pooled
    reference words or characters, the corpus rates)."""
    out: dict[str, Any] = {"per_method": {}, "per_group": {}}
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        out["per_method"][method] = {k: _aggregate(mine, k) for k in metrics}
        out["per_method"][method]["targets"] = len(mine)
        out["per_group"][method] = {
            g: {k: _aggregate([r for r in mine if r["group"] == g], k) for k in metrics}
            for g in dict.fromkeys(r["group"] for r in mine)}
    return out


def write_results(out_dir: str | Path, rows: list[dict[str, Any]], summary: dict[str, Any],
                  settings: dict[str, Any]) -> tuple[Path, Path]:
    """``scores.csv`` (a row per target) and ``summary.json`` (settings, means), atomically."""
    out = Path(out_dir)
    columns = list(rows[0]) if rows else []
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    csv_path = write_text(out / "scores.csv", buf.getvalue())
    json_path = write_text(out / "summary.json", json.dumps(
        {"settings": settings, **summary}, indent=2, sort_keys=True, allow_nan=False) + "\n")
    return csv_path, json_path


def summary_table(summary: dict[str, Any], metrics: Sequence[str] = METRICS) -> str:
    """The per-method means as a plain text table."""
    head = ["method", *metrics, "targets"]
    lines = [head]
    for method, values in summary["per_method"].items():
        lines.append([method, *("-" if values[k] is None else f"{values[k]:.2f}"
                                for k in metrics), str(values["targets"])])
    widths = [max(len(row[i]) for row in lines) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) if i else c.ljust(w)
                               for i, (c, w) in enumerate(zip(row, widths, strict=True)))
                     for row in lines)
