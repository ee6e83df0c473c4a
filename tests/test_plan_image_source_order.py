"""``sonicspec plan --summary``: per scene, the image-source order the build reached (read from
the store's RIR artifacts, and why it is lower) or, before the RIRs are built, an estimate from
the scene's traced mesh against the candidate cap (issue 27)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from test_pipeline_stages import SPEC

from sonicspec.acoustics.paths import image_sources as ism
from sonicspec.plan.compile import compile_spec
from sonicspec.spec import load_spec
from sonicspec.stages import run_job
from sonicspec.stages.inspect import format_outlook, image_source_outlook
from sonicspec.store import ArtifactStore

ROOT = Path(__file__).resolve().parents[1]
TEXT = SPEC.replace("image_source_order: 1", "image_source_order: 2")


def plan_cli(*args: str, cwd: Path) -> str:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-m", "sonicspec.cli", "plan", "--summary", *args,
                           "spec.yaml"], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_plan_summary_says_the_order_each_scene_reached_or_will(tmp_path: Path,
                                                                monkeypatch) -> None:
    (tmp_path / "spec.yaml").write_text(TEXT)
    # before any RIR is built: an estimate from the scene's mesh and one drawn group
    ahead = plan_cli(cwd=tmp_path)
    (line,) = [x for x in ahead.splitlines() if x.startswith("  room: ")]
    assert "not built yet; estimate from one drawn group" in line
    assert "order 2, candidates per order " in line and line.endswith("well under the cap")
    assert ("  1 more scene not built yet, not estimated (sonicspec plan --summary "
            "--estimate-scenes N)") in plan_cli("--estimate-scenes", "0", cwd=tmp_path)

    # a build whose cap cut order 2 (a cap far below the real one, to make it happen here)
    loaded = load_spec(tmp_path / "spec.yaml")
    plan = compile_spec(loaded)
    monkeypatch.setattr(ism, "MAX_CANDIDATES", 12)
    for job in plan.jobs:
        if job.step in ("mesh", "navigation", "placement", "rir"):
            run_job(plan, job.key)
    monkeypatch.undo()
    (scene,) = image_source_outlook(loaded, plan)
    assert (scene["asked"], scene["reached"], scene["built"], scene["rir_jobs"]) == (2, 1, 1, 1)
    assert scene["stopped"] == "order 2 needs more than 12 candidates"
    assert scene["lower"] == scene["sources"] == 4  # two talkers, noise, music
    after = plan_cli(cwd=tmp_path)
    assert ("  room: order 1 reached (order 2 needs more than 12 candidates) for 4 of 4 "
            "sources' RIRs; the ray tracer covers the higher orders, less exactly") in after
    assert format_outlook([scene])[1] in after
    data = json.loads(plan_cli("--json", cwd=tmp_path))
    assert data["image_source_order"][0]["reached"] == 1

    # built again with the real cap, it reaches the asked order
    (rir,) = [j for j in plan.jobs if j.step == "rir"]
    ArtifactStore(plan.store_dir).remove("rir", rir.key)
    run_job(plan, rir.key)
    assert "  room: order 2 reached by all 4 sources' RIRs" in plan_cli(cwd=tmp_path)
