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
    assert rate == 16000 and len(rir) == facts["samples"] == 2 * 16000
    # The same seed, the same bytes; the text report names the materials.
    code, out, _ = run(capsys, *args, "--rays", "2000", "--seed", "3", "-o",
                       str(tmp_path / "again.wav"))
    assert np.array_equal(sf.read(tmp_path / "again.wav", dtype="float32")[0], rir)
    assert "RIR in room.obj:" in out
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
