"""Typed step params: every job of every example spec reads into its step's model and dumps
back to the very data its key was made from; bad params fail naming the job and the field."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from test_plan_compile import DEMO, ROOT, plan_of, sonicset_with_tiny_data

from sonicspec.errors import StageError
from sonicspec.plan.model import STEPS, Job
from sonicspec.plan.params import PARAMS, StepParams, params_data, read_params

EXAMPLES = ["demo.yaml", "array.yaml", "binaural.yaml", "enhancement_static.yaml"]


def _plans(tmp_path: Path):
    for name in EXAMPLES:
        yield name, plan_of((ROOT / "specs" / name).read_text(), tmp_path)
    yield "sonicset.yaml", plan_of(sonicset_with_tiny_data(tmp_path), tmp_path)
    # The branches only some specs take: an obj scene with a label map and a mesh
    # obstacle, a folder corpus, waypoints, every target. (A moving microphone does not
    # validate in this version.)
    shutil.copy(ROOT / "specs" / "meshes" / "room.obj", tmp_path / "room.obj")
    (tmp_path / "voices" / "anna").mkdir(parents=True, exist_ok=True)
    varied = (
        DEMO.replace("targets: []", "")
        .replace("  # An L-shaped office", "  - {kind: mesh, id: scan, path: room.obj, "
                 "label_materials: {floor: carpet_on_concrete}, obstacles: [{kind: mesh, "
                 "path: room.obj, position_m: [1, 1, 0], scale: 0.1}]}\n  # An L-shaped office")
        .replace("speech: {kind: generated, speakers_per_split: 3, utterances_per_speaker: 4}",
                 "speech: {kind: folder, root: voices}")
        .replace("kind: shortest_path", "kind: waypoints\n  points_m: [[3, 2, 1.6], [4, 3, 1.6]]")
        .replace("  tasks:", "  targets: [dry, direct, early]\n  tasks:")
        .replace("scenes: [living_room]}", "scenes: [living_room, scan]}"))
    yield "varied", plan_of(varied, tmp_path)


def test_every_step_has_a_params_model() -> None:
    assert set(PARAMS) == {s.name for s in STEPS}
    assert all(issubclass(m, StepParams) for m in PARAMS.values())


def test_every_job_round_trips_through_its_model(tmp_path: Path) -> None:
    seen: set[str] = set()
    for name, plan in _plans(tmp_path):
        for job in plan:
            data = json.loads(json.dumps(dict(job.params)))  # plain data, as a plan file holds
            typed = read_params(job.step, data, job.label)
            assert params_data(typed) == data, (name, job.label)
            # ... and the same key: the typed model is what the key was made from.
            assert Job(job.step, params_data(typed), job.inputs).key == job.key
            seen.add(job.step)
    assert seen == set(PARAMS)
    varied = dict(_plans(tmp_path))["varied"]
    mesh = next(j for j in varied.by_step()["mesh"] if j.params["scene_id"] == "scan")
    assert mesh.params["obj_labels"] is True and "obstacle0" in mesh.params["files"]


def test_models_declare_no_defaults_of_their_own() -> None:
    # A setting's default lives in the spec model, once; the params models only carry values
    # (fields absent from some jobs' data are the exception, and say so in omitted_when).
    for step, model in PARAMS.items():
        for field, info in model.model_fields.items():
            if not info.is_required():
                assert field in model.omitted_when or info.exclude, (step, field)


def test_bad_params_name_the_job_and_the_field(tmp_path: Path) -> None:
    plan = plan_of(DEMO, tmp_path)
    rir = plan.by_step()["rir"][0]
    data = json.loads(json.dumps(dict(rir.params)))
    data["acoustics"]["rays"] = "many"
    with pytest.raises(StageError, match=r"rir train/living_room#0: parameter acoustics.rays"):
        read_params("rir", data, rir.label)
    data = json.loads(json.dumps(dict(rir.params)))
    data["scene_label_materials"] = {}  # a parameter this version does not have
    with pytest.raises(StageError, match=r"parameter scene_label_materials: Extra inputs"):
        read_params("rir", data, rir.label)
    del data["scene_label_materials"], data["sample_rate_hz"]
    with pytest.raises(StageError, match=r"parameter sample_rate_hz: Field required"):
        read_params("rir", data, rir.label)


def test_portable_models_leave_out_paths_and_ids(tmp_path: Path) -> None:
    plan = plan_of(sonicset_with_tiny_data(tmp_path), tmp_path)
    for job in plan.by_step()["corpus"]:
        assert "root" not in job.params["corpus"]
        assert "root" not in params_data(read_params("corpus", job.params))["corpus"]
    mesh = plan.by_step()["mesh"][0]
    typed = read_params("mesh", mesh.params)
    assert typed.scene.id is None and typed.scene.path is None
    assert "id" not in params_data(typed)["scene"] and "path" not in params_data(typed)["scene"]
    with pytest.raises(StageError, match=r"scene.mesh.path"):
        read_params("mesh", {**mesh.params, "scene": {**mesh.params["scene"], "path": "x.glb"}})


def test_placement_follows_the_trajectorys_smoothing(tmp_path: Path) -> None:
    # trajectory.smooth was in the placement job's params but the stage never passed it on.
    from sonicspec.stages.placement import settings_from

    for smooth in (True, False):
        text = DEMO.replace("rir_spacing_m: 0.25", f"rir_spacing_m: 0.25\n  smooth: {smooth}")
        job = plan_of(text, tmp_path).by_step()["placement"][0]
        assert settings_from(read_params("placement", job.params)).smooth_paths is smooth
