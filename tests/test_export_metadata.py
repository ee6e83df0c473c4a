"""metadata.json's model and schema, and the tracks.npz codec (issue 27: tracks stored once,
compact, lossless at the precision the JSON carried)."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from sonicspec.export.metadata import (
    METADATA_SCHEMA_FILENAME,
    metadata_schema,
    metadata_schema_text,
)
from sonicspec.export.tracks import TrackError, TrackFile, read_track

ROOT = Path(__file__).resolve().parents[1]


def test_checked_in_metadata_schema_is_up_to_date() -> None:
    """Regenerate with: python -c "from sonicspec.export.metadata import metadata_schema_text
    as t; open('schema/sonicspec-metadata-v2.schema.json', 'w').write(t())"."""
    assert (ROOT / "schema" / METADATA_SCHEMA_FILENAME).read_text() == metadata_schema_text()
    jsonschema.Draft202012Validator.check_schema(metadata_schema())
    assert metadata_schema_text() == metadata_schema_text()


def _tracks(tmp_path: Path) -> tuple[dict, dict, dict]:
    rng = np.random.default_rng(3)
    values = {"positions_m": rng.uniform(-50, 50, (600, 3)),
              "azimuth_deg": rng.uniform(-180, 180, 600),
              "elevation_deg": rng.uniform(-90, 90, 600),
              "distance_m": rng.uniform(0, 80, 600)}
    files = TrackFile(tmp_path, tmp_path / "train" / "000000")
    ref = files.add("source1", 0.01, values)
    mic = files.add("microphone", 0.01, {"positions_m": values["positions_m"][:, ::-1]})
    files.write()
    return values, ref, mic


def test_tracks_round_trip_exactly_the_rounded_values(tmp_path: Path) -> None:
    values, ref, mic = _tracks(tmp_path)
    assert ref["file"] == "train/000000/tracks.npz" and ref["frames"] == 600
    got = read_track(tmp_path, ref)
    # What the JSON held before: np.round to 0.1 mm and 0.01 degrees, bit for bit.
    for q, decimals in (("positions_m", 4), ("azimuth_deg", 2), ("elevation_deg", 2),
                        ("distance_m", 4)):
        assert np.array_equal(got[q], np.round(values[q], decimals)), q
    assert got["hop_s"] == 0.01
    assert np.array_equal(read_track(tmp_path, mic)["positions_m"],
                          np.round(values["positions_m"][:, ::-1], 4))
    # Plain numpy reads it: int32 arrays over the scale.
    with np.load(tmp_path / ref["file"]) as z:
        assert z["source1.positions_m"].dtype == np.int32
        assert np.array_equal(z["source1.positions_m"] / 10000, got["positions_m"])


def test_same_tracks_same_bytes(tmp_path: Path) -> None:
    _tracks(tmp_path / "a")
    _tracks(tmp_path / "b")
    a, b = (p / "train" / "000000" / "tracks.npz" for p in (tmp_path / "a", tmp_path / "b"))
    assert a.read_bytes() == b.read_bytes()


def test_older_inline_tracks_still_read(tmp_path: Path) -> None:
    inline = {"hop_s": 0.01, "positions_m": [[1.0, 2.0, 3.0]] * 4, "distance_m": [1.5] * 4}
    got = read_track(tmp_path, inline)
    assert got["positions_m"].shape == (4, 3) and got["distance_m"][0] == 1.5


def test_bad_tracks_are_named(tmp_path: Path) -> None:
    _values, ref, _ = _tracks(tmp_path)
    with pytest.raises(TrackError, match=r"no array 'source9\.positions_m'"):
        read_track(tmp_path, {**ref, "arrays": {"positions_m": "source9.positions_m"}})
    (tmp_path / ref["file"]).write_bytes(b"not a zip")
    with pytest.raises(TrackError, match=r"tracks.npz: cannot read the tracks"):
        read_track(tmp_path, ref)
    with pytest.raises(TrackError, match="expected a reference"):
        read_track(tmp_path, {"positions_m": [1]})
    files = TrackFile(tmp_path, tmp_path)
    with pytest.raises(TrackError, match="no unit for 'speed_m_s'"):
        files.add("source1", 0.01, {"speed_m_s": np.zeros(3)})
    with pytest.raises(TrackError, match=r"source1.positions_m: values beyond"):
        files.add("source1", 0.01, {"positions_m": np.full((2, 3), 1e6)})


def test_schema_rejects_what_the_model_rejects() -> None:
    validator = jsonschema.Draft202012Validator(metadata_schema())
    ref = {"file": "a/tracks.npz", "frames": 1, "hop_s": 0.01,
           "arrays": {"positions_m": "microphone.positions_m"}, "scale": {"positions_m": 10000}}
    record = {"version": 2, "group": "train/000000", "split": "train", "scene_id": "s",
              "mic_m": [1, 2, 3], "floor": 0, "sample_rate_hz": 16000, "num_samples": 10,
              "mixtures": [], "group_gain_db": None, "keys": {}, "microphone_track": ref}
    validator.validate(record)
    bad = [{**record, "sourceX": {}}, {**record, "mic_m": [1, 2]},
           {**record, "version": 1}, {**record, "source1": {"audio": []}}]
    for b in bad:
        assert list(validator.iter_errors(b)), json.dumps(b)[:80]
