"""Loudness and mixing: every component at its target loudness, mixtures without clipping.

Loudness is ITU-R BS.1770-4 integrated loudness (K-weighting, 400 ms blocks, absolute gate at
−70 LUFS and relative gate at −10 LU) measured with ``pyloudnorm``. A multichannel component is
measured on its reference channel: channel 0 (the first capsule of an array, W of
ambisonics), or both ears together for binaural (BS.1770 stereo).

A mix is a *description*: gains per component and which components each mixture sums. The
export applies it; nothing here keeps a second copy of the audio.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sonicspec.errors import AudioError

MIN_LOUDNESS_S = 0.4  # one BS.1770 gating block


def measurement_channels(x: np.ndarray, binaural: bool = False) -> np.ndarray:
    """The channels loudness is measured on, ``(T, k)`` as pyloudnorm expects."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    return x[:2].T if binaural and x.shape[0] == 2 else x[:1].T


def integrated_loudness(x: np.ndarray, sample_rate_hz: int, *, binaural: bool = False,
                        where: str = "signal") -> float:
    """BS.1770 integrated loudness of ``x`` ``(C, T)`` or ``(T,)``, LUFS.

    Raises :class:`AudioError` for a signal shorter than one 400 ms block; returns ``-inf``
    for a silent one (every block below the absolute gate).
    """
    import pyloudnorm

    data = measurement_channels(x, binaural)
    if data.shape[0] < MIN_LOUDNESS_S * sample_rate_hz:
        raise AudioError(f"{where}: expected at least {MIN_LOUDNESS_S} s to measure loudness, "
                         f"got {data.shape[0] / sample_rate_hz:.3f} s")
    if not np.all(np.isfinite(data)):
        raise AudioError(f"{where}: expected finite samples, got NaN or infinity")
    with np.errstate(divide="ignore"):
        value = pyloudnorm.Meter(sample_rate_hz).integrated_loudness(data)
    return float(value)


# How close gain_to_loudness brings a signal to its target, LU, and its correction steps.
LOUDNESS_TOLERANCE_LU = 0.01
_LOUDNESS_STEPS = 4


def gain_to_loudness(x: np.ndarray, sample_rate_hz: int, target_lufs: float, *,
                     binaural: bool = False, where: str = "signal") -> tuple[float, float]:
    """(linear gain, measured LUFS) that bring ``x`` to ``target_lufs``.

    BS.1770's gates are not scale-invariant (the absolute gate at −70 LUFS moves with the
    gain, and the relative gate with it), so a quiet passage near the gate can leave the
    one-step gain a tenth of a LU off. The gain is therefore re-measured and corrected until
    the scaled signal is within ``LOUDNESS_TOLERANCE_LU`` (a few steps at most).
    A silent component cannot be brought to a loudness: :class:`AudioError` naming it.
    """
    measured = integrated_loudness(x, sample_rate_hz, binaural=binaural, where=where)
    if not math.isfinite(measured):
        raise AudioError(f"{where}: expected sound to normalise to {target_lufs:g} LUFS, got "
                         "silence (every 400 ms block below −70 LUFS)")
    gain = 10.0 ** ((target_lufs - measured) / 20.0)
    for _ in range(_LOUDNESS_STEPS):
        reached = integrated_loudness(gain * np.asarray(x), sample_rate_hz, binaural=binaural,
                                      where=where)
        if not math.isfinite(reached) or abs(reached - target_lufs) <= LOUDNESS_TOLERANCE_LU:
            break
        gain *= 10.0 ** ((target_lufs - reached) / 20.0)
    return gain, measured


@dataclass(frozen=True)
class Mixture:
    """One exported mixture: its name, the components it sums, and its targets."""

    name: str
    task: str
    components: tuple[str, ...]
    targets: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "task": self.task, "components": list(self.components),
                "targets": list(self.targets)}


_BACKGROUND = {"noise": ("noise",), "music": ("music",), "both": ("noise", "music"),
               "none": ()}


def _short(name: str) -> str:
    return name.replace("source", "s")


def task_mixtures(tasks: Sequence[Mapping[str, Any]], speakers: Sequence[str],
                  available: Sequence[str], *, where: str = "tasks") -> list[Mixture]:
    """The mixtures the tasks ask for, over the group's speaker tracks.

    Separation of ``k`` speakers: every ``k``-subset of the speakers, plus the background;
    enhancement: every speaker alone plus the background. A background the group lacks is an
    error naming the task (``<where>[i]``; the caller says where the tasks come from).
    """
    out: list[Mixture] = []
    for i, task in enumerate(tasks):
        background = _BACKGROUND[task["background"]]
        missing = [b for b in background if b not in available]
        if missing:
            raise AudioError(f"{where}[{i}]: background {task['background']!r} needs "
                             f"{' and '.join(missing)}, but the group has no such track")
        k = task["speakers"] if task["kind"] == "separation" else 1
        if k > len(speakers):
            raise AudioError(f"{where}[{i}]: separation of {k} speakers, but a group "
                             f"has {len(speakers)}")
        suffix = "" if not background else "_" + task["background"]
        prefix = "sep" if task["kind"] == "separation" else "enh"
        for combo in itertools.combinations(speakers, k):
            name = f"{prefix}_{''.join(_short(s) for s in combo)}{suffix}"
            out.append(Mixture(name, task["kind"], (*combo, *background), tuple(combo)))
    names = [m.name for m in out]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise AudioError(f"{where}: mixtures {dupes} are asked for twice")
    return out


def peak_guard(components: Mapping[str, np.ndarray], gains: Mapping[str, float],
               mixtures: Sequence[Mixture], peak_limit_dbfs: float) -> tuple[float, float]:
    """(group gain ≤ 1, peak before it) keeping every component and mixture under the limit.

    The peak is taken over every gained component and every mixture, so whatever the export
    writes stays below ``peak_limit_dbfs``; the whole group is scaled by one gain so the
    levels between its parts are kept.
    """
    peak = 0.0
    for name, x in components.items():
        peak = max(peak, gains[name] * float(np.max(np.abs(x))) if x.size else 0.0)
    for m in mixtures:
        total = sum(gains[c] * np.asarray(components[c], dtype=np.float64)
                    for c in m.components)
        peak = max(peak, float(np.max(np.abs(total))))
    limit = 10.0 ** (peak_limit_dbfs / 20.0)
    return (limit / peak if peak > limit else 1.0), peak
