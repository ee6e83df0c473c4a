"""The artifact store: atomic writes, identical bytes, provenance, verify catches damage."""

from __future__ import annotations

import errno
import hashlib
import os
import re
from pathlib import Path

import numpy as np
import pytest

from sonicspec.errors import StoreError
from sonicspec.hashing import canonical_json, content_key, rng_for
from sonicspec.store import ArtifactStore


def _files_digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _write_example(store: ArtifactStore) -> str:
    key = content_key("rir", 1, {"rays": 1000, "pos": (1.0, 2.5, 0.1)}, ["a" * 64])
    rng = rng_for(7, key)
    store.write("rir", key, {"rir": rng.standard_normal((3, 1, 400)).astype(np.float32),
                             "points": np.arange(9.0).reshape(3, 3),
                             "empty": np.zeros((0, 3))},
                data={"t30_s": [0.51, 0.49], "scene": "hall"}, params={"rays": 1000},
                input_keys=("a" * 64,))
    return key


def test_round_trip_and_provenance(tmp_path: Path) -> None:
    store = ArtifactStore(tmp_path)
    key = _write_example(store)
    art = store.read("rir", key)
    assert art.arrays["rir"].shape == (3, 1, 400) and art.arrays["rir"].dtype == np.float32
    assert art.arrays["empty"].shape == (0, 3)
    assert art.data == {"scene": "hall", "t30_s": [0.51, 0.49]}
    assert art.provenance["input_keys"] == ["a" * 64]
    assert store.read_data("rir", key)["scene"] == "hall"
    assert store.path("rir", key) == tmp_path / "rir" / key[:2] / f"{key}.zarr"
    assert list(store.artifacts()) == [("rir", key)]
    assert store.verify() == []


def test_present_agrees_with_exists(tmp_path: Path) -> None:
    store = ArtifactStore(tmp_path)
    assert store.present("rir", ["b" * 64]) == set()  # no stage folder yet
    key = _write_example(store)
    unfinished = "c" * 64  # a folder without zarr.json is not an artifact
    (tmp_path / "rir" / "cc" / f"{unfinished}.zarr").mkdir(parents=True)
    keys = [key, unfinished, "d" * 64]
    assert store.present("rir", keys) == {k for k in keys if store.exists("rir", k)} == {key}
    assert store.present("mix", keys) == set()


def test_same_inputs_give_identical_bytes(tmp_path: Path) -> None:
    a, b = ArtifactStore(tmp_path / "a"), ArtifactStore(tmp_path / "b")
    _write_example(a)
    _write_example(b)
    assert _files_digest(tmp_path / "a") == _files_digest(tmp_path / "b")


def test_keys_are_stable_and_sensitive() -> None:
    k = content_key("rir", 1, {"b": 1, "a": 0.1})
    assert k == content_key("rir", 1, {"a": 0.1, "b": 1})
    assert k != content_key("rir", 2, {"a": 0.1, "b": 1})
    assert k != content_key("rir", 1, {"a": 0.1 + 1e-15, "b": 1})
    assert canonical_json({"x": (1, 2.0)}) == '{"x":[1,2.0]}'


def test_rng_streams_are_independent_and_reproducible() -> None:
    a = rng_for(3, "key", "group-1").standard_normal(4)
    assert np.array_equal(a, rng_for(3, "key", "group-1").standard_normal(4))
    assert not np.array_equal(a, rng_for(3, "key", "group-2").standard_normal(4))
    assert not np.array_equal(a, rng_for(4, "key", "group-1").standard_normal(4))


def test_verify_catches_truncated_and_edited_artifacts(tmp_path: Path) -> None:
    store = ArtifactStore(tmp_path)
    key = _write_example(store)
    chunk = next(p for p in (store.path("rir", key) / "rir").rglob("*")
                 if p.is_file() and p.name != "zarr.json")
    original = chunk.read_bytes()
    chunk.write_bytes(original[: len(original) // 2])
    (problem,) = store.verify()
    assert problem.key == key and problem.stage == "rir"
    chunk.write_bytes(original)
    assert store.verify() == []
    # An edit that still decompresses: rewrite the points array through zarr itself.
    import zarr

    zarr.open_group(str(store.path("rir", key)), mode="r+")["points"][0, 0] = 42.0
    (problem,) = store.verify()
    assert "digest" in problem.problem


def test_verify_finds_an_edit_inside_the_data(tmp_path: Path) -> None:
    """Issue 28 item 1: the digest covers the data, not only the arrays."""
    store = ArtifactStore(tmp_path)
    key = _write_example(store)
    meta = store.path("rir", key) / "zarr.json"
    text = meta.read_text()
    assert '"hall"' in text and "\n " not in text  # compact JSON, not indented
    meta.write_text(text.replace('"hall"', '"hail"'))
    (problem,) = store.verify()
    assert problem.key == key and "data" in problem.problem and "digest" in problem.problem
    meta.write_text(text.replace("0.51", "NaN"))  # not even canonical JSON any more
    (problem,) = store.verify()
    assert "data" in problem.problem
    meta.write_text(text)
    assert store.verify() == []


def test_an_artifact_of_the_older_format_is_read_but_not_passed(tmp_path: Path) -> None:
    import json

    store = ArtifactStore(tmp_path)
    key = _write_example(store)
    meta = store.path("rir", key) / "zarr.json"
    doc = json.loads(meta.read_text())
    del doc["attributes"]["sonicspec"]["data_digest"], doc["attributes"]["sonicspec"]["format"]
    meta.write_text(json.dumps(doc, indent=2))
    assert store.read_data("rir", key)["scene"] == "hall"
    (problem,) = store.verify()
    assert re.search(r"store format 1, before 2\).*sonicspec build` makes it again",
                     problem.problem), problem.problem


def test_verify_reports_missing_and_leftover_temp(tmp_path: Path) -> None:
    store = ArtifactStore(tmp_path)
    key = _write_example(store)
    missing = "b" * 64
    (tmp_path / "rir" / "cd" / f".tmp-{'c' * 64}-1-x.zarr").mkdir(parents=True)
    problems = store.verify(expected={key: "rir", missing: "mix"})
    assert {(p.stage, p.key[:5], p.problem[:7]) for p in problems} == {
        ("mix", "bbbbb", "missing"), ("rir", ".tmp-", "unfinis")}


def test_full_disk_leaves_no_partial_artifact(tmp_path: Path, monkeypatch) -> None:
    store = ArtifactStore(tmp_path)
    kept = _write_example(store)

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "rename", no_space)
    key = content_key("mix", 1, {"x": 1})
    with pytest.raises(StoreError, match=r"mix [0-9a-f]{12}: cannot write .*the disk is full"):
        store.write("mix", key, {"x": np.ones(5)})
    monkeypatch.undo()
    assert not store.exists("mix", key)
    assert store.temp_folders() == []
    assert store.verify() == [] and store.exists("rir", kept)


def test_bad_keys_and_dtypes_are_refused(tmp_path: Path) -> None:
    store = ArtifactStore(tmp_path)
    with pytest.raises(StoreError, match="64 lowercase hex"):
        store.path("rir", "XYZ")
    with pytest.raises(StoreError, match="store text in data"):
        store.write("rir", "a" * 64, {"names": np.array(["a", "b"])})
    with pytest.raises(StoreError, match="no artifact"):
        store.read("rir", "a" * 64)


def test_stale_temp_of_a_zombie_writer_is_removed_and_a_live_one_kept(tmp_path: Path) -> None:
    """A writer killed with its parent stays a zombie where nobody reaps it (a container's
    first process): ``os.kill(pid, 0)`` succeeds on it, yet its folder is abandoned."""
    import socket
    import subprocess
    import sys
    import time

    store = ArtifactStore(tmp_path)
    host = socket.gethostname()
    zombie = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 10
    while Path(f"/proc/{zombie.pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z":
        assert time.monotonic() < deadline
        time.sleep(0.01)
    os.kill(zombie.pid, 0)  # still "exists"
    dead = tmp_path / "mix" / "ab" / f".tmp-{'ab' * 32}-{zombie.pid}-0123abcd@{host}.zarr"
    live = tmp_path / "mix" / "cd" / f".tmp-{'cd' * 32}-{os.getpid()}-0123abcd@{host}.zarr"
    for folder in (dead, live):
        folder.mkdir(parents=True)
        (folder / "zarr.json").write_text("{}")
    try:
        assert store.clean_stale_temp() == 1
        assert store.temp_folders() == [live]
    finally:
        zombie.wait()
