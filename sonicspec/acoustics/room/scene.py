"""Embree scene of one mesh with its per-face acoustic coefficients, built once and reused.

Every query of the tracer (first hits of rays, occlusion of segments, the surfaces a segment
crosses) goes through :class:`AcousticScene`. It takes plain arrays, not a ``SceneMesh``, so the
acoustics library does not depend on the geometry package.

Precision: Embree works in float32. The scene is shifted to its bounding-box centre before it
is handed to Embree (halving the coordinate magnitudes), and every hit distance is recomputed in
float64 against the exact plane of the hit face, so hit points lie on their face to float64
precision. Rays leaving a surface start ``eps_m`` off it (see :attr:`AcousticScene.eps_m`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from sonicspec.acoustics.room._scene_kernels import embree_rays
from sonicspec.errors import AcousticsError

T = TypeVar("T")

__all__ = ["AcousticScene"]

_NO_LENGTHS = np.zeros(0)
# Embree returns this distance for rays that hit nothing (query="DISTANCE").
_EMBREE_MISS = 1e36


def _coefficients(name: str, values: np.ndarray, n_faces: int) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[0] != n_faces:
        raise AcousticsError(
            f"{name}: expected an array of shape (n_faces={n_faces}, n_bands), "
            f"got shape {values.shape}"
        )
    if (
        not np.all(np.isfinite(values))
        or values.min(initial=0.0) < 0
        or values.max(initial=0.0) > 1
    ):
        raise AcousticsError(
            f"{name}: expected coefficients in [0, 1], got values in "
            f"[{np.nanmin(values)}, {np.nanmax(values)}]"
        )
    values = np.ascontiguousarray(values)
    values.setflags(write=False)
    return values


class AcousticScene:
    """A triangle mesh in Embree plus per-face absorption, scattering and transmission.

    Parameters
    ----------
    vertices : (V, 3) float
        Vertex positions, metres.
    faces : (F, 3) int
        Vertex indices per triangle; the normal ``(b-a)×(c-a)`` points into the air.
    absorption, scattering, transmission : (F, n_bands) float
        Per-face, per-octave-band energy coefficients in [0, 1]. Energy convention used by the
        whole tracer: of the energy incident on a face, the fraction ``τ`` is transmitted; the
        rest ``(1-τ)`` meets the surface, which absorbs ``α`` of it and reflects ``(1-α)``, of
        which ``s`` is scattered (Lambert) and ``1-s`` reflected specularly. With ``τ = 0`` this
        is the usual random-incidence convention; ``τ = 1`` is an acoustically open surface.

    Notes
    -----
    Faces reflect on both sides (a thin sheet in a scan has air on both sides); the tracer
    uses the normal on the side the sound arrives from.
    """

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        absorption: np.ndarray,
        scattering: np.ndarray,
        transmission: np.ndarray,
    ) -> None:
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
            raise AcousticsError(f"vertices: expected shape (V>=3, 3), got {vertices.shape}")
        if not np.all(np.isfinite(vertices)):
            raise AcousticsError("vertices: expected finite coordinates, got NaN or inf")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise AcousticsError(f"faces: expected shape (F>=1, 3), got {faces.shape}")
        if not np.issubdtype(faces.dtype, np.integer):
            raise AcousticsError(f"faces: expected integer vertex indices, got {faces.dtype}")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise AcousticsError(
                f"faces: expected indices in [0, {len(vertices) - 1}], "
                f"got [{faces.min()}, {faces.max()}]"
            )
        n_faces = len(faces)
        self.absorption = _coefficients("absorption", absorption, n_faces)
        self.scattering = _coefficients("scattering", scattering, n_faces)
        self.transmission = _coefficients("transmission", transmission, n_faces)
        n_bands = self.absorption.shape[1]
        if self.scattering.shape[1] != n_bands or self.transmission.shape[1] != n_bands:
            raise AcousticsError(
                "scattering/transmission: expected the same number of bands as absorption "
                f"({n_bands}), got {self.scattering.shape[1]} and {self.transmission.shape[1]}"
            )

        self.vertices = np.ascontiguousarray(vertices)
        self.faces = np.ascontiguousarray(faces.astype(np.int64))
        self.vertices.setflags(write=False)
        self.faces.setflags(write=False)
        tri = self.vertices[self.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        if np.any(area2 <= 0):
            raise AcousticsError(
                f"faces: expected non-degenerate triangles, got {int(np.sum(area2 <= 0))} with "
                "zero area; hint: repair the mesh first"
            )
        #: Unit face normals (F, 3), into the air.
        self.normals = cross / area2[:, None]
        #: Plane offsets (F,): a point x is on face f's plane when ``normals[f]·x == plane_d[f]``.
        self.plane_d = np.einsum("ij,ij->i", self.normals, tri[:, 0])
        self.face_areas_m2 = 0.5 * area2
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.bounds = np.stack([lo, hi])
        self._shift = 0.5 * (lo + hi)
        extent = float(np.max(hi - lo))
        #: Offset (m) by which rays leaving a surface start off it: far above the float32
        #: resolution of the shifted coordinates, far below any acoustic length scale.
        self.eps_m = max(1e-5, 2e-5 * max(extent, float(np.max(np.abs(self._shift)))))
        #: Largest transmission coefficient of any face and band.
        self.max_transmission = float(self.transmission.max())
        self.has_transmission = self.max_transmission > 0
        #: Faces that transmit nothing in any band (a walk through surfaces stops there).
        self._opaque = ~np.any(self.transmission > 0, axis=1)
        self._memo: dict[str, object] = {}

        self._embree = rtcore_scene.EmbreeScene()
        # Keep a reference: the Embree geometry must live as long as the scene.
        self._mesh = TriangleMesh(
            self._embree,
            (self.vertices - self._shift).astype(np.float32),
            self.faces.astype(np.int32),
        )

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def n_bands(self) -> int:
        return int(self.absorption.shape[1])

    # -- raw queries -------------------------------------------------------------------------

    def _to_f32(self, origins: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(origins - self._shift, dtype=np.float32)

    def intersect(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """First surface hit by each ray.

        Parameters
        ----------
        origins, directions : (n, 3) float
            Ray origins (m) and *unit* directions.

        Returns
        -------
        face : (n,) int64
            Index of the first face hit, -1 where the ray escapes.
        distance_m : (n,) float64
            Distance to the hit along the ray (``inf`` for misses), recomputed in float64 on the
            face's plane.
        """
        n = len(origins)
        if n == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        face, tfar = self.first_hits(origins, directions)
        face = face.astype(np.int64)
        tfar = tfar.astype(np.float64)
        miss = (face < 0) | (tfar >= _EMBREE_MISS)
        any_miss = bool(miss.any())
        if any_miss:  # (np.compress: much faster than boolean indexing of (n, 3) arrays)
            face[miss] = -1
            hit = ~miss
            fh, tfar_hit = face[hit], tfar[hit]
            directions = np.compress(hit, directions, axis=0)
            origins = np.compress(hit, origins, axis=0)
        else:
            fh, tfar_hit = face, tfar
        nrm = np.take(self.normals, fh, axis=0)
        denom = np.einsum("ij,ij->i", nrm, directions)
        exact = (np.take(self.plane_d, fh) - np.einsum("ij,ij->i", nrm, origins)) / np.where(
            np.abs(denom) > 1e-9, denom, 1.0
        )
        # Grazing rays: the plane solve is ill-conditioned; keep Embree's float32 distance.
        good = (np.abs(denom) > 1e-6) & (exact > 0)
        if not any_miss:
            return face, np.where(good, exact, tfar_hit)
        distance = np.full(n, np.inf)
        distance[hit] = np.where(good, exact, tfar_hit)
        return face, distance

    def memoized(self, key: str, build: Callable[[], T]) -> T:
        """``build()`` once per scene and ``key``: derived tables that many traces of the same
        scene reuse (the scene's arrays are read-only, so they never go stale)."""
        if key not in self._memo:
            self._memo[key] = build()
        return self._memo[key]  # type: ignore[return-value]

    def coefficient_classes(self) -> tuple[np.ndarray, np.ndarray]:
        """Faces grouped by identical coefficient rows (absorption, scattering, transmission):
        the class of every face ``(F,)`` and one face of every class ``(C,)``; computed once.

        Rows are keyed by a fixed random projection (one sort instead of comparing whole rows),
        and every row is then checked against its class's representative, so a key collision
        can only fall back to the exact row comparison, never merge two materials.
        """
        return self.memoized("coefficient_classes", self._coefficient_classes)

    def _coefficient_classes(self) -> tuple[np.ndarray, np.ndarray]:
        coef = np.concatenate([self.absorption, self.scattering, self.transmission], axis=1)
        weights = np.random.default_rng(0x5EED).uniform(1.0, 2.0, coef.shape[1])
        _, first, ids = np.unique(coef @ weights, return_index=True, return_inverse=True)
        ids = ids.reshape(-1)
        if not np.array_equal(coef, np.take(coef, np.take(first, ids), axis=0)):
            _, first, ids = np.unique(coef, axis=0, return_index=True, return_inverse=True)
            ids = ids.reshape(-1)  # a collision: exact classes
        return ids.astype(np.int64), first.astype(np.int64)

    def first_hits(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Embree's first hit as it reports it: ``face`` (int32, -1 for a miss) and ``tfar``
        (float32, >= 1e36 for a miss), without :meth:`intersect`'s float64 refinement — for
        callers that refine the distance themselves (the compiled tracer)."""
        if len(origins) == 0:
            return np.zeros(0, dtype=np.int32), np.zeros(0, dtype=np.float32)
        o32, d32, _ = self._rays(origins, directions, 0.0)
        out = self._embree.run(o32, d32, output=1)
        return out["primID"], out["tfar"]

    def _rays(self, origins: np.ndarray, directions: np.ndarray, offset: float,
              lengths: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Float32 origins (moved ``offset`` along their direction, in Embree's frame),
        directions and, for segments, lengths less ``2·offset`` (compiled: one pass)."""
        n = len(origins)
        o32, d32 = np.empty((n, 3), dtype=np.float32), np.empty((n, 3), dtype=np.float32)
        t32 = np.empty(n if lengths is not None else 0, dtype=np.float32)
        embree_rays(np.ascontiguousarray(origins, dtype=np.float64),
                    np.ascontiguousarray(directions, dtype=np.float64), self._shift,
                    float(offset), _NO_LENGTHS if lengths is None else
                    np.ascontiguousarray(lengths, dtype=np.float64), o32, d32, t32)
        return o32, d32, t32

    def occluded(self, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Whether any surface lies strictly between each origin and its target.

        ``eps_m`` is left free at both ends, so points on (or just off) surfaces can be tested.
        Returns a bool array ``(n,)``.
        """
        n = len(origins)
        if n == 0:
            return np.zeros(0, dtype=bool)
        vec = targets - origins
        length = np.linalg.norm(vec, axis=1)
        direction = vec / np.where(length > 0, length, 1.0)[:, None]
        start = origins + direction * self.eps_m
        tfar = np.maximum(length - 2.0 * self.eps_m, 0.0)
        res = self._embree.run(
            self._to_f32(start),
            np.ascontiguousarray(direction, dtype=np.float32),
            dists=np.ascontiguousarray(tfar, dtype=np.float32),
            query="OCCLUDED",
        )
        return (res != -1) & (tfar > 0)

    def occluded_along(
        self, origins: np.ndarray, directions: np.ndarray, lengths_m: np.ndarray
    ) -> np.ndarray:
        """:meth:`occluded` for segments given as origin, unit direction and length (m)."""
        if len(origins) == 0:
            return np.zeros(0, dtype=bool)
        o32, d32, t32 = self._rays(origins, directions, self.eps_m, lengths_m)
        res = self._embree.run(o32, d32, dists=t32, query="OCCLUDED")
        return (res != -1) & (lengths_m - 2.0 * self.eps_m > 0)

    def crossings(
        self, origins: np.ndarray, targets: np.ndarray, max_crossings: int = 64,
        stop_at_opaque: bool = False,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Every surface crossed strictly between origins and targets.

        Repeated first-hit queries, each restarting ``eps_m`` beyond the previous hit.
        ``stop_at_opaque``: a segment's walk ends at the first surface that transmits nothing
        in any band (its crossings up to there are returned: enough for a product of ``τ``,
        which that surface makes 0).

        Returns
        -------
        segment : (m,) int64
            Index of the segment of each crossing.
        face : (m,) int64
            Face crossed.

        Raises
        ------
        AcousticsError
            If a segment crosses more than ``max_crossings`` surfaces (a corrupt mesh).
        """
        origins = np.asarray(origins, dtype=np.float64)
        vec = np.asarray(targets, dtype=np.float64) - origins
        length = np.linalg.norm(vec, axis=1)
        direction = vec / np.where(length > 0, length, 1.0)[:, None]
        live = np.flatnonzero(length > 2.0 * self.eps_m)
        travelled = np.full(len(origins), self.eps_m)
        seg_out: list[np.ndarray] = []
        face_out: list[np.ndarray] = []
        for _ in range(max_crossings + 1):
            if live.size == 0:
                break
            start = origins[live] + direction[live] * travelled[live, None]
            # Embree's float32 distance is plenty to step past a surface (eps_m is far above
            # its error), and skipping intersect()'s refinement halves a step's cost.
            face, tfar = self.first_hits(start, direction[live])
            dist = tfar.astype(np.float64)
            crossed = (face >= 0) & (dist < _EMBREE_MISS)
            crossed &= travelled[live] + dist < length[live] - self.eps_m
            live = live[crossed]
            hit = face[crossed].astype(np.int64)
            seg_out.append(live)
            face_out.append(hit)
            travelled[live] += dist[crossed] + self.eps_m
            if stop_at_opaque:
                go_on = ~self._opaque[hit]
                live = live[go_on]
        else:
            if live.size:
                raise AcousticsError(
                    f"segment crossings: expected at most {max_crossings} surfaces between two "
                    f"points, got more for {live.size} segments; hint: the mesh may have "
                    "duplicated or stacked faces — repair it"
                )
        if not seg_out:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return np.concatenate(seg_out), np.concatenate(face_out)

    def segment_transmission(self, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Per-band *energy* factor ``Π τ`` of the surfaces each segment crosses, ``(n, n_bands)``.

        1 for a free segment, 0 where an opaque surface blocks it. Segments are first screened
        with a cheap occlusion query; only blocked ones are walked surface by surface.
        """
        n = len(origins)
        factor = np.ones((n, self.n_bands))
        if n == 0:
            return factor
        blocked = np.flatnonzero(self.occluded(origins, targets))
        if blocked.size == 0:
            return factor
        if not self.has_transmission:
            factor[blocked] = 0.0
            return factor
        factor[blocked] = self.crossed_transmission(origins[blocked], targets[blocked])
        return factor

    def crossed_transmission(self, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """``Π τ`` per band over the surfaces each segment crosses, walked surface by surface
        (no occlusion screen: for segments already known to be blocked), ``(n, n_bands)``."""
        seg, face = self.crossings(origins, targets, stop_at_opaque=True)
        # log-sum keeps the product order-independent and exact zeros exact.
        with np.errstate(divide="ignore"):
            log_tau = np.log(self.transmission[face])
        acc = np.zeros((len(origins), self.n_bands))
        np.add.at(acc, seg, log_tau)
        return np.exp(acc)
