"""The ``sonicspec`` command. Thin: parse arguments, call package functions, print, exit.

Exit codes: 0 success (a valid spec), 2 an invalid spec or bad arguments, 1 any other failure.
Tracebacks are shown only with ``SONICSPEC_DEBUG=1``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from sonicspec import __version__
from sonicspec.atomic import write_text

EXIT_OK, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2


def _print_problems(problems: Sequence, source: str, stream=None) -> None:
    for p in problems:
        print(p.format(source), file=stream or sys.stderr)


def cmd_validate(args: argparse.Namespace) -> int:
    from sonicspec.spec import validate_file

    worst = EXIT_OK
    report = []
    for path in args.specs:
        scene_file = _scene_file(path)
        if scene_file:  # one scene for `sonicspec rir`
            from sonicspec.spec.validate import validate_scene_file

            loaded, problems = validate_scene_file(path)
        else:
            loaded, problems = validate_file(path, files=args.check_files)
        if loaded is not None and args.check_files and not scene_file:
            loaded, problems = _preflight(loaded, problems)
        errors = [p for p in problems if p.severity == "error"]
        warnings = [p for p in problems if p.severity == "warning"]
        if args.json:
            report.append(
                {
                    "spec": path,
                    "valid": loaded is not None,
                    "problems": [
                        {
                            "severity": p.severity,
                            "path": list(p.path),
                            "line": p.line,
                            "column": p.column,
                            "message": p.message,
                            "text": p.format(path),
                        }
                        for p in problems
                    ],
                }
            )
        else:
            _print_problems(problems, path)
            if loaded is None:
                print(
                    f"{path}: invalid ({len(errors)} error{'s' * (len(errors) != 1)})",
                    file=sys.stderr,
                )
            elif scene_file and not args.quiet:
                print(f"{path}: valid scene file ({loaded.scene.kind} scene "
                      f"{loaded.scene.id!r}; `sonicspec rir {path} --source X Y Z --mic X Y Z`)")
            elif not args.quiet:
                from sonicspec.plan.summary import summarize

                s = summarize(loaded.spec)
                extra = f", {len(warnings)} warning{'s' * (len(warnings) != 1)}" if warnings else ""
                groups = (f"{s.groups} groups" if s.groups is not None
                          else "groups per speaker and scene")
                print(
                    f"{path}: valid ({len(loaded.spec.scenes)} scene entries, "
                    f"{len(s.splits)} splits, {groups}{extra})"
                )
        if loaded is None:
            worst = EXIT_INVALID
    if args.json:
        print(json.dumps(report, indent=2))
    return worst


def _preflight(loaded, problems: list) -> tuple:
    """``(loaded, problems)`` with what a build would meet in files, corpora and environment
    added; ``loaded`` becomes None if any of it is an error."""
    from sonicspec.spec.load import sort_problems
    from sonicspec.stages.preflight import preflight

    found = [p for p in preflight(loaded) if p not in problems]
    if any(p.severity == "error" for p in found):
        loaded = None
    return loaded, sort_problems([*problems, *found])


def cmd_schema(args: argparse.Namespace) -> int:
    from sonicspec.spec.schema import schema_text

    text = schema_text()
    if args.output:
        write_text(Path(args.output), text)
        print(f"wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return EXIT_OK


def cmd_init(args: argparse.Namespace) -> int:
    from sonicspec.spec.templates import render_template

    out = Path(args.output) if args.output else None
    text = render_template(args.preset, out)
    if out is None:
        sys.stdout.write(text)
        return EXIT_OK
    if out.exists() and not args.force:
        print(f"sonicspec: error: {out} exists; pass --force to overwrite it", file=sys.stderr)
        return EXIT_FAILURE
    write_text(out, text)
    print(
        f"wrote {out} (preset {args.preset}); check it with: sonicspec validate {out}",
        file=sys.stderr,
    )
    return EXIT_OK


def _load_or_exit(spec: str, args: argparse.Namespace | None = None):
    from sonicspec.spec import validate_file

    loaded, problems = validate_file(spec, cli_outputs=_cli_outputs(args))
    _print_problems(problems, spec)
    return loaded


def _cli_outputs(args: argparse.Namespace | None) -> tuple[str, ...]:
    """The output folders given on the command line (``--output-dir``, ``--store-dir``)."""
    if args is None:
        return ()
    return tuple(name for name, opt in (("dir", "output_dir"), ("store_dir", "store_dir"))
                 if getattr(args, opt, None))


def _compile(loaded, args: argparse.Namespace):
    from sonicspec.plan.compile import compile_spec

    return compile_spec(loaded, output_dir=getattr(args, "output_dir", None),
                        store_dir=getattr(args, "store_dir", None))


def _preflight_or_exit(loaded, spec: str) -> bool:
    """Print what a build would meet (errors and warnings); False if any is an error."""
    from sonicspec.stages.preflight import preflight

    problems = preflight(loaded)
    _print_problems(problems, spec)
    return not any(p.severity == "error" for p in problems)


def _plot_unavailable(args: argparse.Namespace) -> bool:
    """True (after the message) if ``--plot`` was asked and matplotlib is not installed."""
    from sonicspec.stages.preflight import PLOT_NEEDS, module_available

    if args.plot and not module_available("matplotlib"):
        print(f"sonicspec: error: {PLOT_NEEDS}", file=sys.stderr)
        return True
    return False


def _last_plan_path(plan) -> Path:
    return Path(plan.store_dir) / "plans" / f"last-build-{plan.name}.json"


def cmd_plan(args: argparse.Namespace) -> int:
    from sonicspec.errors import SonicspecError
    from sonicspec.plan.compile import layouts_of, plan_changes, recorded_keys
    from sonicspec.plan.summary import format_summary, summarize
    from sonicspec.spec.splits import EACH_SPEAKER_PER_SCENE
    from sonicspec.stages.workflow import progress
    from sonicspec.store import ArtifactStore

    loaded = _load_or_exit(args.spec, args)
    if loaded is None:
        return EXIT_INVALID
    try:
        layouts = layouts_of(loaded)
        unread = None
    except SonicspecError as err:
        if any(s.groups == EACH_SPEAKER_PER_SCENE for s in loaded.spec.splits.values()):
            print(f"sonicspec: error: {args.spec}: {err}", file=sys.stderr)
            return EXIT_INVALID
        # Fixed group counts: the numbers stand without the data; scenes and speakers do not.
        layouts, unread = None, str(err)
    summary = summarize(loaded.spec, layouts)
    if args.summary:
        print(json.dumps(summary.to_dict(), indent=2) if args.json else format_summary(summary))
        if unread is not None and not args.json:
            print(f"(scenes and speakers not counted: {unread})")
        return EXIT_OK
    if not _preflight_or_exit(loaded, args.spec):
        return EXIT_INVALID
    plan = _compile(loaded, args)
    last = _last_plan_path(plan)
    old = recorded_keys(last)
    changes = plan_changes(old, plan)
    done = {p.step: p.done for p in progress(plan, ArtifactStore(plan.store_dir))}
    steps = {
        step: {"jobs": len(jobs), "in_store": done.get(step, 0), **changes[step]}
        for step, jobs in plan.by_step().items()
        if jobs
    }
    if args.json:
        print(
            json.dumps(
                {
                    "summary": summary.to_dict(),
                    "store_dir": plan.store_dir,
                    "output_dir": plan.output_dir,
                    "plan_digest": plan.digest,
                    "steps": steps,
                    "jobs": [j.to_dict() for j in plan.jobs],
                },
                indent=2,
            )
        )
        return EXIT_OK
    print(format_summary(summary))
    print(f"\nstore {plan.store_dir}\noutput {plan.output_dir}")
    since = "since the last build" if old is not None else "(no earlier build)"
    print(f"{'step':<11} {'jobs':>6} {'in store':>9} {'new':>6} {'dropped':>8}  {since}")
    for step, c in steps.items():
        print(f"{step:<11} {c['jobs']:>6} {c['in_store']:>9} {c['added']:>6} {c['dropped']:>8}")
    if args.keys:
        for job in plan.jobs:
            print(f"{job.key}  {job.label}")
    return EXIT_OK


def _report_unavailable(where: str) -> bool:
    """True (after the message) if matplotlib or jinja2, which the report needs, is missing."""
    from sonicspec.stages.preflight import module_available

    missing = [m for m in ("matplotlib", "jinja2") if not module_available(m)]
    if missing:
        print(f"sonicspec: error: {where} needs {' and '.join(missing)}: "
              "pip install 'sonicspec[report]'", file=sys.stderr)
    return bool(missing)


def cmd_build(args: argparse.Namespace) -> int:
    loaded = _load_or_exit(args.spec, args)
    if loaded is None or not _preflight_or_exit(loaded, args.spec):
        return EXIT_INVALID
    if loaded.spec.outputs.report.enabled and not args.dry_run and not args.until \
            and _report_unavailable(f"{args.spec}: outputs.report.enabled"):
        return EXIT_INVALID
    if not args.dry_run and not args.until and _exports_unavailable(loaded, args.spec):
        return EXIT_INVALID
    from sonicspec.stages.workflow import build

    plan = _compile(loaded, args)
    if args.until:
        plan = plan.until(args.until)
    profile = Path(args.profile) if args.profile else None
    result = build(plan, cores=args.cores, profile=profile, dry_run=args.dry_run)
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
    plan.write(_last_plan_path(plan))
    print(f"dataset written to {plan.output_dir}", file=sys.stderr)
    if loaded.spec.outputs.report.enabled:
        from sonicspec.export.report import write_report

        report = write_report(plan.output_dir,
                              group_pages=loaded.spec.outputs.report.group_pages)
        print(_report_line(report), file=sys.stderr)
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


def _report_line(report) -> str:
    return (f"report written to {report.path} ({report.groups} group"
            f"{'s' * (report.groups != 1)}, {report.group_pages} with a page in "
            f"{report.files_dir.name}/; {report.page_bytes / 1e6:.2f} MB, "
            f"{report.seconds:.1f} s)")


def cmd_report(args: argparse.Namespace) -> int:
    from sonicspec.export.report import write_report

    if _report_unavailable("sonicspec report"):
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
    print(_report_line(report))
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


def cmd_verify(args: argparse.Namespace) -> int:
    from sonicspec.export.checksums import folder_kind
    from sonicspec.store import ArtifactStore

    folder = Path(args.folder)
    if not folder.is_dir():
        print(f"sonicspec: error: {folder}: no such folder", file=sys.stderr)
        return EXIT_INVALID
    kind = folder_kind(folder)
    if kind is None:
        print(f"sonicspec: error: {folder}: not a sonicspec store or dataset (it has neither "
              "sonicspec-store.json nor .sonicspec-dataset.json)", file=sys.stderr)
        return EXIT_INVALID
    if kind == "dataset":
        from sonicspec.stages.repair import verify_dataset_folder

        count, problems = verify_dataset_folder(folder)
        what = "dataset files"
    else:
        store = ArtifactStore(folder)
        expected = None
        if args.spec:
            from sonicspec.plan.compile import compile_spec

            loaded = _load_or_exit(args.spec)
            if loaded is None:
                return EXIT_INVALID
            expected = {j.key: j.step for j in compile_spec(loaded).jobs}
        problems = [p.format() for p in store.verify(expected)]
        count = sum(1 for _ in store.artifacts())
        what = "artifacts"
    for p in problems:
        print(p, file=sys.stderr)
    print(
        f"{folder}: {kind}, {count} {what} checked, {len(problems)} problem"
        f"{'s' * (len(problems) != 1)}",
        file=sys.stderr if problems else sys.stdout,
    )
    return EXIT_FAILURE if problems else EXIT_OK


def _choose_scene(loaded, args: argparse.Namespace) -> bool:
    """Fill ``args.scene`` when the spec has one scene; False (after a message) if ambiguous."""
    from sonicspec.stages.inspect import scene_ids

    if args.scene is None:
        ids = scene_ids(loaded)
        if len(ids) != 1:
            print(f"sonicspec: error: --scene: the spec has {len(ids)} scenes; choose one of "
                  f"{', '.join(ids)}", file=sys.stderr)
            return False
        args.scene = ids[0]
    return True


def cmd_scene_inspect(args: argparse.Namespace) -> int:
    from sonicspec.stages.inspect import format_facts, inspect_scene

    if _plot_unavailable(args):
        return EXIT_INVALID
    loaded = _load_or_exit(args.spec)
    if loaded is None or not _choose_scene(loaded, args):
        return EXIT_INVALID
    facts = inspect_scene(loaded, args.scene, plot=Path(args.plot) if args.plot else None)
    print(json.dumps(facts, indent=2) if args.json else format_facts(facts))
    return EXIT_OK


def cmd_rir(args: argparse.Namespace) -> int:
    from sonicspec.stages.rir import format_rir_facts

    if _plot_unavailable(args):
        return EXIT_INVALID
    if (args.spec is None) == (args.mesh is None):
        print("sonicspec: error: rir: expected a SPEC or --mesh FILE, got "
              f"{'both' if args.spec else 'neither'}", file=sys.stderr)
        return EXIT_INVALID
    if args.mesh is not None:
        if args.scene is not None:
            print("sonicspec: error: --scene: expected a SPEC to choose a scene from, got "
                  "--mesh; the mesh is the scene", file=sys.stderr)
            return EXIT_INVALID
        rir, facts = _rir_of_mesh(args)
        if rir is None:
            return EXIT_INVALID
        title = f"{Path(args.mesh).name}: source {args.source} -> mic {args.mic}"
    else:
        mesh_only = [flag for flag, value in (
            ("--material", args.material), ("--default-material", args.default_material),
            ("--library", args.library), ("--repair", args.repair), ("--rays", args.rays),
            ("--seed", args.seed), ("--sample-rate", args.sample_rate),
            ("--microphone", args.microphone))
            if value not in (None, False)]
        if mesh_only:
            print(f"sonicspec: error: {mesh_only[0]}: expected --mesh FILE with it, got a "
                  "SPEC (the spec sets materials, acoustics and the seed)", file=sys.stderr)
            return EXIT_INVALID
        if _scene_file(args.spec):
            rir, facts = _rir_of_scene_file(args)
            if rir is None:
                return EXIT_INVALID
            title = f"{facts['scene_id']}: source {args.source} -> mic {args.mic}"
        else:
            from sonicspec.stages.rir import rir_from_spec

            loaded = _load_or_exit(args.spec)
            if loaded is None or not _choose_scene(loaded, args):
                return EXIT_INVALID
            rir, facts = rir_from_spec(loaded, args.scene, args.source, args.mic)
            title = f"{args.scene}: source {args.source} -> mic {args.mic}"
    for warning in facts["warnings"]:
        print(f"sonicspec: warning: {warning}", file=sys.stderr)
    if args.output:
        from sonicspec.export.files import write_audio

        write_audio(Path(args.output), rir, facts["sample_rate_hz"],
                    audio_format="wav", subtype="FLOAT")
        facts["output"] = args.output
    if args.plot:
        from sonicspec.export.plots import plot_rir

        plot_rir(rir[0], facts["sample_rate_hz"], facts["figures"]["bands_hz"], Path(args.plot),
                 title=title)
        facts["plot"] = args.plot
    print(json.dumps(facts, indent=2) if args.json else format_rir_facts(facts))
    return EXIT_OK


def _scene_file(path: str) -> bool:
    """Whether ``path`` is a scene file (a ``scene`` and no ``sonicspec:`` version) rather
    than a dataset spec; an unreadable file is left to the spec loader to report."""
    from sonicspec.errors import SpecError
    from sonicspec.spec.load import parse_text
    from sonicspec.spec.scene_file import is_scene_file
    from sonicspec.spec.validate import MAX_SPEC_BYTES

    try:
        p = Path(path)
        if p.stat().st_size > MAX_SPEC_BYTES:
            return False
        data, _ = parse_text(p.read_text(encoding="utf-8"), path)
    except (OSError, UnicodeDecodeError, SpecError):
        return False
    return is_scene_file(data)


def _rir_of_scene_file(args: argparse.Namespace):
    """``sonicspec rir SCENE.yaml``: the RIR and facts of a scene file through the Python API,
    or (None, None) after a message."""
    import warnings

    from sonicspec.api import RirSettings, Scene, compute_rir
    from sonicspec.errors import SonicspecError, SonicspecWarning
    from sonicspec.spec.validate import validate_scene_file

    if args.scene is not None:
        print("sonicspec: error: --scene: a scene file holds one scene; --scene chooses one "
              "of a dataset spec's", file=sys.stderr)
        return None, None
    spec, problems = validate_scene_file(args.spec)
    _print_problems(problems, args.spec)
    if spec is None:
        return None, None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        try:
            scene = Scene.from_spec(spec.scene, spec.materials,
                                    base_dir=Path(args.spec).resolve().parent, seed=spec.seed)
            settings = RirSettings(**spec.acoustics.model_dump(),
                                   sample_rate_hz=spec.sample_rate_hz,
                                   speed_of_sound_m_s=spec.speed_of_sound_m_s)
            result = compute_rir(scene, args.source, args.mic, settings,
                                 receiver=spec.microphone, seed=spec.seed)
        except SonicspecError as exc:
            print(f"sonicspec: error: {args.spec}: {exc}", file=sys.stderr)
            return None, None
    facts = {"scene_id": scene.name, **result.to_dict(), "mesh_triangles": scene.mesh.n_faces,
             "materials_m2": scene.material_areas_m2(),
             "warnings": [str(w.message) for w in caught
                          if issubclass(w.category, SonicspecWarning)]}
    return result.rir, facts


def _spec_default(section: str, field: str) -> object:
    """The spec's default of ``section.field`` (``""``: a top-level field), for help texts: a
    default is written once, in the spec models."""
    from sonicspec.spec.dataset import DatasetSpec

    model = DatasetSpec
    if section:
        model = DatasetSpec.model_fields[section].default_factory().__class__
    return model.model_fields[field].get_default(call_default_factory=True)


def _rir_of_mesh(args: argparse.Namespace):
    """``sonicspec rir --mesh``: the RIR and facts through the Python API, or (None, None)
    after a message when the mesh, a label or a material name is wrong."""
    import warnings

    from pydantic import ValidationError

    from sonicspec.api import RirSettings, Scene, compute_rir
    from sonicspec.errors import SonicspecError, SonicspecWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        try:
            scene = Scene.from_file(args.mesh, dict(args.material or []),
                                    default_material=args.default_material,
                                    library=args.library or "sonicspec", repair=args.repair)
        except SonicspecError as exc:
            print(f"sonicspec: error: {exc}", file=sys.stderr)
            return None, None
        flags = {"rays": ("--rays", args.rays), "sample_rate_hz": ("--sample-rate",
                                                                   args.sample_rate)}
        try:
            settings = RirSettings(**{k: v for k, (_, v) in flags.items() if v is not None})
        except ValidationError as exc:
            error = exc.errors()[0]
            print(f"sonicspec: error: {flags[error['loc'][0]][0]}: {error['msg'].lower()}, got "
                  f"{error['input']}", file=sys.stderr)
            return None, None
        receiver = _microphone_option(args.microphone)
        if receiver is False:
            return None, None
        result = compute_rir(scene, args.source, args.mic, settings, receiver=receiver,
                             seed=args.seed or 0)
    facts = {"scene_id": scene.name, **result.to_dict(), "mesh_triangles": scene.mesh.n_faces,
             "materials_m2": scene.material_areas_m2(),
             "warnings": [str(w.message) for w in caught
                          if issubclass(w.category, SonicspecWarning)]}
    return result.rir, facts


def _microphone_option(text: str | None):
    """``--microphone "{kind: ambisonics, order: 1}"``: the spec's microphone model (None:
    mono), or False after a message when the text is not one."""
    if text is None:
        return None
    import yaml
    from pydantic import TypeAdapter, ValidationError

    from sonicspec.spec.microphone import MicrophoneSpec

    try:
        value = yaml.safe_load(text)
        if not isinstance(value, dict):
            raise ValueError(f"expected a mapping such as '{{kind: ambisonics, order: 1}}', "
                             f"got {text!r}")
        return TypeAdapter(MicrophoneSpec).validate_python(value)
    except (yaml.YAMLError, ValueError) as exc:
        if isinstance(exc, ValidationError):
            error = exc.errors()[0]
            where = ".".join(str(x) for x in error["loc"])
            exc = f"{where}: {error['msg'].lower()}" if where else error["msg"].lower()
        print(f"sonicspec: error: --microphone: {exc}", file=sys.stderr)
        return False


def _label_material(text: str) -> tuple[str, str]:
    label, sep, name = text.partition("=")
    if not sep or not label or not name:
        raise argparse.ArgumentTypeError(f"expected LABEL=NAME, got {text!r}")
    return label, name


def _output_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--output-dir", metavar="DIR",
                   help="write the dataset here instead of the spec's outputs.dir (may be "
                   "outside the spec's folder; content keys do not change)")
    p.add_argument("--store-dir", metavar="DIR",
                   help="use this artifact store instead of the spec's outputs.store_dir")


# --- using a built dataset: evaluate, export (sonicspec.dataload) ---------------------------

def cmd_evaluate(args: argparse.Namespace) -> int:
    from sonicspec.audio.metrics import METRICS
    from sonicspec.dataload.evaluate import evaluate, summarise, summary_table, write_results
    from sonicspec.dataload.folder import DatasetError

    metrics = args.metrics or list(METRICS)
    try:
        unknown = [m for m in metrics if m not in METRICS]
        if unknown:
            raise DatasetError(f"--metrics: expected names from {list(METRICS)}, got "
                               f"{unknown[0]!r}")
        rows = evaluate(args.dataset, args.split, args.task, estimates=args.estimates,
                        oracle=args.oracle, channel=args.channel, metrics=metrics)
    except DatasetError as exc:
        print(f"sonicspec: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    summary = summarise(rows, metrics)
    settings = {"dataset": str(Path(args.dataset).resolve()), "split": args.split,
                "task": args.task, "estimates": args.estimates, "oracle": args.oracle,
                "channel": args.channel, "metrics": metrics, "window_s": 6.0, "hop_s": 3.0,
                "sonicspec_version": __version__}
    out = Path(args.output or f"evaluation-{args.split}-{args.task}")
    csv_path, json_path = write_results(out, rows, summary, settings)
    print(summary_table(summary, metrics))
    print(f"scores: {csv_path}\nsummary: {json_path}")
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


def _add_dataset_commands(sub) -> None:
    from sonicspec.audio.metrics import METRICS
    from sonicspec.dataload.hub import FORMATS

    p = sub.add_parser("evaluate", help="score a model's outputs against a built dataset's "
                       "targets (SI-SNR(i), SDR(i), PESQ, STOI; 6 s windows every 3 s)")
    p.add_argument("dataset", metavar="DATASET", help="a built dataset folder (outputs.dir)")
    p.add_argument("--split", required=True, help="the split to score (e.g. test)")
    p.add_argument("--task", required=True, choices=("separation", "enhancement"))
    p.add_argument("--estimates", metavar="DIR",
                   help="<DIR>/<split>/<group>/<mixture name>.wav, one channel per target")
    p.add_argument("--oracle", action="store_true",
                   help="also score the mixture itself (the baseline) and the targets "
                   "themselves (the ceiling) as estimates")
    p.add_argument("--channel", type=int, default=0,
                   help="the dataset's reference channel (default 0)")
    p.add_argument("--metrics", nargs="+", metavar="NAME",
                   help=f"a subset of {' '.join(METRICS)} (default: all)")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="where scores.csv and summary.json go "
                   "(default: evaluation-<split>-<task>)")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("export", help="a built dataset as Hugging Face datasets (Parquet) or "
                       "WebDataset (tar) shards; only changed shards are rewritten")
    p.add_argument("dataset", metavar="DATASET", help="a built dataset folder (outputs.dir)")
    p.add_argument("--format", required=True, choices=FORMATS)
    p.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="the export folder (outside the dataset folder)")
    p.add_argument("--split", action="append", metavar="SPLIT",
                   help="export this split (repeat; default: all)")
    p.add_argument("--groups-per-shard", type=int, default=64, metavar="N",
                   help="groups per shard (default 64)")
    p.set_defaults(func=cmd_export)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sonicspec",
        description="Realistic moving-source speech datasets from a versioned spec.",
    )
    parser.add_argument("--version", action="version", version=f"sonicspec {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("validate", help="check spec files; exit 0 if valid, 2 if not")
    p.add_argument("specs", nargs="+", metavar="SPEC", help="spec files (YAML or JSON)")
    p.add_argument(
        "--check-files",
        action="store_true",
        help="also check that referenced meshes, SOFA files and corpus folders exist",
    )
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="print only problems")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("schema", help="print the JSON Schema of the spec language")
    p.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of stdout")
    p.set_defaults(func=cmd_schema)

    from sonicspec.spec.templates import PRESETS

    p = sub.add_parser("init", help="write a commented starting spec that validates as written")
    p.add_argument(
        "--preset", choices=sorted(PRESETS), default="demo", help="starting point (default: demo)"
    )
    p.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of stdout")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.set_defaults(func=cmd_init)

    p = sub.add_parser(
        "plan",
        help="show the jobs a spec compiles to, what is already built "
        "and what changed since the last build",
    )
    p.add_argument("spec", metavar="SPEC")
    p.add_argument("--json", action="store_true", help="print everything, jobs included, as JSON")
    p.add_argument(
        "--summary",
        action="store_true",
        help="only the counts the spec fixes (no data needed: nothing is read)",
    )
    p.add_argument("--keys", action="store_true", help="also list every job's key and label")
    _output_options(p)
    p.set_defaults(func=cmd_plan)

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
    _output_options(p)
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("scene", help="look at the scenes of a spec")
    scene_sub = p.add_subparsers(dest="scene_command", metavar="ACTION")
    scene_sub.required = True
    p = scene_sub.add_parser("inspect", help="mesh statistics, repair report, materials, "
                             "floors, walkable area and a floor-plan picture")
    p.add_argument("spec", metavar="SPEC")
    p.add_argument("--scene", metavar="ID", help="scene id (required if the spec has several)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the floor plan with a sampled group")
    p.add_argument("--json", action="store_true", help="print the facts as one JSON object")
    p.set_defaults(func=cmd_scene_inspect)

    p = sub.add_parser("rir", help="one room impulse response, in a spec's scene or in a mesh "
                       "file, with T30, EDT, C50 and DRR")
    p.add_argument("spec", metavar="SPEC", nargs="?",
                   help="a dataset spec (or give --mesh instead)")
    p.add_argument("--scene", metavar="ID", help="scene id (required if the spec has several)")
    p.add_argument("--source", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                   help="source position, metres")
    p.add_argument("--mic", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                   help="microphone position, metres")
    p.add_argument("-o", "--output", metavar="RIR.wav", help="write the RIR (float32 WAV)")
    p.add_argument("--plot", metavar="FILE.png", help="waveform, decay curves, arrivals")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    g = p.add_argument_group("without a spec", "a mesh file (glb, gltf, obj, ply; metres, "
                             "z up for obj/ply) whose labels (object or group names, PLY "
                             "face labels) map to materials; the spec's acoustics defaults")
    g.add_argument("--mesh", metavar="FILE", help="the room's mesh file")
    g.add_argument("--material", metavar="LABEL=NAME", action="append", type=_label_material,
                   help="material of a label (repeat for each label)")
    g.add_argument("--default-material", metavar="NAME",
                   help="material of faces without a label")
    g.add_argument("--library", choices=("sonicspec", "sonicset"),
                   help="material library (default: sonicspec)")
    g.add_argument("--repair", action="store_true",
                   help="repair the mesh first (off: the mesh is traced as given)")
    g.add_argument("--rays", type=int, metavar="N",
                   help=f"rays traced (default: {_spec_default('acoustics', 'rays')})")
    g.add_argument("--seed", type=int, metavar="N", help="random seed (default: 0)")
    g.add_argument("--sample-rate", type=int, metavar="HZ",
                   help=f"sample rate (default: {_spec_default('', 'sample_rate_hz')})")
    g.add_argument("--microphone", metavar="YAML",
                   help="the receiver as the spec writes it, e.g. '{kind: ambisonics, order: 1}'"
                   " or '{kind: circular_array, n: 6, radius_m: 0.05}' (default: mono)")
    p.set_defaults(func=cmd_rir)

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

    p = sub.add_parser("job", help="run one job of a compiled plan (used by the workflow)")
    p.add_argument("--plan", required=True, metavar="PLAN", help="plan JSON file")
    p.add_argument("key", metavar="KEY", help="the job's content key")
    p.set_defaults(func=cmd_job)

    p = sub.add_parser("verify", help="re-check every artifact of a store, or every file of a "
                       "dataset folder against its checksums and the store")
    p.add_argument("folder", metavar="DIR",
                   help="a store (outputs.store_dir) or a dataset folder (outputs.dir)")
    p.add_argument(
        "--spec", metavar="SPEC", help="also report artifacts this spec needs but the store lacks"
    )
    p.set_defaults(func=cmd_verify)

    _add_dataset_commands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("sonicspec: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # the last line of defence: a message, never a traceback
        if os.environ.get("SONICSPEC_DEBUG"):
            raise
        from sonicspec.errors import SonicspecError, SpecError

        if isinstance(exc, SpecError):
            print(str(exc), file=sys.stderr)
            return EXIT_INVALID
        kind = (
            "error" if isinstance(exc, SonicspecError) else f"internal error ({type(exc).__name__})"
        )
        print(f"sonicspec: {kind}: {exc}", file=sys.stderr)
        if not isinstance(exc, SonicspecError):
            print(
                "run again with SONICSPEC_DEBUG=1 for the traceback, and please report it",
                file=sys.stderr,
            )
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
