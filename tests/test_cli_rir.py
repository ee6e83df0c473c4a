"""`sonicspec rir`: one RIR end to end (spec -> mesh -> tracer -> synthesis -> ISO 3382)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.acoustics.air import air_energy_coefficient_per_m
from sonicspec.acoustics.theory import kuttruff_t60, shoebox_free_paths
from sonicspec.cli import main
from sonicspec.testing.hrtf import write_tiny_sofa

SPEC = """\
sonicspec: 1
name: rirtest
seed: 5
scenes:
  - kind: shoebox
    id: box
    size_m: [10, 7, 3]
    materials: {walls: panel, floor: panel, ceiling: panel}
  - kind: l_shape
    id: ell
    size_m: [8, 8, 3]
    cutout_m: [5, 5]
materials:
  custom:
    panel: {absorption: 0.2, scattering: 0.5}
acoustics: {rays: 4000, image_source_order: 2, max_rir_length_s: 1.2}
mixture: {speakers: 1, tasks: []}
corpora: {speech: {kind: generated}}
splits: {train: {groups: 1, scenes: [box]}, test: {groups: 1, scenes: [ell]}}
"""


def run(capsys, *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture
def spec(tmp_path: Path) -> Path:
    path = tmp_path / "rir.yaml"
    path.write_text(SPEC)
    return path


def test_shoebox_rir_matches_eyring_and_free_field(spec: Path, tmp_path: Path, capsys) -> None:
    wav = tmp_path / "rir.wav"
    code, out, _ = run(capsys, "rir", str(spec), "--scene", "box", "--source", "2", "2", "1.5",
                       "--mic", "7", "4.5", "1.6", "-o", str(wav), "--plot",
                       str(tmp_path / "rir.png"), "--json")
    assert code == 0
    facts = json.loads(out)
    bands = facts["figures"]["bands_hz"]
    m = air_energy_coefficient_per_m(bands)
    # What the tracer converges to here (Eyring with Kuttruff's path-length correction, +4.6 %;
    # the tracer test holds it to 2 %); one RIR's low bands add a few % of synthesis noise.
    paths = shoebox_free_paths((10.0, 7.0, 3.0), n_paths=200_000)
    expected = kuttruff_t60(210.0, 2 * (70 + 30 + 21), 0.2, paths.var() / paths.mean() ** 2, m)
    t30 = np.array(facts["figures"]["t30_s"])
    assert t30 == pytest.approx(expected, rel=0.10)
    # The same fits on the energy the RIR was synthesised to have: no noise draw, so close.
    assert np.array(facts["expected"]["t30_s"]) == pytest.approx(expected, rel=0.03)
    # The file holds the RIR: float32 WAV at the spec rate, the direct sound at r/c.
    rir, rate = sf.read(wav, dtype="float32")
    assert rate == 16000 and rir.dtype == np.float32
    r = facts["distance_m"]
    onset = int(np.argmax(np.abs(rir) > 0.5 / (4 * math.pi * r)))
    assert abs(onset - r / 343 * 16000) <= 3
    assert (tmp_path / "rir.png").stat().st_size > 10_000


def test_no_line_of_sight_means_no_direct_sound(spec: Path, capsys) -> None:
    # Source in the lower-right arm, mic in the upper-left arm of the L: the corner occludes.
    code, out, _ = run(capsys, "rir", str(spec), "--scene", "ell", "--source", "7", "1.5", "1.5",
                       "--mic", "1.5", "7", "1.5")
    assert code == 0 and "direct path through walls" in out
    assert "without the noise draw" in out
    # The L-shaped room's walls are single quads: nothing to merge, traced as given.
    assert re.search(r"mesh: (\d+) triangles, traced as \1 ", out)
    opaque = spec.with_name("opaque.yaml")
    opaque.write_text(SPEC.replace("max_rir_length_s: 1.2}", "max_rir_length_s: 1.2, "
                                   "transmission: false}"))
    code, out, _ = run(capsys, "rir", str(opaque), "--scene", "ell", "--source", "7", "1.5",
                       "1.5", "--mic", "1.5", "7", "1.5", "--json")
    facts = json.loads(out)
    # the L's inner corner is a convex edge: the hidden source is heard round it
    assert facts["direct"] == "diffracted" and facts["diffracted_paths"] >= 1
    no_edges = spec.with_name("no_edges.yaml")
    no_edges.write_text(SPEC.replace("max_rir_length_s: 1.2}", "max_rir_length_s: 1.2, "
                                     "transmission: false, diffraction: false}"))
    code, out, _ = run(capsys, "rir", str(no_edges), "--scene", "ell", "--source", "7", "1.5",
                       "1.5", "--mic", "1.5", "7", "1.5", "--json")
    assert json.loads(out)["direct"] == "blocked"


def test_positions_outside_and_unsupported_receivers(spec: Path, tmp_path: Path, capsys) -> None:
    code, _, err = run(capsys, "rir", str(spec), "--scene", "box", "--source", "20", "2", "1",
                       "--mic", "5", "5", "1")
    assert code == 1 and "--source: [20.0, 2.0, 1.0] is outside scene 'box'" in err
    # Arrays and ambisonics render one channel per capsule / ACN channel.
    for mic, channels in (("{kind: circular_array, n: 6, radius_m: 0.05}", 6),
                          ("{kind: ambisonics, order: 1}", 4),
                          ("{kind: binaural}", 2)):
        other = tmp_path / "m.yaml"
        other.write_text(SPEC.replace("acoustics:", f"microphone: {mic}\nacoustics:"))
        wav = tmp_path / "m.wav"
        code, out, _ = run(capsys, "rir", str(other), "--scene", "box", "--source", "2", "2",
                           "1.5", "--mic", "7", "4.5", "1.6", "-o", str(wav), "--json")
        facts = json.loads(out)
        assert code == 0 and facts["channels"] == channels
        assert sf.info(str(wav)).channels == channels
        # Samples per channel, not in all channels together (a bug: 4 x 12,803 read 51,212).
        assert facts["samples"] == sf.info(str(wav)).frames
        code, out, _ = run(capsys, "rir", str(other), "--scene", "box", "--source", "2", "2",
                           "1.5", "--mic", "7", "4.5", "1.6")
        assert f"{channels} channels x {facts['samples']} samples at" in out
    # A SOFA HRTF: a missing file is named; a real one renders two ears through its HRIRs.
    binaural = tmp_path / "b.yaml"
    binaural.write_text(SPEC.replace(
        "acoustics:", "microphone: {kind: binaural, hrtf: {kind: sofa, path: h.sofa}}\nacoustics:"))
    code, _, err = run(capsys, "rir", str(binaural), "--scene", "box", "--source", "2", "2", "1",
                       "--mic", "5", "5", "1")
    assert code == 1 and "microphone.hrtf.path: SOFA file" in err and "h.sofa" in err
    write_tiny_sofa(str(tmp_path / "h.sofa"), 48000.0)
    wav = tmp_path / "b.wav"
    code, out, _ = run(capsys, "rir", str(binaural), "--scene", "box", "--source", "2", "2",
                       "1.5", "--mic", "7", "4.5", "1.6", "-o", str(wav), "--json")
    assert code == 0 and json.loads(out)["channels"] == 2
    ears, _ = sf.read(wav, dtype="float64")
    # The tiny set's right ear is the left one at half gain, a few samples later: compare the
    # energy of the direct sound (the first reflection comes 37 samples after it).
    direct = round(json.loads(out)["distance_m"] / 343 * 16000)
    energy = np.sum(ears[direct - 20: direct + 20] ** 2, axis=0)
    assert energy[1] / energy[0] == pytest.approx(0.25, rel=0.15)


def write_room_obj(path: Path, objects: dict[str, list[str]]) -> Path:
    """A 10 x 7 x 3 m box (normals into the air) as an obj file, one object per key."""
    v = [(0, 0, 0), (10, 0, 0), (10, 7, 0), (0, 7, 0), (0, 0, 3), (10, 0, 3), (10, 7, 3),
         (0, 7, 3)]
    faces = {"floor": [(0, 1, 2), (0, 2, 3)], "ceiling": [(4, 6, 5), (4, 7, 6)],
             "walls": [(0, 4, 5), (0, 5, 1), (1, 5, 6), (1, 6, 2), (2, 6, 7), (2, 7, 3),
                       (3, 7, 4), (3, 4, 0)]}
    lines = [f"v {x} {y} {z}" for x, y, z in v]
    for name, surfaces in objects.items():
        lines.append(f"o {name}")
        lines += [f"f {a + 1} {b + 1} {c + 1}" for s in surfaces for a, b, c in faces[s]]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_mesh_file_without_a_spec(tmp_path: Path, capsys) -> None:
    """`sonicspec rir --mesh`: materials by label, the spec's acoustics defaults, a WAV."""
    obj = write_room_obj(tmp_path / "room.obj", {"floor": ["floor"],
                                                 "shell": ["walls", "ceiling"]})
    wav = tmp_path / "rir.wav"
    args = ["rir", "--mesh", str(obj), "--material", "floor=carpet_on_concrete", "--material",
            "shell=gypsum_board", "--source", "2", "2", "1.5", "--mic", "7", "4.5", "1.6"]
    code, out, err = run(capsys, *args, "--rays", "2000", "--seed", "3", "-o", str(wav),
                         "--json")
    assert code == 0 and err == ""
    facts = json.loads(out)
    assert facts["scene_id"] == "room.obj" and facts["warnings"] == []
    assert facts["materials_m2"] == {"gypsum_board": pytest.approx(172.0),
                                     "carpet_on_concrete": pytest.approx(70.0)}
    assert facts["direct"] == "visible" and facts["channels"] == 1
    rir, rate = sf.read(wav, dtype="float32")
    assert rate == 16000 and len(rir) == facts["samples"]
    # max_rir_length_s: auto: the RIR ends where every band's decay is 60 dB down (plus the
    # band filters' ringing), no band cut by the cap.
    tail = facts["tail"]
    assert tail["rule"] == "auto" and tail["limit_field"] == "max_rir_cap_s"
    assert None not in tail["decay_60db_s"] and set(tail["level_at_limit_db"]) == {None}
    assert tail["decay_end_s"] == max(tail["decay_60db_s"])
    assert 0 < facts["samples"] / 16000 - tail["decay_end_s"] < 0.1
    # The same seed, the same bytes; the text report names the materials.
    code, out, _ = run(capsys, *args, "--rays", "2000", "--seed", "3", "-o",
                       str(tmp_path / "again.wav"))
    assert np.array_equal(sf.read(tmp_path / "again.wav", dtype="float32")[0], rir)
    assert "RIR in room.obj:" in out
    assert (f"length: {len(rir) / 16000:.3f} s (max_rir_length_s: auto, every band's decay "
            "60 dB down, at most 10 s)") in out
    assert "materials: gypsum_board 172.0 m² (71 %), carpet_on_concrete 70.0 m² (29 %)" in out


def test_faces_left_to_the_default_material_are_printed(tmp_path: Path, capsys) -> None:
    obj = write_room_obj(tmp_path / "room.obj", {"floor": ["floor"],
                                                 "shell": ["walls", "ceiling"]})
    code, out, err = run(capsys, "rir", "--mesh", str(obj), "--material",
                         "floor=carpet_on_concrete", "--rays", "500", "--source", "2", "2",
                         "1.5", "--mic", "7", "4.5", "1.6", "--json")
    assert code == 0
    expected = ("room.obj: expected a material for every face label, got none for 'shell' "
                "(71.1 % of the area -> plaster_on_concrete)")
    assert err.startswith(f"sonicspec: warning: {expected}")
    assert json.loads(out)["warnings"][0].startswith(expected)
    # A spec's mesh scene says it too (its warnings used to reach only --json).
    (tmp_path / "spec.yaml").write_text(SPEC.replace(
        "scenes:\n", "scenes:\n  - {kind: mesh, id: scan, path: room.obj}\n").replace(
        "scenes: [ell]}", "scenes: [ell, scan]}"))
    code, out, err = run(capsys, "rir", str(tmp_path / "spec.yaml"), "--scene", "scan",
                         "--source", "2", "2", "1.5", "--mic", "7", "4.5", "1.6")
    assert code == 0 and "RIR in scan:" in out
    assert "sonicspec: warning: scene 'scan': expected a material for every face label, got " \
           "none for 'shell' (71.1 % of the area -> plaster_on_concrete)" in err


def test_mesh_errors_name_the_file_the_label_or_the_material(spec: Path, tmp_path: Path,
                                                             capsys) -> None:
    obj = write_room_obj(tmp_path / "room.obj", {"floor": ["floor"],
                                                 "shell": ["walls", "ceiling"]})
    where = ["--source", "2", "2", "1.5", "--mic", "7", "4.5", "1.6"]
    for extra, message in (
        (["--mesh", str(tmp_path / "nope.obj")], "load_mesh: expected an existing file, got "
         "missing path"),
        (["--mesh", str(obj), "--material", "flor=marble"], "materials: expected labels of "
         "room.obj ('floor', 'shell'), got 'flor'; did you mean 'floor'?"),
        (["--mesh", str(obj), "--material", "floor=plaster_on_brik"], "materials['floor']: "
         "expected a material of library 'sonicspec', got 'plaster_on_brik'; did you mean "
         "'plaster_on_brick'?"),
        (["--mesh", str(obj), "--library", "sonicset", "--default-material", "marble"],
         "default_material: expected a material of library 'sonicset', got 'marble'"),
        (["--mesh", str(obj), "--rays", "5"], "--rays: input should be greater than or equal "
         "to 100, got 5"),
        (["--mesh", str(obj), str(spec)], "rir: expected a SPEC or --mesh FILE, got both"),
        ([], "rir: expected a SPEC or --mesh FILE, got neither"),
        ([str(spec), "--rays", "100"], "--rays: expected --mesh FILE with it, got a SPEC"),
        (["--mesh", str(obj), "--scene", "box"], "--scene: expected a SPEC to choose a scene "
         "from, got --mesh"),
    ):
        code, out, err = run(capsys, "rir", *extra, *where)
        assert code == 2 and out == "", extra
        assert err.startswith(f"sonicspec: error: {message}"), (extra, err)
    (tmp_path / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    code, _, err = run(capsys, "rir", "--mesh", str(tmp_path / "broken.glb"), *where)
    assert code == 2 and "broken.glb: expected a readable glb mesh" in err
    with pytest.raises(SystemExit) as exit_info:
        main(["rir", "--mesh", str(obj), "--material", "floor", *where])
    assert exit_info.value.code == 2
    assert "--material: expected LABEL=NAME, got 'floor'" in capsys.readouterr().err
    code, _, err = run(capsys, "rir", "--mesh", str(obj), "--source", "20", "2", "1", "--mic",
                       "5", "5", "1")
    assert code == 1 and "source: [20.0, 2.0, 1.0] is outside scene 'room.obj'" in err


def test_a_mesh_rir_for_any_receiver_the_spec_knows(tmp_path: Path, capsys) -> None:
    """`--microphone` takes the receiver as the spec writes it (issue 17: `rir --mesh` was
    mono only)."""
    obj = write_room_obj(tmp_path / "room.obj", {"floor": ["floor"],
                                                 "shell": ["walls", "ceiling"]})
    where = ["--mesh", str(obj), "--material", "floor=carpet_on_concrete", "--material",
             "shell=gypsum_board", "--rays", "500", "--source", "2", "2", "1.5", "--mic", "7",
             "4.5", "1.6"]
    for microphone, channels in (("{kind: ambisonics, order: 1}", 4),
                                 ("{kind: circular_array, n: 6, radius_m: 0.05}", 6),
                                 ("{kind: binaural}", 2)):
        code, out, _ = run(capsys, "rir", *where, "--microphone", microphone, "--json")
        assert code == 0 and json.loads(out)["channels"] == channels, microphone
    for microphone, message in (
            ("{kind: ambisonic}", "--microphone: input tag 'ambisonic' found using 'kind' does "
             "not match any of the expected tags"),
            ("[1, 2]", "--microphone: expected a mapping such as '{kind: ambisonics, order: 1}'"
             ", got '[1, 2]'"),
            ("{kind: circular_array, n: 1, radius_m: 0.05}", "--microphone: circular_array.n: ")):
        code, out, err = run(capsys, "rir", *where, "--microphone", microphone)
        assert code == 2 and out == "" and err.startswith(f"sonicspec: error: {message}"), err
    code, _, err = run(capsys, "rir", str(tmp_path / "x.yaml"), "--source", "1", "1", "1",
                       "--mic", "2", "2", "2", "--microphone", "{kind: mono}")
    assert code == 2 and "--microphone: expected --mesh FILE with it, got a SPEC" in err


SCENE_FILE = """\
scene:
  kind: shoebox
  id: studio
  size_m: [10, 7, 3]
  materials: {walls: panel, floor: panel, ceiling: panel}
  obstacles:
    - {kind: box, center_m: [5, 3.5, 0.4], size_m: [1.0, 0.6, 0.8], material: panel}
materials:
  custom:
    panel: {absorption: 0.2, scattering: 0.5}
acoustics: {rays: 4000, image_source_order: 2, max_rir_length_s: 1.2}
seed: 5
"""


def test_a_scene_file_computes_the_rir_the_api_computes(tmp_path: Path, capsys) -> None:
    # Issue 17: `sonicspec rir` takes a scene-only file: a thin caller of the Python API
    # (Scene.from_spec, compute_rir) with the file's materials, settings, receiver and seed.
    import sonicspec as ss
    from sonicspec.spec.validate import validate_scene_file

    room = tmp_path / "studio.yaml"
    room.write_text(SCENE_FILE)
    wav = tmp_path / "rir.wav"
    code, out, err = run(capsys, "rir", str(room), "--source", "2", "2", "1.5", "--mic", "7",
                         "4.5", "1.6", "--json", "-o", str(wav))
    assert code == 0, err
    facts = json.loads(out)
    # room 2 x (10x7 + 10x3 + 7x3) = 242 m², box 2 x (1x0.6 + 1x0.8 + 0.6x0.8) = 3.76 m²
    assert facts["scene_id"] == "studio" and facts["mesh_triangles"] == 24
    assert facts["materials_m2"] == {"panel": pytest.approx(245.76, abs=1e-6)}
    assert facts["direct"] == "visible" and facts["image_source_order"] == 2
    spec, problems = validate_scene_file(room)
    assert problems == []
    settings = ss.RirSettings(**spec.acoustics.model_dump())
    expected = ss.compute_rir(ss.Scene.from_spec(spec.scene, spec.materials), [2, 2, 1.5],
                              [7, 4.5, 1.6], settings, seed=5)
    written, fs = sf.read(str(wav), dtype="float32", always_2d=True)
    assert fs == 16000 and np.array_equal(written.T, expected.rir.astype(np.float32))


def test_scene_file_errors_name_the_line_and_the_field(tmp_path: Path, capsys) -> None:
    room = tmp_path / "bad.yaml"
    room.write_text(SCENE_FILE.replace("size_m: [10, 7, 3]", "size_m: [10, 7]"))
    code, _, err = run(capsys, "rir", str(room), "--source", "1", "1", "1", "--mic", "2", "2",
                       "1")
    assert code == 2 and re.search(r"bad.yaml:4:\d+: scene.shoebox.size_m|bad.yaml:4:\d+: "
                                   r"scene.size_m", err), err
    room.write_text(SCENE_FILE.replace("material: panel}", "material: panle}"))
    code, _, err = run(capsys, "rir", str(room), "--source", "1", "1", "1", "--mic", "2", "2",
                       "1")
    assert code == 2 and "panle" in err and "panel" in err, err  # did you mean
    room.write_text(SCENE_FILE.replace("kind: shoebox\n  id: studio", "kind: mesh\n  id: s\n"
                                       "  path: rooms/*.obj").replace("  size_m: [10, 7, 3]\n"
                                                                      "  materials: {walls: "
                                                                      "panel, floor: panel, "
                                                                      "ceiling: panel}\n", ""))
    code, _, err = run(capsys, "rir", str(room), "--source", "1", "1", "1", "--mic", "2", "2",
                       "1")
    assert code == 2 and "is a glob" in err, err
    room.write_text(SCENE_FILE)
    code, _, err = run(capsys, "rir", str(room), "--scene", "x", "--source", "1", "1", "1",
                       "--mic", "2", "2", "1")
    assert code == 2 and "--scene" in err


def test_validate_knows_a_scene_file(tmp_path: Path, capsys) -> None:
    room = tmp_path / "studio.yaml"
    room.write_text(SCENE_FILE)
    code, out, _ = run(capsys, "validate", str(room))
    assert code == 0 and "valid scene file (shoebox scene 'studio'" in out
    room.write_text(SCENE_FILE.replace("rays: 4000", "rays: -1"))
    code, _, err = run(capsys, "validate", str(room))
    assert code == 2 and "acoustics.rays" in err


def test_the_docs_scene_file_runs_as_written(tmp_path: Path, capsys) -> None:
    readme = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "rir.md").read_text()
    text = readme.split("cat > studio.yaml <<'YAML'\n", 1)[1].split("\nYAML\n", 1)[0]
    command = readme.split("\nYAML\n", 1)[1].splitlines()[0]
    assert command == ("sonicspec validate studio.yaml && sonicspec rir studio.yaml "
                       "--source 1 1 1.5 --mic 4 3 1.5")
    room = tmp_path / "studio.yaml"
    room.write_text(text + "\n")
    assert run(capsys, "validate", str(room))[0] == 0
    code, out, err = run(capsys, "rir", str(room), "--source", "1", "1", "1.5", "--mic", "4",
                         "3", "1.5")
    assert code == 0 and out.startswith("RIR in studio:") and "sofa" in out, err
def test_a_cap_below_the_decay_warns_naming_the_scene_and_the_band(spec: Path,
                                                                   capsys) -> None:
    """Issue 19: `max_rir_length_s: auto` with `max_rir_cap_s` below a live room's decay
    (α 0.03: T60 about 4 s; cap 0.5 s) cuts it and says so on stderr and in the facts,
    naming the scene, the field and each band with the level it reached."""
    live = spec.with_name("live.yaml")
    live.write_text(SPEC.replace("absorption: 0.2", "absorption: 0.03").replace(
        "max_rir_length_s: 1.2}", "max_rir_length_s: auto, max_rir_cap_s: 0.5}"))
    code, out, err = run(capsys, "rir", str(live), "--scene", "box", "--source", "2", "2",
                         "1.5", "--mic", "7", "4.5", "1.6", "--json")
    assert code == 0
    facts = json.loads(out)
    (warning,) = facts["warnings"]
    assert warning.startswith("scene 'box': the RIR's late decay is cut at 0.5 s "
                              "(acoustics.max_rir_cap_s) before it is 60 dB below its early "
                              "level: the 125 Hz band at -"), warning
    assert f"sonicspec: warning: {warning}" in err
    assert facts["samples"] == 8000 and facts["tail"]["rule"] == "auto"
    assert all(v is not None and -15 < v < -3 for v in facts["tail"]["level_at_limit_db"])
    code, out, _ = run(capsys, "rir", str(live), "--scene", "box", "--source", "2", "2",
                       "1.5", "--mic", "7", "4.5", "1.6")
    assert ("length: 0.500 s (max_rir_length_s: auto, every band's decay 60 dB down, at "
            "most 0.5 s); cut at the limit: 125 Hz at -") in out
