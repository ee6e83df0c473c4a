"""Using a built dataset: ``sonicspec report`` (HTML), ``sonicspec evaluate`` (a model's
scores) and ``sonicspec export`` (Hugging Face or WebDataset shards; sonicspec.dataload)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sonicspec import __version__
from sonicspec.cli.common import (
    EXIT_FAILURE,
    EXIT_INVALID,
    EXIT_OK,
    report_line,
    report_unavailable,
)


def cmd_report(args: argparse.Namespace) -> int:
    from sonicspec.export.report import write_report

    if report_unavailable("sonicspec report"):
        return EXIT_INVALID
    folder = Path(args.dataset)
    if not folder.is_dir():
        print(f"sonicspec: error: {folder}: no such folder", file=sys.stderr)
        return EXIT_INVALID
    if args.group_pages is not None and args.group_pages < 0:
        print(f"sonicspec: error: --group-pages: expected >= 0, got {args.group_pages}",
              file=sys.stderr)
        return EXIT_INVALID
    from sonicspec.export.report_data import ReportError

    try:
        report = write_report(folder, args.output, split=args.split,
                              group_pages=args.group_pages)
    except ReportError as exc:
        print(f"sonicspec: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    print(report_line(report))
    if report.missing:
        first = ", ".join(f"{m['path']} ({m['problem']})" for m in report.missing[:3])
        more = f" and {len(report.missing) - 3} more" if len(report.missing) > 3 else ""
        print(f"sonicspec: error: the report is incomplete: {len(report.missing)} file(s) of "
              f"{folder} are missing or empty: {first}{more} (listed under Warnings in the "
              "report); rebuild the dataset or check it with `sonicspec verify`",
              file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _models(args: argparse.Namespace, metrics: list[str]) -> dict:
    """The user-held models the metrics need, opened and checked, and the transcripts."""
    from sonicspec.dataload.evaluate import check_models
    from sonicspec.dataload.folder import DatasetError

    out: dict = {"transcriber": None, "transcripts": None, "mos": {}}
    wer = "wer" in metrics or "cer" in metrics
    dnsmos = any(m.startswith("dnsmos_") for m in metrics)
    if args.asr_model is not None and not wer:
        raise DatasetError("--asr-model: given without wer in --metrics; add it (--metrics "
                           "... wer) or leave the model out")
    if args.dnsmos_dir is not None and not dnsmos:
        raise DatasetError("--dnsmos-dir: given without dnsmos in --metrics; add it "
                           "(--metrics ... dnsmos) or leave the models out")
    if args.transcripts is not None and not wer:
        raise DatasetError("--transcripts: given without wer in --metrics")
    if wer and args.asr_model is not None:
        from sonicspec.dataload.asr import open_transcriber, read_transcripts

        out["transcriber"] = open_transcriber(args.asr_model)
        if args.transcripts is not None:
            out["transcripts"] = read_transcripts(args.transcripts)
    if dnsmos and args.dnsmos_dir is not None:
        from sonicspec.dataload.mos import open_mos

        out["mos"]["dnsmos"] = open_mos("dnsmos", args.dnsmos_dir)
    check_models(metrics, out["transcriber"], out["mos"])
    return out


def _model_files(models: dict) -> dict:
    """The summary's record of the model files: path, bytes, SHA-256 per model."""
    files = {}
    if models["transcriber"] is not None:
        files["asr"] = {"kind": models["transcriber"].kind,
                        "files": models["transcriber"].files}
    for kind, model in models["mos"].items():
        files[kind] = {"kind": kind, "files": model.files}
    return files


def cmd_evaluate(args: argparse.Namespace) -> int:
    from sonicspec.audio.metrics import METRICS
    from sonicspec.dataload.evaluate import (
        evaluate,
        expand_metrics,
        summarise,
        summary_table,
        write_results,
    )
    from sonicspec.dataload.folder import DatasetError
    from sonicspec.dataload.formats import detect

    fmt = None if args.format == "auto" else args.format
    try:
        metrics = expand_metrics(args.metrics or list(METRICS))
        models = _models(args, metrics)
        if args.sets is not None or args.estimates_root is not None:
            return _evaluate_sets(args, metrics, fmt, models)
        if args.dataset is None:
            raise DatasetError("evaluate: give a DATASET folder, or --estimates-root with "
                               "--sets")
        rows = evaluate(args.dataset, args.split, args.task, estimates=args.estimates,
                        oracle=args.oracle, channel=args.channel, metrics=metrics,
                        format=fmt, mixtures=args.mixture, **models)
    except DatasetError as exc:
        print(f"sonicspec: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    summary = summarise(rows, metrics)
    settings = {"dataset": str(Path(args.dataset).resolve()), "split": args.split,
                "task": args.task, "estimates": args.estimates, "oracle": args.oracle,
                "channel": args.channel, "metrics": metrics, "window_s": 6.0, "hop_s": 3.0,
                "format": fmt or detect(args.dataset), "mixtures": args.mixture,
                "sonicspec_version": __version__, "model_files": _model_files(models),
                "transcripts": args.transcripts}
    out = Path(args.output or f"evaluation-{args.split}-{args.task}")
    csv_path, json_path = write_results(out, rows, summary, settings)
    print(summary_table(summary, metrics))
    print(f"scores: {csv_path}\nsummary: {json_path}")
    _warn_silent(rows)
    return EXIT_OK


def _warn_silent(rows) -> None:
    silent = [r for r in rows if r.get("silent_estimate")]
    if silent:
        first = silent[0]
        print(f"sonicspec: warning: {len(silent)} estimate(s) are silent (all zeros) in some "
              f"windows, {sum(r['silent_estimate'] for r in silent)} windows in all, which are "
              "not scored (every metric is undefined for silence); first: group "
              f"{first['group']} {first['mixture']} channel {first['estimate_channel']}, "
              f"{first['silent_estimate']} of {first['scored']} windows", file=sys.stderr)


def _evaluate_sets(args: argparse.Namespace, metrics: list[str], fmt: str | None,
                   models: dict) -> int:
    """``--estimates-root DIR --sets A,B``: the models × sets table."""
    from sonicspec.dataload.folder import DatasetError
    from sonicspec.dataload.tables import cross_set, parse_sets

    if args.sets is None or args.estimates_root is None:
        raise DatasetError("evaluate: --estimates-root and --sets go together (the models' "
                           "folder and the test sets)")
    if args.dataset is not None or args.estimates is not None:
        raise DatasetError("evaluate: with --sets, give no DATASET or --estimates (each set "
                           "is NAME=PATH; estimates are <root>/<model>/<set>/)")
    sets = parse_sets(args.sets, args.split, fmt)
    out = Path(args.output or f"evaluation-sets-{args.task}")
    table = cross_set(args.estimates_root, sets, args.task, out, metrics=metrics,
                      oracle=args.oracle, channel=args.channel, mixtures=args.mixture,
                      settings={"sonicspec_version": __version__, "window_s": 6.0,
                                "hop_s": 3.0, "channel": args.channel,
                                "model_files": _model_files(models),
                                "transcripts": args.transcripts},
                      model_args=models)
    print((out / "table.md").read_text(encoding="utf-8"), end="")
    print(f"table: {out / 'table.md'}, {out / 'table.csv'}\nsummary: {out / 'table.json'}")
    for miss in table["missing"]:
        print(f"sonicspec: warning: {args.estimates_root}/{miss}: no such folder; the cell "
              "is empty (\"-\")", file=sys.stderr)
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    from sonicspec.dataload.folder import DatasetError
    from sonicspec.dataload.hub import export

    try:
        result = export(args.dataset, args.output, args.format, splits=args.split,
                        groups_per_shard=args.groups_per_shard)
    except DatasetError as exc:
        print(f"sonicspec: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    print(f"{args.output}: {len(result['written'])} shard(s) written, {len(result['kept'])} "
          f"unchanged, {len(result['removed'])} removed ({args.format})")
    return EXIT_OK


def add_report(sub) -> None:
    """``sonicspec report DATASET``."""
    p = sub.add_parser("report", help="write an HTML report of a dataset folder: spec, plan, "
                       "build facts, distributions per split, scenes, groups, warnings")
    p.add_argument("dataset", metavar="DATASET", help="a dataset folder (outputs.dir)")
    p.add_argument("-o", "--output", metavar="REPORT.html",
                   help="where to write it (default: DATASET/report.html); group pages go in "
                   "the folder beside it named after it (report_files/)")
    p.add_argument("--split", metavar="S", help="report this split only")
    p.add_argument("--group-pages", type=int, metavar="N",
                   help="at most N groups get a page (default: the spec's "
                   "outputs.report.group_pages, 100)")
    p.set_defaults(func=cmd_report)


def add_evaluate(sub) -> None:
    """``sonicspec evaluate DATASET``."""
    from sonicspec.audio.metrics import METRICS
    from sonicspec.dataload.formats import FORMATS

    p = sub.add_parser("evaluate", help="score a model's outputs against a dataset's targets "
                       "(SI-SNR(i), SDR(i), PESQ, STOI; 6 s windows every 3 s): a built "
                       "dataset or a public test set (LibriMix, WHAM!, SonicSet...), or "
                       "several models on several sets as one table")
    p.add_argument("dataset", metavar="DATASET", nargs="?",
                   help="a built dataset folder (outputs.dir) or a test set in a layout "
                   "--format names (left out with --sets)")
    p.add_argument("--split", required=True,
                   help="the split to score: the set's own name (test, tt, test-noise...) "
                   "or test/val/train, which every layout maps to its own")
    p.add_argument("--format", choices=FORMATS, default="auto",
                   help="the layout of DATASET (and of every --sets folder): auto (default: "
                   "a dataset.json makes a sonicspec dataset, else the layout is "
                   "recognised from its folders and files), sonicspec, or a public set's")
    p.add_argument("--mixture", action="append", metavar="NAME",
                   help="score only the mixtures of this name (repeat; e.g. mix_both for "
                   "LibriMix and WHAM!, noisy for VoiceBank-DEMAND)")
    p.add_argument("--task", required=True, choices=("separation", "enhancement"),
                   help="which mixtures to score: separation (one estimate channel per "
                   "speaker, matched by the best permutation) or enhancement (one channel: "
                   "the speech)")
    p.add_argument("--estimates", metavar="DIR",
                   help="<DIR>/<group id>/<mixture name>.wav (the group id starts with its "
                   "split), one channel per target")
    p.add_argument("--estimates-root", metavar="DIR",
                   help="score several models on several sets as one table: "
                   "<DIR>/<model>/<set>/<group id>/<mixture name>.wav (with --sets)")
    p.add_argument("--sets", metavar="A=PATH,B=PATH",
                   help="the test sets of the table, comma-separated NAME=PATH (a bare PATH "
                   "is named after its folder), each optionally @SPLIT to override --split")
    p.add_argument("--oracle", action="store_true",
                   help="also score the mixture itself (the baseline) and the targets "
                   "themselves (the ceiling) as estimates")
    p.add_argument("--channel", type=int, default=0,
                   help="the dataset's reference channel (default 0)")
    p.add_argument("--metrics", nargs="+", metavar="NAME",
                   help=f"what to score, names separated by spaces or commas: {' '.join(METRICS)}"
                   " (default: these), pesq (both bands), wer (word and character error "
                   "rates of a Whisper transcript; needs --asr-model), dnsmos (P.835 SIG BAK "
                   "OVRL and P.808; needs --dnsmos-dir)")
    p.add_argument("--asr-model", metavar="PATH",
                   help="the speech recogniser for wer: a faster-whisper (CTranslate2) model "
                   "folder or an openai-whisper checkpoint (.pt); never downloaded")
    p.add_argument("--transcripts", metavar="FILE",
                   help="what each target says, for wer where the dataset's metadata has no "
                   "words: UTF-8 lines '<group id>/<target><TAB><text>'")
    p.add_argument("--dnsmos-dir", metavar="DIR",
                   help="the folder holding Microsoft's DNSMOS ONNX files (sig_bak_ovr.onnx "
                   "and model_v8.onnx), or 'speechmos' for those the speechmos package "
                   "ships; never downloaded")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="where scores.csv and summary.json go (default: "
                   "evaluation-<split>-<task>); with --sets, table.md, table.csv, "
                   "table.json and each cell's scores (default: evaluation-sets-<task>)")
    p.set_defaults(func=cmd_evaluate)


def add_export(sub) -> None:
    """``sonicspec export DATASET``."""
    from sonicspec.dataload.hub import FORMATS

    p = sub.add_parser("export", help="a built dataset as Hugging Face datasets (Parquet) or "
                       "WebDataset (tar) shards; only changed shards are rewritten")
    p.add_argument("dataset", metavar="DATASET", help="a built dataset folder (outputs.dir)")
    p.add_argument("--format", required=True, choices=FORMATS,
                   help="huggingface: Parquet shards, one split per file prefix "
                   "(datasets.load_dataset(DIR) reads them, and names the split 'val' "
                   "'validation'); webdataset: tar shards, a sample per group")
    p.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="the export folder (outside the dataset folder)")
    p.add_argument("--split", action="append", metavar="SPLIT",
                   help="export this split (repeat; default: all)")
    p.add_argument("--groups-per-shard", type=int, default=64, metavar="N",
                   help="groups per shard (default 64)")
    p.set_defaults(func=cmd_export)
