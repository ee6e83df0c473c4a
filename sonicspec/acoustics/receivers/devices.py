"""Real microphone devices as data: the presets in ``sonicspec/data/microphones/``.

One JSON file per device: ``name``, ``title``, ``source`` (the datasheet or drawing its geometry
comes from, and how exact it is), ``body`` (``free``: capsules in free field; ``rigid_sphere``
with ``radius_m``: capsules flush on a rigid sphere, rendered by the sphere model of
:mod:`~sonicspec.acoustics.receivers.hrtf`) and ``capsules`` (each a ``position_m`` in the
device's frame — x its front, y its left, z up — and optionally a ``pattern`` of
:data:`~sonicspec.acoustics.receivers.capsules.PATTERNS` and an ``axis``; on a sphere the axis is
the outward normal, in free field +x). The spec reads the same files for the names and the
channel counts.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from importlib import resources

import numpy as np

from sonicspec.acoustics.receivers.capsules import Capsules, pattern_alpha
from sonicspec.errors import AcousticsError


@dataclass(frozen=True)
class Device:
    """A device preset: its name, title, the source of its geometry and its capsules (in the
    device's own frame)."""

    name: str
    title: str
    source: str
    capsules: Capsules

    @property
    def aperture_m(self) -> float:
        """The largest distance between two capsules, metres."""
        p = self.capsules.offsets_m
        return float(np.max(np.linalg.norm(p[:, None] - p[None], axis=-1)))

    @property
    def body(self) -> str:
        r = self.capsules.sphere_radius_m
        return "free field" if r is None else f"rigid sphere, r = {r * 100:g} cm"


def device_names() -> tuple[str, ...]:
    """The presets shipped, sorted by name."""
    folder = resources.files("sonicspec").joinpath("data", "microphones")
    return tuple(sorted(p.name.removesuffix(".json") for p in folder.iterdir()
                        if p.name.endswith(".json")))


@functools.lru_cache(maxsize=32)
def device(name: str) -> Device:
    """The preset ``name`` (:func:`device_names`)."""
    if name not in device_names():
        raise AcousticsError(f"microphone.device: expected one of {', '.join(device_names())}, "
                             f"got {name!r}")
    data = json.loads(resources.files("sonicspec").joinpath(
        "data", "microphones", f"{name}.json").read_text("utf-8"))
    caps = data["capsules"]
    offsets = np.array([c["position_m"] for c in caps], dtype=np.float64)
    body = data["body"]
    radius = float(body["radius_m"]) if body["kind"] == "rigid_sphere" else None
    if radius is not None:
        norms = np.linalg.norm(offsets, axis=1)
        if np.any(np.abs(norms - radius) > 1e-3 * radius):
            raise AcousticsError(f"device {name}: capsules must sit on the sphere "
                                 f"(radius {radius} m)")
        default_axes = offsets / norms[:, None]
    else:
        default_axes = np.tile([1.0, 0.0, 0.0], (len(caps), 1))
    axes = np.array([c.get("axis", default_axes[i]) for i, c in enumerate(caps)],
                    dtype=np.float64)
    alphas = np.array([pattern_alpha(c.get("pattern", "omni")) for c in caps])
    return Device(name=data["name"], title=data["title"], source=data["source"],
                  capsules=Capsules(offsets, axes, alphas, radius))
