"""A diffuse background end to end (issue 30): a tiny spec with spherically isotropic noise
and half-diffuse cylindrical music on a circular array, built in-process; the exported noise
has the isotropic coherence between capsules, its target loudness and its field in the
metadata; a spec that leaves the field at ``point`` keeps every group job's key."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from scipy import signal

from sonicspec.acoustics.theory import spherical_isotropic_coherence
from sonicspec.audio.mix import integrated_loudness
from sonicspec.errors import SpecError
from sonicspec.plan.compile import compile_spec
from sonicspec.plan.model import Plan
from sonicspec.spec import load_spec
from sonicspec.stages import run_job

RADIUS_M = 0.05
SPEC = f"""\
sonicspec: 1
name: tiny_diffuse
seed: 5
sample_rate_hz: 16000
scenes:
  - kind: shoebox
    id: room
    size_m: [6.0, 5.0, 3.0]
    materials: {{walls: plaster_on_brick, floor: carpet_on_concrete,
                ceiling: acoustic_ceiling_tile}}
microphone: {{kind: circular_array, n: 4, radius_m: {RADIUS_M}, yaw_deg: 20}}
placement:
  source_start_distance_m: [1.0, 3.0]
  source_end_distance_m: [1.0, 3.0]
  source_travel_distance_m: [1.0, 2.0]
  noise_distance_m: [1.0, 3.0]
  music_distance_m: [1.0, 3.0]
trajectory: {{kind: shortest_path, rir_spacing_m: 0.5}}
acoustics: {{rays: 300, image_source_order: 1, max_rir_length_s: 0.3}}
corpora:
  speech: {{kind: generated, speakers_per_split: 2, utterances_per_speaker: 2}}
  noise: {{kind: generated, clips_per_split: 2, clip_duration_s: 6.0}}
  music: {{kind: generated, clips_per_split: 2, clip_duration_s: 3.0}}
mixture:
  duration_s: 20.0
  speakers: 1
  utterances_per_speaker: [1, 1]
  noise_clips: [3, 3]
  noise_gap_s: [0.0, 0.2]
  music_clips: [2, 2]
  noise_field: {{field: diffuse_spherical}}
  music_field: {{field: diffuse_cylindrical, diffuse_fraction: 0.5}}
  loudness: {{speech_lufs: -24, noise_lufs: -28, music_lufs: -31}}
  tasks:
    - {{kind: enhancement, background: both}}
splits:
  train: {{groups: 1, scenes: [room]}}
outputs: {{dir: out, store_dir: store, manifests: [lhotse]}}
"""


def build(tmp: Path, text: str = SPEC) -> Plan:
    (tmp / "spec.yaml").write_text(text)
    plan = compile_spec(load_spec(tmp / "spec.yaml"))
    for job in plan.jobs:
        run_job(plan, job.key)
    return plan


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Plan:
    return build(tmp_path_factory.mktemp("diffuse"))


def folder(plan: Plan) -> Path:
    return Path(plan.output_dir) / "train" / "000000"


def read(path: Path) -> np.ndarray:
    x, rate = sf.read(str(path), dtype="float64", always_2d=True)
    assert rate == 16000
    return x.T


def test_the_noise_has_the_isotropic_coherence_between_capsules(built: Plan) -> None:
    x = read(folder(built) / "noise.flac")
    assert x.shape[0] == 4
    yaw = math.radians(20)
    angles = yaw + 2 * math.pi * np.arange(4) / 4
    pos = RADIUS_M * np.column_stack([np.cos(angles), np.sin(angles)])
    for j in (1, 2):  # a side (7.1 cm) and a diameter (10 cm)
        d = float(np.linalg.norm(pos[0] - pos[j]))
        f, pxy = signal.csd(x[0], x[j], 16000, nperseg=512)
        _, pxx = signal.welch(x[0], 16000, nperseg=512)
        _, pyy = signal.welch(x[j], 16000, nperseg=512)
        band = (f >= 100) & (f <= 4000)
        gamma = pxy.real[band] / np.sqrt(pxx[band] * pyy[band])
        rms = float(np.sqrt(np.mean((gamma - spherical_isotropic_coherence(f[band], d)) ** 2)))
        assert rms < 0.05, (d, rms)


def test_the_diffuse_noise_is_at_its_target_loudness(built: Plan) -> None:
    meta = json.loads((folder(built) / "metadata.json").read_text())
    guard = meta["group_gain_db"] or 0.0
    for name, target in (("noise", -28), ("music", -31)):
        x = read(folder(built) / f"{name}.flac")
        assert integrated_loudness(x / 10 ** (guard / 20), 16000) == pytest.approx(
            target, abs=0.1), name
        assert meta[name]["loudness"]["target_lufs"] == target


def test_the_metadata_records_the_field(built: Plan) -> None:
    meta = json.loads((folder(built) / "metadata.json").read_text())
    assert meta["noise"]["field"] == "diffuse_spherical"
    assert meta["noise"]["diffuse_fraction"] == 1.0
    assert meta["music"]["field"] == "diffuse_cylindrical"
    assert meta["music"]["diffuse_fraction"] == 0.5
    assert "field" not in meta["source1"]


def test_same_spec_same_bytes(built: Plan, tmp_path: Path) -> None:
    other = build(tmp_path)

    def digest(plan: Plan) -> dict[str, str]:
        return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
                for p in folder(plan).glob("*.flac")}

    assert digest(other) == digest(built)


def test_a_point_field_keeps_every_group_jobs_key(tmp_path: Path) -> None:
    point = SPEC.replace("  noise_field: {field: diffuse_spherical}\n", "").replace(
        "  music_field: {field: diffuse_cylindrical, diffuse_fraction: 0.5}\n", "")
    (tmp_path / "a.yaml").write_text(point)
    (tmp_path / "b.yaml").write_text(point.replace(
        "  tasks:", "  noise_field: {field: point}\n  tasks:"))
    (tmp_path / "c.yaml").write_text(SPEC)
    (tmp_path / "d.yaml").write_text(SPEC.replace("{field: diffuse_spherical}",
                                                  "{field: diffuse_spherical, "
                                                  "diffuse_fraction: 0.9}"))
    a, b, c, d = (compile_spec(load_spec(tmp_path / n))
                  for n in ("a.yaml", "b.yaml", "c.yaml", "d.yaml"))
    keys = [{j.label: j.key for j in p.jobs if j.step != "dataset"} for p in (a, b, c, d)]
    assert keys[0] == keys[1]

    def changed(k: dict[str, str]) -> set[str]:
        return {label.split()[0] for label in keys[0] if keys[0][label] != k[label]}

    # A background partly heard from its point: the render job and what follows it change,
    # nothing before; heard only as a diffuse field (c), its point source is not traced
    # either, so the rir job changes too.
    assert changed(keys[3]) == {"render", "mix", "export"}
    assert changed(keys[2]) == {"rir", "render", "mix", "export"}
    rir_c = next(j for j in c.jobs if j.step == "rir")
    assert rir_c.params["untraced"] == ["noise"]
    assert "untraced" not in next(j for j in d.jobs if j.step == "rir").params


def test_a_diffuse_only_background_is_not_traced(built: Plan) -> None:
    """diffuse_fraction 1: the rir artifact holds no RIRs for the noise (music, half point,
    keeps its), and its metadata says so: no RIR points, no RIR facts."""
    from sonicspec import artifacts
    from sonicspec.store import ArtifactStore

    job = next(j for j in built.jobs if j.step == "rir")
    store = ArtifactStore(built.store_dir)
    rir = artifacts.decode("rir", store.read_data("rir", job.key), job.label)
    assert [s.name for s in rir.groups[0].sources] == ["source1", "music"]
    meta = json.loads((folder(built) / "metadata.json").read_text())
    assert meta["noise"]["rir_points_m"] == []
    for key in ("t30_s", "drr_db", "direct_path", "rir_tail", "image_source_order"):
        assert key not in meta["noise"], key
        assert key in meta["music"], key
    assert len(meta["noise"]["position_m"]) == 3  # the placement is a point spec's


def test_a_fraction_without_a_diffuse_field_is_an_error(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text(SPEC.replace(
        "{field: diffuse_spherical}", "{field: point, diffuse_fraction: 0.5}"))
    with pytest.raises(SpecError, match=r"noise_field.*diffuse_fraction 0.5 needs field"):
        load_spec(tmp_path / "bad.yaml")


def test_a_diffuse_field_without_its_track_is_a_warning() -> None:
    from sonicspec.spec.load import format_path
    from sonicspec.spec.validate import validate_text

    text = SPEC.replace("  music_clips: [2, 2]\n", "  music_clips: [0, 0]\n").replace(
        "    - {kind: enhancement, background: both}", "    - {kind: enhancement}")
    loaded, problems = validate_text(text, "w.yaml")
    assert loaded is not None, [p.format("w.yaml") for p in problems]
    warned = {format_path(w.path): w.format("w.yaml") for w in loaded.warnings}
    assert "'diffuse_cylindrical' has no effect: a group has no music track" in warned[
        "mixture.music_field"]
    assert "mixture.noise_field" not in warned
