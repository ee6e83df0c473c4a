"""Per-file scaled audio (issue 27, ``outputs.scale: per_file``): files that peak just under full
scale with their scale recorded, read back at the signal's level by every reader."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.dataload import DatasetError
from sonicspec.dataload.folder import Group, read_audio
from sonicspec.errors import StoreError
from sonicspec.export.files import SCALE_TAG, peak_scale, read_scale_tag, write_audio
from sonicspec.export.manifests import RecordingEntry
from sonicspec.spec import validate_text


def loud(seed: int = 0, peak: float = 3.0) -> np.ndarray:
    """Two channels of reverberant-like noise peaking at ``peak`` (above 0 dBFS)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((2, 8000)) * np.exp(-np.arange(8000) / 2000.0)
    return x * (peak / np.max(np.abs(x)))


@pytest.mark.parametrize(("subtype", "bits"), [("PCM_16", None), ("PCM_24", None),
                                               ("PCM_24", 18), ("PCM_24", 20)])
def test_scaled_files_read_back_within_their_quantisation_bound(tmp_path: Path, subtype: str,
                                                                bits: int | None) -> None:
    x = loud()
    scale = peak_scale(x, subtype, bits)
    path = write_audio(tmp_path / "a.flac", x, 16000, subtype=subtype, scale=scale, bits=bits)
    assert read_scale_tag(path) == scale
    n = bits or int(subtype[4:])
    raw, _ = sf.read(str(path), dtype="float64", always_2d=True)  # what a plain tool decodes
    top = 2 ** (n - 1)
    assert np.max(np.abs(raw)) == (top - 1) / top  # just under full scale
    assert np.array_equal(np.round(raw * top), raw * top)  # on the n-bit grid
    bound = np.max(np.abs(x)) * 2.0**-n * top / (top - 1)
    assert np.max(np.abs(raw.T * scale - x)) <= bound * (1 + 1e-12)
    back = read_audio(path)  # the tag's scale, float32
    assert back.dtype == np.float32 and back.shape == x.shape
    assert np.max(np.abs(back - x)) <= bound + 2.0**-24 * np.max(np.abs(x))
    window = read_audio(path, 100, 300, (1,), scale=scale)
    assert np.array_equal(window, back[1:, 100:300])


def test_fewer_bits_make_smaller_flac(tmp_path: Path) -> None:
    """The low bits left zero cost FLAC nothing: it drops bits zero in a whole block."""
    x = loud()
    sizes = {}
    for bits in (16, 18, 24):
        path = write_audio(tmp_path / f"{bits}.flac", x, 16000, subtype="PCM_24",
                           scale=peak_scale(x, "PCM_24", bits), bits=bits)
        sizes[bits] = path.stat().st_size
    assert sizes[16] < sizes[18] < sizes[24]


def test_scale_write_errors(tmp_path: Path) -> None:
    x = loud()
    with pytest.raises(StoreError, match="a scale applies to PCM subtypes"):
        write_audio(tmp_path / "x.wav", x, 16000, audio_format="wav", subtype="FLOAT", scale=2.0)
    with pytest.raises(StoreError, match=r"peak 3 exceeds the scale 2\.0 and would clip"):
        write_audio(tmp_path / "x.flac", x, 16000, subtype="PCM_24", scale=2.0)
    with pytest.raises(StoreError, match=r"x\.flac: scale: expected a finite scale > 0, got -1"):
        write_audio(tmp_path / "x.flac", x, 16000, subtype="PCM_24", scale=-1.0)
    with pytest.raises(StoreError, match=r"bits: expected 8\.\.16 for PCM_16, got 18"):
        write_audio(tmp_path / "x.flac", x, 16000, subtype="PCM_16", scale=4.0, bits=18)
    with pytest.raises(StoreError, match=r"x\.flac: bits \(18\) apply with a scale"):
        write_audio(tmp_path / "x.flac", x / 4, 16000, subtype="PCM_24", bits=18)
    with pytest.raises(StoreError, match="a scale applies to"):
        peak_scale(x, "FLOAT")
    assert list(tmp_path.iterdir()) == []
    assert peak_scale(np.zeros(10), "PCM_24") == 1.0  # silence: nothing to scale


def _tagged(path: Path, comment: str) -> Path:
    with sf.SoundFile(str(path), "w", 16000, 1, "PCM_24", format="FLAC") as fh:
        fh.comment = comment
        fh.write(np.full(100, 1000 << 8, dtype=np.int32))
    return path


@pytest.mark.parametrize("value", ["nan", "abc", "-1", "0", "inf", ""])
def test_an_invalid_tag_is_an_error_naming_the_file(tmp_path: Path, value: str) -> None:
    path = _tagged(tmp_path / "bad.flac", f"{SCALE_TAG}={value}")
    with pytest.raises(DatasetError, match=rf"bad\.flac: comment tag {SCALE_TAG}: expected a "
                                           r"finite scale > 0, got"):
        read_audio(path)


def test_a_tag_that_disagrees_with_the_metadata_is_an_error(tmp_path: Path) -> None:
    path = _tagged(tmp_path / "a.flac", f"{SCALE_TAG}=2.5")
    assert np.allclose(read_audio(path), 2.5 * 1000 / 2**23)
    with pytest.raises(DatasetError, match=rf"a\.flac: its tag {SCALE_TAG}=2.5 differs from "
                                           r"the scale the metadata records \(3.0\)"):
        read_audio(path, scale=3.0)
    other = _tagged(tmp_path / "b.flac", "recorded by hand")  # a comment, but no scale
    assert np.allclose(read_audio(other, scale=3.0), 3.0 * 1000 / 2**23)


def test_group_scales_missing_or_invalid_are_errors(tmp_path: Path) -> None:
    folder = tmp_path / "train" / "000000"
    x = loud()
    s = peak_scale(x, "PCM_24", 18)
    write_audio(folder / "source1.flac", x, 16000, subtype="PCM_24", scale=s, bits=18)
    write_audio(folder / "noise.flac", x / 4, 16000, subtype="PCM_24",
                scale=peak_scale(x / 4, "PCM_24", 18), bits=18)
    meta = {"source1": {"file": "train/000000/source1.flac"},
            "noise": {"file": "train/000000/noise.flac"}, "sample_rate_hz": 16000}
    good = Group(tmp_path, "train/000000", {**meta, "audio_scales": {"source1.flac": s}})
    assert np.max(np.abs(good.read("source1") - x)) <= 2.0**-17 * 3.0
    assert good.scale("source1") == s
    with pytest.raises(DatasetError, match=r"metadata.json: audio_scales: no scale for "
                                           r"'noise.flac'"):
        good.read("noise")
    bad = Group(tmp_path, "train/000000", {**meta, "audio_scales": {"source1.flac": "big"}})
    with pytest.raises(DatasetError, match=r"audio_scales\['source1.flac'\]: expected a finite "
                                           r"scale > 0, got 'big'"):
        bad.read("source1")
    # A group from before scales (no audio_scales): the file's own tag, else 1.
    old = Group(tmp_path, "train/000000", meta)
    assert np.max(np.abs(old.read("noise") - x / 4)) <= 2.0**-17 * 0.75
    assert old.scale("noise") == read_scale_tag(folder / "noise.flac")


def test_lhotse_recording_applies_the_scale_as_a_volume_transform() -> None:
    rec = RecordingEntry("r", "train/000000/source1.flac", 16000, 100, 1, None, 1.75)
    assert rec.to_lhotse()["transforms"] == [{"name": "Volume", "kwargs": {"factor": 1.75}}]
    assert "transforms" not in RecordingEntry("r", "a.flac", 16000, 100, 1).to_lhotse()


def test_levels_above_full_scale_need_a_scale_or_float() -> None:
    from spec_cases import BASE

    loud_spec = BASE.replace("loudness: {speech_lufs: -17}",
                             "loudness: {speech_lufs: -17, peak_limit_dbfs: null}")
    _, problems = validate_text(loud_spec, "s.yaml")
    assert any("outputs.scale: per_file" in p.message for p in problems)
    scaled = loud_spec.replace("subtype: PCM_16",
                               "subtype: PCM_24\n  scale: per_file\n  bits: 18")
    loaded, problems = validate_text(scaled, "s.yaml")
    assert loaded is not None, [p.message for p in problems]
    assert (loaded.spec.outputs.scale, loaded.spec.outputs.bits) == ("per_file", 18)


# -- a built dataset ------------------------------------------------------------------------

def _variant(base_spec: Path, name: str, outputs: str) -> Path:
    """The dataload fixture's spec at loud levels (peaks above 0 dBFS, no peak limit), written
    into ``out/<name>`` with ``outputs`` (the store is shared: only mix, export and the dataset
    step run)."""
    from sonicspec.cli import main

    text = base_spec.read_text()
    for old, new in (("loudness: {speech_lufs: -24, noise_lufs: -28, music_lufs: -31}",
                      "loudness: {speech_lufs: -6, noise_lufs: -10, music_lufs: -24, "
                      "peak_limit_dbfs: null}"),
                     ("dir: out/demo", f"dir: out/{name}"),
                     ("audio_format: flac", outputs),
                     ("manifests: [lhotse, huggingface, webdataset]",
                      "manifests: [lhotse, csv]")):
        assert old in text, old
        text = text.replace(old, new)
    spec = base_spec.with_name(f"{name}.yaml")
    spec.write_text(text)
    assert main(["build", str(spec), "--cores", "2"]) == 0
    return base_spec.parent / "out" / name


@pytest.fixture(scope="module")
def built(tmp_path_factory, dataload_reference: Path) -> dict[str, Path]:
    """A copy of conftest's ``dataload_reference`` (``dataload_cases.build_dataset``, built once
    per session) and its two variants built from the copy's store."""
    import shutil

    tmp = tmp_path_factory.mktemp("scaled") / "b"
    shutil.copytree(dataload_reference, tmp, symlinks=True)
    spec = tmp / "demo.yaml"
    return {"float": _variant(spec, "float", "audio_format: wav\n  subtype: FLOAT"),
            "scaled": _variant(spec, "scaled", "audio_format: flac\n  subtype: PCM_24\n"
                                               "  scale: per_file\n  bits: 18")}


def _audio_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.suffix in (".flac", ".wav")
                  and "rirs" not in p.parts)


@pytest.mark.slow
def test_loader_reads_the_float_signal_within_the_18_bit_bound(built: dict[str, Path]) -> None:
    from sonicspec.dataload import DatasetFolder

    flt, scl = DatasetFolder(built["float"]), DatasetFolder(built["scaled"])
    above = 0
    for split in scl.splits:
        for g in scl.groups(split):
            f = flt.group(g.id)
            scales = g.metadata["audio_scales"]
            files = _audio_files(g.root / g.id)
            assert len(files) == 5 + 5 + 6  # tracks, their direct stems, mixtures
            assert sorted(scales) == [p.relative_to(g.root / g.id).as_posix() for p in files]
            for path in files:
                rel = path.relative_to(g.root / g.id).as_posix()
                assert read_scale_tag(path) == scales[rel]
                assert sf.info(str(path)).subtype == "PCM_24"
                want = f.read(f"{g.id}/{rel[:-len('.flac')]}.wav")  # the float build's
                got = g.read(str(path.relative_to(g.root)))
                peak = float(np.max(np.abs(want)))
                above += peak > 1.0
                # 18 bits of the file's peak, and float32's rounding of both reads (2^-24
                # each, with room for the peak itself being float32's)
                assert np.max(np.abs(got.astype(np.float64) - want)) <= peak * (2.0**-18
                                                                                + 2.0**-22)
    assert above > 0, "the loud variant should peak above 0 dBFS"


@pytest.mark.slow
def test_scaled_dataset_records_its_scales_everywhere(built: dict[str, Path]) -> None:
    root = built["scaled"]
    recs = [json.loads(line) for split in ("train", "val", "test")
            for line in (root / "manifests" / f"{split}_recordings.jsonl").read_text()
            .splitlines()]
    assert recs
    for rec in recs:
        source = rec["sources"][0]["source"]  # <split>/<index>/<file in the group>
        split, index, rel = source.split("/", 2)
        meta = json.loads((root / split / index / "metadata.json").read_text())
        assert rec["transforms"] == [{"name": "Volume",
                                      "kwargs": {"factor": meta["audio_scales"][rel]}}]
    rows = (root / "manifests" / "train.csv").read_text().splitlines()
    assert rows[0].endswith(",scale")
    audio = [r for r in rows[1:] if ".flac," in r]  # not metadata.json, tracks.npz
    assert audio and all(float(r.rsplit(",", 1)[1]) > 0 for r in audio)
    # The old form, float WAV without scales, carries none of it.
    flt = built["float"]
    assert all("audio_scales" not in json.loads(p.read_text())
               for p in flt.rglob("metadata.json"))
    assert "transforms" not in (flt / "manifests" / "train_recordings.jsonl").read_text()


@pytest.mark.slow
def test_evaluate_applies_the_scales(built: dict[str, Path], tmp_path: Path) -> None:
    """The metrics are scale-invariant, so the test leaves the mixtures' files out of the
    scaled dataset's metadata: evaluate then sums the components, which is right only with
    every file's scale applied."""
    import shutil

    from sonicspec.dataload.evaluate import evaluate

    summed = tmp_path / "summed"
    shutil.copytree(built["scaled"], summed)
    for path in summed.rglob("metadata.json"):
        meta = json.loads(path.read_text())
        for m in meta["mixtures"]:
            m["file"] = None
        path.write_text(json.dumps(meta))
    metrics = ("si_snr", "si_snri", "sdr")
    rows = {kind: evaluate(root, "train", "separation", oracle=True, metrics=metrics)
            for kind, root in (("float", built["float"]), ("scaled", built["scaled"]),
                               ("summed", summed))}
    # two groups, three mixtures of two targets each, two methods
    assert len(rows["float"]) == len(rows["scaled"]) == len(rows["summed"]) == 2 * 3 * 2 * 2
    for a, b, c in zip(rows["float"], rows["scaled"], rows["summed"], strict=True):
        assert a["method"] == b["method"] == c["method"] and a["target"] == c["target"]
        if a["method"] == "oracle_mixture":
            assert b["si_snri"] == pytest.approx(0.0, abs=1e-9)
            assert c["si_snri"] == pytest.approx(0.0, abs=1e-9)
            # 18 bits against float: the mixture's SI-SNR the same to 0.01 dB where the
            # target is heard in the window; in a window where it is all but silent (its
            # reverberant tail 40 dB under the mixture, most samples below 1e-6) the file's
            # 18-bit steps are the target, and both builds only agree that it is not there
            if a["si_snr"] > -30.0:
                assert b["si_snr"] == pytest.approx(a["si_snr"], abs=0.01)
                assert c["si_snr"] == pytest.approx(a["si_snr"], abs=0.01)
            else:
                assert b["si_snr"] < -30.0 and c["si_snr"] < -30.0
        else:
            assert b["sdr"] == c["sdr"] == 200.0  # the ceiling, as today


@pytest.mark.slow
def test_exports_carry_the_scales(built: dict[str, Path], tmp_path: Path) -> None:
    import io
    import tarfile

    pq = pytest.importorskip("pyarrow.parquet")
    from sonicspec.dataload import DatasetFolder
    from sonicspec.dataload.hub import export, group_files

    root = built["scaled"]
    folder = DatasetFolder(root)
    export(root, tmp_path / "hf", "huggingface", splits=["train"])
    table = pq.read_table(next((tmp_path / "hf" / "data").glob("train-*.parquet")))
    row = table.to_pylist()[0]
    g = folder.group(row["group"])
    assert set(row["audio_scales"]) == set(group_files(g))
    x, _ = sf.read(io.BytesIO(row["source1"]["bytes"]), dtype="float32", always_2d=True)
    assert np.array_equal((x.astype(np.float64) * row["audio_scales"]["source1"])
                          .astype(np.float32).T, g.read("source1"))
    export(root, tmp_path / "wds", "webdataset", splits=["train"])
    with tarfile.open(next((tmp_path / "wds").glob("train-*.tar"))) as tar:
        scales = json.loads(tar.extractfile(f"{g.id}.scales.json").read())
        data = tar.extractfile(f"{g.id}.noise.flac").read()
    x, _ = sf.read(io.BytesIO(data), dtype="float32", always_2d=True)
    assert scales == row["audio_scales"]
    assert np.array_equal((x.astype(np.float64) * scales["noise"]).astype(np.float32).T,
                          g.read("noise"))
