"""Synthetic inputs of the ``dataset`` step at any size, without rendering a sample of audio.

The dataset step reads only the export jobs' records (the files each group wrote, with their
SHA-256 and size, the Lhotse recordings and supervisions, the metadata's path) and the plan.
:func:`write_dataset_inputs` writes export artifacts whose records have the shape and size of
a SonicSet-preset group's (3 moving talkers of 3–5 utterances, noise, music, the preset's three
mixtures, a dry target per talker, ``metadata.json`` and ``tracks.npz``), built with the same
manifest classes and track references as :mod:`sonicspec.stages.export`, into a store with a
plan file holding those export jobs and the dataset job — what ``sonicspec job`` runs. The
digests and sizes in the records are made up (no dataset folder is written): the step only
copies them.

Shards interleave in group order (groups go to scenes in turn, a shard holds one scene's
groups), as :func:`sonicspec.plan.compile.compile_spec` cuts them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.export.manifests import RecordingEntry, SupervisionEntry
from sonicspec.export.tracks import SCALES, TRACKS_NAME
from sonicspec.hashing import rng_for, sha256_hex
from sonicspec.plan.model import STEP_BY_NAME, Job, Plan
from sonicspec.spec.templates import template_body
from sonicspec.store import ArtifactStore

MIXTURES = (("sep_s1s2_noise", ("source1", "source2", "noise")),
            ("sep_s1s2_music", ("source1", "source2", "music")),
            ("enh_s1_noise", ("source1", "noise")))
"""The sonicset preset's tasks as the mix step names them."""


def _reference(group: str, owner: str, frames: int, quantities: tuple[str, ...]
               ) -> dict[str, Any]:
    return {"file": f"{group}/{TRACKS_NAME}", "frames": frames, "hop_s": 0.01,
            "arrays": {q: f"{owner}.{q}" for q in quantities},
            "scale": {q: SCALES[q] for q in quantities}}


def synthetic_export_group(group: str, scene_id: str, seed: int, *, duration_s: float = 60.0,
                           rate: int = 16000, speakers: int = 3) -> dict[str, Any]:
    """One group's export record (see the module docstring)."""
    rng = rng_for(seed, "synthetic-export", group)
    split, index = group.split("/")
    n = int(duration_s * rate)
    frames = round(duration_s / 0.01)
    files: list[dict[str, Any]] = []
    recordings: list[dict[str, Any]] = []
    rec_ids: dict[str, str] = {}

    def add(kind: str, name: str, channels: int = 1, custom: dict[str, Any] | None = None,
            ext: str = "flac") -> None:
        path = f"{group}/{name}.{ext}"
        files.append({"kind": kind, "name": name, "path": path,
                      "sha256": sha256_hex(f"{seed}:{path}"),
                      "bytes": int(rng.integers(600_000, 1_900_000)), "channels": channels,
                      "num_samples": n, "sample_rate_hz": rate})
        if ext != "json" and ext != "npz":
            rec = f"{group.replace('/', '_')}_{name.replace('/', '_')}"
            rec_ids[name] = rec
            recordings.append(RecordingEntry(rec, path, rate, n, channels, custom).to_lhotse())

    names = [f"source{k + 1}" for k in range(speakers)]
    track_q = ("positions_m", "azimuth_deg", "elevation_deg", "distance_m")
    for name in [*names, "noise", "music"]:
        role = name if name in ("noise", "music") else "speech"
        add(role, name, custom={"track": _reference(group, name, frames, track_q)})
        if role == "speech":
            add("speech_dry", f"{name}_dry")
    for mixture, _ in MIXTURES:
        add("mixture", f"mixtures/{mixture}")
    for kind, name, ext in (("metadata", "metadata", "json"), ("tracks", "tracks", "npz")):
        files.append({"kind": kind, "name": name, "path": f"{group}/{name}.{ext}",
                      "sha256": sha256_hex(f"{seed}:{group}/{name}"),
                      "bytes": int(rng.integers(20_000, 200_000))})
    supervisions = []
    for name in names:
        speaker = f"{split}-{int(rng.integers(1000))}"
        t, segs = 0, []
        for _ in range(int(rng.integers(3, 6))):
            t += int(rng.uniform(0, 8) * rate)
            end = min(n, t + int(rng.uniform(4, 12) * rate))
            if end <= t:
                break
            segs.append((t, end, " ".join(["WORD"] * int(rng.integers(8, 30)))))
            t = end
        heard_in = [name] + [f"mixtures/{m}" for m, parts in MIXTURES if name in parts]
        for rec_name in heard_in:
            rec = rec_ids[rec_name]
            stem = rec if rec_name == name else f"{rec}_{name}"
            supervisions.extend(SupervisionEntry(f"{stem}_{k}", rec, a, b, rate, text,
                                                 speaker).to_lhotse()
                                for k, (a, b, text) in enumerate(segs))
    return {"group": group, "split": split, "scene_id": scene_id,
            "metadata": {"path": f"{split}/{index}/metadata.json"},
            "files": files, "recordings": recordings, "supervisions": supervisions,
            "duration_s": n / rate}


def write_dataset_inputs(root: Path, groups: int, *, scenes: int = 3, groups_per_shard: int = 16,
                         seed: int = 7, duration_s: float = 60.0) -> tuple[Path, str]:
    """A store under ``root`` with the export artifacts of ``groups`` train groups and a plan
    file; ``(plan file, the dataset job's key)`` for ``Plan.read_job`` and ``run_job``."""
    from sonicspec.spec import load_spec

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    spec_file = root / "demo.yaml"
    spec_file.write_text(template_body("demo"))
    spec_json = json.loads(load_spec(spec_file).spec.model_dump_json())
    store = ArtifactStore(root / "store")
    by_scene: dict[str, list[str]] = {}
    for i in range(groups):
        by_scene.setdefault(f"scene{i % scenes:02d}", []).append(f"train/{i:06d}")
    jobs = []
    for scene_id, members in sorted(by_scene.items()):
        for s in range(0, len(members), groups_per_shard):
            shard = members[s:s + groups_per_shard]
            job = Job("export", {"groups": shard, "split": "train", "seed": seed,
                                 "scene_id": scene_id}, (), f"export train/{scene_id}#{s}")
            records = [synthetic_export_group(g, scene_id, seed, duration_s=duration_s)
                       for g in shard]
            store.write("export", job.key,
                        {"file_count": np.array([sum(len(r["files"]) for r in records)])},
                        data={"groups": records}, params=job.params,
                        stage_version=STEP_BY_NAME["export"].version)
            jobs.append(job)
    dataset = Job("dataset", {"spec": spec_json, "output_dir": str(root / "out"),
                              "manifests": ["lhotse", "csv"], "splits": {"train": groups}},
                  tuple(j.key for j in jobs), "dataset")
    plan = Plan(name="scale", seed=seed, store_dir=str(root / "store"),
                output_dir=str(root / "out"), spec_digest=sha256_hex("scale"),
                jobs=(*jobs, dataset))
    path = plan.write(root / "plan.json")
    return path, dataset.key


MEASURE = """
import json, resource, sys, time
from pathlib import Path
from sonicspec.plan.model import Plan
from sonicspec.stages import run_job
path, key = Path(sys.argv[1]), sys.argv[2]
before = resource.getrusage(resource.RUSAGE_SELF)
t0 = time.perf_counter()
plan = Plan.read_job(path, key)
loaded = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t1 = time.perf_counter()
run_job(plan, key)
after = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"peak_rss_mb": after.ru_maxrss / 1024, "plan_rss_mb": loaded / 1024,
                  "plan_wall_s": t1 - t0, "wall_s": time.perf_counter() - t1,
                  "cpu_s": after.ru_utime + after.ru_stime - before.ru_utime
                  - before.ru_stime}))
"""
"""What a ``sonicspec job`` process does for the dataset job, measured from inside: the peak
RSS (``getrusage``), the RSS once the plan excerpt is read, and wall and CPU time."""


def measure_dataset_job(plan_file: Path, key: str, env: dict[str, str] | None = None
                        ) -> dict[str, float]:
    """Run the dataset job in a fresh Python process; its :data:`MEASURE` figures."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", MEASURE, str(plan_file), key],
                          capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"dataset job failed: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])
