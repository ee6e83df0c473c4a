"""Cross-set tables: several models scored on several test sets, one table as the SonicSim
paper prints them (models in rows, each test set a group of metric columns).

Estimates layout (``--estimates-root DIR``)::

    DIR/<model>/<set>/<group id>/<mixture name>.wav

one folder per model, inside it one per test set (named as in ``--sets``), inside that the
set's estimates exactly as ``sonicspec evaluate --estimates`` takes them: the group id is the
set's own (``test/000000`` for a sonicspec dataset, ``tt/<name>`` for WHAM!,
``test/<mixture_ID>`` for LibriMix; ``sonicspec evaluate --oracle`` lists them in its
``scores.csv``). A model without a set's folder gets an empty cell ("-"), said in the
summary; a set folder with a missing or malformed file is an error naming it.

Test sets (``--sets``): comma-separated ``NAME=PATH`` (or a bare ``PATH``, named after its
folder), each optionally ``@SPLIT`` to score another split than ``--split``
(``sonicset-music=/data/SonicSet@test-music``). Each is read in its own layout
(:mod:`sonicspec.dataload.formats`).

Written: ``table.md`` and ``table.csv`` (the table), ``table.json`` (the settings, every
cell's means, the missing cells) and each cell's ``scores.csv`` / ``summary.json`` in
``<out>/<model>/<set>/``. With ``oracle`` two rows come first: *Mixture* (the input as the
estimate: SI-SNRi 0) and *Oracle* (the references: the ceiling).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sonicspec.atomic import write_text
from sonicspec.dataload.evaluate import evaluate, summarise, write_results
from sonicspec.dataload.folder import DatasetError

LABELS = {"si_snr": "SI-SNR", "si_snri": "SI-SNRi", "sdr": "SDR", "sdri": "SDRi",
          "pesq_nb": "NB-PESQ", "pesq_wb": "WB-PESQ", "stoi": "STOI", "wer": "WER",
          "cer": "CER", "dnsmos_sig": "SIG", "dnsmos_bak": "BAK", "dnsmos_ovrl": "OVRL",
          "dnsmos_p808": "P808"}
"""How the paper heads each metric (a metric not listed is headed by its name)."""
DIGITS = {"stoi": 3, "wer": 3, "cer": 3}
"""Decimals shown per metric (2 unless listed)."""
LOWER_IS_BETTER = frozenset({"wer", "cer"})
"""Metrics whose best model is the lowest (higher is better for every other)."""
ORACLE_ROWS = {"oracle_mixture": "Mixture", "oracle_targets": "Oracle"}


@dataclass(frozen=True)
class TestSet:
    """One column group: its name, folder, split and layout (``None``: detected)."""

    name: str
    root: Path
    split: str
    format: str | None = None


def parse_sets(text: str, split: str, format: str | None = None) -> list[TestSet]:
    """``A=PATH[@SPLIT],B=PATH…`` as test sets (``--sets``)."""
    out: list[TestSet] = []
    for raw in text.split(","):
        entry = raw.strip()
        if not entry:
            raise DatasetError(f"--sets: an empty entry in {text!r}; expected "
                               "NAME=PATH[@SPLIT],…")
        name, sep, rest = entry.partition("=")
        if not sep:
            name, rest = "", entry
        path, at, own = rest.rpartition("@") if "@" in rest else (rest, "", "")
        root = Path(path)
        name = name.strip() or root.name
        if not name or "/" in name or name in (".", ".."):
            raise DatasetError(f"--sets: {entry!r}: expected NAME=PATH with a NAME that can "
                               "be a folder name")
        if at and not own:
            raise DatasetError(f"--sets: {entry!r}: nothing after '@'; expected @SPLIT")
        if any(s.name == name for s in out):
            raise DatasetError(f"--sets: the name {name!r} is given twice; each set's "
                               "estimates live in <model>/<name>/")
        out.append(TestSet(name, root, own or split, format))
    return out


def models_in(estimates_root: Path) -> list[str]:
    """The model folders of an estimates root, sorted."""
    if not estimates_root.is_dir():
        raise DatasetError(f"{estimates_root}: no such estimates folder")
    names = sorted(p.name for p in estimates_root.iterdir() if p.is_dir())
    if not names:
        raise DatasetError(f"{estimates_root}: no model folders; expected "
                           "<root>/<model>/<set>/<group id>/<mixture>.wav")
    return names


def cross_set(estimates_root: str | Path, sets: Sequence[TestSet], task: str,
              out_dir: str | Path, *, metrics: Sequence[str], oracle: bool = False,
              channel: int = 0, mixtures: Sequence[str] | None = None,
              settings: dict[str, Any] | None = None,
              model_args: dict[str, Any] | None = None) -> dict[str, Any]:
    """Score every model on every set, write the table and each cell's scores; return
    ``table.json``'s content. ``model_args``: the user-held models of the model metrics
    (``transcriber``, ``transcripts``, ``mos``: :func:`sonicspec.dataload.evaluate.evaluate`'s
    arguments)."""
    root, out = Path(estimates_root), Path(out_dir)
    models = models_in(root)
    cells: dict[str, dict[str, dict[str, Any] | None]] = {}
    missing: list[str] = []
    clash = [m for m in models if m == "_oracle" or (oracle and m in ORACLE_ROWS.values())]
    if clash:
        raise DatasetError(f"{root / clash[0]}: a model folder may not be named "
                           f"{clash[0]!r} (the oracle rows' name); rename it")
    rows_order = [*(ORACLE_ROWS.values() if oracle else ()), *models]
    for label in rows_order:
        cells[label] = {}
    for ts in sets:
        if oracle:
            rows = evaluate(ts.root, ts.split, task, oracle=True, channel=channel,
                            metrics=metrics, format=ts.format, mixtures=mixtures,
                            **(model_args or {}))
            summary = summarise(rows, metrics)
            write_results(out / "_oracle" / ts.name, rows, summary,
                          {"set": ts.name, "root": str(ts.root), "split": ts.split})
            for method, label in ORACLE_ROWS.items():
                cells[label][ts.name] = summary["per_method"][method]
        for model in models:
            folder = root / model / ts.name
            if not folder.is_dir():
                missing.append(f"{model}/{ts.name}")
                cells[model][ts.name] = None
                continue
            rows = evaluate(ts.root, ts.split, task, estimates=folder, channel=channel,
                            metrics=metrics, format=ts.format, mixtures=mixtures,
                            **(model_args or {}))
            summary = summarise(rows, metrics)
            write_results(out / model / ts.name, rows, summary,
                          {"model": model, "set": ts.name, "root": str(ts.root),
                           "split": ts.split, "estimates": str(folder)})
            cells[model][ts.name] = summary["per_method"]["estimates"]
    if all(cells[m][s.name] is None for m in models for s in sets):
        raise DatasetError(f"{root}: no model has a folder for any of the sets "
                           f"{[s.name for s in sets]}; expected "
                           "<root>/<model>/<set>/<group id>/<mixture>.wav")
    table = {"settings": {**(settings or {}), "task": task, "metrics": list(metrics),
                          "sets": [{"name": s.name, "root": str(s.root), "split": s.split,
                                    "format": s.format} for s in sets],
                          "models": models, "estimates_root": str(root)},
             "rows": rows_order, "cells": cells, "missing": missing}
    write_text(out / "table.md", markdown(table))
    write_text(out / "table.csv", table_csv(table))
    write_text(out / "table.json", json.dumps(table, indent=2, sort_keys=True,
                                              allow_nan=False) + "\n")
    return table


def _fmt(metric: str, value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.{DIGITS.get(metric, 2)}f}"


def _columns(table: dict[str, Any]) -> list[tuple[str, str]]:
    return [(s["name"], m) for s in table["settings"]["sets"]
            for m in table["settings"]["metrics"]]


def _value(table: dict[str, Any], row: str, set_name: str, metric: str) -> float | None:
    cell = table["cells"][row].get(set_name)
    return None if cell is None else cell.get(metric)


def markdown(table: dict[str, Any]) -> str:
    """The table in Markdown: a column per (set, metric), the best model per column in bold
    (the lowest WER and CER, the highest of the others; the oracle rows are not candidates)."""
    cols = _columns(table)
    models = table["settings"]["models"]
    best = {}
    for s, m in cols:
        values = [v for r in models if (v := _value(table, r, s, m)) is not None
                  and math.isfinite(v)]
        pick = min if m in LOWER_IS_BETTER else max
        best[(s, m)] = pick(values) if len(values) > 1 else None
    head = ["Model", *(f"{s} {LABELS.get(m, m)}" for s, m in cols)]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join([" --- "] + [" ---: "] * len(cols)) + "|"]
    for row in table["rows"]:
        out = []
        for s, m in cols:
            v = _value(table, row, s, m)
            text = _fmt(m, v)
            if row in models and v is not None and best[(s, m)] is not None \
                    and _fmt(m, v) == _fmt(m, best[(s, m)]):
                text = f"**{text}**"
            out.append(text)
        lines.append("| " + " | ".join([row, *out]) + " |")
    task = table["settings"]["task"]
    lines.append("")
    lines.append(f"{task.capitalize()}: mean over every target of each set "
                 f"({', '.join(LABELS.get(m, m) for m in table['settings']['metrics'])}; "
                 "6 s windows every 3 s). \"-\": not scored"
                 + (f" ({', '.join(table['missing'])} has no estimates)"
                    if table["missing"] else "") + ".")
    return "\n".join(lines) + "\n"


def table_csv(table: dict[str, Any]) -> str:
    """The table as CSV: ``model`` then ``<set>/<metric>`` columns, full precision, empty
    for a missing cell."""
    cols = _columns(table)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["model", *(f"{s}/{m}" for s, m in cols)])
    for row in table["rows"]:
        values = [_value(table, row, s, m) for s, m in cols]
        w.writerow([row, *("" if v is None else f"{v:.6g}" for v in values)])
    return buf.getvalue()
