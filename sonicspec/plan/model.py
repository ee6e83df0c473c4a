"""The plan: every job a build runs, with its content key, in dependency order."""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonicspec.atomic import atomic_path
from sonicspec.errors import CompileError
from sonicspec.hashing import (
    KEY_LENGTH,
    canonical_json,
    normalised_params_and_key,
    sha256_hex,
)


@dataclass(frozen=True)
class Step:
    """A pipeline step: its name, output version, and the resources one of its jobs needs."""

    name: str
    version: int
    threads: int
    mem_mb: int
    runtime_min: int
    description: str


# mem_mb: each step's measured peak RSS with headroom (bench/RESULTS.md, "Each rule's memory";
# bench/bench_rule_memory.py: the sonicset preset, 60 s groups of 3 talkers, 16 groups per
# shard as the preset has, on the fixture scans; peaks in MB in the comments). A shard's
# render, mix and export hold its groups' audio: their peaks grow with
# outputs.groups_per_shard and the group length.
# mesh, navigation and rir also hold the scene: their figures at ~1 M triangles are
# bench_mesh_memory / bench_navigation's and a preset RIR in the furnished apartment (400 MB);
# mesh: 783 MB on bench_mesh_memory's 1.07 M-triangle damaged apartment (1,180 before the
# issue 27 cuts), asked 2000 (2.5x, room for scans of more pieces).
STEPS: tuple[Step, ...] = (
    Step("corpus", 2, 1, 1000, 60, "index (or generate) a corpus"),  # 154; grows with files
    Step("mesh", 2, 1, 2000, 30, "build or import a scene, repair it"),  # 204; 783 at 1 M
    Step("navigation", 1, 1, 2000, 30, "walkable area of each floor"),  # 177; 865 at 1 M
    Step("placement", 3, 1, 1000, 10, "mic, sources and trajectories per group"),  # 160
    Step("arrange", 1, 1, 1000, 10, "utterances and clips per track"),  # 155
    Step("rir", 19, 1, 1500, 60, "room impulse responses along every trajectory"),  # 357
    Step("render", 3, 1, 2000, 30, "moving-source convolution of every track"),  # 1115
    Step("mix", 2, 1, 1500, 10, "loudness normalisation and task mixtures"),  # 864
    Step("export", 6, 1, 1500, 10, "audio files and metadata per group"),  # 875
    # dataset streams: peak RSS 152-156 MB at 10^2-10^4 groups (bench/bench_scale.py), 3x
    Step("dataset", 3, 1, 500, 10, "dataset.json and manifests"),
)
STEP_BY_NAME: Mapping[str, Step] = {s.name: s for s in STEPS}


@dataclass(frozen=True, slots=True)
class Job:
    """One unit of work: a step applied to parameters and to the artifacts of other jobs."""

    step: str
    params: Mapping[str, Any]
    inputs: tuple[str, ...] = ()
    label: str = ""
    paths: Mapping[str, str] = field(default_factory=dict)
    """Where the job's input files are on this machine; not part of the key (files enter the
    key by content through ``params``)."""
    key: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if self.step not in STEP_BY_NAME:
            raise CompileError(
                f"job step: expected one of {', '.join(STEP_BY_NAME)}, got {self.step!r}"
            )
        # Params are normalised to plain JSON data so the key and the stored copy agree.
        params, key = normalised_params_and_key(
            self.step, STEP_BY_NAME[self.step].version, self.params, self.inputs
        )
        object.__setattr__(self, "params", params)
        object.__setattr__(self, "key", key)

    def to_dict(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "key": self.key,
            "label": self.label,
            "inputs": list(self.inputs),
            "params": self.params,
            "paths": dict(self.paths),
        }


@dataclass(frozen=True)
class Plan:
    """All jobs of a build in dependency order (a job's inputs come before it)."""

    name: str
    seed: int
    store_dir: str
    output_dir: str
    spec_digest: str
    jobs: tuple[Job, ...]
    excerpt: bool = field(default=False, compare=False)
    """Only some jobs of a plan (:meth:`read_job`): their inputs' inputs are not in it."""

    def __post_init__(self) -> None:
        if self.excerpt:
            return
        seen: set[str] = set()
        for job in self.jobs:
            missing = [k for k in job.inputs if k not in seen]
            if missing:
                raise CompileError(
                    f"plan: job {job.label or job.key[:12]} needs "
                    f"{missing[0][:12]}, which no earlier job makes"
                )
            seen.add(job.key)

    @property
    def digest(self) -> str:
        """Identifies the plan (its jobs and locations); names the plan file."""
        return sha256_hex(
            canonical_json([self.store_dir, self.output_dir, [j.key for j in self.jobs]])
        )

    def by_key(self) -> dict[str, Job]:
        return {j.key: j for j in self.jobs}

    def by_step(self) -> dict[str, list[Job]]:
        out: dict[str, list[Job]] = {s.name: [] for s in STEPS}
        for job in self.jobs:
            out[job.step].append(job)
        return out

    def until(self, step: str) -> Plan:
        """The jobs of ``step`` and of every step before it (``sonicspec build --until``)."""
        names = [s.name for s in STEPS]
        if step not in names:
            raise CompileError(f"--until: expected one of {', '.join(names)}, got {step!r}")
        keep = set(names[: names.index(step) + 1])
        return Plan(self.name, self.seed, self.store_dir, self.output_dir, self.spec_digest,
                    tuple(j for j in self.jobs if j.step in keep))

    def __iter__(self) -> Iterator[Job]:
        return iter(self.jobs)

    def _header(self) -> dict[str, Any]:
        return {
            "format": "sonicspec-plan",
            "version": 1,
            "name": self.name,
            "seed": self.seed,
            "store_dir": self.store_dir,
            "output_dir": self.output_dir,
            "spec_digest": self.spec_digest,
        }

    def to_dict(self) -> dict[str, Any]:
        return {**self._header(), "jobs": [j.to_dict() for j in self.jobs]}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, excerpt: bool = False) -> Plan:
        if data.get("format") != "sonicspec-plan" or data.get("version") != 1:
            raise CompileError("plan file: not a sonicspec plan (version 1)")
        jobs = []
        for item in data["jobs"]:
            job = Job(
                item["step"],
                item["params"],
                tuple(item["inputs"]),
                item.get("label", ""),
                item.get("paths", {}),
            )
            if job.key != item["key"]:
                raise CompileError(
                    f"plan file: job {item.get('label')} has key {item['key'][:12]}"
                    f" but its parameters hash to {job.key[:12]} (edited or made "
                    "by another sonicspec version); compile the spec again"
                )
            jobs.append(job)
        return cls(
            data["name"],
            data["seed"],
            data["store_dir"],
            data["output_dir"],
            data["spec_digest"],
            tuple(jobs),
            excerpt,
        )

    def write(self, path: Path) -> Path:
        """Write the plan as JSON, atomically."""
        # One job per line, streamed: a plan of 10^6 groups has 1.5 million jobs, too many to
        # hold as one indented text (json's indenting encoder is also its slow one).
        with atomic_path(path) as tmp, tmp.open("w") as fh:
            fh.write(json.dumps(self._header(), sort_keys=True)[:-1] + ', "jobs": [\n')
            for i, job in enumerate(self.jobs):
                fh.write((",\n" if i else "") + json.dumps(job.to_dict(), sort_keys=True))
            fh.write("\n]}\n")
        return path

    @classmethod
    def read_job(cls, path: Path, key: str) -> Plan:
        """The excerpt of a plan file that one job needs: the header, the job and the jobs of
        its inputs, each checked against its key.

        ``sonicspec job`` runs once per job: parsing and re-hashing every job of the plan in
        each would cost more than many jobs (a plan of 10^6 groups takes minutes to read).
        Plans are written one job per line (:meth:`write`), so two passes over the lines find
        the few that matter. Any other layout is read whole.
        """
        return cls.read_jobs(path, [key])

    @classmethod
    def read_jobs(cls, path: Path, keys: list[str] | tuple[str, ...]) -> Plan:
        """:meth:`read_job` for several jobs (a batch, :mod:`sonicspec.plan.batches`): the
        jobs and the jobs of their inputs, in the plan's order."""
        marker = ', "jobs": [\n'
        wanted_jobs = set(keys)
        try:
            with open(path) as fh:
                first = fh.readline()
                if not first.endswith(marker):
                    return cls._excerpt(cls.read(path), keys)
                header = json.loads(first[: -len(marker)] + "}")
                found = cls._lines_with_keys(fh, wanted_jobs)
                missing = wanted_jobs - set(found)
                if missing:
                    raise CompileError(f"plan file {path}: no job with key "
                                       f"{sorted(missing)[0][:12]}")
                wanted = {k for item in found.values() for k in item["inputs"]} - set(found)
                if wanted:
                    fh.seek(0)
                    fh.readline()
                    found.update(cls._lines_with_keys(fh, wanted))
        except FileNotFoundError:
            raise CompileError(f"plan file {path}: does not exist") from None
        except (ValueError, KeyError, TypeError) as exc:
            raise CompileError(f"plan file {path}: unreadable ({exc})") from exc
        missing = wanted - set(found)
        if missing:
            needer = next(k for k in keys if set(found[k]["inputs"]) & missing)
            raise CompileError(f"plan file {path}: job {needer[:12]} needs "
                               f"{sorted(missing)[0][:12]}, which the plan does not have")
        order = [found[k] for key in keys for k in found[key]["inputs"] if k not in wanted_jobs]
        order += [found[k] for k in keys]
        data = {**header, "jobs": list({item["key"]: item for item in order}.values())}
        return cls.from_dict(data, excerpt=True)

    @staticmethod
    def _lines_with_keys(lines, keys: set[str]) -> dict[str, dict[str, Any]]:
        found: dict[str, dict[str, Any]] = {}
        tag = '"key": "'
        for line in lines:
            at = line.find(tag)
            if at >= 0 and line[at + len(tag): at + len(tag) + KEY_LENGTH] in keys:
                item = json.loads(line.rstrip().rstrip(","))
                found[item["key"]] = item
                if len(found) == len(keys):
                    break
        return found

    @classmethod
    def _excerpt(cls, plan: Plan, keys: list[str] | tuple[str, ...]) -> Plan:
        jobs = plan.by_key()
        missing = [k for k in keys if k not in jobs]
        if missing:
            raise CompileError(f"plan: no job with key {missing[0][:12]}")
        order = [jobs[k] for key in keys for k in jobs[key].inputs if k not in keys]
        order += [jobs[k] for k in keys]
        return cls(plan.name, plan.seed, plan.store_dir, plan.output_dir, plan.spec_digest,
                   tuple({j.key: j for j in order}.values()), excerpt=True)

    @classmethod
    def read(cls, path: Path) -> Plan:
        try:
            return cls.from_dict(json.loads(Path(path).read_text()))
        except FileNotFoundError:
            raise CompileError(f"plan file {path}: does not exist") from None
        except (ValueError, KeyError, TypeError) as exc:
            raise CompileError(f"plan file {path}: unreadable ({exc})") from exc
