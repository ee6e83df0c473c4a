"""The small dataset the loader, evaluation and export tests share: the pipeline tests' cut-down
demo with three speakers per group (so dynamic mixing has speakers to choose from) and the
direct-path stem."""

from __future__ import annotations

from pathlib import Path

from build_cases import plan_for, write_spec

from sonicspec.plan.model import Plan
from sonicspec.stages.workflow import run_build


def build_dataset(tmp: Path) -> Plan:
    spec = write_spec(tmp)
    text = spec.read_text()
    for old, new in (("speakers_per_split: 2,", "speakers_per_split: 3,"),
                     ("  speakers: 2\n", "  speakers: 3\n  targets: [direct]\n")):
        assert old in text, old
        text = text.replace(old, new)
    spec.write_text(text)
    plan = plan_for(spec)
    assert run_build(plan, cores=2) == 0
    return plan
