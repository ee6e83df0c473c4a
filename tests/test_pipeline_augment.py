"""Augmentation end to end (issue 30): a spec's ``augmentation:`` block through the build, the
metadata, the loader and the report; and a spec without it keeps every key and byte."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from build_cases import plan_for, write_spec

from sonicspec.audio.augment import apply_chain, parse_chain
from sonicspec.dataload import SonicspecDataset
from sonicspec.dataload.folder import DatasetError
from sonicspec.errors import CompileError
from sonicspec.spec import load_spec
from sonicspec.stages.workflow import run_build

CHAIN = """
augmentation:
  effects:
    - {kind: response, preset: [smartphone, laptop, headset]}
    - {kind: impulse_response, files: [device_ir.wav], probability: 0.5}
    - {kind: self_noise, snr_db: [15, 35], color: pink}
    - {kind: gain, gain_db: [-6, -1], targets: true}
    - {kind: clipping, threshold_dbfs: [-9, -6]}
    - {kind: resample, rate_hz: [8000, 11025]}
"""


def _one_group_spec(tmp: Path, chain: str | None) -> Path:
    spec = write_spec(tmp)
    text = spec.read_text()
    block = re.search(r"^splits:\n(?:  .*\n)+", text, re.M)
    assert block
    text = text.replace(block.group(0),
                        "splits:\n  train: {groups: 1, scenes: [living_room]}\n")
    text = text.replace("rays: 600", "rays: 300")
    spec.write_text(text + (chain or ""))
    return spec


def _device_ir(path: Path) -> None:
    h = np.zeros(128)
    h[2], h[3:40] = 1.0, 0.25 * np.exp(-np.arange(37) / 5.0) * np.cos(0.7 * np.arange(37))
    sf.write(path, h, 16000, subtype="FLOAT")


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("augment")
    _device_ir(tmp / "device_ir.wav")
    spec = _one_group_spec(tmp, CHAIN)
    plan = plan_for(spec)
    assert run_build(plan, cores=2) == 0
    return spec, Path(plan.output_dir)


def _read(path: Path) -> np.ndarray:
    data, _ = sf.read(path, dtype="float64", always_2d=True)
    return data.T


def test_metadata_records_every_draw_and_the_mixture_is_the_chain_of_its_parts(built) -> None:
    spec, out = built
    folder = out / "train" / "000000"
    meta = json.loads((folder / "metadata.json").read_text())
    draw = meta["augmentation"]
    assert [d["kind"] for d in draw] == ["response", "impulse_response", "self_noise", "gain",
                                         "clipping", "resample"]
    assert draw[0]["preset"] in ("smartphone", "laptop", "headset")
    assert draw[1]["file"] == "device_ir.wav"
    assert 15 <= draw[2]["snr_db"] <= 35 and draw[2]["color"] == "pink"
    assert isinstance(draw[2]["seed"], int)
    assert -6 <= draw[3]["gain_db"] <= -1 and draw[3]["targets"] is True
    assert -9 <= draw[4]["threshold_dbfs"] <= -6
    assert draw[5]["rate_hz"] in (8000, 11025)
    assert all(isinstance(d["applied"], bool) for d in draw)
    # The written tracks took only the gain (targets: true); the mixture the whole chain.
    gain = 10 ** (draw[3]["gain_db"] / 20)
    responses = {"device_ir.wav": _read(spec.parent / "device_ir.wav")[0]}
    for m in meta["mixtures"]:
        clean = sum(_read(out / meta[c]["file"]) for c in m["components"]) / gain
        expected, measured = apply_chain(draw, clean, 16000, impulse_responses=responses)
        got = _read(out / m["file"])
        # 16-bit files on both sides: the parts' rounding, filtered, is all that differs
        assert np.max(np.abs(got - np.clip(expected, -1, 1))) < 2e-3, m["name"]
        assert len(m["augmentation"]) == len(draw) + 1  # and the full-scale cut, last
        assert "full_scale_clipped_share" in m["augmentation"][-1]
        level = 10 ** (draw[4]["threshold_dbfs"] / 20)
        if draw[4]["applied"] and not draw[5]["applied"]:
            assert np.max(np.abs(got)) <= level + 1e-4
        assert measured[2]["noise_rms_db"] == pytest.approx(
            m["augmentation"][2]["noise_rms_db"], abs=0.05)


def test_a_spec_without_augmentation_keeps_its_keys_and_params(tmp_path: Path) -> None:
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
    plain = plan_for(_one_group_spec(tmp_path / "a", None))
    _device_ir(tmp_path / "b" / "device_ir.wav")
    augmented = plan_for(_one_group_spec(tmp_path / "b", CHAIN))
    for job in plain.jobs:
        assert "augmentation" not in json.dumps(job.params), job.label
    by_label = {j.label: j.key for j in augmented.jobs}
    for job in plain.jobs:
        same = by_label[job.label] == job.key
        assert same == (job.step not in ("export", "dataset")), job.label
    export = next(j for j in augmented.jobs if j.step == "export")
    assert set(export.params["impulse_responses"]) == {"device_ir.wav"}
    assert export.paths["device_ir.wav"].endswith("device_ir.wav")


def test_a_missing_impulse_response_file_is_a_compile_error_naming_it(tmp_path: Path) -> None:
    spec = _one_group_spec(tmp_path, CHAIN)
    with pytest.raises(CompileError, match=r"augmentation\.effects: impulse-response file "
                       r".*device_ir\.wav .*does not exist"):
        plan_for(spec)


def test_the_loader_applies_the_same_block_on_the_fly(built) -> None:
    spec_path, out = built
    block = load_spec(spec_path).spec.augmentation
    plain = SonicspecDataset(out, "train", "separation", seed=3)
    a = SonicspecDataset(out, "train", "separation", seed=3, augmentation=block,
                         augmentation_dir=spec_path.parent)
    b = SonicspecDataset(out, "train", "separation", seed=3,
                         augmentation=block.model_dump(mode="json"),
                         augmentation_dir=spec_path.parent)
    x, y, p = a.item(0, 0), b.item(0, 0), plain.item(0, 0)
    # the model and its plain data are the same block; the same (seed, epoch, index), the
    # same bytes; the other draws (crop, levels) do not move
    assert x["mixture"].tobytes() == y["mixture"].tobytes()
    assert x["augmentation"] == y["augmentation"]
    assert x["start"] == p["start"] and np.array_equal(x["sir_db"], p["sir_db"])
    draw = json.loads(x["augmentation"])
    expected, _ = apply_chain(draw, p["mixture"], 16000, impulse_responses={
        "device_ir.wav": _read(spec_path.parent / "device_ir.wav")[0]})
    np.testing.assert_allclose(x["mixture"], expected, atol=1e-5)
    # the targets took only the gain marked targets
    gain = 10 ** (draw[3]["gain_db"] / 20) if draw[3]["applied"] else 1.0
    np.testing.assert_allclose(x["targets"], p["targets"] * gain, rtol=1e-5, atol=1e-7)
    # a new epoch, a new draw
    assert a.item(0, 1)["augmentation"] != x["augmentation"]
    with pytest.raises(DatasetError, match=r"augmentation\.effects\[0\]\.snr_db: expected "
                       r"\[min, max\] with min <= max"):
        SonicspecDataset(out, "train", augmentation={"effects": [
            {"kind": "self_noise", "snr_db": [30, 10]}]})
    assert math.isfinite(float(np.max(np.abs(x["mixture"]))))


def test_the_guide_s_loader_block_runs_on_a_built_dataset(built, monkeypatch) -> None:
    """docs/guide/augmentation.md's training-script block, on this module's dataset."""
    spec_path, out = built
    text = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "augmentation.md"
            ).read_text(encoding="utf-8")
    (block,) = [b for b in re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)
                if "SonicspecDataset" in b]
    monkeypatch.chdir(spec_path.parent)
    code = block.replace('"spec.yaml"', repr(spec_path.name)).replace('"out/demo"', repr(str(out)))
    namespace: dict = {}
    exec(compile(code, "docs/guide/augmentation.md", "exec"), namespace)
    assert json.loads(namespace["item"]["augmentation"])  # the item's draw


def test_the_report_shows_the_draws(built, tmp_path: Path) -> None:
    from sonicspec.export.report import write_report

    _, out = built
    write_report(out, tmp_path / "report.html", group_pages=0)
    html = (tmp_path / "report.html").read_text()
    assert 'data-quantity="aug_self_noise_snr_db"' in html
    assert 'data-quantity="augmentation"' in html
    assert 'data-effect="self_noise"' in html


def test_parse_chain_reads_the_spec_model() -> None:
    from spec_cases import BASE

    from sonicspec.spec import validate_text

    loaded, problems = validate_text(BASE + CHAIN, "x.yaml")
    assert loaded is not None, [p.format("x.yaml") for p in problems]
    assert len(parse_chain(loaded.spec.augmentation)) == 6
