"""What a stage sees of the world: its job, its input artifacts, a seeded generator, the store."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.atomic import write_text
from sonicspec.errors import StageError
from sonicspec.hashing import rng_for
from sonicspec.plan.model import STEP_BY_NAME, Job, Plan
from sonicspec.plan.params import StepParams, read_params
from sonicspec.store import Artifact, ArtifactStore


@dataclass(frozen=True)
class JobContext:
    """A job in its plan, with access to the artifacts it depends on."""

    job: Job
    plan: Plan
    store: ArtifactStore
    _last_progress: list[float] = field(default_factory=lambda: [0.0], repr=False)

    _params: list[StepParams] = field(default_factory=list, repr=False)

    @property
    def params(self) -> Any:
        """The job's params as its step's model (:mod:`sonicspec.plan.params`), read once; a
        :class:`StageError` naming the field if they do not fit."""
        if not self._params:
            self._params.append(read_params(self.job.step, self.job.params, self.job.label))
        return self._params[0]

    def input_params(self, step: str) -> Any:
        """The params of this job's single ``step`` input, as that step's model."""
        keys = self.input_keys(step)
        if len(keys) != 1:
            raise StageError(
                f"{self.job.label}: expected one {step} input, found {len(keys)}", self.job.key
            )
        job = self.plan.by_key()[keys[0]]
        return read_params(step, job.params, job.label)

    def input_keys(self, step: str) -> list[str]:
        """Keys of this job's inputs made by ``step``, in the order the plan lists them."""
        jobs = self.plan.by_key()
        return [k for k in self.job.inputs if jobs[k].step == step]

    def input(self, step: str) -> Artifact:
        """The single input artifact of ``step`` (a :class:`StageError` if not exactly one)."""
        keys = self.input_keys(step)
        if len(keys) != 1:
            raise StageError(
                f"{self.job.label}: expected one {step} input, found {len(keys)}", self.job.key
            )
        return self.store.read(step, keys[0])

    def input_data(self, step: str) -> list[Any]:
        """The JSON data of every ``step`` input (cheap: no arrays are read)."""
        return [self.store.read_data(step, k) for k in self.input_keys(step)]

    def rng(self, *names: str) -> np.random.Generator:
        """A generator seeded by the spec seed and ``names`` (e.g. the step and a group id)."""
        return rng_for(self.plan.seed, *names)

    def progress(self, text: str, *, every_s: float = 1.0) -> None:
        """Tell the build how far this job is (shown on its progress line); at most once per
        ``every_s`` seconds."""
        now = time.monotonic()
        if now - self._last_progress[0] >= every_s:
            self._last_progress[0] = now
            write_text(progress_path(self.plan.store_dir, self.job.key), text)

    def write(self, arrays: dict[str, np.ndarray], data: Any = None) -> None:
        self.store.write(
            self.job.step,
            self.job.key,
            arrays,
            data=data,
            params=self.job.params,
            input_keys=self.job.inputs,
            stage_version=STEP_BY_NAME[self.job.step].version,
        )


def progress_path(store_dir: str | Path, key: str) -> Path:
    """Where a running job says how far it is (see :meth:`JobContext.progress`)."""
    return Path(store_dir) / "logs" / "progress" / f"{key}.txt"


def finished_dir(store_dir: str | Path) -> Path:
    """Where each job that finished leaves a marker for the build's head (see
    :func:`mark_finished`)."""
    return Path(store_dir) / "logs" / "finished"


def mark_finished(store_dir: str | Path, key: str) -> None:
    """Tell the build's head that job ``key`` finished (its artifact is in the store).

    One empty file per finished job, in one folder that the head lists and empties as it
    counts: its progress costs O(jobs finished since it last looked), not O(jobs waiting),
    on any executor (local, SLURM, grouped jobs). The head clears leftovers before a build.
    """
    folder = finished_dir(store_dir)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{key}.done").touch()
