"""Building: ``sonicspec build`` (through Snakemake), ``sonicspec job`` (one job, what the
workflow runs) and ``sonicspec verify`` (a store or a dataset folder re-checked)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from sonicspec.cli.common import (
    EXIT_FAILURE,
    EXIT_INVALID,
    EXIT_OK,
    compile_plan,
    last_plan_path,
    load_or_exit,
    output_options,
    preflight_or_exit,
    report_line,
    report_unavailable,
)


def cmd_build(args: argparse.Namespace) -> int:
    loaded = load_or_exit(args.spec, args)
    if loaded is None or not preflight_or_exit(loaded, args.spec):
        return EXIT_INVALID
    if loaded.spec.outputs.report.enabled and not args.dry_run and not args.until \
            and report_unavailable(f"{args.spec}: outputs.report.enabled"):
        return EXIT_INVALID
    if not args.dry_run and not args.until and _exports_unavailable(loaded, args.spec):
        return EXIT_INVALID
    from sonicspec.stages.workflow import build

    plan = compile_plan(loaded, args)
    if args.until:
        plan = plan.until(args.until)
    profile = Path(args.profile) if args.profile else None
    result = build(plan, cores=args.cores, profile=profile, dry_run=args.dry_run,
                   shards_per_batch=args.shards_per_batch)
    if result.code != 0 or args.dry_run:
        return EXIT_OK if result.code == 0 else EXIT_FAILURE
    if args.until:
        print(f"built up to {args.until}; artifacts in {plan.store_dir}", file=sys.stderr)
        return EXIT_OK
    missing = result.missing_files
    if missing:
        print(f"sonicspec: error: the build finished but {len(missing)} dataset file(s) are "
              f"missing (first: {missing[0]}); run the build again", file=sys.stderr)
        return EXIT_FAILURE
    plan.write(last_plan_path(plan))
    print(f"dataset written to {plan.output_dir}", file=sys.stderr)
    if loaded.spec.outputs.report.enabled:
        from sonicspec.export.report import write_report

        report = write_report(plan.output_dir,
                              group_pages=loaded.spec.outputs.report.group_pages)
        print(report_line(report), file=sys.stderr)
    return _write_exports(loaded, plan.output_dir)


def export_folder(output_dir: str | Path, fmt: str) -> Path:
    """Where ``outputs.manifests: [<fmt>]`` writes its export: beside the dataset folder."""
    out = Path(output_dir)
    return out.parent / f"{out.name}-{fmt}"


def _exports_unavailable(loaded, spec: str) -> bool:
    """True (after the message) if an export the spec asks for cannot be written."""
    import importlib.util

    from sonicspec.dataload.hub import FORMATS, REQUIRES

    for fmt in FORMATS:
        if fmt in loaded.spec.outputs.manifests:
            missing = [m for m in REQUIRES[fmt] if importlib.util.find_spec(m) is None]
            if missing:
                print(f"sonicspec: error: {spec}: outputs.manifests: {fmt!r} needs "
                      f"{' and '.join(missing)}; pip install 'sonicspec[export]'",
                      file=sys.stderr)
                return True
    return False


def _write_exports(loaded, output_dir: str | Path) -> int:
    """The exports ``outputs.manifests`` asks for, after a finished build (only shards whose
    groups changed are written)."""
    from sonicspec.dataload.folder import DatasetError
    from sonicspec.dataload.hub import FORMATS, export

    for fmt in FORMATS:
        if fmt not in loaded.spec.outputs.manifests:
            continue
        where = export_folder(output_dir, fmt)
        try:
            result = export(output_dir, where, fmt)
        except DatasetError as exc:
            print(f"sonicspec: error: outputs.manifests: {fmt}: {exc}", file=sys.stderr)
            return EXIT_FAILURE
        print(f"{fmt} export written to {where}: {len(result['written'])} shard(s) written, "
              f"{len(result['kept'])} unchanged, {len(result['removed'])} removed",
              file=sys.stderr)
    return EXIT_OK


def cmd_job(args: argparse.Namespace) -> int:
    import logging

    from sonicspec.plan.model import Plan
    from sonicspec.stages import run_job

    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s", stream=sys.stderr
    )
    run_job(Plan.read_job(Path(args.plan), args.key), args.key)
    return EXIT_OK


def cmd_batch(args: argparse.Namespace) -> int:
    import logging

    from sonicspec.stages.batch import run_batch

    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s", stream=sys.stderr
    )
    failed = run_batch(args.plan, args.layout, args.key)
    return EXIT_FAILURE if failed else EXIT_OK


def _shards_per_batch(text: str) -> int | None:
    if text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected auto or a whole number >= 0, got {text!r}")
    return value


def _verify_lock(store_dir: Path | None):
    """The store's lock, held for a verify (so no build writes while it reads, and it may
    record what it found in the store's check cache); None when the store cannot be written
    (a read-only store: nothing builds there, nothing is recorded). Raises
    :class:`StoreLockedError` while a build runs."""
    from sonicspec.errors import StoreError
    from sonicspec.store.lock import StoreLock, StoreLockedError

    if store_dir is None or not store_dir.is_dir():
        return None
    lock = StoreLock(store_dir, purpose="verify")
    try:
        lock.acquire()
    except StoreLockedError:
        raise
    except StoreError:
        return None
    return lock


def cmd_verify(args: argparse.Namespace) -> int:
    from sonicspec.export.checksums import folder_kind, read_marker
    from sonicspec.stages.checked import CheckCache
    from sonicspec.store import ArtifactStore
    from sonicspec.store.lock import StoreLockedError

    folder = Path(args.folder)
    if not folder.is_dir():
        print(f"sonicspec: error: {folder}: no such folder", file=sys.stderr)
        return EXIT_INVALID
    kind = folder_kind(folder)
    if kind is None:
        print(f"sonicspec: error: {folder}: not a sonicspec store or dataset (it has neither "
              "sonicspec-store.json nor .sonicspec-dataset.json)", file=sys.stderr)
        return EXIT_INVALID
    expected = None
    if kind == "store" and args.spec:
        from sonicspec.plan.compile import compile_spec

        loaded = load_or_exit(args.spec)
        if loaded is None:
            return EXIT_INVALID
        expected = {j.key: j.step for j in compile_spec(loaded).jobs}
    marker = read_marker(folder) if kind == "dataset" else {}
    store_dir = folder if kind == "store" else (
        folder / marker["store"] if "store" in marker else None)
    try:
        lock = _verify_lock(store_dir)
    except StoreLockedError as exc:
        print(f"sonicspec: error: {folder}: not verified: {exc}; a build writes the store and "
              "the dataset folder while it runs, so verify waits for it", file=sys.stderr)
        return EXIT_FAILURE
    try:
        cache = CheckCache.of_store(store_dir) if lock is not None else None
        if kind == "dataset":
            from sonicspec.stages.repair import verify_dataset_folder

            count, problems = verify_dataset_folder(folder, cache)
            what = "dataset files"
        else:
            store = ArtifactStore(folder)
            found = store.verify(expected)
            if cache is not None:
                for p in found:
                    cache.forget_artifact(p.key)  # the next build re-reads and repairs it
            problems = [p.format() for p in found]
            count = sum(1 for _ in store.artifacts())
            what = "artifacts"
        if cache is not None and problems:
            cache.save()
    finally:
        if lock is not None:
            lock.release()
    for p in problems:
        print(p, file=sys.stderr)
    print(
        f"{folder}: {kind}, {count} {what} checked, {len(problems)} problem"
        f"{'s' * (len(problems) != 1)}",
        file=sys.stderr if problems else sys.stdout,
    )
    if problems and cache is not None:
        print("the next `sonicspec build` of this store re-checks what was found here and "
              "remakes what is damaged or missing", file=sys.stderr)
    return EXIT_FAILURE if problems else EXIT_OK


def add_build(sub) -> None:
    """``sonicspec build SPEC``."""
    p = sub.add_parser("build", help="build the dataset through Snakemake")
    p.add_argument("spec", metavar="SPEC")
    p.add_argument(
        "--cores",
        type=int,
        default=os.cpu_count() or 1,
        help="CPU cores to use locally (default: all)",
    )
    p.add_argument(
        "--profile", metavar="DIR", help="Snakemake profile, e.g. workflow/profiles/slurm"
    )
    p.add_argument("--dry-run", action="store_true", help="show the jobs that would run")
    p.add_argument("--until", metavar="STEP", help="stop after this step (e.g. placement)")
    p.add_argument(
        "--shards-per-batch", metavar="N", type=_shards_per_batch, default=None,
        help="run the placement-to-export jobs of N consecutive shards as one Snakemake job "
             "(a batch), so Snakemake's DAG stays small for huge plans; the jobs, keys and "
             "bytes are the same. 0: one Snakemake job per step and shard. auto (default): "
             "batches for plans of more than 20,000 jobs, about 4,000 of them",
    )
    output_options(p)
    p.set_defaults(func=cmd_build)


def add_job(sub) -> None:
    """``sonicspec job --plan PLAN KEY``."""
    # Internal (the workflow's rules call it): no help= keeps it out of the command list
    # (argparse.SUPPRESS there prints "==SUPPRESS==" before Python 3.13).
    p = sub.add_parser("job", description="run one job of a compiled plan (used by the "
                       "workflow; internal)")
    p.add_argument("--plan", required=True, metavar="PLAN", help="plan JSON file")
    p.add_argument("key", metavar="KEY", help="the job's content key")
    p.set_defaults(func=cmd_job)


def add_batch(sub) -> None:
    """``sonicspec batch --plan PLAN --layout LAYOUT KEY``."""
    # Internal, as ``job``.
    p = sub.add_parser("batch", description="run the jobs of one batch of a batched build "
                       "in order (used by the workflow; internal)")
    p.add_argument("--plan", required=True, metavar="PLAN", help="plan JSON file")
    p.add_argument("--layout", required=True, metavar="LAYOUT",
                   help="the build's workflow layout file (names the batch's jobs)")
    p.add_argument("key", metavar="KEY", help="the batch's key")
    p.set_defaults(func=cmd_batch)


def add_verify(sub) -> None:
    """``sonicspec verify DIR``."""
    p = sub.add_parser("verify", help="re-check every artifact of a store, or every file of a "
                       "dataset folder against its checksums and the store")
    p.add_argument("folder", metavar="DIR",
                   help="a store (outputs.store_dir) or a dataset folder (outputs.dir)")
    p.add_argument(
        "--spec", metavar="SPEC", help="also report artifacts this spec needs but the store lacks"
    )
    p.set_defaults(func=cmd_verify)
