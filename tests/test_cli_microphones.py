"""`sonicspec microphones` (the device presets, a picture of a layout) and devices and
directional capsules through `sonicspec rir` and `sonicspec validate` (issue 30)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from test_cli_rir import SPEC, run, write_room_obj

from sonicspec.cli import main


def test_the_list_names_every_preset_with_its_capsules_aperture_and_source(capsys) -> None:
    code, out, _ = run(capsys, "microphones")
    assert code == 0
    for name, capsules in (("respeaker_4mic", 4), ("respeaker_6mic", 6), ("minidsp_uma8", 7),
                           ("smart_speaker_7mic", 7), ("phone_2mic", 2), ("phone_3mic", 3),
                           ("em32", 32)):
        row = next(line for line in out.splitlines() if line.startswith(name + " "))
        assert row.split()[1] == str(capsules), row
    assert "rigid sphere, r = 4.2 cm" in out and "release notes" in out
    code, out, _ = run(capsys, "microphones", "--json")
    rows = {r["name"]: r for r in json.loads(out)}
    assert code == 0 and rows["minidsp_uma8"]["aperture_mm"] == 86.0
    assert rows["respeaker_4mic"]["aperture_mm"] == 64.0
    assert all(len(r["source"]) > 60 for r in rows.values())


def test_plot_writes_a_picture_of_a_layout(tmp_path: Path, capsys) -> None:
    out = tmp_path / "pics" / "em32.png"
    code, text, _ = run(capsys, "microphones", "--plot", "em32", str(out))
    assert code == 0 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and str(out) in text
    assert not list(out.parent.glob("*.tmp*"))  # written atomically
    code, _, err = run(capsys, "microphones", "--plot", "echo_dot", str(out))
    assert code == 2 and err.startswith("sonicspec: error: --plot: expected a device among "
                                        "em32, "), err
    assert "echo_dot" in err


@pytest.mark.parametrize(("microphone", "channels"), [
    ("{kind: device, device: respeaker_4mic}", 4),
    ("{kind: device, device: em32}", 32),
    ("{kind: mono, capsule: {pattern: cardioid, azimuth_deg: 180}}", 1),
    ("{kind: custom, positions_m: [[0, 0.01, 0], [0, -0.01, 0]], capsules: "
     "[{pattern: figure_eight, axis: [0, 1, 0]}, {pattern: hypercardioid}]}", 2),
])
def test_rir_renders_devices_and_directional_capsules(tmp_path: Path, capsys, microphone: str,
                                                      channels: int) -> None:
    obj = write_room_obj(tmp_path / "room.obj", {"floor": ["floor"],
                                                 "shell": ["walls", "ceiling"]})
    wav = tmp_path / "rir.wav"
    code, out, err = run(capsys, "rir", "--mesh", str(obj), "--material",
                         "floor=carpet_on_concrete", "--material", "shell=gypsum_board",
                         "--rays", "300", "--source", "2", "2", "1.5", "--mic", "7", "4.5",
                         "1.6", "--microphone", microphone, "--json", "-o", str(wav))
    assert code == 0, err
    assert json.loads(out)["channels"] == channels
    data, _ = sf.read(wav, always_2d=True)
    assert data.shape[1] == channels and np.all(np.isfinite(data))
    assert np.all(np.max(np.abs(data), axis=0) > 0)  # every channel hears the room


def test_validate_names_the_device_and_the_capsule_field(tmp_path: Path, capsys) -> None:
    good = SPEC + "microphone: {kind: device, device: minidsp_uma8}\n"
    path = tmp_path / "dev.yaml"
    path.write_text(good)
    assert main(["validate", str(path)]) == 0
    path.write_text(SPEC + "microphone: {kind: device, device: echo}\n")
    code, _, err = run(capsys, "validate", str(path))
    assert code == 2 and "microphone.device" in err and "'respeaker_4mic'" in err, err
    path.write_text(SPEC + "microphone: {kind: circular_array, n: 4, radius_m: 0.05, "
                    "capsule: {pattern: cardioid, facing: outward, axis: [1, 0, 0]}}\n")
    code, _, err = run(capsys, "validate", str(path))
    assert code == 2 and "microphone.capsule: give the axis or azimuth_deg" in err, err
