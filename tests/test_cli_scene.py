"""`sonicspec scene inspect`: facts, JSON and a floor plan for procedural and scanned scenes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sonicspec.cli import main

ROOT = Path(__file__).resolve().parents[1]


def run(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_inspect_procedural_scene_json_and_plot(tmp_path: Path, capsys) -> None:
    plot = tmp_path / "plan.png"
    code, out, _ = run(capsys, "scene", "inspect", str(ROOT / "specs/demo.yaml"), "--scene",
                       "living_room", "--json", "--plot", str(plot))
    assert code == 0
    facts = json.loads(out)
    assert facts["bounds_m"] == [[0, 0, 0], [6.0, 4.5, 2.7]]
    # 6 x 4.5 x 2.7 m room minus the 2 x 0.9 x 0.9 box and the r = 0.2 m column (polygonal).
    assert facts["air_volume_m3"] == pytest.approx(72.9 - 1.62 - 0.33, abs=0.02)
    assert set(facts["materials_m2"]) == {"plaster_on_brick", "parquet_on_concrete",
                                          "plaster_on_concrete", "sofa", "concrete_painted"}
    (floor,) = facts["floors"]
    assert floor["floor"]["z_m"] == pytest.approx(0.0)
    assert 10 < floor["walkable_area_m2"] < (6 - 0.5) * (4.5 - 0.5)
    p = facts["placement"]
    assert len(p["speech"]) == 2 and p["noise"] is not None and p["music"] is not None
    assert plot.stat().st_size > 10_000 and plot.read_bytes()[:4] == b"\x89PNG"


def test_inspect_scanned_scene_reports_repair(tmp_path: Path, capsys) -> None:
    from sonicspec.testing.meshes import write_matterport_scene

    write_matterport_scene(tmp_path / "scans" / "abc", "abc")
    spec = tmp_path / "s.yaml"
    spec.write_text(
        "sonicspec: 1\nname: scan\n"
        "scenes: [{kind: mesh, id: mp3d, path: 'scans/*/*.glb', format: matterport}]\n"
        "mixture: {speakers: 1, duration_s: 10, utterances_per_speaker: [1, 1], tasks: []}\n"
        "placement: {source_start_distance_m: [1, 3], source_end_distance_m: [1, 3],"
        " source_travel_distance_m: [0.5, 2]}\n"
        "corpora: {speech: {kind: generated}}\nsplits: {train: {groups: 1, scenes: ['mp3d/*']}}\n")
    code, out, _ = run(capsys, "scene", "inspect", str(spec), "--json")
    assert code == 0
    facts = json.loads(out)
    assert facts["scene_id"] == "mp3d/abc"
    assert facts["repair"]["watertight"] is True
    assert facts["leak"]["fraction"] == 0.0
    # What the rir stage traces after merging flat areas (the spec's default tolerance).
    assert facts["simplify_tolerance_m"] == 0.001
    assert 0 < facts["traced_faces"] <= facts["faces"]
    assert {"wall", "floor", "ceiling", "table", "chair"} <= set(facts["labels"])
    # Faces take materials from their mpcat40 labels through the default library's table.
    assert {"upholstered_seat", "wooden_chair", "plaster_on_brick", "parquet_on_concrete",
            "plaster_on_concrete"} <= set(facts["materials_m2"])
    code, text, _ = run(capsys, "scene", "inspect", str(spec))
    assert "watertight yes" in text and "leak test: 0.0000%" in text
    assert f"the rir stage traces {facts['traced_faces']} " in text
    # A label map in the spec wins over the library; SonicSet's library uses its own names.
    spec.write_text(spec.read_text().replace(
        "format: matterport}", "format: matterport, label_materials: {table: Glass}}")
        + "materials: {library: sonicset}\n")
    code, out, _ = run(capsys, "scene", "inspect", str(spec), "--json")
    assert code == 0
    materials = set(json.loads(out)["materials_m2"])
    assert "Glass" in materials
    assert "Acoustic Tile" in materials  # SonicSet's rule: 'ceiling' -> Acoustic Tile


def test_unknown_scene_is_named(capsys) -> None:
    code, _, err = run(capsys, "scene", "inspect", str(ROOT / "specs/demo.yaml"), "--scene",
                       "livingroom")
    assert code == 1
    assert "did you mean 'living_room'?" in err


def test_several_scenes_need_a_choice(capsys) -> None:
    code, _, err = run(capsys, "scene", "inspect", str(ROOT / "specs/demo.yaml"))
    assert code == 2 and "choose one of living_room, office, hall" in err
