"""Stage ``mesh``: build a procedural room or import a scan, add obstacles, repair, leak-test."""

from __future__ import annotations

import logging
import warnings

from sonicspec import artifacts
from sonicspec.artifacts.scenes import build_scene_mesh
from sonicspec.errors import SonicspecWarning
from sonicspec.stages.context import JobContext

log = logging.getLogger("sonicspec.stages.mesh")


def run(ctx: JobContext) -> None:
    # Warnings raised while the mesh is built (faces that fell back to the library's default
    # material) go to the job's log as WARNING lines, which the build summary collects.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        mesh, report = build_scene_mesh(ctx.params, dict(ctx.job.paths),
                                        ctx.rng("mesh", ctx.job.key))
    for w in caught:
        if issubclass(w.category, SonicspecWarning):
            log.warning("%s", w.message)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    arrays, facts = artifacts.mesh_arrays(mesh)
    # the report's absent parts (weld, repair, leak, warnings) stay absent
    ctx.write(arrays, artifacts.encode("mesh", {**report.model_dump(mode="json"), **facts}))
