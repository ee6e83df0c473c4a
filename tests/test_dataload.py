"""The loader, ``sonicspec evaluate`` and the Hugging Face / WebDataset exports, on one small
built dataset (three speakers per group, the direct-path stem; see dataload_cases.py)."""

from __future__ import annotations

import io
import json
import math
import multiprocessing
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from build_cases import plan_for

from sonicspec.dataload import DatasetError, MixingConfig, SonicspecDataset, preset
from sonicspec.dataload.evaluate import evaluate
from sonicspec.dataload.hub import export
from sonicspec.dataload.loader import rms_db

STATIC = MixingConfig(dynamic=False, crop_s=None)


@pytest.fixture(scope="module")
def root(dataload_reference: Path) -> Path:
    """The dataset folder of conftest's ``dataload_reference`` (built once per session by
    ``dataload_cases.build_dataset``); read-only."""
    return Path(plan_for(dataload_reference / "demo.yaml").output_dir)


def read(root: Path, rel: str) -> np.ndarray:
    data, _ = sf.read(str(root / rel), dtype="float32", always_2d=True)
    return data.T


def meta(root: Path, group: str) -> dict:
    return json.loads((root / group / "metadata.json").read_text())


# -- loader -------------------------------------------------------------------------------

def test_without_dynamic_mixing_the_items_are_the_dataset_mixtures(root: Path) -> None:
    ds = SonicspecDataset(root, "train", "separation", config=STATIC)
    m = meta(root, "train/000000")
    seps = [x for x in m["mixtures"] if x["task"] == "separation"]
    assert len(ds) == 2 * len(seps) == 6
    for i, mix in enumerate(seps):
        item = ds[i]
        assert item["group"] == "train/000000" and item["mixture_name"] == mix["name"]
        assert np.array_equal(item["mixture"], read(root, mix["file"]))
        for k, t in enumerate(mix["targets"]):
            assert np.array_equal(item["targets"][k], read(root, m[t]["file"]))
        # the written mixture is the sum of its written parts, to a few 16-bit steps
        parts = sum(read(root, m[c]["file"]).astype(np.float64) for c in mix["components"])
        assert np.max(np.abs(parts - item["mixture"])) <= 3 / 32768
        assert item["tracks"].tolist() == [int(t[6:]) for t in mix["targets"]]
        assert math.isnan(item["snr_db"]) and np.isnan(item["sir_db"]).all()


def test_static_crops_are_slices_of_the_files(root: Path) -> None:
    ds = SonicspecDataset(root, "train", "enhancement",
                          config=MixingConfig(dynamic=False, crop_s=2.0))
    total = meta(root, "train/000000")["num_samples"]
    for i in range(len(ds)):
        item = ds.item(i, epoch=3)
        start = item["start"]
        assert 0 <= start <= total - 32000 and item["mixture"].shape == (1, 32000)
        name = item["mixture_name"]
        whole = read(root, f"{item['group']}/mixtures/{name}.flac")
        assert np.array_equal(item["mixture"], whole[:, start:start + 32000])


def test_same_seed_epoch_index_same_bytes_and_the_epoch_redraws(root: Path) -> None:
    a = SonicspecDataset(root, "train", "separation", seed=7)
    b = SonicspecDataset(root, "train", "separation", seed=7)
    c = SonicspecDataset(root, "train", "separation", seed=8)
    for i in range(len(a)):
        x, y = a.item(i, 1), b.item(i, 1)
        assert x["mixture"].tobytes() == y["mixture"].tobytes()
        assert x["targets"].tobytes() == y["targets"].tobytes()
    assert any(a.item(i, 1)["start"] != a.item(i, 2)["start"] for i in range(len(a)))
    assert any(a.item(i, 1)["start"] != c.item(i, 1)["start"] for i in range(len(a)))
    a.set_epoch(2)
    assert a[0]["mixture"].tobytes() == b.item(0, 2)["mixture"].tobytes()


def test_dynamic_items_redraw_speakers_inside_the_group(root: Path) -> None:
    ds = SonicspecDataset(root, "train", "separation", config="paper", seed=1)
    seen = {tuple(ds.item(i, e)["tracks"]) for e in range(6) for i in range(len(ds))}
    assert len(seen) > 3  # ordered pairs of three speakers, not only the built (1,2),(1,3),(2,3)
    assert {t for pair in seen for t in pair} == {1, 2, 3}
    for e in range(3):
        for i in range(len(ds)):
            d = ds.draw(i, e)
            item = ds.item(i, e)
            assert d.group.id == ds.items[i][0]  # the group never changes
            for k, name in enumerate(d.targets):
                whole = read(root, d.group.metadata[name]["file"])
                crop = whole[:, d.start:d.start + d.length]
                np.testing.assert_allclose(item["targets"][k], d.gains[name] * crop,
                                           rtol=1e-6, atol=1e-7)


def test_crops_lie_inside_the_clip_and_every_speaker_is_heard(root: Path) -> None:
    ds = SonicspecDataset(root, "train", "separation", config="sonicsim", seed=2)
    assert ds.config.crop_s == 4.0
    total = meta(root, "train/000000")["num_samples"]
    for e in range(4):
        for i in range(len(ds)):
            item = ds.item(i, e)
            assert 0 <= item["start"] <= total - 64000
            assert item["mixture"].shape == (1, 64000) and item["targets"].shape == (2, 1, 64000)
            d = ds.draw(i, e)
            assert all(rms_db(d.crop[n][0]) >= -40.0 for n in d.targets)
            for n in d.targets:  # drawn where each target speaks
                spans = d.group.metadata[n]["start_end_points"]
                assert any(a < d.start + d.length and d.start < b for a, b in spans)


@pytest.mark.parametrize("level", ["rms", "lufs"])
def test_drawn_sir_and_snr_are_in_their_ranges_and_measured(root: Path, level: str) -> None:
    cfg = MixingConfig(crop_s=3.0, sir_db=(-6.0, 6.0), snr_db=(10.0, 20.0), level=level)
    ds = SonicspecDataset(root, "train", "separation", config=cfg, seed=3)
    if level == "lufs":
        import pyloudnorm

        meter = pyloudnorm.Meter(16000)

        def measure(x):
            return meter.integrated_loudness(np.asarray(x, np.float64))
    else:
        measure = rms_db
    for e in range(3):
        for i in range(len(ds)):
            item = ds.item(i, e)
            sir, snr = float(item["sir_db"][0]), item["snr_db"]
            assert -6.0 <= sir <= 6.0 and 10.0 <= snr <= 20.0
            t = item["targets"][:, 0].astype(np.float64)
            speech = t.sum(axis=0)
            noise = item["mixture"][0].astype(np.float64) - speech
            assert measure(t[0]) - measure(t[1]) == pytest.approx(sir, abs=0.1)
            assert measure(speech) - measure(noise) == pytest.approx(snr, abs=0.1)


def test_enhancement_preset_and_a_drawn_background(root: Path) -> None:
    cfg = preset("paper", "enhancement", backgrounds=("music",))
    assert cfg.snr_db == (-10.0, 15.0) and cfg.crop_s == 3.0
    ds = SonicspecDataset(root, "train", "enhancement", config=cfg, seed=4)
    for i in range(len(ds)):
        d = ds.draw(i)
        item = ds.item(i)
        assert d.background == ("music",)
        music = read(root, d.group.metadata["music"]["file"])[:, d.start:d.start + d.length]
        np.testing.assert_allclose(item["mixture"] - item["targets"][0],
                                   d.gains["music"] * music, atol=2e-6)
        assert -10.0 <= item["snr_db"] <= 15.0


def test_stems_carry_their_speakers_gain_and_labels_follow_the_crop(root: Path) -> None:
    ds = SonicspecDataset(root, "train", "separation", stems=("direct",), labels=True, seed=5)
    d = ds.draw(1, 0)
    item = ds.item(1, 0)
    for k, name in enumerate(d.targets):
        direct = read(root, f"{d.group.id}/{name}_direct.flac")[:, d.start:d.start + d.length]
        np.testing.assert_allclose(item["direct"][k], d.gains[name] * direct, rtol=1e-6,
                                   atol=1e-7)
        track = d.group.track(name)
        assert d.group.metadata[name]["track"]["file"] == f"{d.group.id}/tracks.npz"
        first = d.start // 160
        assert item["positions_m"].shape == (2, 300, 3)
        assert item["azimuth_deg"][k, 0] == track["azimuth_deg"][first]
        assert item["distance_m"][k, -1] == track["distance_m"][first + 299]


def test_loader_errors_name_what_is_wrong(root: Path) -> None:
    with pytest.raises(DatasetError, match="task: expected one of"):
        SonicspecDataset(root, "train", "dereverberation")
    with pytest.raises(DatasetError, match="split 'dev' not in the dataset"):
        SonicspecDataset(root, "dev")
    with pytest.raises(DatasetError, match=r"sir_db: expected \(low, high\)"):
        MixingConfig(sir_db=(6.0, -6.0))
    with pytest.raises(DatasetError, match="preset: expected one of"):
        SonicspecDataset(root, "train", config="librimix")
    with pytest.raises(DatasetError, match="no separation mixtures of 3 speakers"):
        SonicspecDataset(root, "train", speakers=3)
    with pytest.raises(DatasetError, match=r"crop_s: 20\.0 s is longer than group"):
        SonicspecDataset(root, "train", config=MixingConfig(crop_s=20.0))[0]
    with pytest.raises(DatasetError, match="channel 1 asked for, the file has 1"):
        SonicspecDataset(root, "train", config=MixingConfig(channels=(1,)))[0]
    with pytest.raises(DatasetError, match=r"dataset\.json: missing"):
        SonicspecDataset(root / "train", "train")
    with pytest.raises(DatasetError, match=r"no source\d_dry file.*mixture.targets: \[dry\]"):
        SonicspecDataset(root, "train", stems=("dry",))[0]


def _worker_items(args: tuple[str, list[int], int]) -> list[bytes]:
    root, indices, epoch = args
    ds = SonicspecDataset(root, "train", "separation", seed=11)
    ds.set_epoch(epoch)
    return [ds[i]["mixture"].tobytes() + ds[i]["targets"].tobytes() for i in indices]


def _as_dataloader_would(root: Path, workers: int, batch: int, epoch: int) -> list[bytes]:
    """DataLoader's sharding without torch: batch ``b`` goes to worker ``b % workers``, each
    worker a separate process with its own copy of the dataset."""
    n = len(SonicspecDataset(root, "train", "separation", seed=11))
    batches = [list(range(i, min(i + batch, n))) for i in range(0, n, batch)]
    if workers == 0:
        return [x for b in batches for x in _worker_items((str(root), b, epoch))]
    per_worker = [[i for j, b in enumerate(batches) if j % workers == w for i in b]
                  for w in range(workers)]
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        out = pool.map(_worker_items, [(str(root), idx, epoch) for idx in per_worker])
    by_index = {i: x for idx, xs in zip(per_worker, out, strict=True)
                for i, x in zip(idx, xs, strict=True)}
    return [by_index[i] for i in range(n)]


def test_items_do_not_depend_on_the_worker_count(root: Path) -> None:
    serial = _as_dataloader_would(root, 0, 2, epoch=1)
    assert _as_dataloader_would(root, 1, 2, epoch=1) == serial
    assert _as_dataloader_would(root, 2, 2, epoch=1) == serial
    assert _as_dataloader_would(root, 2, 2, epoch=2) != serial


def test_a_torch_dataloader_with_0_1_2_workers(root: Path) -> None:
    torch = pytest.importorskip("torch")
    from torch.utils.data import DataLoader

    ds = SonicspecDataset(root, "train", "separation", seed=12)
    ds.set_epoch(3)
    expected = [ds.item(i, 3) for i in range(len(ds))]
    for workers in (0, 1, 2):
        got = []
        for batch in DataLoader(ds, batch_size=2, num_workers=workers):
            assert isinstance(batch["mixture"], torch.Tensor)
            assert batch["mixture"].shape == (2, 1, 48000)
            got.extend(batch["mixture"].numpy())
        assert [g.tobytes() for g in got] == [e["mixture"].tobytes() for e in expected]


def test_lhotse_mixed_cuts_render_the_items(root: Path) -> None:
    pytest.importorskip("lhotse")
    ds = SonicspecDataset(root, "train", "separation", seed=13)
    cuts = ds.to_lhotse(epoch=2)
    assert len(cuts) == len(ds)
    for i, cut in enumerate(cuts):
        item = ds.item(i, 2)
        np.testing.assert_allclose(cut.load_audio(), item["mixture"], atol=3e-7)
        for k in range(2):
            np.testing.assert_allclose(cut.tracks[k].cut.load_audio(), item["targets"][k],
                                       atol=3e-7)


# -- evaluate -----------------------------------------------------------------------------

def test_oracle_mixture_is_the_zero_baseline_and_targets_the_ceiling(root: Path) -> None:
    rows = evaluate(root, "test", "separation", oracle=True,
                    metrics=["si_snr", "si_snri", "sdr", "sdri", "pesq_wb"])
    mix = [r for r in rows if r["method"] == "oracle_mixture"]
    top = [r for r in rows if r["method"] == "oracle_targets"]
    assert len(mix) == len(top) == 3 * 2  # three mixtures of two targets in the test group
    for r in mix:
        assert r["si_snri"] == pytest.approx(0.0, abs=1e-9)
        assert r["sdri"] == pytest.approx(0.0, abs=1e-9)
        assert r["windows"] == 3  # 10 s: [0, 6), [3, 9), [4, 10)
    for r in top:
        assert r["si_snr"] >= 100.0 and r["sdr"] == 200.0
        assert r["pesq_wb"] == pytest.approx(4.644, abs=1e-3)


def test_wer_references_are_the_metadata_words(root: Path) -> None:
    pytest.importorskip("jiwer", reason="jiwer is not installed (sonicspec[asr])")
    english = pytest.importorskip("whisper_normalizer.english",
                                  reason="whisper-normalizer is not installed (sonicspec[asr])")
    from sonicspec.dataload.asr import Transcriber
    from sonicspec.dataload.folder import DatasetFolder

    heard = []
    stub = Transcriber("stub", lambda x: heard.append(len(x)) or "zzz")
    rows = evaluate(root, "test", "separation", oracle=True, metrics=["wer"],
                    transcriber=stub)
    assert len(heard) == len(rows) == 2 * 3 * 2  # two methods, three mixtures, two targets
    norm = english.EnglishTextNormalizer()
    folder = DatasetFolder(root)
    for r in rows:
        words = folder.group(r["group"]).metadata[r["target"]]["words"]
        n = len(norm(" ".join(words)).split())
        assert n > 0 and r["ref_words"] == n
        assert r["wer"] == 1.0  # one substitution, every other word deleted


def _write_estimates(root: Path, out: Path, task: str, swap: bool) -> None:
    """Estimates that are the targets themselves, channels swapped when asked."""
    for g in ("test/000000",):
        m = meta(root, g)
        for mix in m["mixtures"]:
            if mix["task"] != task:
                continue
            ch = np.stack([read(root, m[t]["file"])[0] for t in mix["targets"]], axis=1)
            if swap:
                ch = ch[:, ::-1]
            (out / g).mkdir(parents=True, exist_ok=True)
            sf.write(str(out / g / f"{mix['name']}.wav"), ch, 16000, subtype="FLOAT")


def test_evaluate_solves_the_permutation_of_swapped_outputs(root: Path, tmp_path: Path) -> None:
    _write_estimates(root, tmp_path, "separation", swap=True)
    rows = evaluate(root, "test", "separation", estimates=tmp_path, metrics=["si_snr"])
    assert [r["estimate_channel"] for r in rows] == [1, 0] * 3
    assert all(r["si_snr"] >= 100.0 for r in rows)


def test_cli_evaluate_writes_csv_json_and_a_table(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "scores"
    result = subprocess.run(
        [sys.executable, "-m", "sonicspec.cli", "evaluate", str(root), "--split", "test",
         "--task", "enhancement", "--oracle", "--metrics", "si_snr", "si_snri", "-o", str(out)],
        capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "oracle_mixture" in result.stdout and "si_snri" in result.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["per_method"]["oracle_mixture"]["si_snri"] == pytest.approx(0.0, abs=1e-9)
    assert summary["per_method"]["oracle_mixture"]["targets"] == 3
    assert set(summary["per_group"]["oracle_targets"]) == {"test/000000"}
    lines = (out / "scores.csv").read_text().splitlines()
    assert lines[0].startswith("method,group,mixture,target,estimate_channel,si_snr,si_snri")
    assert len(lines) == 1 + 2 * 3


@pytest.mark.parametrize(("damage", "message"), [
    ("missing", "group test/000000: missing estimate .*sep_s1s2_noise.wav"),
    ("rate", "sep_s1s2_noise.wav: expected 16000 Hz, got 8000 Hz"),
    ("channels", r"sep_s1s2_noise.wav: expected 2 channel\(s\) .* got 1"),
    ("length", "sep_s1s2_noise.wav: expected 160000 samples .* got 159999"),
])
def test_bad_estimates_name_the_group_and_the_file(root: Path, tmp_path: Path, damage: str,
                                                   message: str) -> None:
    _write_estimates(root, tmp_path, "separation", swap=False)
    path = tmp_path / "test/000000/sep_s1s2_noise.wav"
    data, _ = sf.read(str(path))
    if damage == "missing":
        path.unlink()
    elif damage == "rate":
        sf.write(str(path), data, 8000)
    elif damage == "channels":
        sf.write(str(path), data[:, 0], 16000)
    else:
        sf.write(str(path), data[:-1], 16000)
    with pytest.raises(DatasetError, match=message):
        evaluate(root, "test", "separation", estimates=tmp_path, metrics=["si_snr"])
    result = subprocess.run(
        [sys.executable, "-m", "sonicspec.cli", "evaluate", str(root), "--split", "test",
         "--task", "separation", "--estimates", str(tmp_path), "--metrics", "si_snr",
         "-o", str(tmp_path / "out")], capture_output=True, text=True)
    assert result.returncode == 2 and "group test/000000" in result.stderr


# -- exports ------------------------------------------------------------------------------

def _group_audio(root: Path, group: str) -> dict[str, str]:
    m = meta(root, group)
    out = {n: m[n]["file"] for n in m if n.startswith("source") or n in ("noise", "music")}
    out.update({f"{n}_direct": f"{group}/{n}_direct.flac" for n in list(out)})
    out.update({x["name"]: x["file"] for x in m["mixtures"]})
    return out


def test_huggingface_export_loads_with_datasets(root: Path, tmp_path: Path) -> None:
    datasets = pytest.importorskip("datasets")
    out = tmp_path / "hf"
    first = export(root, out, "huggingface", groups_per_shard=1)
    assert len(first["written"]) == 4 and first["kept"] == []
    again = export(root, out, "huggingface", groups_per_shard=1)
    assert again["written"] == [] and len(again["kept"]) == 4
    loaded = datasets.load_dataset(str(out))
    assert sorted(loaded) == ["test", "train", "validation"]
    train = loaded["train"]
    audio = [k for k, f in train.features.items() if isinstance(f, datasets.Audio)]
    assert set(audio) == set(_group_audio(root, "train/000000"))
    # decoding needs torchcodec (datasets >= 4); the bytes are the folder's own files
    raw = train.cast(datasets.Features(
        {k: datasets.Audio(decode=False) if k in audio else f
         for k, f in train.features.items()}))
    assert sorted(raw["group"]) == ["train/000000", "train/000001"]
    for row in raw:
        m = meta(root, row["group"])
        assert json.loads(row["metadata"]) == m
        assert row["scene_id"] == m["scene_id"] and row["num_samples"] == m["num_samples"]
        assert row["speakers"] == [m[f"source{k}"]["speaker"] for k in (1, 2, 3)]
        assert row["transcripts"][0] == " ".join(m["source1"]["words"])
        tracks = np.load(io.BytesIO(row["tracks"]))  # the group's tracks.npz, as written
        assert row["tracks"] == (root / m["source1"]["track"]["file"]).read_bytes()
        assert tracks["source1.positions_m"].shape == (m["source1"]["track"]["frames"], 3)
        for name, rel in _group_audio(root, row["group"]).items():
            assert row[name]["path"] == rel
            assert row[name]["bytes"] == (root / rel).read_bytes()
            decoded, rate = sf.read(io.BytesIO(row[name]["bytes"]), dtype="float32")
            assert rate == 16000 and np.array_equal(decoded, read(root, rel)[0])


def test_webdataset_export_reads_with_webdataset(root: Path, tmp_path: Path) -> None:
    wds = pytest.importorskip("webdataset")
    out = tmp_path / "wds"
    export(root, out, "webdataset", groups_per_shard=2)
    shards = sorted(str(p) for p in out.glob("train-*.tar"))
    assert len(shards) == 1
    samples = list(wds.WebDataset(shards, shardshuffle=False))
    assert [s["__key__"] for s in samples] == ["train/000000", "train/000001"]
    for s in samples:
        assert json.loads(s["metadata.json"]) == meta(root, s["__key__"])
        assert s["tracks.npz"] == (root / s["__key__"] / "tracks.npz").read_bytes()
        for name, rel in _group_audio(root, s["__key__"]).items():
            data = s[f"{name}.flac"]
            assert data == (root / rel).read_bytes()
            decoded, _ = sf.read(io.BytesIO(data), dtype="float32")
            assert np.array_equal(decoded, read(root, rel)[0])
    # the same groups give the same bytes; a changed group rewrites only its shard
    before = {p.name: p.read_bytes() for p in out.glob("*.tar")}
    again = export(root, tmp_path / "wds2", "webdataset", groups_per_shard=2)
    assert {p: (tmp_path / "wds2" / p).read_bytes() for p in again["written"]} == before


def test_export_rewrites_only_changed_shards(root: Path, tmp_path: Path) -> None:
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(root, copy)
    out = tmp_path / "wds"
    first = export(copy, out, "webdataset", groups_per_shard=1)
    # a changed file (and its checksum, as a rebuild writes both) changes one group's key
    sums = (copy / "checksums.sha256").read_text().replace(
        _line(copy, "val/000000/noise.flac"), "0" * 64 + "  val/000000/noise.flac")
    (copy / "checksums.sha256").write_text(sums)
    second = export(copy, out, "webdataset", groups_per_shard=1)
    assert len(second["written"]) == 1 and second["written"][0].startswith("val-")
    assert len(second["kept"]) == 3 and len(second["removed"]) == 1
    assert second["removed"][0] in first["written"]
    assert sorted(p.name for p in out.glob("*.tar")) == sorted(second["written"]
                                                               + second["kept"])


def _line(root: Path, rel: str) -> str:
    return next(line for line in (root / "checksums.sha256").read_text().splitlines()
                if line.endswith("  " + rel))


def test_the_build_writes_the_exports_the_spec_asks_for(root: Path, tmp_path: Path) -> None:
    # outputs.manifests: [huggingface, webdataset]: beside the dataset folder, the same
    # shards `sonicspec export` writes, and a second build rewrites none of them.
    from sonicspec.cli.build import export_folder

    for fmt in ("huggingface", "webdataset"):
        built = export_folder(root, fmt)
        assert built == root.parent / f"{root.name}-{fmt}" and built.is_dir()
        again = export(root, built, fmt)
        assert again["written"] == [] and again["removed"] == [] and again["kept"]
        fresh = export(root, tmp_path / fmt, fmt)
        assert sorted(fresh["written"]) == sorted(again["kept"])
        for rel in fresh["written"]:
            assert (built / rel).read_bytes() == (tmp_path / fmt / rel).read_bytes()


def test_export_errors(root: Path, tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="inside the dataset folder"):
        export(root, root / "hf", "huggingface")
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "x.txt").write_text("mine")
    with pytest.raises(DatasetError, match="not empty and not an export folder"):
        export(root, tmp_path / "busy", "webdataset")
    with pytest.raises(DatasetError, match="format: expected one of"):
        export(root, tmp_path / "o", "tfrecord")
    export(root, tmp_path / "w", "webdataset", splits=["test"])
    with pytest.raises(DatasetError, match="holds a webdataset export"):
        export(root, tmp_path / "w", "huggingface", splits=["test"])
    result = subprocess.run([sys.executable, "-m", "sonicspec.cli", "export", str(root),
                             "--format", "webdataset", "-o", str(root / "x")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and "inside the dataset folder" in result.stderr


# -- the documentation's examples ---------------------------------------------------------

DOCS = Path(__file__).resolve().parents[1] / "docs" / "guide"


def _readme_blocks() -> list[str]:
    """The code blocks of the pages on using the data and on evaluating a model (once the
    README's "Using a dataset" section), in order."""
    import re

    text = "".join((DOCS / page).read_text(encoding="utf-8")
                   for page in ("data.md", "evaluate.md"))
    return re.findall(r"^```(?:python|bash)\n(.*?)^```", text, re.S | re.M)


def _on(root: Path, tmp: Path, code: str) -> str:
    return (code.replace("specs/out/demo-", f"{tmp}/demo-")
            .replace("specs/out/demo", str(root)).replace("specs/out/", f"{tmp}/"))


def test_readme_examples_run_as_written(root: Path, tmp_path: Path) -> None:
    """Every example of docs/guide/data.md and evaluate.md, on the test dataset instead of
    the demo: the Python blocks run here, the shell commands through the CLI."""
    import re
    import shlex

    blocks = _readme_blocks()
    python = [b for b in blocks if b.startswith("from ")]
    assert len(python) == 2  # the loader, and the DataLoader (which needs torch)
    namespace: dict = {}  # the DataLoader block goes on from the loader block
    exec(compile(_on(root, tmp_path, python[0]), "docs/guide/data.md", "exec"), namespace)
    if _torch_available():
        exec(compile(_on(root, tmp_path, python[1]), "docs/guide/data.md", "exec"), namespace)
    commands = []
    for block in blocks:
        if block.startswith("from "):
            continue
        text = _on(root, tmp_path, block).replace("\\\n", " ")
        for part in re.split(r"^python - <<'PY'\n(.*?)^PY\n", text, flags=re.S | re.M):
            if part.startswith(("from ", "import ")):
                commands.append(("python", part))
            else:
                commands += [("sh", line) for line in part.splitlines()
                             if line.startswith("sonicspec ")]
    assert [k for k, _ in commands].count("python") == 2
    # the command scoring VoiceBank-DEMAND with a Whisper model needs data and a model the
    # user holds: tests/test_model_metrics.py runs its options on fixtures and stubs
    held = [c for _, c in commands if "data/VoiceBank-DEMAND" in c]
    assert len(held) == 1 and "--asr-model" in held[0]
    commands = [(k, c) for k, c in commands if c not in held]
    assert sum(1 for _, c in commands if c.startswith("sonicspec evaluate")) == 2
    for kind, code in commands:
        if kind == "python":
            exec(compile(code, "docs/guide", "exec"), {})
            continue
        args = shlex.split(code.partition("#")[0])
        if args[1] == "build":
            continue  # the fixture built the dataset
        if args[1] == "evaluate":  # PESQ and STOI are tested above; keep this test fast
            args += ["--metrics", "si_snr", "si_snri"]
        result = subprocess.run([sys.executable, "-m", "sonicspec.cli", *args[1:]],
                                capture_output=True, text=True)
        assert result.returncode == 0, (code, result.stderr)
    summary = json.loads((tmp_path / "eval-mixture" / "summary.json").read_text())
    assert summary["per_method"]["estimates"]["si_snri"] == pytest.approx(0.0, abs=1e-4)


def _torch_available() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_an_estimate_with_nan_or_inf_is_named_not_a_crash(root: Path, tmp_path: Path,
                                                          bad: float) -> None:
    """Issue 28 item 9: 'matrix contains invalid numeric entries' was a traceback."""
    _write_estimates(root, tmp_path, "separation", swap=False)
    path = tmp_path / "test/000000/sep_s1s2_noise.wav"
    data, _ = sf.read(str(path))
    data[1234, 1] = bad
    data[5000, 0] = bad
    sf.write(str(path), data, 16000, subtype="FLOAT")
    with pytest.raises(DatasetError, match=r"group test/000000: .*sep_s1s2_noise.wav: 2 "
                       r"sample\(s\) are not finite \(NaN or Inf; the first at sample 1234 of "
                       r"channel 1\)"):
        evaluate(root, "test", "separation", estimates=tmp_path, metrics=["si_snr"])


def test_a_silent_estimate_is_scored_as_undefined_and_counted(root: Path,
                                                              tmp_path: Path) -> None:
    """Issue 28 item 9: an all-zero estimate crashed PESQ ('cannot convert float NaN to
    integer') and scored SDR 200 dB (the ceiling). Its windows are undefined for every
    metric: left out of the means, counted in ``silent_estimate``; the CLI warns."""
    _write_estimates(root, tmp_path, "enhancement", swap=False)
    files = sorted((tmp_path / "test/000000").glob("*.wav"))
    silent, partly = files[0], files[1]
    data, _ = sf.read(str(silent))
    sf.write(str(silent), np.zeros_like(data), 16000, subtype="FLOAT")
    data, _ = sf.read(str(partly))
    data[:16000 * 6] = 0.0  # the first window [0, 6 s) silent
    sf.write(str(partly), data, 16000, subtype="FLOAT")
    metrics = ["si_snr", "sdr", "pesq_nb", "pesq_wb", "stoi"]
    rows = {r["mixture"]: r for r in evaluate(root, "test", "enhancement",
                                              estimates=tmp_path, metrics=metrics)}
    zero, some = rows[silent.stem], rows[partly.stem]
    assert zero["silent_estimate"] == zero["scored"] > 0
    assert all(np.isnan(zero[m]) for m in metrics)
    assert some["silent_estimate"] == 1 and some["scored"] >= 2
    assert all(np.isfinite(some[m]) for m in metrics)
    out = tmp_path / "scores"
    result = subprocess.run(
        [sys.executable, "-m", "sonicspec.cli", "evaluate", str(root), "--split", "test",
         "--task", "enhancement", "--estimates", str(tmp_path), "--metrics", "si_snr", "sdr",
         "-o", str(out)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert re.search(r"warning: 2 estimate\(s\) are silent \(all zeros\) in some windows, "
                     r"\d+ windows in all, which are not scored", result.stderr), result.stderr
    assert "silent_estimate" in (out / "scores.csv").read_text().splitlines()[0]
