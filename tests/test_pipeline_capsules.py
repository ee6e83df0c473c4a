"""Directional capsules and devices end to end (issue 30): a cut-down demo built with them
and its metadata recording the capsules (the patterns' physics is tested exactly in
test_acoustics_capsules)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from build_cases import plan_for, write_spec

from sonicspec.stages.workflow import run_build

MICROPHONE = """microphone:
  kind: custom
  height_m: 1.5
  positions_m: [[0, 0.02, 0], [0, -0.02, 0], [0, 0, 0]]
  capsules:
    - {pattern: cardioid, azimuth_deg: 90}
    - {pattern: cardioid, azimuth_deg: -90}
    - {pattern: figure_eight, axis: [0, 0, 1]}
"""


def _spec(tmp: Path, microphone: str) -> Path:
    path = write_spec(tmp)
    text = path.read_text()
    old = "microphone:\n  kind: mono\n  height_m: 1.5\n"
    assert old in text
    text = text.replace(old, microphone)
    for line in ("  val: {groups: 1, scenes: [office]}\n", "  test: {groups: 1, scenes: [hall]}\n"):
        assert line in text
        text = text.replace(line, "")  # the train split's 2 groups are enough
    path.write_text(text)
    return path


@pytest.mark.slow
def test_a_build_with_directional_capsules_records_them(tmp_path: Path) -> None:
    plan = plan_for(_spec(tmp_path, MICROPHONE))
    assert run_build(plan, cores=2) == 0
    folders = sorted(p.parent for p in Path(plan.output_dir).rglob("metadata.json"))
    assert folders
    for folder in folders:
        meta = json.loads((folder / "metadata.json").read_text())
        caps = meta["capsules"]
        assert caps["device"] is None and caps["sphere_radius_m"] is None
        assert [c["pattern"] for c in caps["capsules"]] == ["cardioid", "cardioid",
                                                            "figure_eight"]
        np.testing.assert_allclose(caps["capsules"][0]["axis"], [0, 1, 0], atol=1e-6)
        np.testing.assert_allclose(caps["capsules"][2]["axis"], [0, 0, 1], atol=1e-6)
        audio, _ = sf.read(folder / "source1.flac", always_2d=True)
        assert audio.shape[1] == 3 and np.all(np.std(audio, axis=0) > 0)
        assert np.all(np.isfinite(audio))


@pytest.mark.slow
def test_a_build_with_a_device(tmp_path: Path) -> None:
    plan = plan_for(_spec(tmp_path, "microphone: {kind: device, device: respeaker_4mic, "
                                    "height_m: 1.2}\n"))
    assert run_build(plan, cores=2) == 0
    meta_paths = sorted(Path(plan.output_dir).rglob("metadata.json"))
    assert meta_paths
    meta = json.loads(meta_paths[0].read_text())
    assert meta["capsules"]["device"] == "respeaker_4mic"
    assert len(meta["capsules"]["capsules"]) == 4
    audio, _ = sf.read(meta_paths[0].parent / "source1.flac", always_2d=True)
    assert audio.shape[1] == 4
