"""The public API (issue 17): a scene from a mesh file or a procedural room, its materials
(and the warning when faces fall back to the library's default), and RIRs without a spec."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from build_cases import ROOT, readme_python

import sonicspec as ss
from sonicspec.acoustics.air import air_energy_coefficient_per_m
from sonicspec.errors import AcousticsError, GeometryError, SonicspecWarning
from sonicspec.geometry.materials import load_library
from sonicspec.geometry.procedural import l_shape

# A 6 x 5 x 3 m box, normals into the air: floor, ceiling and the four walls as triangles.
SIZE = (6.0, 5.0, 3.0)
_V = [(0, 0, 0), (6, 0, 0), (6, 5, 0), (0, 5, 0), (0, 0, 3), (6, 0, 3), (6, 5, 3), (0, 5, 3)]
FACES = {
    "floor": [(0, 1, 2), (0, 2, 3)],
    "ceiling": [(4, 6, 5), (4, 7, 6)],
    "walls": [(0, 4, 5), (0, 5, 1), (1, 5, 6), (1, 6, 2), (2, 6, 7), (2, 7, 3), (3, 7, 4),
              (3, 4, 0)],
}
AREA = {"floor": 30.0, "ceiling": 30.0, "walls": 66.0}  # 126 m² in all
SOURCE, MIC = [1.5, 1.5, 1.5], [4.5, 3.2, 1.6]


def write_obj(path: Path, objects: dict[str, list[str]], keyword: str = "o") -> Path:
    """The box as an obj file: one object (or group) per key, made of those surfaces."""
    lines = [f"v {x} {y} {z}" for x, y, z in _V]
    for name, surfaces in objects.items():
        if name:
            lines.append(f"{keyword} {name}")
        lines += [f"f {a + 1} {b + 1} {c + 1}" for s in surfaces for a, b, c in FACES[s]]
    path.write_text("\n".join(lines) + "\n")
    return path


def eyring_t60(alpha_by_area: list[tuple[float, np.ndarray]], bands) -> np.ndarray:
    volume = math.prod(SIZE)
    area = sum(a for a, _ in alpha_by_area)
    mean = sum(a * alpha for a, alpha in alpha_by_area) / area
    air = air_energy_coefficient_per_m(bands)
    return 24 * math.log(10) * volume / (343.0 * (-area * np.log(1 - mean) + 4 * air * volume))


def test_the_readme_example_runs_as_written(monkeypatch) -> None:
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    exec(compile(readme_python(), "README.md", "exec"), namespace)
    result = namespace["result"]
    assert result.rir.dtype == np.float32 and result.rir.shape[0] == 1
    assert result.sample_rate_hz == 16000 and result.direct_visible
    assert 0.3 < result.t30_s[3] < 1.5 and result.arrivals > 10


def test_two_labelled_objects_get_their_materials_and_the_decay_follows(tmp_path) -> None:
    """An obj with two objects, each mapped to a material: every face gets its object's
    material, and T30 follows (a hard shell rings about 3x longer than an absorbing one, each
    near Eyring with the assigned coefficients)."""
    obj = write_obj(tmp_path / "room.obj", {"floor": ["floor"], "shell": ["walls", "ceiling"]})
    bands = (500.0, 1000.0)
    settings = ss.RirSettings(rays=4000, image_source_order=2, bands_hz=[500, 1000])
    lib = load_library("sonicspec")
    t30 = {}
    for shell in ("concrete_painted", "acoustic_ceiling_tile"):
        scene = ss.Scene.from_file(obj, materials={"floor": "carpet_on_concrete",
                                                   "shell": shell})
        mesh = scene.mesh
        for label, material in (("floor", "carpet_on_concrete"), ("shell", shell)):
            faces = mesh.face_label == mesh.labels.index(label)
            assert {mesh.materials[i] for i in mesh.face_material[faces]} == {material}
        assert scene.material_areas_m2() == pytest.approx({shell: 96.0,
                                                           "carpet_on_concrete": 30.0})
        result = ss.compute_rir(scene, SOURCE, MIC, settings, seed=1)
        t30[shell] = np.array(result.expected["t30_s"])
        floor = np.array(lib.get("carpet_on_concrete").at_bands(bands).absorption)
        rest = np.array(lib.get(shell).at_bands(bands).absorption)
        eyring = eyring_t60([(30.0, floor), (96.0, rest)], bands)
        assert t30[shell] == pytest.approx(eyring, rel=0.3), shell
    assert np.all(t30["concrete_painted"] > 2.5 * t30["acoustic_ceiling_tile"])


def test_a_lone_object_keeps_its_name_and_groups_label_too(tmp_path) -> None:
    """Issue 17's case: trimesh drops the name of an obj's only object, so every face took
    the default material and the map did nothing. The API reads it (and groups)."""
    lone = write_obj(tmp_path / "lone.obj", {"room": ["floor", "walls", "ceiling"]})
    scene = ss.Scene.from_file(lone, materials={"room": "acoustic_ceiling_tile"})
    assert scene.labels == ("room",) and scene.mesh.materials == ("acoustic_ceiling_tile",)
    groups = write_obj(tmp_path / "groups.obj", {"floor": ["floor"], "shell": ["walls",
                                                                               "ceiling"]}, "g")
    scene = ss.Scene.from_file(groups, materials={"floor": "carpet_on_concrete",
                                                  "shell": "gypsum_board"})
    assert sorted(scene.labels) == ["floor", "shell"]
    assert scene.material_areas_m2() == pytest.approx({"gypsum_board": 96.0,
                                                       "carpet_on_concrete": 30.0})


def test_faces_left_to_the_default_material_are_named_with_their_area(tmp_path) -> None:
    obj = write_obj(tmp_path / "room.obj", {"floor": ["floor"], "shell": ["walls", "ceiling"]})
    with pytest.warns(SonicspecWarning) as record:
        scene = ss.Scene.from_file(obj, materials={"floor": "carpet_on_concrete"})
    (w,) = record
    assert str(w.message).startswith("room.obj: expected a material for every face label, got "
                                     "none for 'shell' (76.2 % of the area -> "
                                     "plaster_on_concrete)")
    assert scene.material_areas_m2()["plaster_on_concrete"] == pytest.approx(96.0)
    # A file without any label: all of it, unless a default material is given.
    bare = write_obj(tmp_path / "bare.obj", {"": ["floor", "walls", "ceiling"]})
    with pytest.warns(SonicspecWarning, match=r"bare.obj: .* got none for faces without a "
                      r"label \(100.0 % of the area -> plaster_on_concrete\)"):
        ss.Scene.from_file(bare)
    assert ss.Scene.from_file(bare, default_material="gypsum_board").mesh.materials == (
        "gypsum_board",)


def test_scene_errors_name_the_label_the_material_or_the_file(tmp_path) -> None:
    obj = write_obj(tmp_path / "room.obj", {"floor": ["floor"], "shell": ["walls", "ceiling"]})
    with pytest.raises(GeometryError, match=r"materials: expected labels of room.obj \('floor', "
                       r"'shell'\), got 'flor'; did you mean 'floor'\?"):
        ss.Scene.from_file(obj, materials={"flor": "carpet_on_concrete", "shell": "marble"})
    with pytest.raises(GeometryError, match=r"materials\['floor'\]: expected a material of "
                       r"library 'sonicspec', got 'carpet_on_concret'; did you mean "
                       r"'carpet_on_concrete'"):
        ss.Scene.from_file(obj, materials={"floor": "carpet_on_concret", "shell": "marble"})
    with pytest.raises(GeometryError, match="default_material: expected a material of library "
                       "'sonicset', got 'marble'"):
        ss.Scene.from_file(obj, default_material="marble", library="sonicset")
    bare = write_obj(tmp_path / "bare.obj", {"": ["floor", "walls", "ceiling"]})
    with pytest.raises(GeometryError, match="got 'floor'; the mesh has no labels"):
        ss.Scene.from_file(bare, materials={"floor": "marble"})
    with pytest.raises(GeometryError, match="expected an existing file, got missing path"):
        ss.Scene.from_file(tmp_path / "missing.obj")
    (tmp_path / "broken.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement")
    with pytest.raises(GeometryError, match=r"broken\.ply: expected a readable ply mesh"):
        ss.Scene.from_file(tmp_path / "broken.ply")
    with pytest.raises(GeometryError, match="materials: expected keys among walls, floor, "
                       "ceiling, got 'wall'; did you mean 'walls'"):
        ss.Scene.shoebox([4, 3, 2.5], materials={"wall": "marble"})
    with pytest.raises(GeometryError, match="scene 'shoebox': expected a material of library "
                       "'sonicspec', got 'glass'"):
        ss.Scene.shoebox([4, 3, 2.5], materials={"walls": "glass"})


def test_custom_materials_procedural_rooms_and_repair(tmp_path) -> None:
    room = ss.Scene.shoebox([6, 5, 3], materials={"walls": "panel", "floor": "panel",
                                                  "ceiling": "panel"},
                            custom_materials={"panel": {"absorption": 0.2, "scattering": 0.5}})
    assert room.library.get("panel").absorption == (0.2,) * 7
    ell = ss.Scene.from_mesh(l_shape([8, 6, 3], [3, 2]), name="ell")
    assert ell.mesh.materials == ("plaster_on_brick", "parquet_on_concrete",
                                  "plaster_on_concrete")
    relabelled = ss.Scene.from_mesh(l_shape([8, 6, 3], [3, 2]),
                                    materials={"wall": "gypsum_board", "floor": "marble",
                                               "ceiling": "acoustic_ceiling_tile"})
    assert set(relabelled.mesh.materials) == {"gypsum_board", "marble", "acoustic_ceiling_tile"}
    # Loading welds the box's separate objects (to 8 vertices) without repair (issue 32);
    # weld_distance_m=0 keeps the file's copies, which repair=True welds.
    obj = write_obj(tmp_path / "room.obj", {"floor": ["floor"], "shell": ["walls", "ceiling"]})
    mapping = {"floor": "marble", "shell": "marble"}
    plain = ss.Scene.from_file(obj, materials=mapping)
    raw = ss.Scene.from_file(obj, materials=mapping, weld_distance_m=0)
    fixed = ss.Scene.from_file(obj, materials=mapping, weld_distance_m=0, repair=True)
    assert raw.mesh.vertices.shape[0] > fixed.mesh.vertices.shape[0] == 8
    assert plain.mesh.vertices.shape[0] == 8
    assert plain.weld.merged_vertices == raw.mesh.vertices.shape[0] - 8
    assert raw.weld.merged_vertices == 0
    for scene in (plain, fixed):
        assert scene.mesh.air_volume() == pytest.approx(90.0)


def test_receivers_settings_and_seeds() -> None:
    room = ss.Scene.shoebox([6, 5, 3])
    settings = ss.RirSettings(rays=500, max_rir_length_s=0.3, image_source_order=1)
    a = ss.compute_rir(room, SOURCE, MIC, settings, seed=3)
    b = ss.compute_rir(room, SOURCE, MIC, settings, seed=np.random.default_rng(3))
    c = ss.compute_rir(room, SOURCE, MIC, settings, seed=4)
    assert np.array_equal(a.rir, b.rir) and not np.array_equal(a.rir, c.rir)
    assert a.rir.shape == (1, round(0.3 * 16000))
    facts = a.to_dict()
    assert facts["direct"] == "visible" and facts["channels"] == 1
    assert facts["figures"]["bands_hz"] == [125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0]
    assert a.t30_s.shape == a.edt_s.shape == a.c50_db.shape == (6,)
    assert math.isfinite(a.drr_db) and a.distance_m == pytest.approx(np.linalg.norm(
        np.subtract(SOURCE, MIC)))
    for receiver, channels in (({"kind": "binaural"}, 2),
                               ({"kind": "ambisonics", "order": 2}, 9),
                               ({"kind": "linear_array", "n": 3, "spacing_m": 0.05}, 3)):
        r = ss.compute_rir(room, SOURCE, MIC, settings, receiver=receiver, seed=3)
        assert r.rir.shape[0] == channels
    from sonicspec.spec.microphone import CircularArrayMicSpec

    mic = CircularArrayMicSpec(kind="circular_array", n=5, radius_m=0.04)
    assert ss.compute_rir(room, SOURCE, MIC, settings, receiver=mic).rir.shape[0] == 5
    many = ss.compute_rirs(room, [SOURCE, [2.0, 4.0, 1.2]], MIC, settings, seed=3)
    assert [r.source_m for r in many] == [tuple(SOURCE), (2.0, 4.0, 1.2)]
    # The sample rate sets the bands ("auto") and the length.
    fast = ss.compute_rir(room, SOURCE, MIC, ss.RirSettings(
        rays=500, max_rir_length_s=0.3, image_source_order=1, sample_rate_hz=48000))
    assert fast.rir.shape == (1, 14400) and fast.bands_hz[-1] == 8000.0


def test_compute_errors_name_the_problem() -> None:
    room = ss.Scene.shoebox([6, 5, 3])
    with pytest.raises(AcousticsError, match=r"source: \[7.0, 1.0, 1.0\] is outside scene "
                       r"'shoebox' \(bounds \[0.0, 0.0, 0.0\] .. \[6.0, 5.0, 3.0\]\)"):
        ss.compute_rir(room, [7.0, 1.0, 1.0], MIC)
    with pytest.raises(AcousticsError, match=r"sources\[1\]: \[1.0, 1.0, -1.0\] is outside"):
        ss.compute_rirs(room, [SOURCE, [1.0, 1.0, -1.0]], MIC)
    with pytest.raises(ValueError, match="rays"):
        ss.RirSettings(rays=5)
    with pytest.raises(ValueError, match="tag 'omni'"):
        ss.compute_rir(room, SOURCE, MIC, receiver={"kind": "omni"})
    with pytest.raises(AcousticsError, match=r"microphone\.hrtf\.path: SOFA file nowhere\.sofa "
                       r"does not exist"):
        ss.compute_rir(room, SOURCE, MIC, receiver={"kind": "binaural", "hrtf": {
            "kind": "sofa", "path": "nowhere.sofa"}})


def test_the_api_loads_on_first_use() -> None:
    code = ("import sys, sonicspec; assert 'sonicspec.api' not in sys.modules; "
            "sonicspec.Scene; assert 'sonicspec.api' in sys.modules; print(sorted(dir(sonicspec)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert "compute_rir" in out
    with pytest.raises(AttributeError, match="no attribute 'compute_rri'"):
        ss.compute_rri  # noqa: B018


STAGE_SPEC = """\
sonicspec: 1
name: apistage
seed: 7
scenes:
  - kind: mesh
    id: room
    path: room.obj
    label_materials: {shell: panel}
microphone: MIC
trajectory: {kind: shortest_path, rir_spacing_m: 0.5}
acoustics: {rays: 500, image_source_order: 1, max_rir_length_s: 0.3}
materials:
  custom:
    panel: {absorption: 0.15, scattering: 0.4}
mixture: {speakers: 1, tasks: []}
corpora: {speech: {kind: generated}}
splits: {train: {groups: 1, scenes: [room]}}
"""


@pytest.mark.parametrize("mic", ["{kind: mono}", "{kind: ambisonics, order: 1}"])
def test_compute_rirs_equals_the_rir_stage_for_the_same_settings_and_seed(tmp_path, mic):
    """The rir stage and the API call the same engine: the same scene, settings, receiver
    and generator give the same bytes for every point of a group's trajectories; and
    ``sonicspec rir SPEC`` is compute_rir with its own seed."""
    from sonicspec.artifacts import decode, read_mesh
    from sonicspec.hashing import rng_for
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages import run_job
    from sonicspec.stages.rir import _source_points, rir_from_spec
    from sonicspec.store import ArtifactStore

    write_obj(tmp_path / "room.obj", {"floor": ["floor"], "shell": ["walls", "ceiling"]})
    (tmp_path / "spec.yaml").write_text(STAGE_SPEC.replace("MIC", mic))
    loaded = load_spec(tmp_path / "spec.yaml")
    spec = loaded.spec
    plan = compile_spec(loaded)
    for job in plan.jobs:
        if job.step in ("mesh", "navigation", "placement", "rir"):
            run_job(plan, job.key)
    store = ArtifactStore(plan.store_dir)
    (rir_job,) = [j for j in plan.jobs if j.step == "rir"]
    mesh_job, placement_job = (next(j for j in plan.jobs if j.key == k) for k in rir_job.inputs)
    mesh_art = store.read("mesh", mesh_job.key)
    rirs = store.read("rir", rir_job.key)
    scene = ss.Scene.from_mesh(read_mesh(mesh_art.arrays, mesh_art.data), name="room",
                               custom_materials=spec.materials.model_dump()["custom"])
    settings = ss.RirSettings(**spec.acoustics.model_dump(), sample_rate_hz=spec.sample_rate_hz,
                              speed_of_sound_m_s=spec.speed_of_sound_m_s)
    (placement,) = decode("placement", store.read_data("placement", placement_job.key)).groups
    sources = _source_points(placement)
    results = ss.compute_rirs(scene, np.concatenate([p for _, p in sources]),
                              placement.mic_m, settings, receiver=spec.microphone,
                              seed=rng_for(spec.seed, "rir", rir_job.key, placement.group))
    start = 0
    for s, (_, points) in enumerate(sources):
        stored = rirs.arrays[f"g0_s{s}"]
        assert len(points) >= 2 and stored.shape[:2] == (len(points), results[0].rir.shape[0])
        for i in range(len(points)):
            rir = results[start + i].rir
            assert np.array_equal(stored[i, :, :rir.shape[-1]], rir)
        start += len(points)
    # sonicspec rir SPEC: the same engine with the CLI's seed.
    report = rir_from_spec(loaded, "room", SOURCE, MIC)
    rir, facts = report.result.rir, report.to_dict()
    same = ss.compute_rir(scene, SOURCE, MIC, settings, receiver=spec.microphone,
                          seed=rng_for(spec.seed, "rir-cli", mesh_job.key, repr(SOURCE),
                                       repr(MIC)))
    assert np.array_equal(rir, same.rir)
    assert facts["figures"] == same.to_dict()["figures"]


def test_the_mesh_step_logs_the_fallback_and_the_build_summary_lists_it(tmp_path) -> None:
    """A scan whose labels the library does not know: the mesh job's log has a WARNING line
    naming them (as `sonicspec job` prints it), which the build summary collects."""
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages.workflow import job_warnings

    write_obj(tmp_path / "room.obj", {"floor": ["floor"], "shell": ["walls", "ceiling"]})
    (tmp_path / "spec.yaml").write_text(STAGE_SPEC.replace("MIC", "{kind: mono}").replace(
        "    label_materials: {shell: panel}\n", ""))
    plan = compile_spec(load_spec(tmp_path / "spec.yaml"))
    plan_file = plan.write(tmp_path / "plan.json")
    (mesh_job,) = [j for j in plan.jobs if j.step == "mesh"]
    log = Path(plan.store_dir) / "logs" / "mesh" / mesh_job.key[:2] / f"{mesh_job.key}.log"
    log.parent.mkdir(parents=True)
    with log.open("w") as stderr:
        subprocess.run([sys.executable, "-m", "sonicspec.cli", "job", "--plan", str(plan_file),
                        mesh_job.key], stderr=stderr, check=True, cwd=tmp_path)
    (line,) = job_warnings(plan, {mesh_job.key})
    assert line.startswith("mesh room: ")
    assert " WARNING scene 'room': expected a material for every face label" in line
    assert "got none for 'shell' (76.2 % of the area -> plaster_on_concrete)" in line


def test_a_spec_scene_from_an_obj_with_one_object_gets_its_materials(tmp_path) -> None:
    """Issue 17: an obj whose single object lost its name (trimesh drops a lone object's
    name) made every face the default material in a build, silently. The plan now reads obj
    scenes as the API does; only obj scenes' mesh keys carry the flag."""
    from sonicspec.artifacts.scenes import build_scene_mesh
    from sonicspec.plan.compile import compile_spec
    from sonicspec.plan.params import read_params
    from sonicspec.spec import validate_text

    write_obj(tmp_path / "lone.obj", {"room": ["floor", "walls", "ceiling"]})
    text = (ROOT / "specs" / "demo.yaml").read_text().replace(
        "  - kind: shoebox\n    id: living_room",
        "  - kind: mesh\n    id: scan\n    path: lone.obj\n    label_materials: {room: "
        "concrete_painted}\n    repair: {leak_test_rays: 0}\n  - kind: shoebox\n    id: "
        "living_room", 1)
    loaded, problems = validate_text(text, str(tmp_path / "s.yaml"), tmp_path)
    assert loaded is not None, [p.format("s.yaml") for p in problems]
    plan = compile_spec(loaded, cache=False)
    meshes = {j.params["scene_id"]: j for j in plan.by_step()["mesh"]}
    assert meshes["scan"].params["obj_labels"] is True
    assert "obj_labels" not in meshes["living_room"].params  # procedural keys unchanged
    with warnings.catch_warnings():
        warnings.simplefilter("error", SonicspecWarning)  # no fallback warning
        mesh, _ = build_scene_mesh(read_params("mesh", meshes["scan"].params),
                                   dict(meshes["scan"].paths), np.random.default_rng(0))
    assert set(np.asarray(mesh.materials)[np.unique(mesh.face_material)]) == {
        "concrete_painted"}


def test_scene_from_spec_is_the_mesh_a_build_makes(tmp_path: Path) -> None:
    # The stages and the API build scenes with the same code: the demo's living room (a
    # shoebox with a box and a cylinder) from its spec model equals the scene `scene inspect`
    # builds as the mesh stage does.
    from sonicspec.spec import load_spec
    from sonicspec.stages.inspect import build_scene

    loaded = load_spec(ROOT / "specs" / "demo.yaml")
    mesh, *_ = build_scene(loaded, "living_room")
    scene = ss.Scene.from_spec(loaded.spec.scenes[0], loaded.spec.materials)
    assert scene.name == "living_room" and scene.mesh.materials == mesh.materials
    assert np.array_equal(scene.mesh.vertices, mesh.vertices)
    assert np.array_equal(scene.mesh.faces, mesh.faces)
    assert np.array_equal(scene.mesh.face_material, mesh.face_material)
    # A mesh scene: the obj file with the spec's label map, as the mesh stage reads it.
    from sonicspec.spec.scene import MeshSceneSpec

    shutil.copy(ROOT / "specs" / "meshes" / "room.obj", tmp_path / "room.obj")
    spec = MeshSceneSpec(kind="mesh", id="room", path="room.obj",
                         label_materials={"floor": "carpet_on_concrete"})
    from sonicspec.errors import GeometryError, SonicspecWarning

    with pytest.warns(SonicspecWarning, match="got none for 'walls'"):  # the fallback shows
        scene = ss.Scene.from_spec(spec, base_dir=tmp_path)
    assert "carpet_on_concrete" in scene.material_areas_m2()

    with pytest.raises(GeometryError, match="is a glob"):
        ss.Scene.from_spec(spec.model_copy(update={"path": "*.obj"}), base_dir=tmp_path)
def test_diffraction_adds_nothing_to_a_room_without_convex_edges() -> None:
    # A shoebox's corners are all concave: the RIR with diffraction on is the same, byte for
    # byte (tests/test_acoustics_diffraction_engine.py has the rooms where it is not).
    room = ss.Scene.shoebox([6, 5, 3])
    settings = {"rays": 500, "max_rir_length_s": 0.3, "image_source_order": 1}
    off = ss.compute_rir(room, SOURCE, MIC, ss.RirSettings(**settings), seed=3)
    on = ss.compute_rir(room, SOURCE, MIC, ss.RirSettings(diffraction=True, **settings), seed=3)
    np.testing.assert_array_equal(on.rir, off.rir)
