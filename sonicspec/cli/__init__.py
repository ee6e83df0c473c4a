"""The ``sonicspec`` command. Thin: parse arguments, call package functions, print, exit.

One module per command group; each registers its commands' arguments beside their code:

* ``spec``  -- ``validate``, ``schema``, ``init`` (the spec language)
* ``plan``  -- ``plan`` (the jobs a spec compiles to)
* ``build`` -- ``build``, ``job``, ``verify`` (building through Snakemake, checking a store)
* ``scene`` -- ``scene inspect``, ``rir`` (looking at a room)
* ``microphones`` -- ``microphones`` (the device presets and their layouts)
* ``data``  -- ``report``, ``evaluate``, ``export`` (using a built dataset)
* ``recording`` -- ``playback``, ``align`` (a real recorded test set)
* ``common`` -- exit codes and the steps the groups share (load a spec, compile, preflight)

Exit codes: 0 success (a valid spec), 2 an invalid spec or bad arguments, 1 any other failure.
Tracebacks are shown only with ``SONICSPEC_DEBUG=1``.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from sonicspec import __version__
from sonicspec.cli import build, data, microphones, plan, recording, scene, spec
from sonicspec.cli.common import EXIT_FAILURE, EXIT_INVALID

# The commands in the order ``sonicspec --help`` lists them.
COMMANDS = (spec.add_validate, spec.add_schema, spec.add_init, plan.add_plan, build.add_build,
            scene.add_scene, scene.add_rir, microphones.add_microphones, data.add_report,
            build.add_job, build.add_batch, build.add_verify, data.add_evaluate, data.add_export,
            recording.add_playback, recording.add_align)


def build_parser() -> argparse.ArgumentParser:
    """The whole command line: every command and its options (the CLI reference reads it)."""
    parser = argparse.ArgumentParser(
        prog="sonicspec",
        description="Realistic moving-source speech datasets from a versioned spec.",
    )
    parser.add_argument("--version", action="version", version=f"sonicspec {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for add in COMMANDS:
        add(sub)
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
        if isinstance(exc, OSError):  # an I/O failure: where, and why (never "internal")
            from sonicspec.atomic import os_error_cause

            where = exc.filename
            folder = os.path.dirname(os.path.abspath(where)) if where else None
            print(f"sonicspec: error: {where or 'a file'}: {os_error_cause(exc, folder)}",
                  file=sys.stderr)
            return EXIT_FAILURE
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

