"""The mix stage's level policy (issue 20): the peak guard, or absolute levels kept."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from sonicspec.artifacts import RenderedTrack, RenderGroup
from sonicspec.audio.mix import integrated_loudness
from sonicspec.plan.params import MixParams
from sonicspec.stages.mix import mix_group

FS = 16000


def _group() -> tuple[RenderGroup, dict[str, np.ndarray]]:
    """Two speakers and a noise whose sum at the targets peaks well above 0 dBFS: clicks."""
    rng = np.random.default_rng(0)
    arrays, tracks = {}, []
    for name, role in (("source1", "speech"), ("source2", "speech"), ("noise", "noise")):
        x = 0.01 * rng.standard_normal(4 * FS)
        x[FS::FS // 2] = 1.0  # peaks 40 dB above the body
        arrays[f"{name}_reverberant"] = x[None, :]
        arrays[f"{name}_dry"] = x[None, :]
        tracks.append(RenderedTrack(name=name, role=role, channels=1, arrays={
            "reverberant": f"{name}_reverberant", "dry": f"{name}_dry"}))
    return RenderGroup(group="train/000000", clip_samples=4 * FS, tracks=tracks), arrays


def _params(limit) -> MixParams:
    return MixParams.model_validate({
        "groups": ["train/000000"], "split": "train", "seed": 0, "speakers": 2,
        "sample_rate_hz": FS, "binaural": False, "targets": [],
        "loudness": {"speech_lufs": -17, "noise_lufs": -21, "music_lufs": -24, "jitter_lu": 0,
                     "stage": "reverberant", "preset": None, "peak_limit_dbfs": limit},
        "tasks": [{"kind": "separation", "speakers": 2, "background": "noise"}]})


@pytest.mark.parametrize("limit", [-1.0, None])
def test_the_guard_lowers_the_group_and_null_keeps_the_levels(limit) -> None:
    group, arrays = _group()
    mixed = mix_group(group, arrays, _params(limit), np.random.default_rng(0))
    for name, target in (("source1", -17.0), ("source2", -17.0), ("noise", -21.0)):
        level = integrated_loudness(mixed.gains[name] * arrays[f"{name}_reverberant"], FS)
        if limit is None:  # absolute levels: at the targets, peaks above 0 dBFS allowed
            assert level == pytest.approx(target, abs=0.1) and mixed.group_gain_db == 0.0
        else:  # one gain for the group, below the targets by it
            assert mixed.group_gain_db < -1.0
            assert level == pytest.approx(target + mixed.group_gain_db, abs=0.1)
    assert mixed.peak_before_guard_dbfs > 0.0


def test_a_median_cut_above_one_db_is_a_warning_in_the_jobs_log(caplog) -> None:
    from sonicspec.stages import mix as stage

    group, arrays = _group()

    class Ctx:  # what mix.run reads of its context
        params = _params(-1.0)
        job = type("J", (), {"label": "mix train/room#0"})()

        def input(self, step):
            from sonicspec.artifacts import RenderData
            return type("A", (), {"arrays": arrays, "data": RenderData(
                groups=[group], sample_rate_hz=FS).model_dump(mode="json")})()

        def rng(self, *names):
            return np.random.default_rng(0)

        def write(self, arrays, data):
            self.written = data

    with caplog.at_level(logging.WARNING, logger="sonicspec.stages.mix"):
        stage.run(Ctx())
    assert any("the peak guard lowered 1 of 1 groups of mix train/room#0 by a median" in r.message
               for r in caplog.records)
