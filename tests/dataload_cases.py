"""The small dataset the loader, evaluation and export tests share: the pipeline tests' cut-down
demo with three speakers per group (so dynamic mixing has speakers to choose from) and the
direct-path stem, and the Hugging Face and WebDataset exports beside it."""

from __future__ import annotations

from pathlib import Path

from build_cases import plan_for, write_spec

from sonicspec.cli import main
from sonicspec.plan.model import Plan


def build_dataset(tmp: Path) -> Plan:
    spec = write_spec(tmp)
    text = spec.read_text()
    for old, new in (("speakers_per_split: 2,", "speakers_per_split: 3,"),
                     ("manifests: [lhotse]", "manifests: [lhotse, huggingface, webdataset]"),
                     ("  speakers: 2\n", "  speakers: 3\n  targets: [direct]\n")):
        assert old in text, old
        text = text.replace(old, new)
    spec.write_text(text)
    plan = plan_for(spec)
    assert main(["build", str(spec), "--cores", "2"]) == 0  # the exports come with the CLI
    return plan
