"""Dataset files: atomic audio/JSON writes, clear failures, Lhotse-shaped manifests."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.errors import StoreError
from sonicspec.export.files import write_audio, write_json
from sonicspec.export.manifests import RecordingEntry, SupervisionEntry, csv_text, jsonl


@pytest.mark.parametrize(("fmt", "subtype", "tol"), [("flac", "PCM_16", 2**-15),
                                                     ("flac", "PCM_24", 2**-23),
                                                     ("wav", "FLOAT", 1e-7)])
def test_audio_round_trip(tmp_path: Path, fmt: str, subtype: str, tol: float) -> None:
    rng = np.random.default_rng(0)
    audio = 0.5 * rng.uniform(-1, 1, (3, 1600))
    path = write_audio(tmp_path / f"a.{fmt}", audio, 16000, audio_format=fmt, subtype=subtype)
    back, rate = sf.read(path, always_2d=True)
    assert rate == 16000 and back.shape == (1600, 3)
    assert np.max(np.abs(back.T - audio)) <= tol
    assert [p.name for p in tmp_path.iterdir()] == [f"a.{fmt}"]


def test_audio_refuses_clipping_nan_and_bad_formats(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="exceeds full scale"):
        write_audio(tmp_path / "x.flac", np.full(10, 1.5), 16000)
    with pytest.raises(StoreError, match="NaN"):
        write_audio(tmp_path / "x.flac", np.array([0.0, np.nan]), 16000)
    with pytest.raises(StoreError, match="cannot be written as flac"):
        write_audio(tmp_path / "x.flac", np.zeros(10), 16000, subtype="FLOAT")
    assert list(tmp_path.iterdir()) == []


def test_full_disk_keeps_the_old_file(tmp_path: Path, monkeypatch) -> None:
    path = write_json(tmp_path / "meta.json", {"a": 1})

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "replace", no_space)
    with pytest.raises(StoreError, match="the disk is full"):
        write_json(path, {"a": 2})
    monkeypatch.undo()
    assert json.loads(path.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["meta.json"]


def test_lhotse_shapes() -> None:
    rec = RecordingEntry("train/000001/source1", "train/000001/source1.flac", 16000, 32000, 2)
    sup = SupervisionEntry("train/000001/source1/0", rec.id, 1600, 17600, 16000, "HELLO", "84")
    r, s = rec.to_lhotse(), sup.to_lhotse()
    assert r["duration"] == 2.0 and r["sources"][0]["channels"] == [0, 1]
    assert (s["start"], s["duration"], s["speaker"]) == (0.1, 1.0, "84")
    lines = jsonl([r, s]).splitlines()
    assert [json.loads(x)["id"] for x in lines] == [rec.id, sup.id]
    assert csv_text([{"a": 1}], ["a", "b"]) == "a,b\n1,\n"


def test_float_wav_bytes_do_not_depend_on_the_time_of_writing(tmp_path: Path) -> None:
    """Regression: libsndfile's PEAK chunk stamped float WAVs with the clock, so two builds of
    the same RIRs differed in bytes."""
    import time

    x = np.sin(np.linspace(0, 20, 1000))[None, :] * 3.0  # floats may exceed full scale
    write_audio(tmp_path / "a.wav", x, 16000, audio_format="wav", subtype="FLOAT")
    time.sleep(1.1)  # the PEAK chunk's clock counts seconds
    write_audio(tmp_path / "b.wav", x, 16000, audio_format="wav", subtype="FLOAT")
    assert (tmp_path / "a.wav").read_bytes() == (tmp_path / "b.wav").read_bytes()
    y, rate = sf.read(str(tmp_path / "a.wav"), dtype="float32", always_2d=True)
    assert rate == 16000 and np.array_equal(y.T, x.astype(np.float32))
