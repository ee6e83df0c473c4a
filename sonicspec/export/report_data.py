"""What the dataset report shows, as numbers: read from the dataset folder (and, when it is
reachable, the artifact store the folder names), never by decoding audio.

Every distribution is aggregated from the groups' ``metadata.json`` (the SonicSet form that
``stages.export`` writes; fields a metadata file lacks are left out and counted, so a SonicSet
release's plainer metadata reports what it has). Scene geometry, material areas, repair facts
and the RIRs of the sampled groups come from the store; without a store those parts say so.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.errors import SonicspecError
from sonicspec.export.checksums import DATASET_MARKER
from sonicspec.export.tracks import TrackError, is_reference, read_track
from sonicspec.hashing import rng_for
from sonicspec.units import OCTAVE_BANDS_HZ, bands_below_nyquist

# The SonicSim paper's recipe where it states one (as the `sonicset` preset writes it:
# specs/sonicset.yaml, "the paper's rules: 1-8 m"; spec.mixture.LOUDNESS_PRESETS
# "sonicsim_paper": -17 / -21 / -24 LUFS).
PAPER_DISTANCE_M = (1.0, 8.0)
PAPER_TRAVEL_M = (1.0, 8.0)

# Thresholds of the warnings the issue asks for.
GUARD_CUT_DB = -3.0
CLOSE_SOURCE_M = 0.5

ROLES = ("speech", "noise", "music")


class ReportError(SonicspecError):
    """A folder the report cannot read (not a dataset, unreadable metadata)."""


# --- reading -------------------------------------------------------------------------------


@dataclass
class DatasetInfo:
    """A dataset folder: its summary (``dataset.json``, may be empty), marker and groups."""

    root: Path
    summary: dict[str, Any]
    marker: dict[str, Any]
    groups: list[dict[str, Any]]  # {"group", "split", "scene_id", "metadata_path"}

    @property
    def spec(self) -> dict[str, Any]:
        return self.summary.get("spec") or {}

    @property
    def store_dir(self) -> Path | None:
        rel = self.marker.get("store")
        if not rel:
            return None
        path = (self.root / rel).resolve()
        return path if path.is_dir() else None


def read_dataset(root: Path) -> DatasetInfo:
    """The dataset folder ``root``: ``dataset.json`` when there (a sonicspec build), else every
    ``<split>/<group>/metadata.json`` found (a SonicSet-style folder)."""
    root = Path(root)
    if not root.is_dir():
        raise ReportError(f"{root}: no such folder")
    marker: dict[str, Any] = {}
    if (root / DATASET_MARKER).is_file():
        marker = _read_json(root / DATASET_MARKER)
    summary_path = root / "dataset.json"
    summary: dict[str, Any] = {}
    groups: list[dict[str, Any]] = []
    if summary_path.is_file():
        summary = _read_json(summary_path)
        for g in summary.get("groups", []):
            rel = (g.get("metadata") or {}).get("path")
            groups.append({"group": g["group"], "split": g["split"],
                           "scene_id": g.get("scene_id"),
                           "metadata_path": root / rel if rel else None})
    else:
        for path in sorted(root.glob("*/*/metadata.json")):
            split, index = path.parent.parent.name, path.parent.name
            groups.append({"group": f"{split}/{index}", "split": split, "scene_id": None,
                           "metadata_path": path})
    if not groups:
        raise ReportError(f"{root}: expected a dataset folder (dataset.json, or "
                          "<split>/<group>/metadata.json files), found neither")
    return DatasetInfo(root, summary, marker, groups)


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ReportError(f"{path}: unreadable JSON ({exc})") from None


_TRACK = b'track": {'
# A moving microphone's track has a heading (stages.export.microphone_track); so does a
# directional source's (its facing): such a file is parsed whole, which is right either way.
_MOVING_MIC = b'"yaw_deg"'


def read_metadata(path: Path) -> dict[str, Any]:
    """A group's metadata, read fast in either form.

    Since metadata version 2 the position tracks are references to ``tracks.npz`` and the
    file is compact JSON (a few kB), parsed whole (``read_track`` reads the tracks). The
    older form held the tracks inline in indented JSON (``track``, ``microphone_track``: a
    number every 10 ms, 90 % of a 60 s group's 3 MB, which the report does not use): they
    are cut from the bytes before parsing, 15x faster than parsing them. Such a track holds
    no nested object, so it ends at the first ``}``; if another ``{`` comes first, the file
    is parsed whole."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ReportError(f"{path}: unreadable ({exc.strerror or exc})") from None
    if _MOVING_MIC in data:  # a moving microphone: distances need the tracks (issue 28)
        try:
            return json.loads(data)
        except ValueError as exc:
            raise ReportError(f"{path}: unreadable JSON ({exc})") from None
    parts, pos = [], 0
    while True:
        j = data.find(_TRACK, pos)
        if j < 0:
            parts.append(data[pos:])
            break
        body = j + len(_TRACK)
        k = data.find(b"}", body)
        if k < 0 or data.find(b"{", body, k) >= 0:
            parts = [data]
            break
        parts += [data[pos:body], b"}"]
        pos = k + 1
    try:
        return json.loads(b"".join(parts))
    except ValueError:
        try:
            return json.loads(data)
        except ValueError as exc:
            raise ReportError(f"{path}: unreadable JSON ({exc})") from None


# --- per-group facts -------------------------------------------------------------------------


def _union_length(intervals: Iterable[Sequence[float]]) -> float:
    """Total length covered by ``[start, end)`` intervals."""
    total, end = 0.0, -math.inf
    for a, b in sorted((float(a), float(b)) for a, b in intervals):
        if b <= a:
            continue
        if a > end:
            total += b - a
            end = b
        elif b > end:
            total += b - end
            end = b
    return total


def overlap_ratio(speakers: Sequence[Sequence[Sequence[float]]]) -> float | None:
    """Time two or more speakers talk at once over the time at least one does (None: no
    speech). ``speakers``: per speaker, its ``[start, end)`` intervals."""
    events = []
    for intervals in speakers:
        # one speaker's own intervals do not overlap each other: merge them first
        merged: list[list[float]] = []
        for a, b in sorted((float(a), float(b)) for a, b in intervals):
            if b <= a:
                continue
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        for a, b in merged:
            events += [(a, 1), (b, -1)]
    if not events:
        return None
    events.sort()
    active, last, any_time, multi_time = 0, events[0][0], 0.0, 0.0
    for t, step in events:
        if active >= 1:
            any_time += t - last
        if active >= 2:
            multi_time += t - last
        active += step
        last = t
    return multi_time / any_time if any_time > 0 else None


def segment_distances(points: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Distance from ``at`` (3,) to every segment of the polyline ``points`` (P, 3), exact;
    a single point is its own segment."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    a, b = (p[:-1], p[1:]) if len(p) > 1 else (p, p)
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", at - a, ab) / np.where(length2 > 0, length2, 1.0), 0, 1)
    return np.linalg.norm(a + t[:, None] * ab - at, axis=1)


def _distances(entry: dict[str, Any], mic: np.ndarray | None) -> tuple[float, ...] | None:
    """Source–microphone distance at the start and end of the path and its minimum along it
    (exact, from the path's polyline; a static source's position), m."""
    points = entry.get("trajectory_m") or ([entry["position_m"]] if entry.get("position_m")
                                           else None)
    if points is None or mic is None:
        return None
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    ends = np.linalg.norm(p[[0, -1]] - mic, axis=1)
    return float(ends[0]), float(ends[1]), float(segment_distances(p, mic).min())


def track_values(entry: Any, root: Path | None) -> dict[str, np.ndarray]:
    """A position track's arrays (float64, :func:`sonicspec.export.tracks.read_track`): the
    inline lists, or a reference into the group's ``tracks.npz`` (``file`` relative to the
    dataset folder ``root``). Empty when there is none."""
    if not isinstance(entry, dict) or not entry or (is_reference(entry) and root is None):
        return {}  # none, or cut by read_metadata (the report reads inline tracks seldom)
    try:
        track = read_track(root or Path("."), entry)
    except TrackError as exc:
        raise ReportError(str(exc)) from None
    return {k: v for k, v in track.items() if k != "hop_s"}


def microphone_path(meta: dict[str, Any], root: Path | None = None) -> np.ndarray | None:
    """Where a moving microphone is every 10 ms, ``(frames, 3)`` (``microphone_track``);
    None when it stands still."""
    pos = track_values(meta.get("microphone_track"), root).get("positions_m")
    if pos is None or pos.size < 6:
        return None
    pos = pos.reshape(-1, 3)
    return pos if np.ptp(pos, axis=0).max() > 0 else None


FACING_EVERY = 10
"""The report's facing histogram takes every 10th 10 ms frame of a facing track (0.1 s)."""


def facing_to_mic_deg(entry: dict[str, Any], mic_path: np.ndarray | None,
                      mic: np.ndarray | None, root: Path | None) -> list[float] | None:
    """Where a directional source faces relative to the microphone: the horizontal angle
    between its front (its track's ``yaw_deg``) and the direction from it to the microphone,
    degrees in [0, 180] (0: it faces the microphone, 180: its back is turned), every
    :data:`FACING_EVERY`-th frame. None for a source without a facing track (omni)."""
    track = entry.get("track")
    if not isinstance(track, dict) or "yaw_deg" not in (track.get("arrays") or track):
        return None  # an omni source: no archive opened
    values = track_values(track, root)
    yaw, pos = values.get("yaw_deg"), values.get("positions_m")
    if yaw is None or pos is None:
        return None
    pos, yaw = pos.reshape(-1, 3), yaw.reshape(-1)
    n = min(len(pos), len(yaw))
    if mic_path is not None and len(mic_path) >= n:
        to_mic = mic_path[:n, :2] - pos[:n, :2]
    elif mic is not None:
        to_mic = mic[None, :2] - pos[:n, :2]
    else:
        return None
    bearing = np.degrees(np.arctan2(to_mic[:, 1], to_mic[:, 0]))
    angle = np.abs((yaw[:n] - bearing + 180.0) % 360.0 - 180.0)
    return [round(float(a), 2) for a in angle[::FACING_EVERY]]


def facing_shares(angles: np.ndarray) -> dict[str, float] | None:
    """Shares of facing angles towards the microphone (< 45°), sideways (45–135°) and away
    (> 135°); None without angles."""
    if not angles.size:
        return None
    return {"towards": float(np.mean(angles < 45.0)),
            "sideways": float(np.mean((angles >= 45.0) & (angles <= 135.0))),
            "away": float(np.mean(angles > 135.0))}


def _moving_distances(entry: dict[str, Any], mic_path: np.ndarray, root: Path | None
                      ) -> tuple[float, ...] | None:
    """Source–microphone distance at the first and last frame and its minimum, both moving:
    the source's own track (its ``distance_m`` from the microphone, frame by frame), or its
    positions against the microphone's at the same frames; without a track, its path against
    every place the microphone passes (the minimum is then a lower bound)."""
    values = track_values(entry.get("track"), root)
    d = values.get("distance_m")
    if d is None and values.get("positions_m") is not None:
        pos = values["positions_m"].reshape(-1, 3)
        if len(pos) == len(mic_path):
            d = np.linalg.norm(pos - mic_path, axis=1)
    if d is not None and d.size:
        return float(d[0]), float(d[-1]), float(d.min())
    points = entry.get("trajectory_m") or ([entry["position_m"]] if entry.get("position_m")
                                           else None)
    if points is None:
        return None
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nearest = min(float(segment_distances(p, m).min()) for m in mic_path)
    return (float(np.linalg.norm(p[0] - mic_path[0])),
            float(np.linalg.norm(p[-1] - mic_path[-1])), nearest)


def _speed(entry: dict[str, Any], rate: float | None, speed_m_s: float | None,
           span: str = "speech", clip_samples: int | None = None) -> float | None:
    """Walking speed: the spec's, or (null there) the path over the time the walk spans, as
    the renderer walks it (``trajectory.span``: from the first utterance's start to the last
    one's end, or the whole clip), m/s."""
    if speed_m_s:
        return float(speed_m_s)
    length, spans = _num(entry.get("path_length_m")), entry.get("start_end_points")
    if length is None or not rate:
        return None
    if span == "clip":
        duration = float(clip_samples or 0) / float(rate)
    elif not spans:
        return None
    else:
        duration = (float(spans[-1][1]) - float(spans[0][0])) / float(rate)
    return length / duration if duration > 0 else None


def rir_cut(tail: Any, rate: float | None = None) -> dict[str, Any] | None:
    """A source's RIRs cut while still decaying (its metadata's ``rir_tail``: bands whose
    decay the length limit cut before it was 60 dB down): the limit, the bands, the level
    each had reached and the longest fitted T60; None when nothing was cut."""
    if not isinstance(tail, dict):
        return None
    levels = tail.get("level_at_limit_db") or []
    bands = list(tail.get("bands_hz") or (bands_below_nyquist(rate, OCTAVE_BANDS_HZ) if rate
                                          else ()))
    if len(bands) != len(levels):  # bands set in the spec: not in the metadata
        bands = [None] * len(levels)
    cut = [(b, v) for b, v in zip(bands, levels, strict=False) if v is not None]
    if not cut:
        return None
    t60 = [v for v in tail.get("fitted_t60_s") or [] if v is not None]
    return {"limit_s": _num(tail.get("limit_s")), "field": tail.get("limit_field"),
            "levels_db": [v for _, v in cut], "bands_hz": [b for b, _ in cut],
            "fitted_t60_s": max(t60) if t60 else None}


def _num(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def source_names(meta: dict[str, Any]) -> list[str]:
    """``source1``, ``source2``, ... in order, then ``noise`` and ``music`` when present."""
    speech = sorted((k for k in meta if re.fullmatch(r"source\d+", k)), key=lambda k: int(k[6:]))
    return speech + [k for k in ("noise", "music") if isinstance(meta.get(k), dict)]


def group_facts(meta: dict[str, Any], speed_m_s: float | None = None,
                span: str = "speech", root: Path | None = None) -> dict[str, Any]:
    """One group's figures for the report: per source and per group (see the module doc).
    ``speed_m_s``: the spec's walking speed (None: the walk spans ``span``, the spec's
    ``trajectory.span``). A moving microphone's distances come from the tracks (``root``:
    the dataset folder the tracks' files are relative to), never from ``mic_m``, where it
    starts."""
    mic = np.asarray(meta["mic_m"], dtype=np.float64) if meta.get("mic_m") else None
    mic_path = microphone_path(meta, root)
    n = meta.get("num_samples")
    rate = meta.get("sample_rate_hz")
    sources = []
    for name in source_names(meta):
        e = meta[name]
        role = "speech" if name.startswith("source") else name
        loud = e.get("loudness") or {}
        dist = (_moving_distances(e, mic_path, root) if mic_path is not None
                else _distances(e, mic))
        s: dict[str, Any] = {
            "name": name, "role": role,
            "t30_s": _num(e.get("t30_s")), "drr_db": _num(e.get("drr_db")),
            "direct_path": e.get("direct_path"),
            "measured_lufs": _num(loud.get("measured_lufs")),
            "output_lufs": _num(loud.get("output_lufs")),
            "target_lufs": _num(loud.get("target_lufs")),
            "distance_start_m": dist[0] if dist is not None else None,
            "distance_end_m": dist[1] if dist is not None else None,
            "distance_min_m": dist[2] if dist is not None else None,
            "intervals": [list(p) for p in e.get("start_end_points") or []],
            "position_m": e.get("position_m"), "file": e.get("file"),
            "rir_cut": rir_cut(e.get("rir_tail"), rate),
            "image_source_order": e.get("image_source_order"),
        }
        s["facing_to_mic_deg"] = facing_to_mic_deg(e, mic_path, mic, root)
        if role == "speech":
            s.update(path_length_m=_num(e.get("path_length_m")),
                     speed_m_s=_speed(e, rate, speed_m_s, span, n),
                     speaker=e.get("speaker"), trajectory_m=e.get("trajectory_m"))
        sources.append(s)
    speech = [s for s in sources if s["role"] == "speech"]
    facts: dict[str, Any] = {
        "group": meta.get("group"), "split": meta.get("split"), "scene_id": meta.get("scene_id"),
        "floor": meta.get("floor"), "mic_m": meta.get("mic_m"),
        # a moving microphone's walk, every 10th frame (10 ms each) and its last, to draw
        "mic_path_m": (None if mic_path is None else
                       np.concatenate([mic_path[::10], mic_path[-1:]]).tolist()),
        "empty": not source_names(meta) and meta.get("num_samples") is None,
        "group_gain_db": _num(meta.get("group_gain_db")),
        "overlap_ratio": overlap_ratio([s["intervals"] for s in speech]),
        "sources": sources,
        "mixtures": [(m.get("name"), m.get("file")) for m in meta.get("mixtures") or []],
        "num_samples": n, "sample_rate_hz": meta.get("sample_rate_hz"),
        "rir_key": (meta.get("keys") or {}).get("rir"),
        "device": (meta.get("capsules") or {}).get("device"),
    }
    facts.update(augmentation_facts(meta))
    for role in ROLES:
        of_role = [iv for s in sources if s["role"] == role for iv in s["intervals"]]
        facts[f"{role}_activity"] = (_union_length(of_role) / n if n and of_role
                                     else (0.0 if n else None))
    return facts


# The augmentation draws the report shows (issue 30): (kind, drawn field, label, unit).
AUGMENT_QUANTITIES = (
    ("self_noise", "snr_db", "augmentation: self-noise SNR", "dB"),
    ("gain", "gain_db", "augmentation: gain", "dB"),
    ("clipping", "threshold_dbfs", "augmentation: clipping level", "dBFS"),
    ("resample", "rate_hz", "augmentation: resampled through", "Hz"),
    ("mp3", "bitrate_kbps", "augmentation: MP3 bit rate asked", "kbit/s"),
    ("opus", "bitrate_kbps", "augmentation: Opus bit rate asked", "kbit/s"),
)


def _applied_effects(meta: dict[str, Any]) -> list[dict[str, Any]]:
    """The effects of a group's augmentation draw that were applied (a one_of's choice in
    its place)."""
    out = []
    for d in meta.get("augmentation") or []:
        if isinstance(d, dict) and d.get("applied"):
            out.append(d["effect"] if d.get("kind") == "one_of" and "effect" in d else d)
    return out


def augmentation_facts(meta: dict[str, Any]) -> dict[str, Any]:
    """A group's augmentation draw as report facts: ``augmented`` (a draw is recorded),
    ``aug_effects`` (how many effects were applied), ``aug_labels`` (each applied effect,
    a response with its preset), per :data:`AUGMENT_QUANTITIES` the drawn value (None: not
    applied) and ``aug_codec_kbps_measured``, the codec's measured bit rate on the first
    mixture."""
    if not meta.get("augmentation"):  # every key, so a quantity finds its field
        return {"augmented": False, "aug_effects": None, "aug_labels": [],
                "aug_codec_kbps_measured": None,
                **{f"aug_{kind}_{name}": None for kind, name, _, _ in AUGMENT_QUANTITIES}}
    applied = _applied_effects(meta)
    facts: dict[str, Any] = {"augmented": True, "aug_effects": len(applied),
                             "aug_labels": [d["kind"] + (f":{d['preset']}" if d.get("preset")
                                                         else "") for d in applied]}
    for kind, name, _, _ in AUGMENT_QUANTITIES:
        values = [d.get(name) for d in applied if d.get("kind") == kind]
        facts[f"aug_{kind}_{name}"] = _num(values[0]) if values else None
    measured = None
    mixtures = meta.get("mixtures") or []
    for m in (mixtures[0].get("augmentation") or []) if mixtures else []:
        if isinstance(m, dict) and "bitrate_kbps" in m:
            measured = _num(m["bitrate_kbps"])
    facts["aug_codec_kbps_measured"] = measured
    return facts


def augmentation_shares(groups: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per applied effect (a response with its preset): groups and share of ``groups``."""
    augmented = [g for g in groups if g.get("augmented")]
    counts: dict[str, int] = {}
    for g in augmented:
        for label in set(g.get("aug_labels") or []):
            counts[label] = counts.get(label, 0) + 1
    return {k: {"count": n, "share": n / len(augmented)} for k, n in sorted(counts.items())}


def _augment_range(spec: dict[str, Any], kind: str, name: str) -> tuple[float, float] | None:
    """The spec's range of ``kind``'s ``name`` (the first such effect, one_of's included)."""
    effects = list((spec.get("augmentation") or {}).get("effects") or [])
    effects += [e for o in effects if o.get("kind") == "one_of" for e in o.get("effects") or []]
    for e in effects:
        if e.get("kind") == kind and name in e:
            v = e[name]
            if isinstance(v, list) and v and all(isinstance(x, int | float) for x in v):
                return float(min(v)), float(max(v))
    return None


def read_group_facts(info: DatasetInfo, split: str | None = None) -> list[dict[str, Any]]:
    """Facts of every group (of ``split``) whose metadata file exists, in group order."""
    trajectory = info.spec.get("trajectory") or {}
    speed_m_s, span = trajectory.get("speed_m_s"), trajectory.get("span", "speech")
    out = []
    for g in info.groups:
        if split is not None and g["split"] != split:
            continue
        path = g["metadata_path"]
        if path is None or not path.is_file():
            continue
        meta = read_metadata(path)
        facts = group_facts(meta, speed_m_s, span, info.root)
        if facts["empty"]:  # `{}`: listed by missing_files
            continue
        facts["group"] = facts["group"] or g["group"]
        facts["split"] = facts["split"] or g["split"]
        facts["scene_id"] = facts["scene_id"] or g["scene_id"] or "unknown"
        facts["metadata_path"] = path
        out.append(facts)
    return out


# --- distributions -------------------------------------------------------------------------


@dataclass(frozen=True)
class Quantity:
    """A figure the report shows per split: how to collect it and what marks it has."""

    key: str
    label: str
    unit: str
    per: str  # "group" or a role ("speech", "any" for every source)
    field: str
    marks: tuple[tuple[str, float], ...] = ()  # (label, value) vertical lines
    ranges: tuple[tuple[str, float, float], ...] = ()  # (label, lo, hi) shaded


def _spec_range(spec: dict[str, Any], *path: str) -> tuple[float, float] | None:
    node: Any = spec
    for p in path:
        if not isinstance(node, dict) or p not in node:
            return None
        node = node[p]
    return (float(node[0]), float(node[1])) if isinstance(node, list) and len(node) == 2 else None


def quantities(spec: dict[str, Any]) -> list[Quantity]:
    """The distributions, with the spec's recipe and the paper's values marked."""
    from sonicspec.spec.mixture import LOUDNESS_PRESETS

    paper = LOUDNESS_PRESETS["sonicsim_paper"]
    loud = (spec.get("mixture") or {}).get("loudness") or {}

    def ranges(*path: str, paper_range: tuple[float, float] | None = None):
        out = []
        r = _spec_range(spec, "placement", *path)
        if r is not None:
            out.append(("spec", *r))
        if paper_range is not None:
            out.append(("paper", *paper_range))
        return tuple(out)

    def level(role: str):
        marks = []
        if f"{role}_lufs" in loud:
            marks.append(("spec target", float(loud[f"{role}_lufs"])))
        marks.append(("paper", paper[f"{role}_lufs"]))
        return tuple(marks)

    speed = (spec.get("trajectory") or {}).get("speed_m_s")
    guard_marks = [("warning below", GUARD_CUT_DB)]
    qs = [
        Quantity("t30", "T30 (broadband, first RIR point)", "s", "any", "t30_s"),
        Quantity("drr", "DRR (first RIR point)", "dB", "any", "drr_db"),
        Quantity("distance_start", "source–mic distance at the start", "m", "speech",
                 "distance_start_m",
                 ranges=ranges("source_start_distance_m", paper_range=PAPER_DISTANCE_M)),
        Quantity("distance_end", "source–mic distance at the end", "m", "speech",
                 "distance_end_m",
                 ranges=ranges("source_end_distance_m", paper_range=PAPER_DISTANCE_M)),
        Quantity("distance_min", "minimum source–mic distance along the path", "m", "any",
                 "distance_min_m", marks=(("warning below", CLOSE_SOURCE_M),)),
        Quantity("path_length", "path length", "m", "speech", "path_length_m",
                 ranges=ranges("source_travel_distance_m", paper_range=PAPER_TRAVEL_M)),
        Quantity("speed", "walking speed while moving", "m/s", "speech", "speed_m_s",
                 marks=(("spec", float(speed)),) if speed else ()),
    ]
    for role in ROLES:
        qs.append(Quantity(f"{role}_before", f"{role} loudness before normalisation", "LUFS",
                           role, "measured_lufs"))
        qs.append(Quantity(f"{role}_after", f"{role} loudness after normalisation and guard",
                           "LUFS", role, "output_lufs", marks=level(role)))
    qs += [
        Quantity("group_gain", "peak-guard gain", "dB", "group", "group_gain_db",
                 marks=tuple(guard_marks)),
        Quantity("overlap", "speaker overlap ratio", "", "group", "overlap_ratio"),
    ]
    qs += [Quantity(f"{role}_activity", f"{role} activity (share of the clip)", "", "group",
                    f"{role}_activity") for role in ROLES]
    # Augmentation draws (shown when a dataset has them: a quantity without values is left out)
    qs.append(Quantity("aug_effects", "augmentation: effects applied per group", "", "group",
                       "aug_effects"))
    for kind, name, label, unit in AUGMENT_QUANTITIES:
        r = _augment_range(spec, kind, name)
        qs.append(Quantity(f"aug_{kind}_{name}", label, unit, "group", f"aug_{kind}_{name}",
                           ranges=(("spec", *r),) if r else ()))
    qs.append(Quantity("aug_codec_kbps", "augmentation: codec bit rate measured (first "
                       "mixture, per channel)", "kbit/s", "group", "aug_codec_kbps_measured"))
    return qs


def values_of(q: Quantity, groups: Sequence[dict[str, Any]]) -> np.ndarray:
    """Every finite value of ``q`` in ``groups``."""
    if q.per == "group":
        vals = [g[q.field] for g in groups]
    else:
        vals = [s.get(q.field) for g in groups for s in g["sources"]
                if q.per == "any" or s["role"] == q.per]
    return np.asarray([v for v in vals if v is not None and math.isfinite(v)],
                      dtype=np.float64)


def missing_of(q: Quantity, groups: Sequence[dict[str, Any]]) -> int:
    """How many of ``q``'s values ``groups`` lack (null in the metadata: a T30 that the
    decay did not allow to measure, a field a plainer metadata does not have)."""
    if q.per == "group":
        vals = [g.get(q.field) for g in groups]
    else:
        vals = [s.get(q.field) for g in groups for s in g["sources"]
                if q.per == "any" or s["role"] == q.per]
    return sum(1 for v in vals if v is None or not math.isfinite(v))


def missing_files(info: DatasetInfo) -> list[dict[str, Any]]:
    """What the report would silently lack: groups whose ``metadata.json`` is missing or
    empty, and (a sonicspec build: ``checksums.sha256`` lists its files) listed files that
    are gone. ``{"path", "problem"}`` each, paths relative to the dataset folder."""
    from sonicspec.export.checksums import CHECKSUMS_NAME

    out: list[dict[str, Any]] = []
    for g in info.groups:
        path = g["metadata_path"]
        if path is None or not path.is_file():
            rel = (Path(os.path.relpath(path, info.root)).as_posix() if path is not None
                   else f"{g['group']}/metadata.json")
            out.append({"path": rel, "problem": "missing"})
        elif path.stat().st_size < 16 and path.read_bytes().strip() in (b"{}", b""):
            out.append({"path": Path(os.path.relpath(path, info.root)).as_posix(),
                        "problem": "empty"})
    listing = info.root / CHECKSUMS_NAME
    if listing.is_file():
        try:
            lines = listing.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise ReportError(f"{listing}: unreadable ({exc.strerror or exc})") from None
        for line in lines:
            _, _, rel = line.partition("  ")
            rel = rel.strip()
            if rel and not (info.root / rel).is_file():
                out.append({"path": rel, "problem": "missing"})
    return out


def stats(values: np.ndarray) -> dict[str, float | int | None]:
    """Count, median, 5th and 95th percentile, mean, min and max (None when empty)."""
    if values.size == 0:
        return {"n": 0, "median": None, "p5": None, "p95": None, "mean": None, "min": None,
                "max": None}
    return {"n": int(values.size), "median": float(np.median(values)),
            "p5": float(np.percentile(values, 5)), "p95": float(np.percentile(values, 95)),
            "mean": float(values.mean()), "min": float(values.min()),
            "max": float(values.max())}


def direct_path_shares(groups: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per kind of direct path (visible, through walls, blocked, diffracted, ...): the count
    and share of the sources that have one."""
    kinds = [s["direct_path"] for g in groups for s in g["sources"] if s["direct_path"]]
    total = len(kinds)
    return {k: {"count": kinds.count(k), "share": kinds.count(k) / total}
            for k in sorted(set(kinds))}


# --- sampling ------------------------------------------------------------------------------


def sample_groups(groups: Sequence[dict[str, Any]], cap: int, seed: int) -> list[str]:
    """Up to ``cap`` group ids, drawn with ``seed``: every (split, scene) in turn, so each
    gets pages before any gets many; returned in group order."""
    strata: dict[tuple[str, str], list[str]] = {}
    for g in groups:
        strata.setdefault((g["split"], g["scene_id"]), []).append(g["group"])
    rng = rng_for(seed, "report", "group_pages")
    queues = [list(np.asarray(ids)[rng.permutation(len(ids))]) for _, ids in sorted(
        strata.items())]
    chosen: list[str] = []
    while len(chosen) < cap and any(queues):
        for q in queues:
            if q and len(chosen) < cap:
                chosen.append(str(q.pop(0)))
    return sorted(chosen)


# --- warnings ------------------------------------------------------------------------------


@dataclass
class Warnings:
    leaked_scenes: list[dict[str, Any]] = field(default_factory=list)
    guard_cut: list[dict[str, Any]] = field(default_factory=list)
    close_sources: list[dict[str, Any]] = field(default_factory=list)
    default_materials: list[dict[str, Any]] = field(default_factory=list)
    truncated_rirs: list[dict[str, Any]] = field(default_factory=list)
    missing: list[dict[str, Any]] = field(default_factory=list)
    lower_order: list[dict[str, Any]] = field(default_factory=list)
    """Sources whose RIRs' exact early reflections stopped below the order asked."""

    @property
    def count(self) -> int:
        return (len(self.leaked_scenes) + len(self.guard_cut) + len(self.close_sources)
                + len(self.default_materials) + len(self.truncated_rirs) + len(self.missing)
                + len(self.lower_order))


def group_warnings(groups: Sequence[dict[str, Any]], warnings: Warnings) -> None:
    """Groups the guard cut more than 3 dB, sources closer than 0.5 m (a moving microphone's
    distances from its track), sources whose RIRs were cut while still decaying and sources
    whose image-source search stopped below the order asked, into ``warnings``."""
    for g in groups:
        for s in g["sources"]:
            cut = s.get("rir_cut")
            if cut is not None:
                warnings.truncated_rirs.append({"group": g["group"], "source": s["name"],
                                                **cut})
            order = s.get("image_source_order")
            if isinstance(order, dict) and order.get("reached", 0) < order.get("asked", 0):
                warnings.lower_order.append({"group": g["group"], "scene": g.get("scene_id"),
                                             "source": s["name"], **order})
        gain = g["group_gain_db"]
        if gain is not None and gain < GUARD_CUT_DB:
            warnings.guard_cut.append({"group": g["group"], "gain_db": gain})
        for s in g["sources"]:
            d = s["distance_min_m"]
            if d is not None and d < CLOSE_SOURCE_M:
                warnings.close_sources.append({"group": g["group"], "source": s["name"],
                                               "distance_m": d})


_LOG_PREFIX = re.compile(r"^.*?\bWARNING\s+")


def scene_warnings(scene_id: str, report: dict[str, Any], log_lines: Sequence[str],
                   max_leak_fraction: float | None, warnings: Warnings) -> list[str]:
    """A scene's warnings (its mesh report's and its mesh job's log lines, without the log's
    time stamp); a leak beyond what the spec allows and default-material fallbacks also go
    into ``warnings``."""
    lines = list(dict.fromkeys([*report.get("warnings", []),
                                *(_LOG_PREFIX.sub("", x) for x in log_lines)]))
    leak = (report.get("leak") or {}).get("fraction")
    if (leak is not None and leak > (max_leak_fraction or 0.0)) or any(
            "leave the mesh" in w for w in lines):
        warnings.leaked_scenes.append({"scene": scene_id, "fraction": leak,
                                       "allowed": max_leak_fraction})
    warnings.default_materials += [{"scene": scene_id, "message": w} for w in lines
                                   if "expected a material for every face label" in w]
    return lines


# --- the store: scenes, RIRs, build facts ----------------------------------------------------


MAX_PLANS_READ = 4


class StoreView:
    """What the report reads from the artifact store a dataset names (None-safe)."""

    def __init__(self, store_dir: Path, dataset_key: str | None) -> None:
        from sonicspec.plan.model import Plan
        from sonicspec.store import ArtifactStore

        self.root = store_dir
        self.store = ArtifactStore(store_dir)
        self.plan = None
        # The last build's plan first, then the newest others (a plan of 10^5 groups is tens
        # of MB: a few are read at most).
        plans = sorted((store_dir / "plans").glob("*.json"),
                       key=lambda p: (not p.name.startswith("last-build-"), -p.stat().st_mtime))
        for path in plans[:MAX_PLANS_READ]:
            try:
                plan = Plan.read(path)
            except Exception:  # an unreadable or foreign plan file: try the next one
                continue
            if dataset_key is None or any(j.key == dataset_key for j in plan.jobs):
                self.plan = plan
                break
        self.jobs = self.plan.by_key() if self.plan is not None else {}

    def jobs_of(self, step: str) -> list[Any]:
        return [j for j in self.jobs.values() if j.step == step]

    def scene(self, scene_id: str) -> dict[str, Any] | None:
        """The scene's mesh (vertices, faces, materials), its mesh report, its floors and the
        warning lines of its mesh job's log; None if the store lacks them."""
        mesh_job = next((j for j in self.jobs_of("mesh") if j.params.get("scene_id") == scene_id),
                        None)
        if mesh_job is None or not self.store.exists("mesh", mesh_job.key):
            return None
        art = self.store.read("mesh", mesh_job.key)
        nav_job = next((j for j in self.jobs_of("navigation") if mesh_job.key in j.inputs), None)
        floors = []
        if nav_job is not None and self.store.exists("navigation", nav_job.key):
            floors = [f["floor"]["z_m"] for f in
                      self.store.read_data("navigation", nav_job.key)["floors"]]
        log = self.root / "logs" / "mesh" / mesh_job.key[:2] / f"{mesh_job.key}.log"
        lines = []
        if log.is_file():
            lines = [x.strip() for x in log.read_text(errors="replace").splitlines()
                     if re.search(r"\bWARNING\b", x)]
        from sonicspec.plan.params import read_params

        repair = getattr(read_params("mesh", mesh_job.params, mesh_job.label).scene, "repair",
                         None)
        return {"arrays": art.arrays, "report": art.data, "floors_z_m": floors,
                "log_warnings": lines,
                "max_leak_fraction": None if repair is None else repair.max_leak_fraction}

    def first_rirs(self, rir_key: str, group: str) -> tuple[dict[str, np.ndarray], dict] | None:
        """Each source's RIR at its first point (channel 0) in group ``group``, and the rir
        artifact's bands and rate; None if the store lacks them."""
        if not self.store.exists("rir", rir_key):
            return None
        from sonicspec.artifacts import decode

        data = decode("rir", self.store.read_data("rir", rir_key))
        entry = next((g for g in data.groups if g.group == group), None)
        if entry is None:
            return None
        rirs = {s.name: self.store.read_array("rir", rir_key, s.array, 0)[0]
                for s in entry.sources}
        return rirs, {"bands_hz": list(data.bands_hz), "sample_rate_hz": data.sample_rate_hz}

    def build_facts(self, dataset_key: str | None) -> dict[str, Any]:
        """When, how long and on what the build ran: the Snakemake log that ran the dataset
        job (its header) and the jobs' benchmark files (seconds and peak memory per step)."""
        facts: dict[str, Any] = {}
        logs = sorted((self.root / "logs").glob("snakemake-*.log"),
                      key=lambda p: p.stat().st_mtime, reverse=True)
        chosen = None
        for path in logs:
            text = path.read_text(errors="replace")
            if dataset_key is None or f"key={dataset_key}" in text:
                chosen = (path, text)
                break
        if chosen is not None:
            path, text = chosen
            for name in ("Date", "Host", "Platform", "Snakemake version", "Python version"):
                m = re.search(rf"^\s*{name}: (.+)$", text, re.M)
                if m:
                    facts[name.lower().replace(" ", "_")] = m.group(1).strip()
            m = re.search(r"^Provided cores: (\d+)", text, re.M)
            if m:
                facts["cores"] = int(m.group(1))
            facts["log"] = str(path)
            facts["finished_utc"] = utc_text(path.stat().st_mtime)
        steps: dict[str, dict[str, float]] = {}
        for job in self.jobs.values():
            bench = (self.root / "benchmarks" / job.step / job.key[:2] / f"{job.key}.tsv")
            try:
                rows = bench.read_text().splitlines()
            except OSError:
                continue
            if len(rows) < 2:
                continue
            head, values = rows[0].split("\t"), rows[1].split("\t")
            row = dict(zip(head, values, strict=False))
            step = steps.setdefault(job.step, {"jobs": 0, "seconds": 0.0, "max_rss_mb": 0.0})
            step["jobs"] += 1
            step["seconds"] += _float(row.get("s"))
            step["max_rss_mb"] = max(step["max_rss_mb"], _float(row.get("max_rss")))
        facts["steps"] = steps
        facts["job_seconds"] = sum(s["seconds"] for s in steps.values())
        return facts


def _float(x: str | None) -> float:
    try:
        return float(x) if x not in (None, "", "-", "NA") else 0.0
    except ValueError:
        return 0.0


def utc_text(t: float) -> str:
    """A file time as people read it."""
    import datetime as dt

    return dt.datetime.fromtimestamp(t, dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


def open_store(info: DatasetInfo) -> StoreView | None:
    """The store the dataset names, when it is there and holds a plan of this dataset."""
    store_dir = info.store_dir
    if store_dir is None or not (store_dir / "plans").is_dir():
        return None
    view = StoreView(store_dir, info.marker.get("dataset_key"))
    return view if view.plan is not None else None


def material_areas(arrays: dict[str, np.ndarray], materials: Sequence[str]) -> dict[str, float]:
    """Area per material, m², largest first."""
    v = np.asarray(arrays["vertices"], dtype=np.float64)
    f = np.asarray(arrays["faces"])
    tri = v[f]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    per = np.bincount(np.asarray(arrays["face_material"]), weights=areas,
                      minlength=len(materials))
    return dict(sorted(((materials[i], float(a)) for i, a in enumerate(per) if a > 0),
                       key=lambda kv: -kv[1]))


def rir_files(root: Path, group: str, names: Iterable[str]) -> dict[str, Path]:
    """RIRs the dataset itself holds (``outputs.rirs``): each source's first point."""
    out = {}
    for name in names:
        path = root / group / "rirs" / name / "000.wav"
        if path.is_file():
            out[name] = path
    return out


def relative(path: Path, start: Path) -> str:
    """``path`` relative to the folder ``start``, as a URL path (for links in the page)."""
    from urllib.parse import quote

    return quote(Path(os.path.relpath(path, start)).as_posix())
