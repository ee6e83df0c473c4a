"""The stages from corpus to dataset, run in-process on one tiny group, checked by their output.

What a user of the dataset relies on: every exported component at its target loudness, the
mixtures are the sums of their parts, utterances sit where the metadata says, training targets
line up with the reverberant track, manifests point at real files, and a failing job names
itself and keeps what was finished.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from sonicspec.audio.mix import integrated_loudness
from sonicspec.errors import StageError
from sonicspec.export.tracks import read_track
from sonicspec.plan.compile import compile_spec
from sonicspec.plan.model import Plan
from sonicspec.spec import load_spec
from sonicspec.stages import run_job
from sonicspec.store import ArtifactStore

SPEC = """\
sonicspec: 1
name: tiny
seed: 11
sample_rate_hz: 16000
scenes:
  - kind: shoebox
    id: room
    size_m: [6.0, 5.0, 3.0]
    materials: {walls: plaster_on_brick, floor: carpet_on_concrete, ceiling: acoustic_ceiling_tile}
placement:
  source_start_distance_m: [1.0, 3.0]
  source_end_distance_m: [1.0, 3.0]
  source_travel_distance_m: [1.0, 2.0]
  noise_distance_m: [1.0, 3.0]
  music_distance_m: [1.0, 3.0]
trajectory: {kind: shortest_path, rir_spacing_m: 0.5}
acoustics: {rays: 500, image_source_order: 1, max_rir_length_s: 0.3}
corpora:
  speech: {kind: generated, speakers_per_split: 2, utterances_per_speaker: 2}
  noise: {kind: generated, clips_per_split: 2, clip_duration_s: 2.0}
  music: {kind: generated, clips_per_split: 2, clip_duration_s: 2.0}
mixture:
  duration_s: 8.0
  speakers: 2
  utterances_per_speaker: [1, 2]
  utterance_gap_s: [0.0, 1.0]
  noise_clips: [2, 3]
  noise_gap_s: [0.0, 0.5]
  music_clips: [2, 3]
  music_gap_s: [0.0, 0.5]
  targets: [dry, direct, early]
  tasks:
    - {kind: separation, speakers: 2, background: music}
    - {kind: enhancement, background: noise}
splits:
  train: {groups: 1, scenes: [room]}
outputs: {dir: out, store_dir: store, manifests: [lhotse, csv], rirs: true}
"""


def build(tmp: Path, text: str = SPEC) -> Plan:
    (tmp / "spec.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp / "spec.yaml"))
    for job in plan.jobs:
        run_job(plan, job.key)
    return plan


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Plan:
    return build(tmp_path_factory.mktemp("tiny"))


def group_folder(plan: Plan) -> Path:
    return Path(plan.output_dir) / "train" / "000000"


def read(path: Path) -> np.ndarray:
    x, rate = sf.read(str(path), dtype="float64", always_2d=True)
    assert rate == 16000
    return x.T


def test_components_are_at_their_target_loudness(built: Plan) -> None:
    meta = json.loads((group_folder(built) / "metadata.json").read_text())
    # espeak's peaky speech at -17 LUFS over noise peaks above -1 dBFS in a mixture: the
    # guard lowers the whole group by one recorded gain, keeping the levels between parts.
    guard = meta["group_gain_db"]
    assert -6.0 < guard < 0.0
    peaks = [np.max(np.abs(read(p))) for p in group_folder(built).rglob("*.flac")]
    assert max(peaks) == pytest.approx(10 ** (-1 / 20), abs=1e-4)
    for name, target in (("source1", -17), ("source2", -17), ("noise", -21), ("music", -24)):
        x = read(group_folder(built) / f"{name}.flac")
        # The normalised component (the file before the group's guard) is at its target.
        normalised = x / 10 ** (guard / 20)
        assert integrated_loudness(normalised, 16000) == pytest.approx(target, abs=0.1), name
        # The file is what the metadata says; target + guard only up to BS.1770's gates,
        # which do not scale with the gain (quiet blocks cross the −70 LUFS gate).
        out = meta[name]["loudness"]["output_lufs"]
        assert integrated_loudness(x, 16000) == pytest.approx(out, abs=0.02), name
        assert out == pytest.approx(target + guard, abs=0.5), name
        assert meta[name]["loudness"]["target_lufs"] == target
    # The dry target is brought to the same level on its own, or lower to keep its peaks
    # under the limit (-1 dBFS).
    for name in ("source1", "source2"):
        dry = read(group_folder(built) / f"{name}_dry.flac")
        level, peak = integrated_loudness(dry, 16000), float(np.max(np.abs(dry)))
        assert level == pytest.approx(-17, abs=0.1) or (
            level < -17 and peak == pytest.approx(10 ** (-1 / 20), abs=1e-4)), (level, peak)


def test_mixtures_are_the_sums_of_their_parts(built: Plan) -> None:
    folder = group_folder(built)
    meta = json.loads((folder / "metadata.json").read_text())
    names = [m["name"] for m in meta["mixtures"]]
    assert names == ["sep_s1s2_music", "enh_s1_noise", "enh_s2_noise"]
    for m in meta["mixtures"]:
        total = sum(read(folder / f"{c}.flac") for c in m["components"])
        mixture = read(Path(built.output_dir) / m["file"])
        # Each file is rounded to 16 bits on its own: at most one LSB per part apart.
        assert np.max(np.abs(mixture - total)) <= (len(m["components"]) + 1) / 32768


def test_utterances_sit_where_the_metadata_says(built: Plan) -> None:
    folder = group_folder(built)
    meta = json.loads((folder / "metadata.json").read_text())
    for name in ("source1", "source2"):
        entry = meta[name]
        dry = read(folder / f"{name}_dry.flac")[0]
        assert len(entry["audio"]) == len(entry["start_end_points"]) == len(entry["words"])
        inside = np.zeros(dry.size, dtype=bool)
        for (start, end), words, rel in zip(entry["start_end_points"], entry["words"],
                                            entry["audio"], strict=True):
            assert 0 <= start < end <= 8 * 16000
            assert words == words.upper() and len(words.split()) >= 3
            assert rel.startswith(f"generated-train/{entry['speaker']}/")
            assert np.max(np.abs(dry[start:start + 1600])) > 1e-3  # speech starts there
            inside[start:end] = True
        assert np.all(dry[~inside] == 0.0)  # and nothing plays elsewhere
        assert len(entry["rir_points_m"]) >= 3  # a moving source, RIRs every 0.5 m


def test_targets_line_up_with_the_reverberant_track(built: Plan) -> None:
    folder = group_folder(built)
    full = read(folder / "source1.flac")[0]
    direct = read(folder / "source1_direct.flac")[0]
    early = read(folder / "source1_early.flac")[0]
    e_full, e_direct, e_early = (float(np.sum(x**2)) for x in (full, direct, early))
    assert e_direct < e_early < e_full
    # The direct sound arrives first: the reverberant track and the direct target start
    # together (and the early target too), and until the first reflection they are equal.
    threshold = 0.05 * float(np.max(np.abs(direct)))
    onsets = [int(np.argmax(np.abs(x) > threshold)) for x in (full, direct, early)]
    assert max(onsets) - min(onsets) <= 2, onsets
    start = onsets[0]
    assert np.max(np.abs(full[start:start + 8] - early[start:start + 8])) <= 2 / 32768


def test_rirs_and_manifests_point_at_real_files(built: Plan) -> None:
    out = Path(built.output_dir)
    rir = read(group_folder(built) / "rirs" / "source1" / "000.wav")
    assert rir.shape[0] == 1 and 0.2 * 16000 < rir.shape[1] <= 0.3 * 16000 + 200
    recordings = [json.loads(line) for line in
                  (out / "manifests" / "train_recordings.jsonl").read_text().splitlines()]
    supervisions = [json.loads(line) for line in
                    (out / "manifests" / "train_supervisions.jsonl").read_text().splitlines()]
    by_id = {r["id"]: r for r in recordings}
    for r in recordings:
        info = sf.info(str(out / r["sources"][0]["source"]))
        assert info.frames == r["num_samples"] and info.channels == len(r["channel_ids"])
    meta = json.loads((group_folder(built) / "metadata.json").read_text())
    # How each source's RIR length was chosen (issue 19): the spec's 0.3 s, taken as asked.
    tail = meta["source1"]["rir_tail"]
    assert tail["rule"] == "fixed" and tail["limit_s"] == 0.3
    assert len(tail["decay_60db_s"]) == len(tail["level_at_limit_db"]) == 6
    spoken = sum(len(meta[s]["words"]) for s in ("source1", "source2"))
    # Each utterance is supervised on its source, its dry/direct/early targets are not
    # recordings of the task, and on every mixture containing it (1 separation + 1 enhancement).
    assert len(supervisions) == 3 * spoken
    assert all(s["recording_id"] in by_id for s in supervisions)
    # IDs are unique (Lhotse's validate_recordings_and_supervisions refused the duplicates a
    # mixture's sources made), and every supervision lies inside its recording.
    assert len({s["id"] for s in supervisions}) == len(supervisions)
    assert len(by_id) == len(recordings)
    for s in supervisions:
        assert 0 <= s["start"] and s["start"] + s["duration"] <= by_id[s["recording_id"]][
            "duration"] + 1e-6
    summary = json.loads((out / "dataset.json").read_text())
    assert summary["splits"]["train"]["groups"] == 1 and summary["spec"]["name"] == "tiny"
    assert (out / "manifests" / "train.csv").read_text().count("\n") == 1 + len(
        [f for f in summary_files(out)])


def summary_files(out: Path) -> list[Path]:
    return [p for p in (out / "train").rglob("*") if p.is_file()]


def test_same_spec_same_bytes_in_another_folder(built: Plan, tmp_path: Path) -> None:
    other = build(tmp_path)
    for p in sorted(Path(built.output_dir).rglob("*")):
        if p.is_file() and p.suffix in (".flac", ".wav", ".jsonl"):
            twin = Path(other.output_dir) / p.relative_to(built.output_dir)
            assert twin.read_bytes() == p.read_bytes(), p


def test_impossible_placement_names_the_job_and_keeps_finished_work(tmp_path: Path) -> None:
    text = SPEC.replace("source_start_distance_m: [1.0, 3.0]", "source_start_distance_m: "
                        "[7.9, 8.2]")
    (tmp_path / "spec.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp_path / "spec.yaml"))
    store = ArtifactStore(plan.store_dir)
    done = []
    with pytest.raises(StageError, match=r"placement train/room#0: .*room"):
        for job in plan.jobs:
            run_job(plan, job.key)
            done.append(job)
    assert done and all(store.exists(j.step, j.key) for j in done)
    assert store.verify() == []


def test_unreadable_mesh_names_the_job(tmp_path: Path) -> None:
    (tmp_path / "broken.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nend_header\n"
                                         "0 0\n")
    text = SPEC.replace("  - kind: shoebox\n    id: room\n    size_m: [6.0, 5.0, 3.0]\n",
                        "  - kind: mesh\n    id: room\n    path: broken.ply\n")
    text = text.replace("    materials: {walls: plaster_on_brick, floor: carpet_on_concrete, "
                        "ceiling: acoustic_ceiling_tile}\n", "")
    (tmp_path / "spec.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp_path / "spec.yaml"))
    mesh = next(j for j in plan.jobs if j.step == "mesh")
    with pytest.raises(StageError, match=r"mesh room: .*broken.ply"):
        run_job(plan, mesh.key)
    assert not ArtifactStore(plan.store_dir).exists("mesh", mesh.key)


def test_full_disk_during_export_names_the_job_and_file(built: Plan, tmp_path: Path,
                                                        monkeypatch) -> None:
    """A full disk while writing the dataset folder stops the export job with a message
    naming it and the file; the files already there keep their content."""
    before = (group_folder(built) / "source1.flac").read_bytes()
    plan = build(tmp_path)  # a finished build; now make its export run again
    export = next(j for j in plan.jobs if j.step == "export")
    store = ArtifactStore(plan.store_dir)
    import shutil

    shutil.rmtree(store.path("export", export.key))
    real_replace = os.replace

    def full(src, dst):
        if str(dst).endswith(".flac"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(StageError, match=r"export train/room#0: cannot write .*\.flac.*the disk "
                                         "is full"):
        run_job(plan, export.key)
    monkeypatch.undo()
    assert not store.exists("export", export.key)
    assert (group_folder(plan) / "source1.flac").read_bytes() == before
    assert [p for p in Path(plan.output_dir).rglob(".*tmp*")] == []


def test_real_corpus_layouts_feed_a_build(tmp_path: Path) -> None:
    """LibriSpeech, FSD50K and FMA as they are laid out on disk (written by the fixtures)
    go through the real readers into a dataset; the metadata names their files."""
    from sonicspec.audio.generated import write_librispeech
    from sonicspec.testing import corpora as tc

    data = tmp_path / "data"
    write_librispeech(data / "LibriSpeech", {"train-clean-360": 3}, 2, seed=1)
    tc.write_fsd50k(data / "FSD50K", 6, 2, clip_duration_s=2.0, seed=2)
    tc.write_fma(data / "fma", 10, clip_duration_s=2.0, seed=3)
    text = SPEC.replace(
        "  speech: {kind: generated, speakers_per_split: 2, utterances_per_speaker: 2}\n"
        "  noise: {kind: generated, clips_per_split: 2, clip_duration_s: 2.0}\n"
        "  music: {kind: generated, clips_per_split: 2, clip_duration_s: 2.0}\n",
        "  speech: {kind: librispeech, root: data/LibriSpeech, subsets: {train: "
        "[train-clean-360]}}\n"
        "  noise: {kind: fsd50k, root: data/FSD50K, split_ratios: {train: 1.0}}\n"
        "  music: {kind: fma, root: data/fma, split_ratios: {train: 1.0}}\n")
    assert "librispeech" in text
    plan = build(tmp_path, text)
    meta = json.loads((group_folder(plan) / "metadata.json").read_text())
    assert all(p.startswith("train-clean-360/") and p.endswith(".flac")
               for p in meta["source1"]["audio"])
    assert all(p.startswith("FSD50K.") and p.endswith(".wav") for p in meta["noise"]["audio"])
    assert all(p.startswith("fma_small/") and p.endswith(".mp3") for p in meta["music"]["audio"])
    music = read(group_folder(plan) / "music.flac")
    assert integrated_loudness(music, 16000) == pytest.approx(-24 + meta["group_gain_db"],
                                                              abs=0.1)


def test_a_clip_repeated_in_a_track_and_cut_at_the_end_renders(tmp_path: Path) -> None:
    """Issue 20's bug: with a small corpus a noise clip repeats in its track and its last use
    is cut at the clip's end; the render kept only the cut copy and the full use failed
    ("segment 'n0': needs 48000 samples ... the clip has ...")."""
    from sonicspec.artifacts import ArrangedTrack
    from sonicspec.audio.arrange import Clip, arrange_background, assemble
    from sonicspec.stages.render import _AudioCache, track_audio

    fs = 16000
    clip = np.random.default_rng(0).uniform(-0.5, 0.5, 3 * fs)
    sf.write(str(tmp_path / "n0.wav"), clip, fs, subtype="FLOAT")
    segments = arrange_background([Clip("n0", 3 * fs)], 10 * fs, (4, 4), (0.0, 0.0), fs,
                                  np.random.default_rng(1))
    assert [s.id for s in segments] == ["n0"] * 4 and segments[-1].end - segments[-1].start < 3 * fs
    track = ArrangedTrack(name="noise", role="noise", speaker="",
                          segments=[s.to_dict() for s in segments],
                          files={"n0": {"path": "n0.wav", "sample_rate_hz": fs, "speaker": ""}})
    dry = assemble(segments, track_audio(track, segments, _AudioCache(fs), tmp_path), 10 * fs)
    for s in segments:
        np.testing.assert_allclose(dry[s.start:s.end], clip[:s.end - s.start], atol=1e-7)


def test_metadata_tracks_are_the_positions_the_renderer_used(built: Plan) -> None:
    """Issue 18: every source (and the microphone) has its position every 10 ms over the
    whole clip, from the walk the renderer read, with azimuth, elevation and distance in the
    microphone's frame; the Lhotse recording of a source carries the same track."""
    from sonicspec.audio.arrange import Segment, speech_span
    from sonicspec.audio.render import walk_index

    meta = json.loads((group_folder(built) / "metadata.json").read_text())
    store = ArtifactStore(built.store_dir)
    jobs = built.by_step()
    placement = store.read_data("placement", jobs["placement"][0].key)["groups"][0]
    arranged = {t["name"]: t for t in
                store.read_data("arrange", jobs["arrange"][0].key)["groups"][0]["tracks"]}
    clip = meta["num_samples"]
    mic = np.asarray(meta["mic_m"])
    hops = -(-clip // 160)
    out = Path(built.output_dir)
    for name in ("source1", "source2", "noise", "music"):
        track = read_track(out, meta[name]["track"])
        assert track["hop_s"] == 0.01 and len(track["positions_m"]) == hops
        geometry = (placement["speech"][int(name[6:]) - 1] if name.startswith("source")
                    else placement[name])
        segments = [Segment.from_dict(s) for s in arranged[name]["segments"]]
        index = walk_index(geometry["rir_points_distance_m"], clip, speech_span(segments),
                           None, 16000)
        points = np.asarray(geometry["rir_points_m"])
        used = np.stack([np.interp(index, np.arange(len(points)), points[:, i])
                         for i in range(3)], axis=1)[::160]
        positions = np.asarray(track["positions_m"])
        np.testing.assert_allclose(positions, used, atol=1e-4)
        np.testing.assert_allclose(positions[0], points[0], atol=1e-4)  # held before
        np.testing.assert_allclose(positions[-1], points[-1], atol=1e-4)  # and after
        offset = positions - mic
        np.testing.assert_allclose(track["distance_m"], np.linalg.norm(offset, axis=1),
                                   atol=2e-4)
        # The mono microphone faces +x (yaw 0): azimuth is the bearing from +x.
        np.testing.assert_allclose(track["azimuth_deg"],
                                   np.degrees(np.arctan2(offset[:, 1], offset[:, 0])), atol=0.02)
    mic_track = read_track(out, meta["microphone_track"])
    np.testing.assert_allclose(mic_track["positions_m"], [meta["mic_m"]] * hops,
                               atol=1e-4)  # labels to 0.1 mm, as the sources'
    assert "yaw_deg" not in mic_track  # a static microphone: no heading
    recordings = {json.loads(x)["id"]: json.loads(x) for x in
                  (Path(built.output_dir) / "manifests" / "train_recordings.jsonl")
                  .read_text().splitlines()}
    assert recordings["train_000000_source1"]["custom"]["track"] == meta["source1"]["track"]
    assert "custom" not in recordings["train_000000_mixtures_sep_s1s2_music"]


def test_metadata_validates_and_the_tracks_are_stored_once(built: Plan) -> None:
    """Issue 27: metadata.json follows its schema (and model), is compact JSON, and holds
    references to tracks.npz, not the 10 ms numbers; the non-audio bytes stay within 20 kB
    per group-second."""
    import jsonschema

    from sonicspec.export.metadata import GroupMetadata, metadata_schema

    path = group_folder(built) / "metadata.json"
    text = path.read_text()
    meta = json.loads(text)
    jsonschema.Draft202012Validator(metadata_schema()).validate(meta)
    assert GroupMetadata.model_validate(meta).to_json() == text  # the model wrote it
    assert meta["version"] == 2 and "\n " not in text
    # issue 27 item 6: each track says how far its exact early reflections went
    assert meta["source1"]["image_source_order"] == {"asked": 1, "reached": 1, "stopped": None}
    refs = [meta[n]["track"] for n in ("source1", "source2", "noise", "music")]
    assert {r["file"] for r in [*refs, meta["microphone_track"]]} == {"train/000000/tracks.npz"}
    with np.load(group_folder(built) / "tracks.npz") as z:
        assert sorted(z.files) == sorted(
            [f"{n}.{q}" for n in ("source1", "source2", "noise", "music")
             for q in ("positions_m", "azimuth_deg", "elevation_deg", "distance_m")]
            + ["microphone.positions_m"])
    seconds = meta["num_samples"] / meta["sample_rate_hz"]
    non_audio = sum(p.stat().st_size for p in group_folder(built).iterdir()
                    if p.is_file() and p.suffix in (".json", ".npz"))
    assert non_audio / seconds <= 20_000, non_audio / seconds
    # The export record references the tracks too (it held a third copy of the numbers).
    record = ArtifactStore(built.store_dir).read_data(
        "export", built.by_step()["export"][0].key)["groups"][0]
    tracked = [r["custom"]["track"] for r in record["recordings"] if "custom" in r]
    assert tracked == refs and all(len(json.dumps(r)) < 1000 for r in record["recordings"])


def test_a_cap_below_the_decay_is_a_warning_in_the_rir_jobs_log(tmp_path: Path,
                                                                caplog) -> None:
    """Issue 19: with `max_rir_length_s: auto` a cap below the room's decay is logged by the
    rir job as a WARNING line naming the scene (what the build's summary collects)."""
    text = SPEC.replace("max_rir_length_s: 0.3}", "max_rir_length_s: auto, "
                        "max_rir_cap_s: 0.2}")
    (tmp_path / "spec.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp_path / "spec.yaml"))
    with caplog.at_level("WARNING", logger="sonicspec.stages.rir"):
        for job in plan.jobs:
            if job.step in ("mesh", "navigation", "placement", "rir"):
                run_job(plan, job.key)
    (record,) = [r for r in caplog.records if r.name == "sonicspec.stages.rir"]
    assert record.levelname == "WARNING"
    assert record.getMessage().startswith("scene 'room' (")
    assert "cut at 0.2 s (acoustics.max_rir_cap_s)" in record.getMessage()


def test_the_rir_job_records_its_edges_and_image_source_order(tmp_path: Path, caplog) -> None:
    """Issues 32 and 27: the rir artifact says per group how the diffracting edges were chosen
    (one set for the group, for its own positions) and per source the image-source order
    asked and reached; the job's log says how many edges it kept."""
    text = SPEC.replace("max_rir_length_s: 0.3}", "max_rir_length_s: 0.3, "
                        "diffraction: true, diffraction_max_edges: 2}").replace(
        "ceiling: acoustic_ceiling_tile}", "ceiling: acoustic_ceiling_tile}\n    obstacles: "
        "[{kind: box, center_m: [5.5, 4.5, 0.4], size_m: [0.4, 0.4, 0.8]}]")
    (tmp_path / "spec.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp_path / "spec.yaml"))
    with caplog.at_level("INFO", logger="sonicspec.stages.rir"):
        for job in plan.jobs:
            if job.step in ("mesh", "navigation", "placement", "rir"):
                run_job(plan, job.key)
    (rir_job,) = [j for j in plan.jobs if j.step == "rir"]
    data = ArtifactStore(plan.store_dir).read_data("rir", rir_job.key)
    for group in data["groups"]:
        edges = group["diffraction_edges"]
        # the box stands on the floor: its four bottom edges are buried, not in the air
        assert (edges["found"], edges["kept"], edges["buried_left_out"]) == (8, 2, 4)
        assert edges["near_points"] >= 2
        assert "distance to the nearest of" in edges["rule"]
        for source in group["sources"]:
            assert source["image_source_order"] == source["image_source_order_asked"] == 1
            assert source["image_source_order_stopped"] is None
    lines = [r.getMessage() for r in caplog.records if "diffraction keeps" in r.getMessage()]
    assert len(lines) == len(data["groups"])
    assert not [r for r in caplog.records if r.levelname == "WARNING"
                and "image-source order" in r.getMessage()]


def test_rirs_a_fixed_length_cuts_while_decaying_are_a_warning_in_the_log(tmp_path: Path,
                                                                        caplog) -> None:
    """Issue 28 item 8: a fixed ``max_rir_length_s`` below the room's decay is taken as asked,
    but the rir job logs a WARNING (what the build summary collects) naming the scene, the
    group, how many RIRs, the bands' levels and the field to raise."""
    (tmp_path / "spec.yaml").write_text(SPEC.replace("max_rir_length_s: 0.3}",
                                                     "max_rir_length_s: 0.05}"))
    plan = compile_spec(load_spec(tmp_path / "spec.yaml"))
    with caplog.at_level("WARNING", logger="sonicspec.stages.rir"):
        for job in plan.jobs:
            if job.step in ("mesh", "navigation", "placement", "rir"):
                run_job(plan, job.key)
    messages = [r.getMessage() for r in caplog.records if r.name == "sonicspec.stages.rir"]
    assert messages, "no warning for RIRs cut at 0.05 s"
    assert re.match(r"scene 'room', group train/000000: \d+ of \d+ RIRs cut at 0.05 s "
                    r"\(acoustics.max_rir_length_s\) while still decaying \(125 Hz at -\d+ dB",
                    messages[0]), messages[0]
    assert messages[0].endswith("raise acoustics.max_rir_length_s or set it to auto")
    # a decay 60 dB down within the length, or an `auto` cut (the engine's warning): none here
    from sonicspec.acoustics.engine import RirFacts
    from sonicspec.acoustics.late.tails import TailFacts
    from sonicspec.stages.rir import fixed_cut_warning

    def facts(tail: TailFacts) -> RirFacts:
        return RirFacts(arrivals=1, direct="visible", image_source_order=1,
                        image_source_order_asked=1, image_source_order_stopped=None,
                        escaped_ray_fraction=0.0, tail=tail)

    done = TailFacts(rule="fixed", limit_s=1.0, limit_field="max_rir_length_s",
                     decay_end_s=0.5, decay_60db_s=(0.5, 0.4), continued_from_s=(None, None),
                     level_at_limit_db=(None, None), fitted_t60_s=(None, None))
    assert fixed_cut_warning([facts(done)], (500.0, 1000.0), "x") is None
    auto = dataclasses.replace(done, rule="auto", level_at_limit_db=(-20.0, None))
    assert fixed_cut_warning([facts(auto)], (500.0, 1000.0), "x") is None
    cut = dataclasses.replace(done, level_at_limit_db=(-20.0, None), fitted_t60_s=(3.0, None))
    assert "1 of 1 RIRs cut at 1 s" in fixed_cut_warning([facts(cut)], (500.0, 1000.0), "x")
