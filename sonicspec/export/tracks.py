"""Position tracks: written once per group as ``tracks.npz``, referenced from everywhere else.

A group's 10 ms tracks (where each source is, its azimuth, elevation and distance from the
microphone, and where the microphone is and faces) are numbers every 10 ms: 6,000 frames per
60 s group. They are stored once, in the group's folder, as a NumPy ``.npz`` archive of int32
arrays in fixed units — exactly the values the JSON held before (positions and distances
rounded to 0.1 mm, angles to 0.01°), deflated. For a 60 s group whose three talkers walk the
whole clip that is 129 kB (2.1 kB per group-second) against 2.8 MB of indented JSON (kept
three times before), 217 kB as deflated float32 (which is not exact) and 19 kB as deflated
frame differences (6.8x smaller, but no longer ``array / scale``: plain readability won;
``python bench/bench_scale.py --only tracks``). ``metadata.json``, the
Lhotse recording's ``custom`` field and the export's record carry a *reference* instead::

    "track": {"file": "train/000000/tracks.npz", "frames": 6000, "hop_s": 0.01,
              "arrays": {"positions_m": "source1.positions_m", "azimuth_deg": ...},
              "scale": {"positions_m": 10000, "azimuth_deg": 100, ...}}

``file`` is relative to the dataset folder (like every path in the manifests); each value is
``array / scale`` (``np.load(file)["source1.positions_m"] / 10000`` in metres, shape
``(frames, 3)``). :func:`read_track` does that, and also reads the older inline form (the
lists themselves under the same names), so datasets built before still load.

The archive is written with fixed member times and names in a fixed order, so the same tracks
give the same bytes.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.atomic import atomic_path
from sonicspec.errors import SonicspecError

TRACKS_NAME = "tracks.npz"
SCALES = {"positions_m": 10_000, "distance_m": 10_000, "azimuth_deg": 100,
          "elevation_deg": 100, "yaw_deg": 100}
"""Integers per unit of each quantity: 0.1 mm and 0.01°, the precision the JSON carried."""
_EPOCH = (1980, 1, 1, 0, 0, 0)  # zip's earliest time: no clock in the bytes


class TrackError(SonicspecError):
    """A track reference or a ``tracks.npz`` that cannot be read as described."""


class TrackFile:
    """The tracks of one group, collected and then written as one archive."""

    def __init__(self, out: Path, folder: Path) -> None:
        self.path = folder / TRACKS_NAME
        self.rel = self.path.relative_to(out).as_posix()
        self.arrays: dict[str, np.ndarray] = {}

    def add(self, owner: str, hop_s: float, values: Mapping[str, np.ndarray]) -> dict[str, Any]:
        """Store ``values`` (quantity -> array over frames) under ``owner`` (``source1``,
        ``microphone``); the reference that replaces them."""
        names, frames = {}, None
        for quantity, array in values.items():
            if quantity not in SCALES:
                raise TrackError(f"track {owner}: no unit for {quantity!r}; expected one of "
                                 f"{sorted(SCALES)}")
            a = np.asarray(array, dtype=np.float64)
            stored = np.rint(a * SCALES[quantity])
            if np.any(np.abs(stored) > np.iinfo(np.int32).max):
                raise TrackError(f"track {owner}.{quantity}: values beyond "
                                 f"{np.iinfo(np.int32).max / SCALES[quantity]:g} do not fit")
            name = f"{owner}.{quantity}"
            self.arrays[name] = stored.astype(np.int32)
            names[quantity] = name
            frames = a.shape[0] if frames is None else frames
        return {"file": self.rel, "frames": int(frames or 0), "hop_s": hop_s,
                "arrays": names, "scale": {q: SCALES[q] for q in names}}

    def write(self) -> Path:
        """The archive, atomically, with the same bytes for the same tracks."""
        with atomic_path(self.path) as tmp, zipfile.ZipFile(tmp, "w") as zf:
            for name in sorted(self.arrays):
                buf = io.BytesIO()
                np.lib.format.write_array(buf, self.arrays[name], allow_pickle=False)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, buf.getvalue(), compresslevel=9)
        return self.path


def is_reference(entry: Any) -> bool:
    """Whether a metadata ``track`` entry is a reference to ``tracks.npz`` (not inline lists)."""
    return isinstance(entry, Mapping) and "file" in entry and "arrays" in entry


def read_track(root: str | Path, entry: Mapping[str, Any],
               cache: dict[str, Any] | None = None) -> dict[str, Any]:
    """A track as ``{"hop_s": float, quantity: float64 array}``, from a reference (``root``:
    the dataset folder its ``file`` is relative to) or from the older inline lists.

    ``cache`` (path -> loaded archive) lets a reader open a group's archive once for all its
    tracks.
    """
    if not is_reference(entry):
        if not isinstance(entry, Mapping) or "hop_s" not in entry:
            raise TrackError(f"track: expected a reference to {TRACKS_NAME} or inline lists "
                             f"with hop_s, got {str(entry)[:80]!r}")
        return {k: (float(v) if k == "hop_s" else np.asarray(v, dtype=np.float64))
                for k, v in entry.items()}
    path = Path(root) / entry["file"]
    key = str(path)
    archive = cache.get(key) if cache is not None else None
    if archive is None:
        try:
            with np.load(path, allow_pickle=False) as z:
                archive = {n: z[n] for n in z.files}
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            raise TrackError(f"{path}: cannot read the tracks ({exc})") from None
        if cache is not None:
            cache[key] = archive
    out: dict[str, Any] = {"hop_s": float(entry["hop_s"])}
    for quantity, name in entry["arrays"].items():
        if name not in archive:
            raise TrackError(f"{path}: no array {name!r} (the metadata names it)")
        out[quantity] = archive[name].astype(np.float64) / float(entry["scale"][quantity])
    return out
