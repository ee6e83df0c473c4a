"""Result types of the tracer: discrete arrivals and energy–time histograms.

Units and conventions (DESIGN.md §5)
------------------------------------
Everything is sound pressure for a *unit point source*: the free-field direct sound has
amplitude ``1/(4πr)`` at delay ``r/c``. Discrete arrivals (direct sound, image sources) carry a
per-band pressure *amplitude*; histograms carry per-band *energy* in the same units squared,
i.e. the expected sum of squared arrival amplitudes landing in each time bin. The two therefore
add directly: ``Σ amplitude²`` of the arrivals in a bin plus the histogram value of that bin is
the total squared-pressure energy of the bin, which is what the Schroeder integral and the late
RIR synthesis need.

Directions are *directions of arrival*: unit vectors pointing from the receiver towards where
the sound comes from (the image source, the last reflection point), in the scene frame (z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sonicspec.errors import AcousticsError

__all__ = ["IDENTITY", "KIND_DIFFRACTED", "KIND_DIRECT", "KIND_SPECULAR", "Arrivals",
           "EnergyHistogram", "TraceResult"]

#: ``Arrivals.kind`` code of the direct sound (possibly through transmitting surfaces).
KIND_DIRECT = 0
#: ``Arrivals.kind`` code of a specular reflection found by the image-source method.
KIND_SPECULAR = 1
#: ``Arrivals.kind`` code of an edge-diffracted path (:mod:`sonicspec.acoustics.paths.edge_paths`).
KIND_DIFFRACTED = 2


#: ``Arrivals.isometry`` of a path that is not mirrored: the direct sound.
IDENTITY = np.hstack([np.eye(3), np.zeros((3, 1))])
IDENTITY.setflags(write=False)


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Arrivals:
    """Discrete arrivals at one receiver (direct sound and/or image sources).

    Attributes
    ----------
    times_s : (n,) float64
        Arrival time ``path length / c`` in seconds, fractional (never rounded to a sample).
    amplitudes : (n, n_bands) float64
        Pressure amplitude per octave band for a unit point source (``1/(4πr)`` in free field),
        including spreading, surface reflection/transmission factors and air absorption.
    directions : (n, 3) float64
        Unit direction of arrival at the receiver (pointing towards the apparent source).
    order : (n,) int64
        Number of reflections of the path (0 for the direct sound; for a diffracted path, the
        number of edges it bends round).
    kind : (n,) int8
        :data:`KIND_DIRECT`, :data:`KIND_SPECULAR` or :data:`KIND_DIFFRACTED`.
    path_length_m : (n,) float64
        Unfolded path length in metres.
    isometry : (n, 3, 4) float64
        ``[M | b]``: the rigid map ``x ↦ M x + b`` that takes the point the paths were
        traced from to the path's image (the identity for the direct sound, the product of
        the path's mirrors for an image source); NaN where a path has none (an edge-diffracted
        path, or arrivals made without it). With it a path is followed while both of its
        ends move (:class:`~sonicspec.acoustics.moving.delays.PathSet`).
    path_id : (n,) int64
        Which geometric path an edge-diffracted arrival takes (its edges and reflector, the
        same for every source and receiver position: :mod:`~sonicspec.acoustics.paths.edge_paths`),
        so it is followed along a walk; -1 for other arrivals.
    departures : (n, 3) float64
        Unit direction in which an edge-diffracted path leaves the source (towards its first
        edge apex or reflection point), for a directional source; zero for other arrivals,
        whose departure their isometry gives (:func:`~sonicspec.acoustics.directivity.
        departure_directions`).
    """

    times_s: np.ndarray
    amplitudes: np.ndarray
    directions: np.ndarray
    order: np.ndarray
    kind: np.ndarray
    path_length_m: np.ndarray
    isometry: np.ndarray | None = None
    path_id: np.ndarray | None = None
    departures: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.isometry is None:
            object.__setattr__(self, "isometry", np.full((len(self.times_s), 3, 4), np.nan))
        if self.path_id is None:
            object.__setattr__(self, "path_id", np.full(len(self.times_s), -1, dtype=np.int64))
        if self.departures is None:
            object.__setattr__(self, "departures", np.zeros((len(self.times_s), 3)))
        for name in ("times_s", "amplitudes", "directions", "order", "kind", "path_length_m",
                     "isometry", "path_id", "departures"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))

    @property
    def n_bands(self) -> int:
        return int(self.amplitudes.shape[1])

    def __len__(self) -> int:
        return int(self.times_s.shape[0])

    @staticmethod
    def empty(n_bands: int) -> Arrivals:
        """No arrivals (e.g. the direct sound of an occluded, opaque path)."""
        return Arrivals(
            times_s=np.zeros(0),
            amplitudes=np.zeros((0, n_bands)),
            directions=np.zeros((0, 3)),
            order=np.zeros(0, dtype=np.int64),
            kind=np.zeros(0, dtype=np.int8),
            path_length_m=np.zeros(0),
        )

    @staticmethod
    def concatenate(parts: list[Arrivals]) -> Arrivals:
        """Join arrival sets of one receiver, sorted by time (stable, so ties keep their order)."""
        if not parts:
            raise ValueError("parts: expected at least one Arrivals, got an empty list")
        times = np.concatenate([p.times_s for p in parts])
        order = np.argsort(times, kind="stable")
        return Arrivals(
            times_s=times[order],
            amplitudes=np.concatenate([p.amplitudes for p in parts])[order],
            directions=np.concatenate([p.directions for p in parts])[order],
            order=np.concatenate([p.order for p in parts])[order],
            kind=np.concatenate([p.kind for p in parts])[order],
            path_length_m=np.concatenate([p.path_length_m for p in parts])[order],
            isometry=np.concatenate([p.isometry for p in parts])[order],
            path_id=np.concatenate([p.path_id for p in parts])[order],
            departures=np.concatenate([p.departures for p in parts])[order],
        )

    def energy_histogram(self, bin_s: float, n_bins: int) -> np.ndarray:
        """Squared amplitudes summed per time bin, ``(n_bins, n_bands)``; later arrivals dropped.

        Used to add the deterministic early part to the ray tracer's histogram before a
        Schroeder integration.
        """
        index = np.floor(self.times_s / bin_s).astype(np.int64)
        keep = index < n_bins
        out = np.zeros((n_bins, self.n_bands))
        np.add.at(out, index[keep], self.amplitudes[keep] ** 2)
        return out


@dataclass(frozen=True, eq=False)
class EnergyHistogram:
    """Per-band energy–time histogram of the ray-traced (stochastic) part at one receiver.

    Attributes
    ----------
    bin_s : float
        Bin width in seconds; bin ``k`` covers ``[k·bin_s, (k+1)·bin_s)``.
    energy : (n_bins, n_bands) float64
        Expected sum of squared pressure amplitudes (unit point source) arriving in each bin,
        the same units as ``Arrivals.amplitudes**2``. It excludes the direct sound and the
        specular paths the image-source method renders (energy is counted once).
    direction_sum : (n_bins, 3) float64
        Σ (band-summed energy × unit direction of arrival) per bin. Divided by
        ``energy.sum(axis=1)`` it is the energy-weighted mean direction; its length (0…1) says
        how directional the bin is (≈0 in a diffuse field, 1 for a single direction).
    departure_sum : (n_bins, 3) float64
        The same for the direction in which each contributing ray *left the source*. Under
        reciprocity (tracing from a static microphone to many source positions) this is the
        direction of arrival at the microphone.
    """

    bin_s: float
    energy: np.ndarray
    direction_sum: np.ndarray
    departure_sum: np.ndarray

    def __post_init__(self) -> None:
        for name in ("energy", "direction_sum", "departure_sum"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))

    @property
    def n_bins(self) -> int:
        return int(self.energy.shape[0])

    @property
    def times_s(self) -> np.ndarray:
        """Start time of every bin, seconds."""
        return np.arange(self.n_bins) * self.bin_s

    def smoothed(self, relative_width: float) -> EnergyHistogram:
        """The histogram averaged over a window that grows with time: bin ``k`` (centre
        ``t``) becomes the mean of the bins within ``± relative_width · t / 2`` (clipped to
        the histogram), in every band and in both direction sums.

        Why: late in the decay few rays remain (Russian roulette keeps their number in step
        with the energy), so 1 ms bins are often empty and the envelope the RIR is shaped by
        comes in bursts — Monte-Carlo noise, not reflections. A window proportional to ``t``
        leaves the early bins alone (none below ``2/relative_width`` bins) and turns a pure
        exponential decay into the same decay times ``sinh(x)/x``, ``x = k·relative_width·t/2``
        (``k`` its rate): 0.03 dB at 0.5 s and 0.1 dB at 1 s for a 0.87 s T60 with width 0.05,
        so T30 moves by about 0.1 %.
        """
        if not (np.isfinite(relative_width) and 0 <= relative_width <= 1):
            raise AcousticsError(f"relative_width: expected a value in [0, 1], got "
                                 f"{relative_width!r}")
        n = self.n_bins
        k = np.arange(n)
        half = np.floor(relative_width * (k + 0.5) / 2).astype(np.int64)
        if n == 0 or not half.any():
            return self
        lo, hi = np.maximum(k - half, 0), np.minimum(k + half, n - 1)

        def mean(x: np.ndarray) -> np.ndarray:
            if x.size and np.isnan(x).all():  # direction sums not traced: NaN they stay
                return x
            # Window sums from running sums: a window of empty bins subtracts two equal sums,
            # so it stays exactly 0 (the RIR ends at the last bin with energy), and running
            # sums of energies never decrease, so no energy goes below 0.
            cs = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
            out = (cs[hi + 1] - cs[lo]) / (hi - lo + 1)[:, None]
            out[half == 0] = x[half == 0]  # no window: the bin as it is, to the bit
            return out

        return EnergyHistogram(self.bin_s, mean(self.energy), mean(self.direction_sum),
                               mean(self.departure_sum))

    def mean_direction(self) -> np.ndarray:
        """Energy-weighted mean direction of arrival per bin, ``(n_bins, 3)`` (0 where empty)."""
        total = self.energy.sum(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, self.direction_sum / np.where(total > 0, total, 1.0), 0.0)


@dataclass(frozen=True, eq=False)
class TraceResult:
    """What the stochastic tracer found for one receiver.

    Attributes
    ----------
    histogram : EnergyHistogram
        Late (diffuse + high-order specular) energy.
    n_rays : int
        Rays launched from the source (shared by every receiver of the trace).
    escaped_ray_fraction : float
        Fraction of launched rays that left the mesh (hit nothing): in a closed, opaque room
        this measures leaks (holes, float32 cracks); with transmitting outer walls it also
        counts sound transmitted to the outside. Their energy is lost, and reported here
        instead of silently dropped.
    specular_order_excluded : int
        Purely specular paths with at most this many reflections were *not* counted here
        because the image-source method renders them.
    mean_reflections : float
        Mean number of surface interactions per ray before termination.
    """

    histogram: EnergyHistogram
    n_rays: int
    escaped_ray_fraction: float
    specular_order_excluded: int
    mean_reflections: float
