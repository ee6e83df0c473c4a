"""The sonicset_realistic preset: SonicSet's recipe plus the realism of issue 30, nothing else.

``sonicset`` stays the paper's (which used none of it); the realistic preset differs from it in
exactly the fields listed here, and a cut-down build of it records the talkers' facing tracks,
the phone's capsules, the diffuse noise and the augmentation draws, which the report shows.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from sonicspec.spec import validate_text

ROOT = Path(__file__).resolve().parents[1]
PAPER = (ROOT / "specs" / "sonicset.yaml").read_text()
REALISTIC = (ROOT / "specs" / "sonicset_realistic.yaml").read_text()


def _dump(text: str, tmp_path: Path) -> dict[str, Any]:
    loaded, problems = validate_text(text, str(tmp_path / "s.yaml"), tmp_path)
    assert loaded is not None, [p.format("s.yaml") for p in problems]
    return loaded.spec.model_dump(mode="json")


def _flat(data: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(data, dict):
        out: dict[str, Any] = {}
        for k, v in data.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else k))
        return out
    return {prefix: data}


def test_the_realistic_preset_differs_from_sonicset_in_the_realism_fields_only(
        tmp_path: Path) -> None:
    paper, real = _flat(_dump(PAPER, tmp_path)), _flat(_dump(REALISTIC, tmp_path))
    differ = {k for k in paper.keys() | real.keys() if paper.get(k, "-") != real.get(k, "-")}
    top = {k.split(".")[0] if not k.startswith(("mixture.", "materials.", "outputs."))
           else ".".join(k.split(".")[:2]) for k in differ}
    assert top == {"name", "description", "materials.scattering_override", "microphone",
                   "directivity", "mixture.noise_field", "mixture.interpolation",
                   "augmentation", "outputs.dir"}, sorted(differ)
    assert set(paper["materials.scattering_override"]) == {1.0}  # per band
    assert real["materials.scattering_override"] is None
    assert paper["microphone.kind"] == "mono" and real["microphone.device"] == "phone_2mic"
    assert real["directivity.speech.pattern"] == "speech"
    assert real["directivity.speech.facing"] == "walk"
    assert real["directivity.speech.head_turn.std_deg"] == 10.0
    assert real["mixture.noise_field.field"] == "diffuse_spherical"
    assert paper.get("augmentation") is None and "augmentation.effects" in real
    # the paper preset says what it leaves out, and where to find it
    description = _dump(PAPER, tmp_path)["description"]
    for word in ("no talker directivity", "no device microphone", "no diffuse background",
                 "no device or codec effects", "sonicset_realistic"):
        assert word in description


def _cut(text: str) -> str:
    """One group per split on three scans, 20 s groups (the fixture's utterances are 8 s),
    cheap acoustics."""
    for old, new in (("scene_count: 62", "scene_count: 1"), ("scene_count: 19", "scene_count: 1"),
                     ("scene_count: 9", "scene_count: 1"),
                     ("test: {groups: 247,", "test: {groups: 1,"),
                     ("rays: 4000", "rays: 300"), ("image_source_order: 3",
                                                   "image_source_order: 1"),
                     ("duration_s: 60.0", "duration_s: 20.0"),
                     ("utterance_gap_s: [0.0, 8.0]", "utterance_gap_s: [0.0, 2.0]"),
                     ("utterances_per_speaker: [3, 5]", "utterances_per_speaker: [1, 2]"),
                     ("noise_clips: [6, 8]", "noise_clips: [2, 2]"),
                     ("music_clips: [6, 8]", "music_clips: [2, 2]")):
        assert old in text, old
        text = text.replace(old, new)
    return text


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sonicspec.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-group-per-split cut of the preset on three scans, built through every stage."""
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages import run_job
    from sonicspec.testing.sonicset import write_sonicset_inputs

    folder = tmp_path_factory.mktemp("realistic")
    write_sonicset_inputs(folder / "data", ["s0", "s1", "s2"],
                          {"train-clean-360": 3, "dev-clean": 3, "test-clean": 3})
    (folder / "sonicset_realistic.yaml").write_text(_cut(REALISTIC))
    plan = compile_spec(load_spec(folder / "sonicset_realistic.yaml"))
    assert len(plan.by_step()["export"]) == 3
    for job in plan.jobs:
        run_job(plan, job.key)
    return Path(plan.output_dir)


def test_validate_and_plan_summary_accept_the_preset(built: Path) -> None:
    folder = built.parents[1]
    done = cli("validate", "sonicset_realistic.yaml", cwd=folder)
    assert done.returncode == 0, done.stderr
    done = cli("plan", "--summary", "sonicset_realistic.yaml", cwd=folder)
    assert done.returncode == 0, done.stderr
    assert "test" in done.stdout and "total" in done.stdout


def test_a_cut_down_build_records_the_realism(built: Path) -> None:
    import numpy as np

    for split in ("train", "val", "test"):
        group = built / split / "000000"
        meta = json.loads((group / "metadata.json").read_text())
        assert meta["capsules"]["device"] == "phone_2mic"
        assert len(meta["capsules"]["capsules"]) == 2
        assert meta["noise"]["field"] == "diffuse_spherical"
        assert meta["noise"]["diffuse_fraction"] == 0.7
        assert "music" not in meta or "field" not in meta["music"]  # music stays a point
        kinds = [d["kind"] for d in meta["augmentation"]]
        assert kinds[:2] == ["response", "self_noise"] and kinds[2] == "one_of", kinds
        snr = next(d for d in meta["augmentation"] if d["kind"] == "self_noise")
        assert 30.0 <= snr["snr_db"] <= 50.0
        tracks = np.load(group / "tracks.npz")
        yaws = [k for k in tracks.files if k.endswith("yaw_deg")]
        assert len(yaws) >= 3, tracks.files  # a facing track per talker
        for k in yaws:
            y = tracks[k] / 100.0  # 0.01 degree units
            assert np.all(np.abs(y) <= 180.0) and np.ptp(y) > 0.0  # it turns


def test_the_report_shows_facing_patterns_and_the_device(built: Path, tmp_path: Path) -> None:
    """The realism sections (issue 30) from the built set; the facing shares equal those
    computed here from tracks.npz and the microphone's position."""
    import re

    import numpy as np

    from sonicspec.export import report
    from sonicspec.export.report import write_report

    result = write_report(built, tmp_path / "r.html", group_pages=0)
    html = result.path.read_text(encoding="utf-8")
    for quantity in ("facing", "directivity", "device", "augmentation"):
        assert f'data-quantity="{quantity}"' in html, quantity
    assert 'data-role="speech" data-pattern="speech"' in html
    assert 'data-device="phone_2mic"' in html
    for split in ("train", "val", "test"):
        meta = json.loads((built / split / "000000" / "metadata.json").read_text())
        tracks = np.load(built / split / "000000" / "tracks.npz")
        mic = np.asarray(meta["mic_m"])
        angles = []
        for k in (1, 2, 3):
            yaw = tracks[f"source{k}.yaw_deg"] / 100.0
            pos = tracks[f"source{k}.positions_m"] / 10_000.0
            to_mic = np.degrees(np.arctan2(mic[1] - pos[:, 1], mic[0] - pos[:, 0]))
            d = (yaw - to_mic) % 360.0
            angles.append(np.minimum(d, 360.0 - d)[::10])
        a = np.concatenate(angles)
        row = re.search(rf'<tr data-split="{split}">(.*?)</tr>', html.split(
            'data-quantity="facing"')[1]).group(1)
        for name, share in (("towards", np.mean(a < 45)), ("away", np.mean(a > 135))):
            shown = float(re.search(rf'data-share="{name}" data-value="([0-9.e-]+)"',
                                    row).group(1))
            assert shown == pytest.approx(share, abs=1e-9), (split, name)
    # a set without directivity, devices or augmentation gets none of the sections
    groups = [{**g, "device": None, "sources": [{**s, "facing_to_mic_deg": None}
                                                for s in g["sources"]]}
              for g in report.rd.read_group_facts(report.rd.read_dataset(built))]
    assert report._realism({}, groups, ["train", "val", "test"]) == {
        "facing": None, "patterns": None, "devices": None}
