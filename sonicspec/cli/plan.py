"""``sonicspec plan``: the jobs a spec compiles to, what is in the store and what changed."""

from __future__ import annotations

import argparse
import json
import sys

from sonicspec.cli.common import (
    EXIT_INVALID,
    EXIT_OK,
    compile_plan,
    last_plan_path,
    load_or_exit,
    output_options,
    preflight_or_exit,
)


def cmd_plan(args: argparse.Namespace) -> int:
    from sonicspec.errors import SonicspecError
    from sonicspec.plan.compile import layouts_of, plan_changes, recorded_keys
    from sonicspec.plan.data_needs import missing_data
    from sonicspec.plan.summary import format_summary, summarize
    from sonicspec.spec.splits import EACH_SPEAKER_PER_SCENE
    from sonicspec.stages.workflow import progress
    from sonicspec.store import ArtifactStore

    loaded = load_or_exit(args.spec, args)
    if loaded is None:
        return EXIT_INVALID
    try:
        layouts = layouts_of(loaded)
        unread = None
    except SonicspecError as err:
        per_speaker = any(s.groups == EACH_SPEAKER_PER_SCENE
                          for s in loaded.spec.splits.values())
        if per_speaker and not args.summary:
            print(f"sonicspec: error: {args.spec}: {err}", file=sys.stderr)
            for line in missing_data(loaded.spec, loaded.base_dir.resolve()):
                print(f"  {line}", file=sys.stderr)
            return EXIT_INVALID
        # The summary needs no data: what the data decides (scenes, speakers, the groups of a
        # split composed per speaker) is '?'.
        layouts, unread = None, str(err)
    summary = summarize(loaded.spec, layouts)
    if args.summary:
        from sonicspec.stages.inspect import format_outlook, image_source_outlook

        orders = None
        if unread is None:
            orders = image_source_outlook(loaded, compile_plan(loaded, args),
                                          estimate=args.estimate_scenes)
        if args.json:
            print(json.dumps({**summary.to_dict(), "image_source_order": orders}, indent=2))
        else:
            print(format_summary(summary))
            for line in format_outlook(orders or []):
                print(line)
        if unread is not None and not args.json:
            print(f"(? : counted from the data, which is not there: {unread})")
            missing = missing_data(loaded.spec, loaded.base_dir.resolve())
            if missing:
                print("to build it, get:")
                for line in missing:
                    print(f"  {line}")
        return EXIT_OK
    if not preflight_or_exit(loaded, args.spec):
        return EXIT_INVALID
    plan = compile_plan(loaded, args)
    last = last_plan_path(plan)
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


def add_plan(sub) -> None:
    """``sonicspec plan SPEC``."""
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
        help="only the counts the spec fixes (no data needed), and per scene the "
        "image-source order the build reached or will (when the data is there)",
    )
    p.add_argument("--keys", action="store_true", help="also list every job's key and label")
    p.add_argument(
        "--estimate-scenes",
        type=int,
        default=3,
        metavar="N",
        help="with --summary: per scene, the image-source order its RIRs reached (read from "
        "the store) or, for up to N scenes not built yet, an estimate from the scene's "
        "traced mesh and one drawn group (candidates per order against the cap; "
        "default 3, 0 for none)",
    )
    output_options(p)
    p.set_defaults(func=cmd_plan)
