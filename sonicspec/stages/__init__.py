"""Pipeline stages: thin adapters from artifacts to library calls and back (DESIGN.md §1).

Each step of :data:`sonicspec.plan.model.STEPS` has one function here, found through
:data:`STAGES` and imported only when its job runs, so the command line stays quick.
"""

from __future__ import annotations

import importlib
import logging
import time
import traceback

from sonicspec.errors import SonicspecError, StageError
from sonicspec.plan.model import Plan
from sonicspec.stages.context import JobContext, mark_finished, progress_path
from sonicspec.store import ArtifactStore

STAGES: dict[str, str] = {
    "mesh": "sonicspec.stages.mesh:run",
    "navigation": "sonicspec.stages.navigation:run",
    "placement": "sonicspec.stages.placement:run",
    "rir": "sonicspec.stages.rir:run",
    "corpus": "sonicspec.stages.corpus:run",
    "arrange": "sonicspec.stages.arrange:run",
    "render": "sonicspec.stages.render:run",
    "mix": "sonicspec.stages.mix:run",
    "export": "sonicspec.stages.export:run",
    "dataset": "sonicspec.stages.dataset:run",
}
"""Step name -> ``module:function`` taking a :class:`JobContext`."""

log = logging.getLogger("sonicspec.stages")


def stage_function(step: str):
    try:
        target = STAGES[step]
    except KeyError:
        raise StageError(f"step {step!r} has no stage in this sonicspec version") from None
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


def run_job(plan: Plan, key: str) -> bool:
    """Run one job of ``plan`` unless its artifact exists; True if it ran.

    Every failure becomes a :class:`StageError` that names the job, and no partial artifact
    is left behind (the store writes atomically).
    """
    jobs = plan.by_key()
    if key not in jobs:
        raise StageError(f"no job with key {key[:12]} in plan {plan.name!r}", key)
    job = jobs[key]
    store = ArtifactStore(plan.store_dir)
    if store.exists(job.step, key):
        log.info("%s: already in the store", job.label)
        mark_finished(plan.store_dir, key)
        return False
    for k in job.inputs:
        if not store.exists(jobs[k].step, k):
            raise StageError(
                f"{job.label}: input {jobs[k].label} ({k[:12]}) is not in the store", key
            )
    fn = stage_function(job.step)
    start = time.perf_counter()
    log.info("%s: starting (%s)", job.label, key)
    try:
        fn(JobContext(job, plan, store))
    except StageError:
        raise
    except SonicspecError as exc:
        raise StageError(f"{job.label}: {exc}", key) from exc
    except Exception as exc:
        log.error("%s", traceback.format_exc())
        raise StageError(f"{job.label}: internal error {type(exc).__name__}: {exc}", key) from exc
    finally:
        progress_path(plan.store_dir, key).unlink(missing_ok=True)
    if not store.exists(job.step, key):
        raise StageError(f"{job.label}: the stage finished without writing its artifact", key)
    mark_finished(plan.store_dir, key)
    log.info("%s: done in %.2f s", job.label, time.perf_counter() - start)
    return True
