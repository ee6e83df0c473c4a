"""Stage ``mix``: the gain of every track and the task mixtures of every group.

Each component is brought to its target loudness (speech, noise, music; each target drawn in
target ± jitter from the group's own generator), measured on the reverberant track at the
microphone or on the dry source (``mixture.loudness.stage``). The ``dry`` training target is
brought to the same target on its own (a dry source is 20–40 dB louder than its reverberant
image, so the reverberant gain would clip it), or lower if its peak would pass the limit;
``direct`` and ``early`` share their track's gain, being parts of it. Then one group gain keeps
every other written signal and every mixture under the peak limit. The result is a
description (gains and mixture lists): the export applies it.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from sonicspec import artifacts
from sonicspec.artifacts import ComponentLevel, MixData, MixGroup, Mixture, RenderGroup
from sonicspec.audio.mix import gain_to_loudness, integrated_loudness, peak_guard, task_mixtures
from sonicspec.errors import AudioError
from sonicspec.plan.params import MixParams
from sonicspec.stages.context import JobContext

log = logging.getLogger("sonicspec.stages.mix")


def _db(gain: float) -> float | None:
    """Decibels, or None for silence (JSON has no infinity)."""
    return 20.0 * math.log10(gain) if gain > 0 else None


def mix_group(render_group: RenderGroup, arrays: dict[str, np.ndarray], params: MixParams,
              rng: np.random.Generator) -> MixGroup:
    """Gains, loudness and mixtures of one group."""
    loud = params.loudness
    targets = {"speech": loud.speech_lufs, "noise": loud.noise_lufs, "music": loud.music_lufs}
    keep_levels = loud.peak_limit_dbfs is None  # no guard: absolute levels, float output
    rate = params.sample_rate_hz
    group = render_group.group
    signals: dict[str, np.ndarray] = {}
    gains: dict[str, float] = {}
    dry_gains: dict[str, float] = {}
    levels: dict[str, tuple[str, float, float]] = {}
    """Track -> (role, target, measured level), LUFS."""
    for track in render_group.tracks:
        name, role = track.name, track.role
        jitter = loud.jitter_lu
        target = targets[role] + (rng.uniform(-jitter, jitter) if jitter > 0 else 0.0)
        reverberant = np.asarray(arrays[track.arrays["reverberant"]], dtype=np.float64)
        dry = np.asarray(arrays[track.arrays["dry"]], dtype=np.float64)
        where = f"group {group} {name}"
        measured_on = dry if loud.stage == "dry" else reverberant
        gain, measured = gain_to_loudness(measured_on, rate, target, where=where,
                                          binaural=params.binaural and measured_on.shape[0] == 2)
        signals[name], gains[name] = reverberant, gain
        for kind in ("direct", "early"):
            if kind in track.arrays:
                signals[f"{name}_{kind}"] = np.asarray(arrays[track.arrays[kind]])
                gains[f"{name}_{kind}"] = gain
        if "dry" in params.targets:
            # The dry target has its own level and its own guard: its peaks (no room to
            # smooth them) must not pull the whole group down.
            dry_gain, _ = gain_to_loudness(dry, rate, target, where=f"{where} (dry target)")
            if not keep_levels:
                limit = 10.0 ** (loud.peak_limit_dbfs / 20.0)
                dry_gain = min(dry_gain, limit / float(np.max(np.abs(dry))))
            dry_gains[f"{name}_dry"] = dry_gain
        levels[name] = (role, target, measured)
    speakers = [t.name for t in render_group.tracks if t.role == "speech"]
    available = [t.name for t in render_group.tracks if t.role != "speech"]
    try:
        mixtures = task_mixtures([t.model_dump(mode="json") for t in params.tasks], speakers,
                                 available, where="mixture.tasks")
    except AudioError as err:
        raise AudioError(f"{err} (a group's tracks: mixture.speakers speakers, and noise or "
                         "music from corpora.<role> with a non-zero mixture.<role>_clips)"
                         ) from None
    if keep_levels:
        _, peak = peak_guard(signals, gains, mixtures, 0.0)  # measured, not applied
        group_gain = 1.0
    else:
        group_gain, peak = peak_guard(signals, gains, mixtures, loud.peak_limit_dbfs)
    final = {k: g * group_gain for k, g in gains.items()} | dry_gains
    components = {name: ComponentLevel(
        role=role, target_lufs=target, measured_lufs=measured, measured_on=loud.stage,
        gain_db=_db(final[name]), output_lufs=integrated_loudness(
            final[name] * (signals[name]), rate, where=f"group {group} {name}",
            binaural=params.binaural and signals[name].shape[0] == 2))
        for name, (role, target, measured) in levels.items()}
    return MixGroup(group=group, gains=final, group_gain_db=_db(group_gain),
                    peak_before_guard_dbfs=_db(peak), components=components,
                    mixtures=[Mixture(**m.to_dict()) for m in mixtures])


def run(ctx: JobContext) -> None:
    params: MixParams = ctx.params
    art = ctx.input("render")
    render = artifacts.decode("render", art.data, ctx.job.label)
    groups = [mix_group(g, art.arrays, params, ctx.rng("mix", g.group)) for g in render.groups]
    cuts = [-g.group_gain_db for g in groups if g.group_gain_db is not None]
    if cuts and float(np.median(cuts)) > 1.0:
        log.warning("mixture.loudness: the peak guard lowered %d of %d groups of %s by a median "
                    "of %.1f dB, so their components sit that far below the targets; "
                    "peak_limit_dbfs: null keeps absolute levels (with float WAV output)",
                    sum(c > 0 for c in cuts), len(groups), ctx.job.label, float(np.median(cuts)))
    names = sorted({k for g in groups for k in g.gains})
    table = np.array([[g.gains.get(k, np.nan) for k in names] for g in groups])
    ctx.write({"gains": table}, artifacts.encode("mix", MixData(
        groups=groups, gain_columns=names, sample_rate_hz=params.sample_rate_hz)))
