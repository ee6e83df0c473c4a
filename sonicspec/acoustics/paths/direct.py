"""Direct sound from a source to receivers, through any surfaces in between."""

from __future__ import annotations

import numpy as np

from sonicspec.acoustics.arrivals import IDENTITY, KIND_DIRECT, Arrivals
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S

__all__ = ["check_air", "check_points", "direct_sound"]


def check_points(name: str, points: np.ndarray) -> np.ndarray:
    """Positions as a float64 ``(n, 3)`` array; a single ``(3,)`` point becomes ``(1, 3)``."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim == 1:
        points = points[None, :]
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise AcousticsError(
            f"{name}: expected finite positions of shape (n, 3), got {points.shape}"
        )
    return points


def check_air(air_m_per_band: np.ndarray | None, n_bands: int) -> np.ndarray:
    """Per-band air energy attenuation coefficient ``m`` (1/m) as ``(n_bands,)``; None means 0."""
    if air_m_per_band is None:
        return np.zeros(n_bands)
    air = np.asarray(air_m_per_band, dtype=np.float64).reshape(-1)
    if air.shape != (n_bands,) or not np.all(np.isfinite(air)) or np.any(air < 0):
        raise AcousticsError(
            f"air_m_per_band: expected {n_bands} finite values >= 0 (1/m, one per band), "
            f"got {np.asarray(air_m_per_band).tolist()}"
        )
    return air


def direct_sound(
    scene: AcousticScene,
    source: np.ndarray,
    receivers: np.ndarray,
    air_m_per_band: np.ndarray | None = None,
    speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
) -> list[Arrivals]:
    """Direct sound at every receiver, attenuated by the surfaces it has to pass through.

    Parameters
    ----------
    scene : AcousticScene
        The mesh with its per-face coefficients.
    source : (3,) float
        Source position, metres.
    receivers : (n, 3) float
        Receiver positions, metres.
    air_m_per_band : (n_bands,) float, optional
        ISO 9613-1 air *energy* attenuation coefficient ``m`` per band, 1/m (energy decays as
        ``exp(-m·r)``, so pressure as ``exp(-m·r/2)``). None: no air absorption.
    speed_of_sound_m_s : float
        Speed of sound, m/s.

    Returns
    -------
    list of Arrivals
        One per receiver, with zero or one arrival of amplitude
        ``exp(-m·r/2) · Π√τ / (4πr)`` per band at the fractional delay ``r/c`` (``τ``: energy
        transmission coefficient of each surface crossed, so ``√τ`` in pressure). A path
        through an opaque surface (``τ = 0`` in every band) yields no arrival; the sound
        bent round the occluder's edges is
        :func:`~sonicspec.acoustics.paths.edge_paths.diffracted_sound`'s.
    """
    source = check_points("source", source)
    if len(source) != 1:
        raise AcousticsError(f"source: expected one position, got {len(source)}")
    receivers = check_points("receivers", receivers)
    air = check_air(air_m_per_band, scene.n_bands)
    if not speed_of_sound_m_s > 0:
        raise AcousticsError(f"speed_of_sound_m_s: expected > 0, got {speed_of_sound_m_s}")
    vec = source - receivers
    r = np.linalg.norm(vec, axis=1)
    if np.any(r < 1e-6):
        raise AcousticsError(
            "receivers: expected positions distinct from the source, got a receiver at distance "
            f"{float(r.min())} m"
        )
    energy_tau = scene.segment_transmission(np.repeat(source, len(receivers), axis=0), receivers)
    amp = (
        np.sqrt(energy_tau) * np.exp(-0.5 * air[None, :] * r[:, None]) / (4.0 * np.pi * r[:, None])
    )
    out = []
    for i in range(len(receivers)):
        if not np.any(amp[i] > 0):
            out.append(Arrivals.empty(scene.n_bands))
            continue
        out.append(
            Arrivals(
                times_s=np.array([r[i] / speed_of_sound_m_s]),
                amplitudes=amp[i][None, :],
                directions=(vec[i] / r[i])[None, :],
                order=np.zeros(1, dtype=np.int64),
                kind=np.full(1, KIND_DIRECT, dtype=np.int8),
                path_length_m=np.array([r[i]]),
                isometry=IDENTITY[None],
            )
        )
    return out
