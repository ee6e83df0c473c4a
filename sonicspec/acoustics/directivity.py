"""Directivity patterns per octave band, for sources (talkers) and capsules alike.

A pattern is a pressure gain per band for a direction given in the *local* frame of the
source or capsule: +x is its front (on-axis), +y its left, +z its top (the frame
:func:`local_directions` maps scene directions into; yaw counter-clockwise seen from above,
pitch positive upwards, the convention of the microphones' ``yaw_deg``/``pitch_deg``). Every
pattern here is normalised to gain 1 on-axis in every band, so a directional source is as
loud as an omnidirectional one straight ahead and quieter elsewhere; its diffuse-field power
``⟨g²⟩`` (the mean of the squared gain over the sphere, ``1/Q`` with ``Q`` the directivity
factor, directivity index ``DI = −10 log10 ⟨g²⟩``) is what scales the late reverberation.

Patterns
--------
* The first-order (cardioid) family ``g = α + (1 − α) cos θ`` (:class:`CardioidPattern`,
  :func:`cardioid_gain`): omni α = 1, subcardioid 0.7, cardioid 0.5, supercardioid
  (√3 − 1)/2 ≈ 0.366 (the largest front-to-back energy ratio), hypercardioid 0.25 (the largest
  directivity factor, Q = 4), figure-eight 0. The same at every band. ``⟨g²⟩ = α² + (1 − α)²/3``
  exactly. Negative gains (the rear lobe of super- and hypercardioids) flip the polarity.
* A human talker (:data:`SPEECH`, :class:`TabulatedPattern`): per octave band, level relative
  to on-axis in the horizontal plane (every 45°, left–right symmetric) and straight above and
  below; see :data:`SPEECH` for where the numbers come from.
* Measured sets (:class:`SofaPattern`): a SOFA ``FreeFieldDirectivityTF`` file's magnitude
  averaged per octave band (energy mean over the band's bins), normalised on-axis, read between
  measured directions with weights of the three nearest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from sonicspec.acoustics.directions import fibonacci_sphere
from sonicspec.errors import AcousticsError

__all__ = ["CARDIOID_ALPHA", "SPEECH", "CardioidPattern", "DirectivityPattern", "SofaPattern",
           "SourceDirectivity", "TabulatedPattern", "cardioid_gain", "departure_directions",
           "directional_arrivals", "emission_gains", "local_directions", "pattern_by_name",
           "rotation", "split_gains"]

#: α of the first-order patterns ``α + (1 − α) cos θ`` by name.
CARDIOID_ALPHA: dict[str, float] = {
    "omni": 1.0,
    "subcardioid": 0.7,
    "cardioid": 0.5,
    "supercardioid": (math.sqrt(3.0) - 1.0) / 2.0,
    "hypercardioid": 0.25,
    "figure_eight": 0.0,
}

#: Directions of the lattice that integrates tabulated and measured patterns over the sphere.
_SPHERE_POINTS = 4096


def cardioid_gain(cos_theta, alpha: float) -> np.ndarray:
    """Pressure gain ``α + (1 − α) cos θ`` of a first-order pattern; ``cos_theta`` the cosine
    of the angle off-axis (any shape)."""
    if not (math.isfinite(alpha) and 0.0 <= alpha <= 1.0):
        raise AcousticsError(f"alpha: expected a value in [0, 1], got {alpha!r}")
    return alpha + (1.0 - alpha) * np.asarray(cos_theta, dtype=np.float64)


def rotation(yaw_deg: float, pitch_deg: float = 0.0) -> np.ndarray:
    """Rotation taking the local frame to the scene: pitch about y, then yaw about z."""
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    ry = np.array([[math.cos(p), 0, -math.sin(p)], [0, 1, 0], [math.sin(p), 0, math.cos(p)]])
    return rz @ ry


def local_directions(directions, yaw_deg, pitch_deg: float = 0.0) -> np.ndarray:
    """Scene directions ``(n, 3)`` in the local frame of a source or capsule turned by
    ``yaw_deg`` (one, or one per direction: a talker that turns) and ``pitch_deg``."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    yaw = np.radians(np.asarray(yaw_deg, dtype=np.float64))
    c, s = np.cos(yaw), np.sin(yaw)
    turned = np.stack(np.broadcast_arrays(c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                                          d[:, 2]), axis=-1)
    if pitch_deg:
        p = math.radians(pitch_deg)
        turned = np.stack([math.cos(p) * turned[:, 0] + math.sin(p) * turned[:, 2],
                           turned[:, 1],
                           -math.sin(p) * turned[:, 0] + math.cos(p) * turned[:, 2]], axis=-1)
    return turned


class DirectivityPattern(Protocol):
    """What the engine asks of a pattern."""

    name: str

    @property
    def frequency_independent(self) -> bool:
        """True when every band has the same gain in every direction."""

    def gains(self, local: np.ndarray, bands_hz: Sequence[float]) -> np.ndarray:
        """Pressure gain ``(n, B)`` for unit directions ``local`` ``(n, 3)`` (local frame)."""

    def diffuse_power(self, bands_hz: Sequence[float]) -> np.ndarray:
        """``⟨g²⟩`` over the sphere per band ``(B,)``: the late field's energy factor."""


def _unit(local: np.ndarray) -> np.ndarray:
    v = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def _sphere_mean_square(pattern: DirectivityPattern, bands_hz: Sequence[float]) -> np.ndarray:
    g = pattern.gains(fibonacci_sphere(_SPHERE_POINTS), bands_hz)
    return np.mean(g * g, axis=0)


@dataclass(frozen=True)
class CardioidPattern:
    """``g = α + (1 − α) cos θ`` in every band (θ the angle off the front, +x)."""

    alpha: float
    name: str = "cardioid"

    def __post_init__(self) -> None:
        cardioid_gain(0.0, self.alpha)  # checks α

    @property
    def frequency_independent(self) -> bool:
        return True

    def gains(self, local: np.ndarray, bands_hz: Sequence[float]) -> np.ndarray:
        cos_t = _unit(local)[:, 0]
        g = cardioid_gain(cos_t, self.alpha)
        return np.repeat(g[:, None], len(bands_hz), axis=1)

    def diffuse_power(self, bands_hz: Sequence[float]) -> np.ndarray:
        return np.full(len(bands_hz), self.alpha ** 2 + (1.0 - self.alpha) ** 2 / 3.0)


def _band_rows(table_bands: np.ndarray, values: np.ndarray, bands_hz: Sequence[float]
               ) -> np.ndarray:
    """Rows of ``values`` (one per table band) read at ``bands_hz``: linear in log-frequency
    between table bands, held beyond them."""
    x = np.log2(np.asarray(bands_hz, dtype=np.float64))
    xp = np.log2(table_bands)
    # interpolation weights (B_out, B_table): np.interp of each table band's unit vector
    weights = np.stack([np.interp(x, xp, row) for row in np.eye(len(xp))], axis=1)
    flat = values.reshape(len(table_bands), -1)
    return (weights @ flat).reshape((len(x), *values.shape[1:]))


@dataclass(frozen=True)
class TabulatedPattern:
    """Levels relative to on-axis, dB, per band: in the horizontal plane at ``azimuth_deg``
    (0 = front … 180 = behind, left–right symmetric) and straight above and below.

    Between them a direction at azimuth φ and elevation ε gets
    ``L = cos²ε · H(φ) + sin²ε · V±`` (``V+`` above for ε > 0, ``V−`` below), ``H`` linear in
    φ between the tabulated azimuths: continuous everywhere, exact on the tabulated directions.
    Between bands the levels are linear in log-frequency, held beyond the table.
    """

    name: str
    bands_hz: tuple[float, ...]
    azimuth_deg: tuple[float, ...]
    horizontal_db: tuple[tuple[float, ...], ...]
    above_db: tuple[float, ...]
    below_db: tuple[float, ...]
    _table: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        bands = np.asarray(self.bands_hz, dtype=np.float64)
        az = np.asarray(self.azimuth_deg, dtype=np.float64)
        h = np.asarray(self.horizontal_db, dtype=np.float64)
        if (bands.ndim != 1 or bands.size == 0 or np.any(np.diff(bands) <= 0)
                or np.any(bands <= 0)):
            raise AcousticsError(f"{self.name}.bands_hz: expected increasing positive bands, "
                                 f"got {self.bands_hz!r}")
        if az.ndim != 1 or az[0] != 0 or az[-1] != 180 or np.any(np.diff(az) <= 0):
            raise AcousticsError(f"{self.name}.azimuth_deg: expected increasing angles from 0 "
                                 f"to 180, got {self.azimuth_deg!r}")
        if h.shape != (bands.size, az.size) or np.any(h[:, 0] != 0):
            raise AcousticsError(f"{self.name}.horizontal_db: expected ({bands.size}, "
                                 f"{az.size}) levels, 0 dB on-axis, got shape {h.shape}")
        for label in ("above_db", "below_db"):
            if len(getattr(self, label)) != bands.size:
                raise AcousticsError(f"{self.name}.{label}: expected {bands.size} levels")
        object.__setattr__(self, "_table", (bands, az, h, np.asarray(self.above_db, float),
                                            np.asarray(self.below_db, float)))

    @property
    def frequency_independent(self) -> bool:
        _, _, h, up, down = self._table
        return bool(np.all(h == h[:1]) and np.all(up == up[0]) and np.all(down == down[0]))

    def levels_db(self, local: np.ndarray, bands_hz: Sequence[float]) -> np.ndarray:
        """Level relative to on-axis, dB, ``(n, B)``."""
        bands, az, h, up, down = self._table
        u = _unit(local)
        phi = np.degrees(np.abs(np.arctan2(u[:, 1], u[:, 0])))
        sin2 = u[:, 2] ** 2
        hb = _band_rows(bands, h, bands_hz)  # (B, A)
        vb = _band_rows(bands, np.where(u[:, 2] >= 0, up[:, None], down[:, None]), bands_hz)
        horizontal = np.stack([np.interp(phi, az, hb[b]) for b in range(len(hb))], axis=1)
        return (1.0 - sin2)[:, None] * horizontal + sin2[:, None] * vb.T

    def gains(self, local: np.ndarray, bands_hz: Sequence[float]) -> np.ndarray:
        return 10.0 ** (self.levels_db(local, bands_hz) / 20.0)

    def diffuse_power(self, bands_hz: Sequence[float]) -> np.ndarray:
        return _sphere_mean_square(self, bands_hz)


#: A human talker, per octave band 125 Hz – 8 kHz: level relative to straight ahead (dB) in
#: the horizontal plane at 0°, 45°, 90°, 135° and 180°, and straight above and below the head.
#:
#: Based on the long-term-average-speech directivity of W. T. Chu and A. C. C. Warnock,
#: "Detailed directivity of sound fields around human talkers", NRC Institute for Research
#: in Construction, Research Report IRC-RR-104 (2002) (40 talkers, horizontal- and
#: vertical-plane polar plots per octave band), and the horizontal-plane octave-band
#: directivity of running speech in B. B. Monson, E. J. Hunter and B. H. Story, "Horizontal
#: directivity of low- and high-frequency energy in speech and singing", J. Acoust. Soc. Am.
#: 132(1), 433–441 (2012) (its polar plots per octave band). The numbers are NOT transcribed
#: from a table of either paper: they are rounded values (1 dB, uncertain by about ±2 dB)
#: consistent with the trends both report — nearly omnidirectional at 125–250 Hz, the level
#: behind the talker 5–6 dB down at 1 kHz and 8–12 dB down at 2–8 kHz, the sides 2–6 dB down
#: above 1 kHz, below the head (chest shadow) lower than above it. Directivity index from
#: about 0.5 dB at 125 Hz to about 6 dB at 8 kHz. For measured data use a SOFA file
#: (:class:`SofaPattern`).
SPEECH = TabulatedPattern(
    name="speech",
    bands_hz=(125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0),
    azimuth_deg=(0.0, 45.0, 90.0, 135.0, 180.0),
    horizontal_db=(
        (0.0, 0.0, -0.5, -1.0, -1.5),     # 125 Hz
        (0.0, -0.5, -1.0, -2.0, -2.5),    # 250 Hz
        (0.0, -0.5, -1.5, -3.0, -4.0),    # 500 Hz
        (0.0, -1.0, -2.5, -5.0, -6.0),    # 1 kHz
        (0.0, -1.5, -4.0, -7.0, -8.0),    # 2 kHz
        (0.0, -2.0, -5.0, -9.0, -10.0),   # 4 kHz
        (0.0, -2.5, -6.0, -10.0, -12.0),  # 8 kHz
    ),
    above_db=(-1.0, -1.5, -2.0, -3.0, -4.0, -5.0, -6.0),
    below_db=(-1.0, -2.0, -3.0, -4.0, -6.0, -8.0, -10.0),
)


@dataclass(frozen=True)
class SofaPattern:
    """A measured pattern: per-band gains ``(R, B_m)`` at unit directions ``(R, 3)`` (local
    frame) for the bands ``bands_hz``; read at other directions with inverse-angle weights of
    the three nearest measured directions, at other bands linearly in log-frequency."""

    name: str
    directions: np.ndarray
    band_gains: np.ndarray
    bands_hz: tuple[float, ...]

    def __post_init__(self) -> None:
        d = _unit(self.directions)
        g = np.asarray(self.band_gains, dtype=np.float64)
        if len(d) < 3 or g.shape != (len(d), len(self.bands_hz)) or not np.all(np.isfinite(g)):
            raise AcousticsError(f"{self.name}: expected finite gains for >= 3 directions and "
                                 f"{len(self.bands_hz)} bands, got shape {g.shape}")
        object.__setattr__(self, "directions", d)
        object.__setattr__(self, "band_gains", g)

    @property
    def frequency_independent(self) -> bool:
        return bool(np.all(self.band_gains == self.band_gains[:, :1]))

    def gains(self, local: np.ndarray, bands_hz: Sequence[float]) -> np.ndarray:
        u = _unit(local)
        cos = np.clip(np.einsum("nk,rk->nr", u, self.directions), -1.0, 1.0)
        near = np.argpartition(-cos, 2, axis=1)[:, :3]
        angle = np.arccos(np.take_along_axis(cos, near, axis=1))
        w = 1.0 / np.maximum(angle, 1e-9)
        w /= w.sum(axis=1, keepdims=True)
        measured = np.einsum("nk,nkb->nb", w, self.band_gains[near])
        table = np.asarray(self.bands_hz, dtype=np.float64)
        return _band_rows(table, measured.T, bands_hz).T

    def diffuse_power(self, bands_hz: Sequence[float]) -> np.ndarray:
        return _sphere_mean_square(self, bands_hz)

    @staticmethod
    def from_sofa(sofa: Any, bands_hz: Sequence[float], name: str = "sofa",
                  measurement: int = 0) -> SofaPattern:
        """From a ``sofar.Sofa`` of the ``FreeFieldDirectivityTF`` convention: ``Data_Real``,
        ``Data_Imag`` ``(M, R, N)`` at frequencies ``N``, the receivers' directions
        ``ReceiverPosition`` (spherical: azimuth, elevation in degrees; the source faces
        azimuth 0, elevation 0). Each band's gain is the energy mean of ``|H|²`` over the bins
        within its edges (the nearest bin if none), normalised by the direction nearest
        on-axis; ``measurement`` picks one of ``M`` (e.g. one note of an instrument)."""
        convention = getattr(sofa, "GLOBAL_SOFAConventions", "")
        if convention != "FreeFieldDirectivityTF":
            raise AcousticsError(f"{name}: expected a SOFA FreeFieldDirectivityTF file, got "
                                 f"convention {convention!r}")
        data = (np.asarray(sofa.Data_Real, dtype=np.float64)
                + 1j * np.asarray(sofa.Data_Imag, dtype=np.float64))
        if data.ndim != 3 or not 0 <= measurement < data.shape[0]:
            raise AcousticsError(f"{name}: expected Data (M, R, N) with measurement "
                                 f"{measurement} < M, got shape {data.shape}")
        freqs = np.atleast_1d(np.asarray(sofa.N, dtype=np.float64))
        pos = np.asarray(sofa.ReceiverPosition, dtype=np.float64)
        pos = pos.reshape(pos.shape[0], 3) if pos.ndim >= 2 else pos.reshape(-1, 3)
        if len(pos) != data.shape[1] or freqs.size != data.shape[2]:
            raise AcousticsError(f"{name}: {len(pos)} receiver positions and {freqs.size} "
                                 f"frequencies for data of shape {data.shape}")
        if str(getattr(sofa, "ReceiverPosition_Type", "spherical")) == "spherical":
            az, el = np.radians(pos[:, 0]), np.radians(pos[:, 1])
            dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
        else:
            dirs = _unit(pos)
        power = np.abs(data[measurement]) ** 2  # (R, N)
        bands = np.asarray(bands_hz, dtype=np.float64)
        gains = np.empty((len(dirs), bands.size))
        for b, centre in enumerate(bands):
            inside = (freqs >= centre / math.sqrt(2)) & (freqs < centre * math.sqrt(2))
            if not np.any(inside):
                inside = np.arange(freqs.size) == np.argmin(np.abs(np.log2(
                    np.maximum(freqs, 1e-9) / centre)))
            gains[:, b] = np.sqrt(np.mean(power[:, inside], axis=1))
        front = int(np.argmax(_unit(dirs)[:, 0]))
        if np.any(gains[front] <= 0):
            raise AcousticsError(f"{name}: the on-axis direction has zero gain; cannot "
                                 "normalise")
        return SofaPattern(name=name, directions=dirs, band_gains=gains / gains[front],
                           bands_hz=tuple(float(b) for b in bands))


def pattern_by_name(name: str) -> DirectivityPattern:
    """A built-in pattern: one of :data:`CARDIOID_ALPHA` or ``speech``."""
    if name == "speech":
        return SPEECH
    if name in CARDIOID_ALPHA:
        return CardioidPattern(alpha=CARDIOID_ALPHA[name], name=name)
    raise AcousticsError(f"directivity pattern: expected one of "
                         f"{sorted([*CARDIOID_ALPHA, 'speech'])}, got {name!r}")


def emission_gains(pattern: DirectivityPattern, directions, yaw_deg, bands_hz: Sequence[float],
                    pitch_deg: float = 0.0) -> np.ndarray:
    """Pressure gain ``(n, B)`` of sound leaving a source along scene ``directions``
    ``(n, 3)`` while it faces ``yaw_deg`` (one, or one per direction) and ``pitch_deg``;
    zero-length directions (no path) get gain 1."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    g = pattern.gains(local_directions(d, yaw_deg, pitch_deg), bands_hz)
    known = np.linalg.norm(d, axis=1) > 0
    return np.where(known[:, None], g, 1.0)


# --- a directional source's paths ------------------------------------------------------------

@dataclass(frozen=True)
class SourceDirectivity:
    """A directional source: its pattern and where it faces. ``yaw_deg`` is one yaw or one
    per position (:func:`~sonicspec.acoustics.engine.simulate_rirs`: per source point;
    :func:`~sonicspec.acoustics.moving.delays.render_paths`: per dry sample), degrees
    counter-clockwise from +x seen from above; ``pitch_deg`` up from horizontal."""

    pattern: DirectivityPattern
    yaw_deg: Any = 0.0
    pitch_deg: float = 0.0

    def __post_init__(self) -> None:
        yaw = np.asarray(self.yaw_deg, dtype=np.float64)
        if not np.all(np.isfinite(yaw)) or not math.isfinite(self.pitch_deg):
            raise AcousticsError("SourceDirectivity: expected finite yaw_deg and pitch_deg")
        yaw.setflags(write=False)
        object.__setattr__(self, "yaw_deg", yaw)

    def yaw_at(self, k) -> np.ndarray:
        """The yaw at position(s) ``k`` (any yaw when only one is given)."""
        return self.yaw_deg if self.yaw_deg.ndim == 0 else self.yaw_deg[k]


def departure_directions(arrivals, source_m, receiver_m, traced_from: str = "receiver"
                         ) -> np.ndarray:
    """Unit direction ``(n, 3)`` in which each arrival's path leaves the source: towards its
    first reflection point, which is where the receiver's image lies seen from the source
    (arrivals traced from the receiver, ``traced_from="receiver"``: ``M r + b − s``) or the
    receiver seen from the source's image, mapped back by the mirrors (traced from the source:
    ``Mᵀ (r − (M s + b))``); an edge-diffracted path's own ``departures`` (towards its first
    edge); zero where neither is known (gain 1 then)."""
    if traced_from not in ("receiver", "source"):
        raise AcousticsError(f"traced_from: expected 'receiver' or 'source', got "
                             f"{traced_from!r}")
    s = np.asarray(source_m, dtype=np.float64).reshape(3)
    r = np.asarray(receiver_m, dtype=np.float64).reshape(3)
    iso = arrivals.isometry
    out = np.array(arrivals.departures, dtype=np.float64)
    mirrored = np.all(np.isfinite(iso.reshape(len(iso), -1)), axis=1)
    if np.any(mirrored):
        m, b = iso[mirrored, :, :3], iso[mirrored, :, 3]
        if traced_from == "receiver":
            d = np.einsum("nij,j->ni", m, r) + b - s
        else:
            d = np.einsum("nji,nj->ni", m, r - (np.einsum("nij,j->ni", m, s) + b))
        out[mirrored] = _unit(d)
    return out


def directional_arrivals(arrivals, gains: np.ndarray):
    """``arrivals`` with each path's amplitudes times its per-band ``gains`` ``(n, B)``."""
    from dataclasses import replace

    return replace(arrivals, amplitudes=arrivals.amplitudes * gains)


def split_gains(gains: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(n, B)`` gains as a broadband part ``(n,)`` (their mean over bands, signed: a rear
    lobe keeps its polarity) times a spectral tilt ``(n, B)`` (1 where the mean is 0); a
    pattern that is the same in every band has tilt exactly 1."""
    g = np.asarray(gains, dtype=np.float64)
    broad = g.mean(axis=1)
    ok = np.abs(broad) > 1e-12
    tilt = np.ones_like(g)
    tilt[ok] = g[ok] / broad[ok, None]
    if g.shape[1] and np.all(g == g[:, :1]):
        tilt[:] = 1.0
    return broad, tilt


# --- where a source faces ----------------------------------------------------------------------

#: Below this speed (m/s) a source counts as standing: it keeps the last direction it walked in.
STANDING_M_S = 0.05


def _gaussian_smooth(x: np.ndarray, sigma: float) -> np.ndarray:
    """Rows of ``x`` smoothed along axis 0 by a Gaussian of ``sigma`` frames (edges held)."""
    if sigma <= 0 or len(x) < 2:
        return x
    half = int(np.ceil(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
    k /= k.sum()
    padded = np.concatenate([np.repeat(x[:1], half, 0), x, np.repeat(x[-1:], half, 0)])
    return np.stack([np.convolve(padded[:, j], k, mode="valid") for j in range(x.shape[1])],
                    axis=1)


def _bearing_deg(from_m: np.ndarray, to_m) -> np.ndarray:
    d = np.asarray(to_m, dtype=np.float64) - from_m
    return np.degrees(np.arctan2(d[..., 1], d[..., 0]))


def facing_yaw_deg(positions_m, hop_s: float, facing, mic_m, smoothing_s: float = 0.5
                   ) -> np.ndarray:
    """Where a source faces at each frame ``(F,)``, degrees, unwrapped (continuous).

    ``facing``: ``"walk"`` — the horizontal direction of travel (the velocity of
    ``positions_m`` ``(F, 3)``, one every ``hop_s``, averaged by a Gaussian of
    ``smoothing_s``); while the source stands (slower than :data:`STANDING_M_S`) it keeps
    the direction it last walked in (before it first walks: the first one), and a source that
    never walks faces ``mic_m``; ``"toward_mic"``; or a fixed yaw (degrees).
    """
    p = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    n = len(p)
    if not isinstance(facing, str):
        return np.full(n, float(facing))
    toward = _bearing_deg(p, mic_m)
    if facing == "toward_mic":
        return np.degrees(np.unwrap(np.radians(toward)))
    if facing != "walk":
        raise AcousticsError(f"facing: expected 'walk', 'toward_mic' or a yaw in degrees, got "
                             f"{facing!r}")
    if n < 2:
        return toward
    v = np.gradient(p[:, :2], hop_s, axis=0)
    v = _gaussian_smooth(v, smoothing_s / hop_s)
    moving = np.linalg.norm(v, axis=1) >= STANDING_M_S
    if not np.any(moving):
        return np.degrees(np.unwrap(np.radians(toward)))
    # hold the last direction walked in: forward fill, the first one before it
    last = np.maximum.accumulate(np.where(moving, np.arange(n), -1))
    last[last < 0] = int(np.argmax(moving))
    v = v[last]
    return np.degrees(np.unwrap(np.arctan2(v[:, 1], v[:, 0])))


def point_yaws_deg(points_m, facing, mic_m) -> np.ndarray:
    """Where a source faces at each of its RIR points ``(N,)``: along the path (the mean of
    the segments either side; a single point faces ``mic_m``), towards ``mic_m``, or a fixed
    yaw (:func:`facing_yaw_deg`'s ``facing``)."""
    p = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    if not isinstance(facing, str):
        return np.full(len(p), float(facing))
    toward = _bearing_deg(p, mic_m)
    if facing == "toward_mic" or len(p) < 2:
        return toward
    if facing != "walk":
        raise AcousticsError(f"facing: expected 'walk', 'toward_mic' or a yaw in degrees, got "
                             f"{facing!r}")
    seg = np.diff(p[:, :2], axis=0)
    seg /= np.maximum(np.linalg.norm(seg, axis=1, keepdims=True), 1e-12)
    t = np.concatenate([seg[:1], seg[:-1] + seg[1:], seg[-1:]])
    return np.degrees(np.arctan2(t[:, 1], t[:, 0]))


def head_turns_deg(n_frames: int, hop_s: float, std_deg: float, time_constant_s: float,
                   rng: np.random.Generator) -> np.ndarray:
    """A head's yaw deviation around its facing ``(n_frames,)``, degrees: a stationary
    Ornstein–Uhlenbeck process (standard deviation ``std_deg``, correlation time
    ``time_constant_s``) sampled every ``hop_s``, drawn from ``rng``."""
    if not (std_deg >= 0 and time_constant_s > 0 and hop_s > 0):
        raise AcousticsError(f"head turns: expected std_deg >= 0, time_constant_s > 0 and "
                             f"hop_s > 0, got {std_deg!r}, {time_constant_s!r}, {hop_s!r}")
    a = math.exp(-hop_s / time_constant_s)
    e = rng.standard_normal(n_frames) * std_deg
    e[1:] *= math.sqrt(1.0 - a * a)
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -a], e) if n_frames else e


def yaw_per_sample(frames_deg: np.ndarray, hop: int, n_samples: int) -> np.ndarray:
    """Frame yaws (one every ``hop`` samples from sample 0, unwrapped) read at every sample,
    linearly between frames, held after the last."""
    f = np.asarray(frames_deg, dtype=np.float64)
    return np.interp(np.arange(n_samples), np.arange(len(f)) * hop, f)
