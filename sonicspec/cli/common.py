"""What the command groups share: exit codes, loading a spec with its problems printed,
compiling it with the command line's folders, and the checks a command makes before it runs."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

EXIT_OK, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2


def print_problems(problems: Sequence, source: str, stream=None) -> None:
    for p in problems:
        print(p.format(source), file=stream or sys.stderr)


def load_or_exit(spec: str, args: argparse.Namespace | None = None):
    from sonicspec.spec import validate_file

    loaded, problems = validate_file(spec, cli_outputs=cli_outputs(args))
    print_problems(problems, spec)
    return loaded


def cli_outputs(args: argparse.Namespace | None) -> tuple[str, ...]:
    """The output folders given on the command line (``--output-dir``, ``--store-dir``)."""
    if args is None:
        return ()
    return tuple(name for name, opt in (("dir", "output_dir"), ("store_dir", "store_dir"))
                 if getattr(args, opt, None))


def compile_plan(loaded, args: argparse.Namespace):
    from sonicspec.plan.compile import compile_spec

    return compile_spec(loaded, output_dir=getattr(args, "output_dir", None),
                        store_dir=getattr(args, "store_dir", None))


def preflight_or_exit(loaded, spec: str) -> bool:
    """Print what a build would meet (errors and warnings); False if any is an error."""
    from sonicspec.stages.preflight import preflight

    problems = preflight(loaded)
    print_problems(problems, spec)
    return not any(p.severity == "error" for p in problems)


def plot_unavailable(args: argparse.Namespace) -> bool:
    """True (after the message) if ``--plot`` was asked and matplotlib is not installed."""
    from sonicspec.stages.preflight import PLOT_NEEDS, module_available

    if args.plot and not module_available("matplotlib"):
        print(f"sonicspec: error: {PLOT_NEEDS}", file=sys.stderr)
        return True
    return False


def report_unavailable(where: str) -> bool:
    """True (after the message) if matplotlib or jinja2, which the report needs, is missing."""
    from sonicspec.stages.preflight import module_available

    missing = [m for m in ("matplotlib", "jinja2") if not module_available(m)]
    if missing:
        print(f"sonicspec: error: {where} needs {' and '.join(missing)}: "
              "pip install 'sonicspec[report]'", file=sys.stderr)
    return bool(missing)


def last_plan_path(plan) -> Path:
    return Path(plan.store_dir) / "plans" / f"last-build-{plan.name}.json"


def report_line(report) -> str:
    return (f"report written to {report.path} ({report.groups} group"
            f"{'s' * (report.groups != 1)}, {report.group_pages} with a page in "
            f"{report.files_dir.name}/; {report.page_bytes / 1e6:.2f} MB, "
            f"{report.seconds:.1f} s)")


def names_scene_file(path: str) -> bool:
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


def output_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--output-dir", metavar="DIR",
                   help="write the dataset here instead of the spec's outputs.dir (may be "
                   "outside the spec's folder; content keys do not change)")
    p.add_argument("--store-dir", metavar="DIR",
                   help="use this artifact store instead of the spec's outputs.store_dir")
