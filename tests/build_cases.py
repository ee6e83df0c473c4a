"""The cut-down demo build the pipeline tests share: its spec, its plan and its digests."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from sonicspec.plan.compile import compile_spec
from sonicspec.plan.model import Plan
from sonicspec.spec import load_spec
from sonicspec.stages import STAGES

ROOT = Path(__file__).resolve().parents[1]


def write_spec(tmp: Path) -> Path:
    """The demo spec, smaller and with a cheaper tracer (the machinery, not the physics, is
    under test)."""
    text = (ROOT / "specs" / "demo.yaml").read_text()
    for old, new in (("rays: 4000", "rays: 600"), ("max_rir_length_s: auto",
                                                   "max_rir_length_s: 0.4"),
                     ("train: {groups: 4,", "train: {groups: 2,"),
                     ("speakers_per_split: 3, utterances_per_speaker: 4",
                      "speakers_per_split: 2, utterances_per_speaker: 2")):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp / "demo.yaml"
    path.write_text(text)
    return path


def plan_for(spec: Path) -> Plan:
    plan = compile_spec(load_spec(spec))
    assert {j.step for j in plan.jobs} <= set(STAGES)
    return plan


def store_digest(store: Path) -> dict[str, str]:
    """SHA-256 of every artifact file (logs, benchmarks, plans and Snakemake state excluded)."""
    out = {}
    for p in sorted(store.rglob("*")):
        rel = p.relative_to(store)
        if p.is_file() and rel.parts[0] not in ("logs", "benchmarks", "plans", ".snakemake",
                                                "cache"):
            out[str(rel)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def build_digest(plan: Plan) -> dict[str, str]:
    """Digests of the store's artifacts and of every file of the dataset folder."""
    out = {f"store/{k}": v for k, v in store_digest(Path(plan.store_dir)).items()}
    folder = Path(plan.output_dir)
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            out[f"out/{p.relative_to(folder)}"] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


EDITS = [  # (section of the spec, old text, new text): one edit each, applied one after another
    ("scenes", "walls: gypsum_board", "walls: concrete_painted"),
    ("microphone", "height_m: 1.5", "height_m: 1.4"),
    ("placement", "noise_distance_m: [1.0, 4.0]", "noise_distance_m: [1.0, 3.5]"),
    ("trajectory", "rir_spacing_m: 0.25", "rir_spacing_m: 0.3"),
    ("acoustics", "rays: 600", "rays: 500"),
    ("corpora", "clips_per_split: 4, clip_duration_s: 3.0}\n  music",
     "clips_per_split: 5, clip_duration_s: 3.0}\n  music"),
    ("mixture", "speech_lufs: -24,", "speech_lufs: -22,"),
    ("splits", "train: {groups: 2,", "train: {groups: 3,"),
    ("outputs", "manifests: [lhotse]", "manifests: [lhotse, csv]"),
]


def readme_spec() -> str:
    """The YAML block under "The spec in one screen" in README.md."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    found = re.search(r"^## The spec in one screen\n\n```yaml\n(.*?)^```", text, re.S | re.M)
    assert found, "README.md: the one-screen spec block moved"
    return found.group(1)


def readme_python() -> str:
    """The Python block under "One RIR from Python" in README.md."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    found = re.search(r"^## One RIR from Python\n.*?^```python\n(.*?)^```", text, re.S | re.M)
    assert found, "README.md: the Python example block moved"
    return found.group(1)
