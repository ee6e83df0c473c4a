"""The compiler: deterministic keys, and a change reruns exactly what depends on it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonicspec.errors import CompileError
from sonicspec.hashing import canonical_json, content_key, normalised_params_and_key, shared
from sonicspec.plan.compile import compile_spec, plan_changes
from sonicspec.plan.model import STEP_BY_NAME, Plan
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


def test_a_job_reads_only_its_excerpt_of_the_plan(tmp_path: Path) -> None:
    plan = plan_of(DEMO, tmp_path)
    path = plan.write(tmp_path / "plan.json")
    jobs = plan.by_key()
    for job in plan.jobs:
        part = Plan.read_job(path, job.key)
        assert part.excerpt and (part.name, part.seed, part.store_dir) == (
            plan.name, plan.seed, plan.store_dir)
        assert [j.key for j in part.jobs] == [*dict.fromkeys(job.inputs), job.key]
        assert all(j.params == jobs[j.key].params and j.paths == jobs[j.key].paths
                   for j in part.jobs)
    # Another layout (an older plan file, indented) is read whole, with the same result.
    old = tmp_path / "old.json"
    old.write_text(json.dumps(plan.to_dict(), indent=1, sort_keys=True))
    export = plan.by_step()["export"][0]
    assert [j.key for j in Plan.read_job(old, export.key).jobs] == [
        j.key for j in Plan.read_job(path, export.key).jobs]
    with pytest.raises(CompileError, match="no job with key 000000000000"):
        Plan.read_job(path, "0" * 64)
    path.write_text(path.read_text().replace('"rays": 4000', '"rays": 4001', 1))
    rir = plan.by_step()["rir"][0]
    with pytest.raises(CompileError, match="parameters hash to"):
        Plan.read_job(path, rir.key)


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


def sonicset_with_tiny_data(tmp_path: Path) -> str:
    """The sonicset spec over four tiny Matterport-style scans, LibriSpeech speaker folders
    (3 / 3 / 3) and empty noise and music folders."""
    from sonicspec.testing.meshes import write_matterport_scene
    from sonicspec.testing.sonicset import write_speaker_folders

    for name in ("aaa", "bbb", "ccc", "ddd"):
        write_matterport_scene(tmp_path / "mp3d" / name, name)
    write_speaker_folders(tmp_path / "ls", {"train-clean-360": 3, "dev-clean": 3,
                                            "test-clean": 3}, utterances=1, utterance_s=0.5)
    text = (ROOT / "specs" / "sonicset.yaml").read_text()
    text = text.replace("data/mp3d/*/*.glb", "mp3d/*/*.glb")
    for count, new in ((62, 2), (19, 1), (9, 1)):
        text = text.replace(f"scene_count: {count}}}", f"scene_count: {new}}}")
    for old, new in (("data/LibriSpeech", "ls"), ("data/FSD50K", "fsd"), ("data/fma", "fma")):
        text = text.replace(f"root: {old}", f"root: {new}")
    for d in ("ls", "fsd", "fma"):
        (tmp_path / d).mkdir(exist_ok=True)
    return text


def test_mesh_globs_expand_and_split_by_count(tmp_path: Path) -> None:
    text = sonicset_with_tiny_data(tmp_path)
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
                .replace('test: {groups: 247, scenes: ["mp3d/*"], scene_count: 1}',
                         'test: {groups: 247, scenes: ["mp3d/*"], scene_count: 3}'), tmp_path)


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


def test_fast_keys_are_the_reference_keys(tmp_path: Path) -> None:
    # Jobs key their params by splicing the canonical JSON of shared sub-dicts (issue 16: a
    # plan of 10^6 groups). The keys must stay the bytes the reference path hashes, or every
    # user's dataset would rebuild: re-key every job of varied plans the slow way.
    varied = (DEMO.replace("Embedded demo", "Démo «intégrée» 中文 \\u2028")
              .replace("groups_per_shard: 2", "groups_per_shard: 3")
              .replace("train: {groups: 4,", "train: {groups: 11,")
              .replace("rays: 4000", "rays: 4000\n  energy_threshold_db: 60.000000000000014\n"
                       "  receiver_radius_m: 1.0e-3"))
    plans = [plan_of(varied, tmp_path), plan_of(sonicset_with_tiny_data(tmp_path), tmp_path)]
    assert plans[0].jobs[-1].params["spec"]["description"].startswith("Démo «intégrée» 中文")
    for plan in plans:
        for job in plan:
            version = STEP_BY_NAME[job.step].version
            assert job.key == content_key(job.step, version, job.params, job.inputs), job.label
            reference = json.loads(canonical_json(job.params))
            assert job.params == reference and list(job.params) == list(reference)
        again = Plan.from_dict(json.loads(json.dumps(plan.to_dict())))  # plain dicts, no sharing
        assert [j.key for j in again] == [j.key for j in plan]


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=8),
    lambda inner: st.one_of(st.lists(inner, min_size=1, max_size=4), st.tuples(inner, inner),
                            st.dictionaries(st.text(max_size=6), inner, min_size=1,
                                            max_size=4)),
    max_leaves=20,
)


@settings(max_examples=300, deadline=None)
@given(params=st.dictionaries(st.text(max_size=6), _json_values, max_size=5),
       sharable=_json_values, inputs=st.lists(st.text(max_size=4), max_size=3))
def test_fast_path_matches_canonical_json(params: dict, sharable: object, inputs: list) -> None:
    if isinstance(sharable, (dict, list, tuple)):
        params = {**params, "shared": shared(sharable)}
    plain, key = normalised_params_and_key("rir", 3, params, inputs)
    assert key == content_key("rir", 3, params, inputs)
    assert json.dumps(plain) == json.dumps(json.loads(canonical_json(params)))


def test_fast_path_falls_back_for_other_types() -> None:
    params = {"n": np.int64(3), "x": np.float32(0.5)}
    plain, key = normalised_params_and_key("rir", 1, params)
    assert plain == {"n": 3, "x": 0.5} and key == content_key("rir", 1, params)
    with pytest.raises(CompileError, match=r"params.bad: cannot hash a non-finite number"):
        normalised_params_and_key("rir", 1, {"bad": float("nan")})
    with pytest.raises(CompileError, match=r"params: keys must be text to hash, got 1"):
        normalised_params_and_key("rir", 1, {1: "x"})
