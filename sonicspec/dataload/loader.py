"""A map-style dataset over a built dataset folder, with dynamic mixing.

Item ``i`` of a split is one of the dataset's mixtures of the task (every group's
``sep_…``/``enh_…`` mixtures, in group order). Without dynamic mixing it returns that
mixture and its targets as written (a random crop if asked). With dynamic mixing it keeps the
item's group (its room, microphone and paths: sources of different rooms never meet) and
re-draws, the way the released SonicSim training loader does: which of the group's speech
tracks are mixed, in which order, which background, a crop where every chosen speaker is heard,
each further speaker's level against the first (SIR) and the background's level against the
speech (SNR). Levels are the RMS of the crop on the reference channel (the recipe's
``compute_mch_rms_dB``) or BS.1770 loudness (``level="lufs"``); a gain is capped at
``max_gain_db``, as in the recipe.

Every draw comes from a generator seeded by ``(seed, epoch, index)`` alone, so an item is the
same bytes whichever worker makes it and however many workers there are. The class needs no
torch: ``torch.utils.data.DataLoader`` takes any object with ``__len__`` and ``__getitem__``
and its default collate turns the numpy arrays into tensors. Call :meth:`set_epoch` before
each epoch (with ``persistent_workers=False``, the default, each epoch's workers get a fresh
copy of the dataset and so see the new epoch).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.audio.augment import (
    apply_chain,
    chain_files,
    draw_chain,
    parse_chain,
    read_impulse_response,
)
from sonicspec.dataload.folder import BACKGROUNDS, STEMS, DatasetError, Group
from sonicspec.errors import AudioError
from sonicspec.hashing import rng_for

TASKS = ("separation", "enhancement")
SILENCE_RMS_DB = -40.0  # the recipe's "is this speaker heard in the crop" threshold


@dataclass(frozen=True)
class MixingConfig:
    """How items are drawn. Ranges are ``(low, high)`` dB, drawn uniformly.

    ``sir_db``: each further speaker's level relative to the first (separation);
    ``snr_db``: the speech (all chosen speakers) against the background; ``None`` keeps a
    range's levels as built. ``crop_s``: crop length in seconds (``None``: the whole clip).
    ``backgrounds``: the backgrounds one is drawn from (``None``: the task's own).
    """

    dynamic: bool = True
    crop_s: float | None = 3.0
    sir_db: tuple[float, float] | None = (-6.0, 6.0)
    snr_db: tuple[float, float] | None = (10.0, 20.0)
    level: str = "rms"
    max_gain_db: float = 40.0
    backgrounds: tuple[str, ...] | None = None
    channels: tuple[int, ...] | None = None
    crop_tries: int = 100

    def __post_init__(self) -> None:
        for name in ("sir_db", "snr_db"):
            r = getattr(self, name)
            if r is not None and (len(r) != 2 or not r[0] <= r[1]):
                raise DatasetError(f"MixingConfig.{name}: expected (low, high) with low <= "
                                   f"high, got {r!r}")
        if self.crop_s is not None and not self.crop_s > 0:
            raise DatasetError(f"MixingConfig.crop_s: expected > 0 s or None, got "
                               f"{self.crop_s!r}")
        if self.level not in ("rms", "lufs"):
            raise DatasetError(f"MixingConfig.level: expected 'rms' or 'lufs', got "
                               f"{self.level!r}")
        for b in self.backgrounds or ():
            if b not in BACKGROUNDS:
                raise DatasetError(f"MixingConfig.backgrounds: expected names from "
                                   f"{sorted(BACKGROUNDS)}, got {b!r}")
        if self.channels is not None and (not self.channels or min(self.channels) < 0):
            raise DatasetError(f"MixingConfig.channels: expected channel indices >= 0, got "
                               f"{self.channels!r}")


# The released SonicSim training loader (separation/look2hear/datas/movingdatamodule.py and
# its enhancement twin): 4 s crops, interferer ±6 dB against the first speaker, background
# 10…20 dB below the speech for separation and −10…15 dB for enhancement.
# The paper's setting: the same draws on 3 s crops.
PRESETS: dict[str, dict[str, MixingConfig]] = {
    "sonicsim": {
        "separation": MixingConfig(crop_s=4.0, sir_db=(-6.0, 6.0), snr_db=(10.0, 20.0)),
        "enhancement": MixingConfig(crop_s=4.0, sir_db=None, snr_db=(-10.0, 15.0)),
    },
    "paper": {
        "separation": MixingConfig(crop_s=3.0, sir_db=(-6.0, 6.0), snr_db=(10.0, 20.0)),
        "enhancement": MixingConfig(crop_s=3.0, sir_db=None, snr_db=(-10.0, 15.0)),
    },
}


def preset(name: str, task: str, **changes: Any) -> MixingConfig:
    """A named preset for a task, with fields changed (``preset("paper", "separation",
    crop_s=2.0)``)."""
    if name not in PRESETS:
        raise DatasetError(f"preset: expected one of {sorted(PRESETS)}, got {name!r}")
    if task not in TASKS:
        raise DatasetError(f"task: expected one of {list(TASKS)}, got {task!r}")
    return replace(PRESETS[name][task], **changes)


def rms_db(x: np.ndarray) -> float:
    """The recipe's level: 10 log10 of the mean square (floored at 1e-20), dB."""
    return 10.0 * math.log10(max(1e-20, float(np.mean(np.square(x, dtype=np.float64)))))


@dataclass(frozen=True)
class Draw:
    """One item's draws: its group and mixture, the target and background tracks, the crop
    (``start``, ``length`` samples), each track's linear gain, the SIRs and SNR drawn (dB,
    NaN when not drawn) and the crops read, before the gains (the targets', and the
    background's unless the built mixture is read instead)."""

    group: Group
    mixture: dict[str, Any]
    targets: tuple[str, ...]
    background: tuple[str, ...]
    start: int
    length: int
    gains: dict[str, float]
    sir_db: np.ndarray
    snr_db: float
    crop: dict[str, np.ndarray]


class SonicspecDataset:
    """Items of one split of a built dataset for one task, as numpy arrays.

    Parameters
    ----------
    root, split
        The dataset folder (``outputs.dir``) and the split (``train``…).
    task
        ``"separation"`` or ``"enhancement"``.
    config
        A :class:`MixingConfig`, or a preset's name (``"paper"``, ``"sonicsim"``).
    speakers
        Speakers per separation item (default: the dataset's separation mixtures' count).
    background
        The background of the mixtures the items come from (default: the first task of that
        kind in the dataset).
    stems
        Extra targets returned per speaker (``"dry"``, ``"direct"``, ``"early"``), with the
        speaker's gain.
    labels
        Also return each speaker's positions, azimuth, elevation and distance every 10 ms.
    seed
        The seed of every draw (with the epoch and the index).
    augmentation
        Device and channel effects applied on the fly: a spec's ``augmentation:`` block (the
        validated model, ``load_spec(path).augmentation``, or the same block as plain data),
        drawn per item and epoch from its own stream (the other draws do not change with
        it), applied to the mixture, and to the targets for effects marked ``targets``.
    augmentation_dir
        The folder the block's impulse-response files are relative to (default: the
        current one; a spec's block names them relative to the spec).
    format
        The folder's layout (:mod:`sonicspec.dataload.formats`: ``librimix``, ``wham``…);
        ``None``: detected (a folder with ``dataset.json`` is a sonicspec dataset). Sets
        whose background was not released (VoiceBank-DEMAND, DNS, the SonicSet benchmarks)
        give their items as written: dynamic mixing needs the background track.

    Notes
    -----
    Each item is a dict: ``mixture`` ``(C, T)`` float32, ``targets`` ``(k, C, T)``,
    ``<stem>`` ``(k, C, T)`` per stem, ``tracks`` (the source numbers, ``int64`` ``(k,)``),
    ``start`` (first sample of the crop), ``sir_db`` ``(k-1,)`` and ``snr_db`` (the gains
    drawn; NaN when not drawn), ``group`` and ``mixture_name`` (str), and with ``labels``
    ``positions_m`` ``(k, F, 3)``, ``azimuth_deg``, ``elevation_deg``, ``distance_m``
    ``(k, F)``; with ``augmentation`` also ``augmentation``, the item's draw as JSON text
    (as ``metadata.json`` records a group's). A dataset built with ``augmentation:`` holds
    its effects in the mixture files only (the tracks and targets stay clean unless an effect
    says ``targets``): items read as written (``MixingConfig(dynamic=False)``) have them, and
    ``augmentation`` is then the group's recorded draw; dynamic mixing re-mixes the clean
    tracks, so pass the spec's block as ``augmentation`` to have them on the fly.
    """

    def __init__(self, root: str | Path, split: str, task: str = "separation", *,
                 config: MixingConfig | str = "paper", speakers: int | None = None,
                 background: str | None = None, stems: tuple[str, ...] = (),
                 labels: bool = False, seed: int = 0, format: str | None = None,
                 augmentation: Any = None, augmentation_dir: str | Path | None = None) -> None:
        from sonicspec.dataload.formats import open_dataset

        if task not in TASKS:
            raise DatasetError(f"task: expected one of {list(TASKS)}, got {task!r}")
        self.folder = open_dataset(root, format)
        self.split, self.task, self.seed = split, task, int(seed)
        self.config = preset(config, task) if isinstance(config, str) else config
        for s in stems:
            if s not in STEMS:
                raise DatasetError(f"stems: expected names from {list(STEMS)}, got {s!r}")
        self.stems, self.labels = tuple(stems), bool(labels)
        try:
            self.augmentation = (parse_chain(augmentation) if augmentation is not None
                                 else None)
        except AudioError as err:
            raise DatasetError(str(err)) from None
        self._ir_dir = Path(augmentation_dir) if augmentation_dir is not None else Path()
        self._impulse_responses: dict[tuple[str, int], np.ndarray] = {}
        self.epoch = 0
        self.items: list[tuple[str, dict[str, Any]]] = []
        for group in self.folder.groups(split):
            for m in group.mixtures(task):
                k = len(m["targets"])
                bg = tuple(c for c in m["components"] if c not in m["targets"])
                if speakers is not None and k != speakers:
                    continue
                if background is not None and bg != BACKGROUNDS.get(background):
                    continue
                self.items.append((group.id, m))
        if not self.items:
            raise DatasetError(f"{self.folder.root}: split {split!r} has no {task} mixtures"
                               + (f" of {speakers} speakers" if speakers else "")
                               + (f" with background {background!r}" if background else "")
                               + "; see mixture.tasks in its spec")
        if self.config.dynamic:
            partial = next((g for g, m in self.items
                            if m.get("components_complete") is False), None)
            if partial is not None:
                raise DatasetError(f"{self.folder.root}: group {partial}'s mixture has a "
                                   "background that is not among its files (the layout does "
                                   "not release it), so it cannot be re-mixed; use "
                                   "MixingConfig(dynamic=False) for its items as written")
        if background is None:
            first = self.items[0][1]
            self.items = [(g, m) for g, m in self.items
                          if [c for c in m["components"] if c not in m["targets"]]
                          == [c for c in first["components"] if c not in first["targets"]]
                          and len(m["targets"]) == len(first["targets"])]

    def __len__(self) -> int:
        return len(self.items)

    def set_epoch(self, epoch: int) -> None:
        """The epoch whose draws :meth:`__getitem__` makes."""
        self.epoch = int(epoch)

    def __getitem__(self, index: int) -> dict[str, Any]:
        return self.item(index, self.epoch)

    def describe(self) -> dict[str, Any]:
        return {"root": str(self.folder.root), "split": self.split, "task": self.task,
                "seed": self.seed, "items": len(self), "config": asdict(self.config)}

    # -- drawing -------------------------------------------------------------------------

    def _crop_length(self, group: Group) -> int:
        if self.config.crop_s is None:
            return group.num_samples
        n = round(self.config.crop_s * group.sample_rate_hz)
        if n > group.num_samples:
            raise DatasetError(f"crop_s: {self.config.crop_s} s is longer than group "
                               f"{group.id}'s clip ({group.num_samples / group.sample_rate_hz}"
                               " s)")
        return n

    def _level(self, x: np.ndarray, rate: int) -> float:
        if self.config.level == "rms":
            return rms_db(x)
        from sonicspec.audio.mix import integrated_loudness

        value = integrated_loudness(x, rate, where="loader crop")
        return value if math.isfinite(value) else -200.0

    def _gain_to(self, x: np.ndarray, rate: int, target_db: float) -> float:
        """The linear gain bringing ``x`` to ``target_db`` (capped at ``max_gain_db``)."""
        if self.config.level == "lufs" and math.isfinite(self._level(x, rate)) \
                and self._level(x, rate) > -200.0:
            from sonicspec.audio.mix import gain_to_loudness

            gain, _ = gain_to_loudness(x, rate, target_db, where="loader crop")
            return min(gain, 10.0 ** (self.config.max_gain_db / 20.0))
        return 10.0 ** (min(target_db - self._level(x, rate), self.config.max_gain_db) / 20.0)

    def draw(self, index: int, epoch: int = 0) -> Draw:
        """What item ``index`` of epoch ``epoch`` is made of: the group, the tracks, the crop
        and the gains (the audio of the crop too, as :meth:`item` uses it)."""
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} out of range for {len(self)} items")
        cfg = self.config
        group_id, mixture = self.items[index]
        group = self.folder.group(group_id)
        rate = group.sample_rate_hz
        rng = rng_for(self.seed, "loader", self.split, self.task, str(epoch), str(index))
        length = self._crop_length(group)
        targets = list(mixture["targets"])
        background = [c for c in mixture["components"] if c not in targets]
        if cfg.dynamic:
            order = rng.permutation(len(group.speakers))[:len(targets)]
            targets = [group.speakers[i] for i in order]
            if cfg.backgrounds:
                choice = cfg.backgrounds[int(rng.integers(len(cfg.backgrounds)))]
                background = list(BACKGROUNDS[choice])
                missing = [b for b in background if b not in group.backgrounds]
                if missing:
                    raise DatasetError(f"{group.root / group.id}: background {choice!r} needs "
                                       f"{' and '.join(missing)}, which the group lacks")
        start, crop = self._draw_crop(rng, group, targets, length)
        if cfg.dynamic or not mixture.get("file"):  # else the built mixture is read instead
            crop.update({n: group.read(n, start, start + length, cfg.channels)
                         for n in background})
        sir = np.full(max(len(targets) - 1, 0), np.nan)
        snr = math.nan
        gains = dict.fromkeys([*targets, *background], 1.0)
        if cfg.dynamic:
            ref = crop[targets[0]][0]
            if cfg.sir_db is not None and len(targets) > 1:
                sir = rng.uniform(cfg.sir_db[0], cfg.sir_db[1], size=len(targets) - 1)
                first = self._level(ref, rate)
                for s, name in zip(sir, targets[1:], strict=True):
                    gains[name] = self._gain_to(crop[name][0], rate, first - float(s))
            if cfg.snr_db is not None and background:
                snr = float(rng.uniform(cfg.snr_db[0], cfg.snr_db[1]))
                speech = sum(gains[n] * crop[n][0].astype(np.float64) for n in targets)
                noise = sum(crop[n][0].astype(np.float64) for n in background)
                g = self._gain_to(noise, rate, self._level(speech, rate) - snr)
                for n in background:
                    gains[n] = g
        return Draw(group, mixture, tuple(targets), tuple(background), start, length, gains,
                    sir, snr, crop)

    def item(self, index: int, epoch: int = 0) -> dict[str, Any]:
        """Item ``index`` of epoch ``epoch`` (what ``__getitem__`` returns after
        ``set_epoch(epoch)``)."""
        d = self.draw(index, epoch)
        cfg, group, gains, crop = self.config, d.group, d.gains, d.crop
        start, length = d.start, d.length
        target_arr = np.stack([gains[n] * crop[n] for n in d.targets]).astype(np.float32)
        if cfg.dynamic or not d.mixture.get("file"):
            mix = sum(gains[n] * crop[n].astype(np.float64) for n in crop).astype(np.float32)
        else:
            mix = group.read(d.mixture["file"], start, start + length, cfg.channels)
        out: dict[str, Any] = {
            "mixture": mix, "targets": target_arr,
            "tracks": np.array([int(n[6:]) for n in d.targets], dtype=np.int64),
            "start": int(start), "sir_db": d.sir_db, "snr_db": d.snr_db,
            "group": group.id, "mixture_name": d.mixture["name"]}
        for stem in self.stems:
            out[stem] = np.stack([
                gains[n] * group.read(f"{n}_{stem}", start, start + length, cfg.channels)
                for n in d.targets]).astype(np.float32)
        recorded = group.metadata.get("augmentation")
        if recorded and not cfg.dynamic and d.mixture.get("file"):
            # the built mixture, read as written: the effects the build applied to it
            out["augmentation"] = json.dumps(recorded, sort_keys=True)
        if self.augmentation is not None:
            out.update(self._augment(out, index, epoch, group.sample_rate_hz))
        if self.labels:
            out.update(self._labels(group, list(d.targets), start, length))
        return out

    def _augment(self, item: dict[str, Any], index: int, epoch: int, rate: int
                 ) -> dict[str, Any]:
        """The item's mixture (and targets and stems, for effects marked ``targets``) through
        one draw of the augmentation chain, seeded by (seed, epoch, index)."""
        assert self.augmentation is not None
        rng = rng_for(self.seed, "augment", self.split, self.task, str(epoch), str(index))
        draw = draw_chain(self.augmentation, rng)
        responses = {}
        for name in chain_files(self.augmentation):
            if (name, rate) not in self._impulse_responses:
                self._impulse_responses[(name, rate)] = read_impulse_response(
                    self._ir_dir / name, rate, where=f"augmentation impulse_response {name!r}")
            responses[name] = self._impulse_responses[(name, rate)]
        out: dict[str, Any] = {"augmentation": json.dumps(draw, sort_keys=True)}
        mix, _ = apply_chain(draw, item["mixture"], rate, impulse_responses=responses)
        out["mixture"] = mix.astype(np.float32)
        if any(d["applied"] and d["targets"] for d in draw):
            for key in ("targets", *self.stems):
                out[key] = np.stack([
                    apply_chain(draw, t, rate, target=True, impulse_responses=responses)[0]
                    for t in item[key]]).astype(np.float32)
        return out

    def to_lhotse(self, epoch: int = 0):
        """The items of ``epoch`` as a Lhotse ``CutSet`` of ``MixedCut`` s: one track per
        target then per background, each a crop of the track's recording with its drawn gain
        (``perturb_volume``), so ``cut.load_audio()`` is the item's mixture and
        ``cut.tracks[i].cut.load_audio()`` target ``i``. Needs ``lhotse``."""
        try:
            from lhotse import CutSet, MonoCut, Recording
            from lhotse.cut import MixedCut, MixTrack
        except ImportError:
            raise DatasetError("to_lhotse needs lhotse: pip install lhotse") from None
        cuts = []
        recordings: dict[str, Any] = {}
        for i in range(len(self)):
            d = self.draw(i, epoch)
            rate = d.group.sample_rate_hz
            tracks = []
            for name in (*d.targets, *d.background):
                rec_id = f"{d.group.id.replace('/', '_')}_{name}"
                if rec_id not in recordings:
                    recordings[rec_id] = Recording.from_file(d.group.track_path(name),
                                                             recording_id=rec_id)
                rec = recordings[rec_id]
                channel = list(self.config.channels) if self.config.channels else \
                    list(range(rec.num_channels))
                cut = MonoCut(id=f"{rec_id}-{self.split}-{epoch}-{i}", start=d.start / rate,
                              duration=d.length / rate,
                              channel=channel[0] if len(channel) == 1 else channel,
                              recording=rec)
                # The file's scale (outputs.scale: per_file) times the drawn gain.
                factor = d.gains[name] * d.group.scale(name)
                if factor != 1.0:
                    cut = cut.perturb_volume(factor=factor, affix_id=False)
                tracks.append(MixTrack(cut=cut))
            cuts.append(MixedCut(id=f"{self.split}-{self.task}-{epoch}-{i}", tracks=tracks))
        return CutSet.from_cuts(cuts)

    def _draw_crop(self, rng: np.random.Generator, group: Group, targets: list[str],
                   length: int) -> tuple[int, dict[str, np.ndarray]]:
        """A crop start in ``[0, clip - length]`` and the targets' crops.

        With dynamic mixing the crop must hear every target (RMS of at least −40 dB, the
        recipe's test). The recipe re-draws blind, reading audio each time; here the start is
        drawn among those whose crop overlaps an utterance of every target (the metadata's
        ``start_end_points``), then checked on the audio, and re-drawn (up to ``crop_tries``)
        only if the check fails. Only the crops are read (FLAC and WAV seek).
        """
        total, channels = group.num_samples, self.config.channels
        candidates = (self._speech_starts(group, targets, length)
                      if self.config.dynamic and length < total else None)

        def draw() -> int:
            if candidates is not None and candidates.size:
                return int(candidates[rng.integers(candidates.size)])
            return int(rng.integers(0, total - length + 1))

        start = draw()
        crop = {n: group.read(n, start, start + length, channels) for n in targets}
        if not self.config.dynamic or length >= total:
            return start, crop
        for _ in range(self.config.crop_tries):
            if all(rms_db(crop[n][0]) >= SILENCE_RMS_DB for n in targets):
                break
            start = draw()
            crop = {n: group.read(n, start, start + length, channels) for n in targets}
        return start, crop

    @staticmethod
    def _speech_starts(group: Group, targets: list[str], length: int) -> np.ndarray:
        """Crop starts (every 10 ms) whose crop overlaps an utterance of every target."""
        hop = max(1, group.sample_rate_hz // 100)
        starts = np.arange(0, group.num_samples - length + 1, hop)
        ok = np.ones(starts.size, dtype=bool)
        for name in targets:
            spans = group.metadata[name].get("start_end_points") or []
            heard = np.zeros(starts.size, dtype=bool)
            for a, b in spans:  # [start, start + length) meets [a, b)
                heard |= (starts < b) & (starts + length > a)
            ok &= heard
        return starts[ok]

    def _labels(self, group: Group, targets: list[str], start: int,
                length: int) -> dict[str, np.ndarray]:
        by_name = group.tracks(targets)
        tracks = [by_name[n] for n in targets]
        hop = round(tracks[0]["hop_s"] * group.sample_rate_hz)
        first, count = start // hop, -(-length // hop)
        out = {}
        for key in ("positions_m", "azimuth_deg", "elevation_deg", "distance_m"):
            rows = []
            for t in tracks:
                values = t[key]
                idx = np.minimum(np.arange(first, first + count), len(values) - 1)
                rows.append(values[idx])
            out[key] = np.stack(rows)
        return out
