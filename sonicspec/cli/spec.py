"""The spec language: ``sonicspec validate``, ``sonicspec schema``, ``sonicspec init``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sonicspec.atomic import write_text
from sonicspec.cli.common import (
    EXIT_FAILURE,
    EXIT_INVALID,
    EXIT_OK,
    names_scene_file,
    print_problems,
)


def cmd_validate(args: argparse.Namespace) -> int:
    from sonicspec.spec import validate_file

    worst = EXIT_OK
    report = []
    for path in args.specs:
        scene_file = names_scene_file(path)
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
            print_problems(problems, path)
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


def add_validate(sub) -> None:
    """``sonicspec validate SPEC...``."""
    p = sub.add_parser("validate", help="check spec files; exit 0 if valid, 2 if not")
    p.add_argument("specs", nargs="+", metavar="SPEC", help="spec files (YAML or JSON)")
    p.add_argument(
        "--check-files",
        action="store_true",
        help="also check the data: load every referenced mesh through the build's reader, "
        "probe the corpus folders' audio, check that SOFA files exist and that the optional "
        "packages the spec needs are installed (slower: meshes are read)",
    )
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="print only problems")
    p.set_defaults(func=cmd_validate)


def add_schema(sub) -> None:
    """``sonicspec schema``."""
    p = sub.add_parser("schema", help="print the JSON Schema of the spec language")
    p.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of stdout")
    p.set_defaults(func=cmd_schema)


def add_init(sub) -> None:
    """``sonicspec init``."""
    from sonicspec.spec.templates import PRESETS

    p = sub.add_parser("init", help="write one of the preset specs (default: the demo, its "
                       "comments included) to start from; it validates as written")
    p.add_argument(
        "--preset", choices=sorted(PRESETS), default="demo",
        help="which preset (default: demo, the embedded demo: procedural rooms and generated "
        "corpora, no data to download)"
    )
    p.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of stdout")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.set_defaults(func=cmd_init)
