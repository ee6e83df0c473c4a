"""Every realism feature of issue 30 at once, through the CLI as a user would run it: a talker
with the speech pattern facing its walk, a device microphone (a two-capsule phone), a noise
background heard only as a diffuse field and a device chain ending in a codec, in one small
spec — ``sonicspec validate``, ``build``, the loader, ``evaluate --oracle``, ``report`` and
every export (Lhotse and CSV manifests, Hugging Face Parquet, WebDataset tars): each carries
the realism metadata (orientation track, capsules and device, background field, augmentation
draws) or, for the manifests, does not, as docs/guide/data.md says."""

from __future__ import annotations

import csv
import glob
import io
import json
import tarfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.cli import main

pytestmark = pytest.mark.slow

SPEC = """\
sonicspec: 1
name: realism
seed: 11
sample_rate_hz: 16000
scenes:
  - kind: shoebox
    id: room
    size_m: [6.0, 5.0, 3.0]
    materials: {walls: plaster_on_brick, floor: carpet_on_concrete,
                ceiling: acoustic_ceiling_tile}
microphone: {kind: device, device: phone_2mic, height_m: 0.8}
placement:
  source_start_distance_m: [1.0, 3.0]
  source_end_distance_m: [1.0, 3.0]
  source_travel_distance_m: [1.0, 2.0]
  noise_distance_m: [1.0, 3.0]
trajectory: {kind: shortest_path, rir_spacing_m: 0.5}
directivity:
  speech: {pattern: speech, facing: walk}
acoustics: {rays: 300, image_source_order: 1, max_rir_length_s: 0.3}
corpora:
  speech: {kind: generated, speakers_per_split: 2, utterances_per_speaker: 2}
  noise: {kind: generated, clips_per_split: 2, clip_duration_s: 6.0}
mixture:
  duration_s: 10.0
  speakers: 2
  utterances_per_speaker: [1, 1]
  utterance_gap_s: [0.0, 1.0]
  noise_clips: [2, 2]
  noise_gap_s: [0.0, 0.2]
  music_clips: [0, 0]
  noise_field: {field: diffuse_spherical}
  loudness: {speech_lufs: -24, noise_lufs: -30}
  tasks:
    - {kind: separation, speakers: 2, background: noise}
    - {kind: enhancement, background: noise}
augmentation:
  effects:
    - {kind: response, preset: [smartphone]}
    - {kind: self_noise, snr_db: [30, 40], color: pink}
    - {kind: mp3, bitrate_kbps: [64]}
splits:
  train: {groups: 1, scenes: [room]}
outputs: {dir: out, store_dir: store, rirs: true,
          manifests: [lhotse, csv, huggingface, webdataset]}
"""
KINDS = ["response", "self_noise", "mp3"]


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The spec validated and built with the CLI; the dataset folder."""
    folder = tmp_path_factory.mktemp("realism")
    spec = folder / "spec.yaml"
    spec.write_text(SPEC)
    assert main(["validate", str(spec)]) == 0
    assert main(["build", str(spec), "--cores", "2"]) == 0
    return folder / "out"


def _meta(out: Path) -> dict:
    return json.loads((out / "train" / "000000" / "metadata.json").read_text())


def _read(path: Path) -> np.ndarray:
    x, rate = sf.read(path, dtype="float64", always_2d=True)
    assert rate == 16000
    return x.T


def _check_realism(meta: dict, tracks: dict) -> None:
    """What a consumer of any export must find: the talkers' facing track, the phone's
    capsules, the diffuse noise (not traced) and the group's augmentation draw."""
    assert meta["capsules"]["device"] == "phone_2mic"
    assert len(meta["capsules"]["capsules"]) == 2
    assert meta["noise"]["field"] == "diffuse_spherical"
    assert meta["noise"]["diffuse_fraction"] == 1.0
    assert meta["noise"]["rir_points_m"] == [] and "rir_tail" not in meta["noise"]
    assert [d["kind"] for d in meta["augmentation"]] == KINDS
    assert meta["augmentation"][2]["bitrate_kbps"] == 64
    for name in ("source1", "source2"):
        ref = meta[name]["track"]
        assert "yaw_deg" in ref["arrays"], name
        yaw = tracks[ref["arrays"]["yaw_deg"]] / ref["scale"]["yaw_deg"]
        pos = tracks[ref["arrays"]["positions_m"]] / ref["scale"]["positions_m"]
        assert yaw.shape == (ref["frames"],), name
        # facing: walk — where the talker walks, it faces its direction of travel (the
        # facing is smoothed over 0.5 s, so away from the walk's first and last 0.5 s)
        step = np.diff(pos[:, :2], axis=0)
        moving = np.flatnonzero(np.linalg.norm(step, axis=1) > 1e-4)
        assert moving.size > 100, name
        inner = moving[(moving > moving[0] + 50) & (moving < moving[-1] - 50)]
        heading = np.degrees(np.arctan2(step[inner, 1], step[inner, 0]))
        off = (yaw[inner] - heading + 180.0) % 360.0 - 180.0
        assert np.median(np.abs(off)) < 5.0, (name, np.median(np.abs(off)))
    assert "yaw_deg" not in meta["noise"]["track"]["arrays"]  # omni noise: no facing


def test_the_built_group_records_every_feature(built: Path) -> None:
    meta = _meta(built)
    _check_realism(meta, np.load(built / "train" / "000000" / "tracks.npz"))
    assert _read(built / "train" / "000000" / "source1.flac").shape[0] == 2  # two capsules
    for m in meta["mixtures"]:
        codec = m["augmentation"][2]
        assert codec["bitrate_kbps"] == pytest.approx(64, rel=0.1), codec
    # the noise, heard only as a diffuse field, was not traced: the rir artifact has the
    # talkers' RIRs only
    from sonicspec import artifacts
    from sonicspec.store import ArtifactStore

    store = ArtifactStore(built.parent / "store")
    rir = artifacts.decode("rir", store.read_data("rir", meta["keys"]["rir"]), "rir")
    assert [s.name for s in rir.groups[0].sources] == ["source1", "source2"]
    # outputs.rirs: the talkers' RIRs are written, the untraced noise has none
    rirs = built / "train" / "000000" / "rirs"
    assert sorted(p.name for p in rirs.iterdir()) == ["source1", "source2"]
    assert len(meta["source1"]["rir_points_m"]) == len(list((rirs / "source1").glob("*.wav")))


def test_the_loader_reads_the_mixtures_as_augmented_and_the_targets_clean(built: Path) -> None:
    from sonicspec.dataload import MixingConfig, SonicspecDataset
    from sonicspec.spec import load_spec

    meta = _meta(built)
    as_written = SonicspecDataset(built, "train", "enhancement",
                                  config=MixingConfig(dynamic=False, crop_s=None))
    item = as_written.item(0)
    record = next(m for m in meta["mixtures"] if m["name"] == item["mixture_name"])
    mixture = _read(built / record["file"])
    np.testing.assert_allclose(item["mixture"], mixture, atol=1e-6)
    # the draw the build applied is the item's, and the mixture is not its clean sum
    assert json.loads(item["augmentation"]) == meta["augmentation"]
    clean = sum(_read(built / meta[c]["file"]) for c in record["components"])
    assert np.max(np.abs(mixture - clean)) > 1e-2
    # the targets stay clean: the written speech track itself
    np.testing.assert_allclose(item["targets"][0], _read(built / meta["source1"]["file"]),
                               atol=1e-6)
    # dynamic mixing re-mixes the clean tracks; the spec's block applies the chain on the fly
    block = load_spec(built.parent / "spec.yaml").spec.augmentation
    fly = SonicspecDataset(built, "train", "enhancement", augmentation=block).item(0)
    assert [d["kind"] for d in json.loads(fly["augmentation"])] == KINDS
    assert fly["mixture"].shape[0] == 2 and np.all(np.isfinite(fly["mixture"]))


def test_evaluate_oracle_scores_the_augmented_mixtures(built: Path, tmp_path: Path) -> None:
    out = tmp_path / "scores"
    assert main(["evaluate", str(built), "--split", "train", "--task", "enhancement",
                 "--oracle", "--metrics", "si_snr", "-o", str(out)]) == 0
    with (out / "scores.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert rows
    by_method: dict[str, list[float]] = {}
    for row in rows:
        by_method.setdefault(row["method"], []).append(float(row["si_snr"]))
    assert set(by_method) == {"oracle_mixture", "oracle_targets"}
    # the clean targets themselves (the ceiling) far above the augmented noisy mixture
    assert np.median(by_method["oracle_targets"]) > 40.0, by_method
    assert np.median(by_method["oracle_mixture"]) < 40.0, by_method
    assert np.all(np.isfinite(by_method["oracle_mixture"]))


def test_the_report_shows_facing_patterns_device_and_draws(built: Path, tmp_path: Path) -> None:
    html_path = tmp_path / "report.html"
    assert main(["report", str(built), "-o", str(html_path), "--group-pages", "1"]) == 0
    html = html_path.read_text(encoding="utf-8")
    for quantity in ("facing", "directivity", "device", "augmentation"):
        assert f'data-quantity="{quantity}"' in html, quantity
    assert 'data-device="phone_2mic"' in html
    assert 'data-effect="mp3"' in html


def test_the_lhotse_and_csv_manifests(built: Path) -> None:
    """The Lhotse recordings carry each source's track reference (its facing included); the
    device, the background field and the draws are in metadata.json only, which every
    recording id names (docs/guide/data.md says so)."""
    meta = _meta(built)
    recordings = [json.loads(line) for line in
                  (built / "manifests" / "train_recordings.jsonl").read_text().splitlines()]
    by_id = {r["id"]: r for r in recordings}
    source = by_id["train_000000_source1"]
    assert source["custom"]["track"] == meta["source1"]["track"]
    assert "yaw_deg" in source["custom"]["track"]["arrays"]
    assert all(len(r["channel_ids"]) == 2 for r in recordings)  # the phone's capsules
    for r in recordings:
        assert set(r.get("custom", {})) <= {"track"}, r["id"]
        assert r["id"].startswith("train_000000_")  # -> train/000000/metadata.json
    with (built / "manifests" / "train.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {r["group"] for r in rows} == {"train/000000"}
    assert {"metadata", "tracks"} <= {r["kind"] for r in rows}  # where the rest is
    guide = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "data.md").read_text()
    assert "Realism metadata in each export" in guide


def test_the_hugging_face_export_carries_the_realism(built: Path, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    beside = Path(f"{built}-huggingface")
    files = sorted(glob.glob(str(beside / "data" / "train-*.parquet")))
    assert len(files) == 1
    table = pq.read_table(files[0]).to_pylist()
    (row,) = table
    meta = json.loads(row["metadata"])
    assert meta == _meta(built)
    _check_realism(meta, np.load(io.BytesIO(row["tracks"])))
    mixture = next(m for m in meta["mixtures"] if m["task"] == "enhancement")
    audio, _ = sf.read(io.BytesIO(row[mixture["name"]]["bytes"]), always_2d=True)
    np.testing.assert_array_equal(audio.T, _read(built / mixture["file"]))
    # the CLI writes the same shard
    assert main(["export", str(built), "--format", "huggingface", "-o",
                 str(tmp_path / "hf")]) == 0
    again = sorted(glob.glob(str(tmp_path / "hf" / "data" / "train-*.parquet")))
    assert [Path(f).name for f in again] == [Path(f).name for f in files]


def test_the_webdataset_export_carries_the_realism(built: Path, tmp_path: Path) -> None:
    assert main(["export", str(built), "--format", "webdataset", "-o",
                 str(tmp_path / "wds")]) == 0
    (shard,) = sorted((tmp_path / "wds").glob("train-*.tar"))
    with tarfile.open(shard) as tar:
        members = {m.name: tar.extractfile(m).read() for m in tar.getmembers()}
    meta = json.loads(members["train/000000.metadata.json"])
    assert meta == _meta(built)
    _check_realism(meta, np.load(io.BytesIO(members["train/000000.tracks.npz"])))
    beside = sorted(Path(f"{built}-webdataset").glob("train-*.tar"))
    assert [p.name for p in beside] == [shard.name]
