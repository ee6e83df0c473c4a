"""Synthetic dataset folders for the report's tests and benchmark: ``dataset.json`` and one
``metadata.json`` per group in the form ``stages.export`` writes, with no audio and no store.

Positions, paths, levels and segments are drawn from a seeded generator so the figures vary
like a real dataset's; nothing here is acoustically meaningful.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.hashing import rng_for

SPEC = {
    "sonicspec": 1, "name": "synthetic", "description": "metadata only, for the report",
    "seed": 7, "sample_rate_hz": 16000,
    "placement": {"source_start_distance_m": [1.0, 8.0], "source_end_distance_m": [1.0, 8.0],
                  "source_travel_distance_m": [1.0, 8.0]},
    "mixture": {"duration_s": 60.0, "speakers": 3,
                "loudness": {"speech_lufs": -17.0, "noise_lufs": -21.0, "music_lufs": -24.0}},
    "splits": {"train": {"groups": 0}, "val": {"groups": 0}, "test": {"groups": 0}},
}


def _track(points: np.ndarray, mic: np.ndarray, n: int, start: int, end: int) -> dict[str, Any]:
    """A 10 ms track that walks ``points`` between hops ``start`` and ``end``, held outside."""
    t = np.clip((np.arange(n) - start) / max(1, end - start), 0.0, 1.0)
    seg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    at = t * seg[-1]
    pos = np.stack([np.interp(at, seg, points[:, i]) for i in range(3)], axis=1)
    rel = pos - mic
    dist = np.linalg.norm(rel, axis=1)
    return {"hop_s": 0.01, "positions_m": np.round(pos, 4).tolist(),
            "azimuth_deg": np.round(np.degrees(np.arctan2(rel[:, 1], rel[:, 0])), 2).tolist(),
            "elevation_deg": np.round(np.degrees(np.arcsin(rel[:, 2] / np.maximum(dist, 1e-9))),
                                      2).tolist(),
            "distance_m": np.round(dist, 4).tolist()}


def synthetic_metadata(group: str, scene_id: str, seed: int, *, speakers: int = 3,
                       duration_s: float = 60.0, rate: int = 16000) -> dict[str, Any]:
    """One group's metadata (see the module docstring)."""
    rng = rng_for(seed, "synthetic-metadata", group)
    split = group.split("/")[0]
    n = int(duration_s * rate)
    hops = round(duration_s / 0.01)
    mic = np.array([*rng.uniform(2.0, 8.0, 2), 1.5])
    gain = float(min(0.0, rng.normal(-0.5, 1.5)))
    meta: dict[str, Any] = {}
    for k in range(speakers):
        a = np.array([*rng.uniform(0.0, 10.0, 2), 1.7])
        b = np.array([*rng.uniform(0.0, 10.0, 2), 1.7])
        mid = (a + b) / 2 + np.array([*rng.normal(0, 0.5, 2), 0.0])
        path = np.stack([a, mid, b])
        length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        segs = []
        t0 = int(rng.integers(0, n // 3))
        for _ in range(int(rng.integers(1, 4))):
            t1 = min(n, t0 + int(rng.uniform(3, 12) * rate))
            segs.append([t0, t1])
            t0 = t1 + int(rng.uniform(0, 5) * rate)
            if t0 >= n:
                break
        measured = float(rng.normal(-35, 4))
        target = -17.0
        meta[f"source{k + 1}"] = {
            "audio": [f"{split}/spk{k}/utt{j}.flac" for j in range(len(segs))],
            "start_end_points": segs, "file": f"{group}/source{k + 1}.flac",
            "rir_points_m": path.tolist(), "t30_s": float(rng.uniform(0.3, 1.2)),
            "drr_db": float(rng.normal(-4, 4)),
            "direct_path": str(rng.choice(["visible", "visible", "visible", "through walls",
                                           "blocked"])),
            "loudness": {"role": "speech", "target_lufs": target, "measured_lufs": measured,
                         "gain_db": target - measured, "output_lufs": target + gain,
                         "measured_on": "reverberant"},
            "track": _track(path, mic, hops, segs[0][0] // 160, segs[-1][1] // 160),
            "words": ["A SENTENCE"] * len(segs), "speaker": f"{split}-{int(rng.integers(40))}",
            "trajectory_m": path.tolist(), "path_length_m": length,
        }
    for role, target in (("noise", -21.0), ("music", -24.0)):
        p = np.array([[*rng.uniform(0.0, 10.0, 2), 1.6]])
        measured = float(rng.normal(-33, 4))
        meta[role] = {
            "audio": [f"{split}/{role}.flac"], "start_end_points": [[0, n // 2], [n // 2, n]],
            "file": f"{group}/{role}.flac", "rir_points_m": p.tolist(),
            "t30_s": float(rng.uniform(0.3, 1.2)), "drr_db": float(rng.normal(-8, 3)),
            "direct_path": "visible",
            "loudness": {"role": role, "target_lufs": target, "measured_lufs": measured,
                         "gain_db": target - measured, "output_lufs": target + gain,
                         "measured_on": "reverberant"},
            "track": _track(np.repeat(p, 2, axis=0), mic, hops, 0, 1),
            "position_m": p[0].tolist(),
        }
    meta.update(group=group, split=split, scene_id=scene_id, mic_m=mic.tolist(), floor=0,
                sample_rate_hz=rate, num_samples=n,
                mixtures=[{"name": "sep_s1s2_noise", "task": "separation",
                           "components": ["source1", "source2", "noise"],
                           "targets": ["source1", "source2"],
                           "file": f"{group}/mixtures/sep_s1s2_noise.flac"}],
                group_gain_db=gain, keys={})
    return meta


def write_synthetic_dataset(root: Path, groups: dict[str, int], *, scenes: int = 3,
                            seed: int = 7, duration_s: float = 60.0) -> Path:
    """A dataset folder with ``groups[split]`` groups per split over ``scenes`` scenes per
    split (metadata and ``dataset.json`` only)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    entries = []
    for s, (split, count) in enumerate(groups.items()):
        for i in range(count):
            group = f"{split}/{i:06d}"
            scene = f"scene{s * scenes + i % scenes:02d}"
            folder = root / group
            folder.mkdir(parents=True, exist_ok=True)
            meta = synthetic_metadata(group, scene, seed, duration_s=duration_s)
            # as stages.export writes it (export.files.write_json)
            (folder / "metadata.json").write_text(
                json.dumps(meta, indent=2, sort_keys=True, ensure_ascii=False) + "\n")
            entries.append({"group": group, "split": split, "scene_id": scene,
                            "metadata": {"path": f"{group}/metadata.json"}})
    spec = json.loads(json.dumps(SPEC))
    spec["seed"] = seed
    spec["splits"] = {s: {"groups": c} for s, c in groups.items()}
    spec["mixture"]["duration_s"] = duration_s
    summary = {"name": "synthetic", "description": SPEC["description"],
               "sonicspec_version": "synthetic", "spec_version": 1, "spec": spec,
               "splits": {s: {"groups": c, "files": 0, "audio_hours": c * duration_s / 3600}
                          for s, c in groups.items()},
               "groups": entries, "manifests": [], "corpus_files_skipped": {}}
    (root / "dataset.json").write_text(json.dumps(summary, indent=2))
    return root
