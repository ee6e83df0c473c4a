"""The compiler: deterministic keys, and a change reruns exactly what depends on it."""

from __future__ import annotations

from pathlib import Path

import pytest

from sonicspec.errors import CompileError
from sonicspec.plan.compile import compile_spec, plan_changes
from sonicspec.plan.model import Plan
from sonicspec.spec import validate_text

ROOT = Path(__file__).resolve().parents[1]
DEMO = (ROOT / "specs" / "demo.yaml").read_text()


def plan_of(text: str, tmp_path: Path) -> Plan:
    loaded, problems = validate_text(text, str(tmp_path / "spec.yaml"), tmp_path)
    assert loaded is not None, [p.format("spec.yaml") for p in problems]
    return compile_spec(loaded)


def steps_changed(a: Plan, b: Plan) -> dict[str, int]:
    return {step: c["added"] for step, c in plan_changes(a, b).items() if c["added"]}


def test_plan_is_deterministic_and_ordered(tmp_path: Path) -> None:
    a, b = plan_of(DEMO, tmp_path), plan_of(DEMO, tmp_path)
    assert [j.key for j in a] == [j.key for j in b]
    assert a.digest == b.digest
    seen = set()
    for job in a:
        assert set(job.inputs) <= seen
        seen.add(job.key)
    counts = {step: len(jobs) for step, jobs in a.by_step().items()}
    # demo: 3 corpora, 3 scenes, train 4 groups in shards of 2, val 1, test 1 -> 4 shards.
    assert counts == {"corpus": 3, "mesh": 3, "navigation": 3, "placement": 4, "arrange": 4,
                      "rir": 4, "render": 4, "mix": 4, "export": 4, "dataset": 1}


def test_plan_round_trips_through_json(tmp_path: Path) -> None:
    plan = plan_of(DEMO, tmp_path)
    path = plan.write(tmp_path / "plan.json")
    assert [j.key for j in Plan.read(path)] == [j.key for j in plan]


def test_edited_plan_file_is_refused(tmp_path: Path) -> None:
    plan = plan_of(DEMO, tmp_path)
    path = plan.write(tmp_path / "plan.json")
    path.write_text(path.read_text().replace('"rays": 4000', '"rays": 4001', 1))
    with pytest.raises(CompileError, match="parameters hash to"):
        Plan.read(path)


def test_ray_count_reruns_tracing_and_downstream_not_meshes(tmp_path: Path) -> None:
    a = plan_of(DEMO, tmp_path)
    b = plan_of(DEMO.replace("rays: 4000", "rays: 5000"), tmp_path)
    assert steps_changed(a, b) == {"rir": 4, "render": 4, "mix": 4, "export": 4, "dataset": 1}


def test_one_split_change_reruns_only_its_groups(tmp_path: Path) -> None:
    a = plan_of(DEMO, tmp_path)
    b = plan_of(DEMO.replace("test: {groups: 1,", "test: {groups: 2,"), tmp_path)
    changed = steps_changed(a, b)
    # Only the test split's one shard (now two groups) and the dataset summary change.
    assert changed == {"placement": 1, "arrange": 1, "rir": 1, "render": 1, "mix": 1,
                       "export": 1, "dataset": 1}
    new_test = [j for j in b.by_step()["placement"] if j.params["split"] == "test"]
    assert new_test[0].params["groups"] == ["test/000000", "test/000001"]


def test_material_change_keeps_placement(tmp_path: Path) -> None:
    a = plan_of(DEMO, tmp_path)
    b = plan_of(DEMO.replace("ceiling: acoustic_ceiling_tile", "ceiling: gypsum_board"), tmp_path)
    changed = steps_changed(a, b)
    # The office mesh carries its materials; navigation depends on the mesh, so the val
    # shard's placement changes too, but no other split's work does.
    assert changed["mesh"] == 1 and "corpus" not in changed and "arrange" not in changed
    assert changed["rir"] == 1


def test_groups_per_shard_regroups_without_changing_group_ids(tmp_path: Path) -> None:
    a = plan_of(DEMO, tmp_path)
    b = plan_of(DEMO.replace("groups_per_shard: 2", "groups_per_shard: 3"), tmp_path)
    groups_a = sorted(g for j in a.by_step()["placement"] for g in j.params["groups"])
    groups_b = sorted(g for j in b.by_step()["placement"] for g in j.params["groups"])
    assert groups_a == groups_b and len(groups_a) == 6


def test_mesh_globs_expand_and_split_by_count(tmp_path: Path) -> None:
    from sonicspec.testing.meshes import write_matterport_scene

    for name in ("aaa", "bbb", "ccc", "ddd"):
        write_matterport_scene(tmp_path / "mp3d" / name, name)
    text = (ROOT / "specs" / "sonicset.yaml").read_text()
    text = text.replace("data/mp3d/*/*.glb", "mp3d/*/*.glb")
    for count, new in ((62, 2), (19, 1), (9, 1)):
        text = text.replace(f"scene_count: {count}}}", f"scene_count: {new}}}")
    for old, new in (("data/LibriSpeech", "ls"), ("data/FSD50K", "fsd"), ("data/fma", "fma")):
        text = text.replace(f"root: {old}", f"root: {new}")
    for d in ("ls", "fsd", "fma"):
        (tmp_path / d).mkdir()
    plan = plan_of(text, tmp_path)
    scenes = {j.params["scene_id"] for j in plan.by_step()["placement"]}
    assert scenes <= {"mp3d/aaa", "mp3d/bbb", "mp3d/ccc", "mp3d/ddd"} and len(scenes) == 4
    by_split = {}
    for j in plan.by_step()["placement"]:
        by_split.setdefault(j.params["split"], set()).add(j.params["scene_id"])
    assert sum(len(v) for v in by_split.values()) == 4  # disjoint
    # Too many asked for: a clear error naming the split.
    with pytest.raises(CompileError, match=r"splits.test.scene_count: asks for 3"):
        plan_of(text.replace("scene_count: 1}\n  test", "scene_count: 1}\n  test")
                .replace('test: {groups: 1000, scenes: ["mp3d/*"], scene_count: 1}',
                         'test: {groups: 1000, scenes: ["mp3d/*"], scene_count: 3}'), tmp_path)


def test_missing_corpus_folder_and_meshes_are_compile_errors(tmp_path: Path) -> None:
    text = (ROOT / "specs" / "sonicset.yaml").read_text()
    with pytest.raises(CompileError, match=r"corpora.speech.root: corpus folder .* does not"):
        plan_of(text, tmp_path)
    for d in ("data/LibriSpeech", "data/FSD50K", "data/fma"):
        (tmp_path / d).mkdir(parents=True)
    with pytest.raises(CompileError, match=r"scenes\[0\].path: glob 'data/mp3d/\*/\*.glb' matches"):
        plan_of(text, tmp_path)


def test_sofa_hrtf_enters_the_rir_key_by_content(tmp_path: Path) -> None:
    from sonicspec.testing.hrtf import write_tiny_sofa

    text = DEMO.replace("microphone:\n  kind: mono",
                        "microphone:\n  kind: binaural\n  hrtf: {kind: sofa, path: h.sofa}")
    with pytest.raises(CompileError, match=r"microphone.hrtf.path: SOFA file .*h.sofa"):
        plan_of(text, tmp_path)
    write_tiny_sofa(str(tmp_path / "h.sofa"), 48000.0)
    a = plan_of(text, tmp_path)
    rir = a.by_step()["rir"][0]
    assert rir.paths["hrtf"] == str(tmp_path / "h.sofa") and len(rir.params["files"]["hrtf"]) == 64
    write_tiny_sofa(str(tmp_path / "h.sofa"), 44100.0)  # other content, same path
    assert steps_changed(a, plan_of(text, tmp_path)) == {
        "rir": 4, "render": 4, "mix": 4, "export": 4, "dataset": 1}
