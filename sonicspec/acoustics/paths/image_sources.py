"""Early specular reflections by the image-source method over the mesh's planar regions.

Why regions, not triangles: a flat wall is usually several triangles. Mirroring the source in
every triangle would create the same image once per triangle (duplicated arrivals) and lose the
reflection whose point falls exactly on a shared edge. Coplanar, edge-connected triangles with
the same material are therefore merged into one planar region first; a reflection point is valid
when it lies inside the union of the region's triangles (which is the region polygon, holes and
non-convex outlines included, without building an outline).

Pruning, before any path is backtracked (the image tree of a furnished or scanned room has
millions of candidates by order 3):

* reach: a region can only be reflected in next if some part of it lies on the side the last
  reflection sends sound to (Borish 1984);
* beams: sound reflected at a region leaves along the rays from the image through that region,
  so only regions that cone of rays meets (bounding spheres against a cone round the last
  region's sphere) can hold the next reflection. Both are exact: a pruned candidate has no
  valid path, so they change no arrival;
* audibility (``audible_floor_db``, off by default): a candidate whose paths cannot come
  within that many dB of the free-field direct sound — its reflections' product, bounded over
  the bands, times the direct distance over the image's distance (no later path is shorter or
  reflects more) — is dropped with its whole subtree; those are the only arrivals it changes;
* the last order: only images a receiver can hear through their last region (the segment
  from the receiver to the image crosses its plane within the region's sphere) are kept —
  the backtracking would reject the others anyway;
* the count cap (``max_candidates``), last: an order that still needs more candidates is not
  searched, and the result says so (``stopped``).

Validity of a candidate path (Borish 1984, backtracking from the receiver): every reflection
point must lie inside its region, between its two neighbouring path points' sides of the plane,
and every path segment (source → first reflection → … → receiver) must be free — or pass
through transmitting surfaces, whose ``√τ`` then multiplies the amplitude (a segment through an
opaque surface kills the path). Everything is vectorised per order over arrays of candidates.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from sonicspec.acoustics.arrivals import IDENTITY, KIND_SPECULAR, Arrivals
from sonicspec.acoustics.paths import _image_source_kernels as KI
from sonicspec.acoustics.paths.direct import check_air, check_points
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError, SonicspecWarning
from sonicspec.units import SPEED_OF_SOUND_M_S

T = TypeVar("T")

__all__ = ["ImageSourceResult", "PlanarRegions", "image_sources", "planar_regions"]

_NO_REACH = np.zeros((2, 0, 0), dtype=bool)
MAX_CANDIDATES = 2_000_000
"""The default cap on one order's candidate images after pruning (about 0.3 GB of them)."""
# Regions above this count skip the P×P "can one region be reached from another" table.
_MAX_REGIONS_FOR_REACH_TABLE = 3000


@dataclass(frozen=True, eq=False)
class PlanarRegions:
    """Coplanar, edge-connected, same-material triangles merged into planar regions.

    Attributes
    ----------
    normals : (P, 3) float64
        Unit region normals (into the air, the faces' orientation).
    plane_d : (P,) float64
        Plane offsets: ``normals[p]·x == plane_d[p]`` on the plane.
    face_region : (F,) int64
        Region of every face.
    region_start : (P+1,) int64
        ``region_faces[region_start[p]:region_start[p+1]]`` are the faces of region ``p``.
    region_faces : (F,) int64
        Faces sorted by region.
    reflection_energy : (P, n_bands) float64
        Specular reflection energy factor ``(1-τ)(1-α)(1-s)`` per region and band.
    distance_tol_m : float
        The coplanarity tolerance used: how far a region's triangles may lie off its plane.
    """

    normals: np.ndarray
    plane_d: np.ndarray
    face_region: np.ndarray
    region_start: np.ndarray
    region_faces: np.ndarray
    reflection_energy: np.ndarray
    distance_tol_m: float = 0.0
    #: Tables derived from the regions and their scene (reach table, bounding boxes).
    memo: dict = field(default_factory=dict, repr=False)

    @property
    def n_regions(self) -> int:
        return int(self.normals.shape[0])

    def memoized(self, key: Hashable, build: Callable[[], T]) -> T:
        """``build()`` once per regions and ``key`` (as :meth:`AcousticScene.memoized`): a
        trajectory calls the image-source search point by point on the same regions."""
        if key not in self.memo:
            self.memo[key] = build()
        return self.memo[key]  # type: ignore[return-value]


def planar_regions(
    scene: AcousticScene, angle_tol_rad: float = 1e-4, distance_tol_m: float = 1e-4
) -> PlanarRegions:
    """Merge coplanar, edge-connected triangles with identical coefficients into regions.

    Parameters
    ----------
    scene : AcousticScene
        The mesh.
    angle_tol_rad : float
        Largest angle between the normals of two neighbouring triangles of one region.
    distance_tol_m : float
        Largest distance of a triangle's far vertex from its neighbour's plane, metres.

    Returns
    -------
    PlanarRegions
        Region planes are the area-weighted mean of their triangles' planes (exact when the
        triangles are exactly coplanar). Above the default distance tolerance (scan
        tolerances), a region grows from its largest triangle and takes edge-connected
        neighbours whose normals are within ``angle_tol_rad`` of its plane so far and whose
        vertices lie within ``distance_tol_m`` of it, so a curved surface does not chain
        into one mirror.

    Notes
    -----
    The defaults merge exactly planar (procedural, CAD) faces only. On scans, noise makes every
    triangle its own region and the image-source tree explodes (the search then stops at a
    lower order with a warning); pass tolerances matching the scan noise (e.g. 0.1 rad and
    0.02 m for 3 mm noise on ~1 m triangles) so walls merge — image sources then reflect on
    the mean plane, an approximation of the order of that noise. Growing regions by
    neighbour normals needs a larger angle tolerance for finer tessellations.
    """
    faces = scene.faces
    n_faces = scene.n_faces
    # Undirected edges of every face, sorted so equal edges are adjacent.
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edge_face = np.repeat(np.arange(n_faces), 3)
    key = edges[:, 0] * (int(edges.max()) + 1) + edges[:, 1]
    order = np.argsort(key, kind="stable")
    key, edge_face = key[order], edge_face[order]
    # Chain faces that share an edge (non-manifold edges chain their faces in order).
    same = key[1:] == key[:-1]
    fa, fb = edge_face[:-1][same], edge_face[1:][same]
    nrm = scene.normals
    # (np.take: several times faster than fancy indexing for these million-row gathers.)
    nrm_a = np.take(nrm, fa, axis=0)
    cos_ok = np.einsum("ij,ij->i", nrm_a, np.take(nrm, fb, axis=0)) >= np.cos(angle_tol_rad)
    # Coplanar, not merely parallel: every vertex of b lies on a's plane.
    vb = np.take(scene.vertices, np.take(faces, fb, axis=0), axis=0)
    off = np.abs(np.einsum("ij,ikj->ik", nrm_a, vb) - np.take(scene.plane_d, fa)[:, None])
    classes = scene.coefficient_classes()[0]
    same_mat = np.take(classes, fa) == np.take(classes, fb)
    if distance_tol_m > _STRICT_TOL:
        # Scan tolerances: neighbour tests would chain round a gently curved surface, so each
        # region grows from its largest face and takes a neighbour only when all its
        # vertices lie within the tolerance of the region's plane so far.
        label, n_regions = _seeded_regions(scene, fa[same_mat], fb[same_mat], angle_tol_rad,
                                           distance_tol_m)
    else:
        link = cos_ok & (off.max(axis=1) <= distance_tol_m) & same_mat
        label, n_regions = _components(fa[link], fb[link], n_faces)
    normals, plane_d = _fitted_planes(scene, label, n_regions)

    region_faces = np.argsort(label, kind="stable")
    region_start = np.searchsorted(label[region_faces], np.arange(n_regions + 1))
    first = region_faces[region_start[:-1]]
    t, a, s = scene.transmission[first], scene.absorption[first], scene.scattering[first]
    return PlanarRegions(
        normals=normals,
        plane_d=plane_d,
        face_region=label,
        region_start=region_start.astype(np.int64),
        region_faces=region_faces.astype(np.int64),
        reflection_energy=(1.0 - t) * (1.0 - a) * (1.0 - s),
        distance_tol_m=float(distance_tol_m),
    )


_STRICT_TOL = 1e-4  # planar_regions' default tolerances: exactly planar faces


def _components(fa: np.ndarray, fb: np.ndarray, n_faces: int) -> tuple[np.ndarray, int]:
    """Connected components of the faces linked by the pairs ``(fa, fb)``: labels, count."""
    graph = coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(n_faces, n_faces))
    n_regions, label = connected_components(graph, directed=False)
    return label.astype(np.int64), int(n_regions)


def _seeded_regions(scene: AcousticScene, fa: np.ndarray, fb: np.ndarray,
                    angle_tol_rad: float, distance_tol_m: float) -> tuple[np.ndarray, int]:
    """Regions grown over the face pairs ``(fa, fb)`` (sharing an edge and a material) from
    the largest unassigned face: a face joins when its normal is within ``angle_tol_rad`` of
    the region's plane and its vertices within ``distance_tol_m`` of it (the plane refitted
    as faces join, :func:`~._image_source_kernels.grow_regions`)."""
    n_faces = scene.n_faces
    both_a, both_b = np.concatenate([fa, fb]), np.concatenate([fb, fa])
    order = np.argsort(both_a, kind="stable")
    adj = both_b[order].astype(np.int64)
    adj_start = np.searchsorted(both_a[order], np.arange(n_faces + 1)).astype(np.int64)
    seeds = np.argsort(-scene.face_areas_m2, kind="stable").astype(np.int64)
    label = np.empty(n_faces, dtype=np.int64)
    n_regions = KI.grow_regions(seeds, adj_start, adj, scene.normals, scene.face_areas_m2,
                                scene.vertices, scene.faces, float(np.cos(angle_tol_rad)),
                                float(distance_tol_m), label)
    return label, int(n_regions)


def _fitted_planes(scene: AcousticScene, label: np.ndarray, n_regions: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each region's plane: the area-weighted mean of its triangles' normals and offsets."""
    nrm, faces = scene.normals, scene.faces
    area = scene.face_areas_m2
    weighted = np.zeros((n_regions, 3))
    np.add.at(weighted, label, nrm * area[:, None])
    normals = weighted / np.linalg.norm(weighted, axis=1, keepdims=True)
    centroid = scene.vertices[faces].mean(axis=1)
    d_num = np.zeros(n_regions)
    np.add.at(d_num, label, area * np.einsum("ij,ij->i", normals[label], centroid))
    d_den = np.zeros(n_regions)
    np.add.at(d_den, label, area)
    return normals, d_num / d_den


@dataclass(frozen=True, eq=False)
class ImageSourceResult:
    """Image-source arrivals per receiver and the order that was completed.

    ``max_order`` may be lower than requested when the candidate count hit the limit (a
    warning says so); the ray tracer must then be told this order so that no specular path
    is lost or counted twice.
    """

    arrivals: tuple[Arrivals, ...]
    max_order: int
    stopped: str | None = None
    """Why ``max_order`` is lower than asked (``"order 3 needs more than 2,000,000
    candidates"``), None when the asked order was reached."""
    candidates: tuple[int, ...] = ()
    """Candidate images searched per order (1, 2, …), after pruning."""
    inaudible: int = 0
    """Candidates dropped below ``audible_floor_db`` (their subtrees not counted)."""


def _region_extremes(scene: AcousticScene, regions: PlanarRegions
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each region's outline corners and how far its vertices stray from its plane.

    A linear function's extremes over a planar region lie at corners of the convex hull of its
    vertices (in the plane), so a finely tessellated wall reduces to a handful of points.
    Returns ``points (K, 3)``, ``starts (P+1,)`` (region p's points are
    ``points[starts[p]:starts[p+1]]``) and ``stray (P,)``, the largest distance of a vertex
    of p from p's plane (nonzero for scans; a corner-only test can miss at most twice that).
    """
    chunks, counts = [], []
    stray = np.zeros(regions.n_regions)
    for p in range(regions.n_regions):
        fcs = regions.region_faces[regions.region_start[p]:regions.region_start[p + 1]]
        pts = scene.vertices[np.unique(scene.faces[fcs])]
        stray[p] = float(np.max(np.abs(pts @ regions.normals[p] - regions.plane_d[p])))
        if len(pts) > 8:
            # Imported here: a shoebox never needs it, and it costs 0.15 s to import.
            from scipy.spatial import ConvexHull, QhullError

            n = regions.normals[p]
            u = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
            u /= np.linalg.norm(u)
            v = np.cross(n, u)
            # Collinear or degenerate outlines keep every vertex.
            with contextlib.suppress(QhullError, ValueError):
                pts = pts[ConvexHull(np.column_stack([pts @ u, pts @ v])).vertices]
        chunks.append(pts)
        counts.append(len(pts))
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return np.concatenate(chunks), starts, stray


def _reach_tables(scene: AcousticScene, regions: PlanarRegions, tol: float) -> np.ndarray | None:
    """``reach[side, q, p]``: region p has a vertex strictly on side (0: front, 1: back) of q.

    A path reflected at q towards side ``σ`` can only next reach regions with some part on that
    side; this prunes candidates in non-convex scenes. Conservative: a region whose vertices
    stray off its plane counts as reaching by that much more. None when there are too many
    regions.
    """
    n_regions = regions.n_regions
    if n_regions > _MAX_REGIONS_FOR_REACH_TABLE or n_regions == 0:
        return None
    points, starts, stray = _region_extremes(scene, regions)
    reach = np.zeros((2, n_regions, n_regions), dtype=bool)
    chunk = max(1, 4_000_000 // max(1, len(points)))
    for q0 in range(0, n_regions, chunk):
        q = slice(q0, min(n_regions, q0 + chunk))
        dist = regions.normals[q] @ points.T - regions.plane_d[q][:, None]  # (Q, K)
        reach[0, q] = np.maximum.reduceat(dist, starts[:-1], axis=1) + 2 * stray > tol
        reach[1, q] = np.minimum.reduceat(dist, starts[:-1], axis=1) - 2 * stray < -tol
    return reach


def _region_boxes(scene: AcousticScene, regions: PlanarRegions) -> np.ndarray:
    """``(P, 2, 3)``: each region's bounding box (lower, upper corner), widened by more than a
    point the barycentric test calls inside can lie outside it (the region's triangles may lie
    ``distance_tol_m`` off its plane, and the test allows ``1e-9`` in barycentric units).
    Built once per regions."""

    def build() -> np.ndarray:
        tri = scene.vertices[scene.faces[regions.region_faces]]  # (F, 3, 3), by region
        starts = regions.region_start[:-1]
        lower = np.minimum.reduceat(tri.min(axis=1), starts, axis=0)
        upper = np.maximum.reduceat(tri.max(axis=1), starts, axis=0)
        margin = (2.0 * regions.distance_tol_m + 1e-6 * max(1.0, float(np.abs(tri).max()))
                  + 1e-6 * (upper - lower).max(axis=1, keepdims=True))
        return np.ascontiguousarray(np.stack([lower - margin, upper + margin], 1))

    return regions.memoized("region_boxes", build)


# Regions with more triangles than this are tested with an Embree probe ray, not barycentrics.
_MAX_TRIANGLES_FOR_BARYCENTRIC = 64


def _inside_regions(
    scene: AcousticScene,
    regions: PlanarRegions,
    points: np.ndarray,
    region: np.ndarray,
    side: np.ndarray,
) -> np.ndarray:
    """Whether each point (on its region's plane) lies inside its region.

    Small regions: barycentric test against each triangle in float64 (exact up to 1e-9).
    Large regions (e.g. finely tessellated walls): a probe ray from ``eps_m`` in front of the
    point (on ``side`` of the plane: +1 front, -1 back) straight back onto the plane; the point
    is inside when the face it hits belongs to the region — O(log F) per point.
    """
    inside = np.zeros(len(points), dtype=bool)
    if len(points) == 0:
        return inside
    tol = 1e-9
    n_tri = np.diff(regions.region_start)[region]
    big = n_tri > _MAX_TRIANGLES_FOR_BARYCENTRIC
    if np.any(big):
        idx = np.flatnonzero(big)
        nrm = regions.normals[region[idx]] * side[idx, None]
        # Start off the plane by more than the triangles may deviate from it (scans).
        probe = max(4.0 * scene.eps_m, 2.0 * regions.distance_tol_m)
        face, dist = scene.intersect(points[idx] + probe * nrm, -nrm)
        hit = (face >= 0) & (dist < 2.0 * probe)
        inside[idx] = hit & (regions.face_region[np.maximum(face, 0)] == region[idx])
    small = np.flatnonzero(~big)
    if small.size:
        KI.inside_small_regions(np.ascontiguousarray(points, dtype=np.float64),
                                region.astype(np.int64), small, _region_boxes(scene, regions),
                                regions.region_start, regions.region_faces, scene.faces,
                                scene.vertices, tol, inside)
    return inside


def image_sources(
    scene: AcousticScene,
    source: np.ndarray,
    receivers: np.ndarray,
    max_order: int = 3,
    air_m_per_band: np.ndarray | None = None,
    speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
    regions: PlanarRegions | None = None,
    max_path_length_m: float | None = None,
    max_candidates: int | None = None,
    audible_floor_db: float | None = None,
    beams: bool = True,
) -> ImageSourceResult:
    """Specular reflections of order 1…``max_order`` from a source to every receiver.

    Parameters
    ----------
    scene : AcousticScene
        The mesh with its per-face coefficients.
    source : (3,) float
        Source position, metres.
    receivers : (n, 3) float
        Receiver positions, metres.
    max_order : int
        Highest reflection order (>= 0; 0 gives no arrivals).
    air_m_per_band : (n_bands,) float, optional
        ISO 9613-1 air energy attenuation ``m`` per band, 1/m; pressure decays as
        ``exp(-m·L/2)`` over the unfolded path length ``L``.
    speed_of_sound_m_s : float
        Speed of sound, m/s.
    regions : PlanarRegions, optional
        Precomputed :func:`planar_regions` of ``scene`` (reuse across sources).
    max_path_length_m : float, optional
        Drop paths longer than this (e.g. ``c ×`` the RIR length). Safe pruning: a valid
        path's length never decreases with further reflections.
    max_candidates : int, optional
        Largest number of candidate images of one order, after pruning (default
        :data:`MAX_CANDIDATES`): a last resort. If the
        next order would exceed it, the search stops at the previous order with a
        :class:`SonicspecWarning` (the result's ``max_order`` and ``stopped`` say so).
    audible_floor_db : float, optional
        Drop candidates whose paths cannot come within this many dB of the free-field direct
        sound at any receiver (``20 log10`` of the bound in the module docstring; e.g. 60).
        None keeps every candidate (exact).
    beams : bool
        Beam pruning (exact; False only to compare against the unpruned search).

    Returns
    -------
    ImageSourceResult
        Per receiver, arrivals with amplitude per band
        ``Π√((1-τ)(1-α)(1-s)) · Π√τ_crossed · exp(-m·L/2) / (4πL)`` at delay ``L/c``,
        the direction of arrival (towards the image source) and the order.

    Notes
    -----
    Reflection factors are energy coefficients for random incidence applied as angle-independent
    pressure factors (no phase, no angle dependence), like pyroomacoustics' ISM. Faces reflect
    on both sides. Diffraction at region edges is not modelled.
    """
    source = check_points("source", source)
    if len(source) != 1:
        raise AcousticsError(f"source: expected one position, got {len(source)}")
    receivers = check_points("receivers", receivers)
    if not isinstance(max_order, int | np.integer) or max_order < 0:
        raise AcousticsError(f"max_order: expected an integer >= 0, got {max_order!r}")
    air = check_air(air_m_per_band, scene.n_bands)
    if not speed_of_sound_m_s > 0:
        raise AcousticsError(f"speed_of_sound_m_s: expected > 0, got {speed_of_sound_m_s}")
    if regions is None:
        regions = planar_regions(scene)
    if len(regions.face_region) != scene.n_faces:
        raise AcousticsError(
            f"regions: expected the planar regions of this scene ({scene.n_faces} faces), "
            f"got regions of {len(regions.face_region)} faces"
        )
    if max_candidates is None:
        max_candidates = MAX_CANDIDATES
    src = source[0]
    n_rcv = len(receivers)
    tol = scene.eps_m
    reach = None
    if max_order >= 2:
        reach = regions.memoized(("reach", tol), lambda: _reach_tables(scene, regions, tol))
    normals = regions.normals
    counts = None if reach is None else regions.memoized(
        ("reach_counts", tol), lambda: reach.sum(axis=2))
    spheres = (regions.memoized("region_spheres", lambda: _region_spheres(scene, regions))
               if beams and regions.n_regions else np.zeros((0, 4)))
    hull_pts, hull_start = (regions.memoized("region_outlines",
                                             lambda: _region_outlines(scene, regions))
                            if beams and max_order >= 2 else (np.zeros((0, 3)),
                                                              np.zeros(1, np.int64)))
    # How far a valid reflection point (on the region's plane) may lie outside its outline
    # (the corners projected onto that plane): the probe rays of large regions run along the
    # normal, so none; a small region's off-plane triangles tilt by at most the angle
    # tolerance over twice the distance tolerance; with room to spare.
    margin = (4.0 * scene.eps_m + 2.0 * regions.distance_tol_m
              + 1e-6 * max(1.0, float(np.abs(scene.vertices).max(initial=0.0))))
    floor = 0.0
    if audible_floor_db is not None:
        if not audible_floor_db > 0:
            raise AcousticsError(f"audible_floor_db: expected > 0 dB, got {audible_floor_db}")
        floor = 10.0 ** (-float(audible_floor_db) / 20.0)
    direct_m = np.linalg.norm(receivers - source[0], axis=1)
    region_gain = np.sqrt(regions.reflection_energy.max(axis=1)) if regions.n_regions else (
        np.zeros(0))
    candidates = _CandidateTest(normals, regions.plane_d, tol, reach, counts, spheres, floor,
                                direct_m, hull_pts, hull_start, margin)

    per_receiver: list[list[Arrivals]] = [[] for _ in range(n_rcv)]
    # The image tree, one order at a time: levels[k] holds the images after k+1 reflections
    # (their parent's row in levels[k-1], their position, the region of reflection k+1);
    # side[i] is the side (0 front, 1 back) of the last plane on which the pre-image lies
    # (where the reflected sound goes). Whole chains are built only for the images whose
    # paths are backtracked (:func:`_chains`).
    levels: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    iso = IDENTITY[None].copy()  # [M | b] of the current level: image = M @ source + b
    side = np.zeros(1, dtype=np.int64)
    gain = np.ones(1)
    last_pos = src[None, :]
    completed = 0
    stopped = None
    searched: list[int] = []
    dropped = np.zeros(1, dtype=np.int64)
    for order in range(1, max_order + 1):
        # Candidates (parent image, region), compiled: at most min(pairs, limit) rows.
        last_plane = levels[-1][2] if order > 1 else None
        count = max_candidates + 1  # decided without building the images
        last = bool(len(spheres)) and order == max_order
        if not _provably_too_many(candidates, last_pos, last_plane, side, gain, receivers,
                                  max_path_length_m, max_candidates, last):
            rows = min(_pair_bound(candidates, last_pos, last_plane, side), max_candidates)
            parent, plane = np.empty(rows, np.int64), np.empty(rows, np.int64)
            new_pos, new_side = np.empty((rows, 3)), np.empty(rows, np.int64)
            new_gain = np.empty(rows)
            count = KI.next_order(
                np.ascontiguousarray(last_pos, dtype=np.float64),
                _own_planes(last_pos, last_plane), side.astype(np.int64), normals,
                regions.plane_d, tol, reach if reach is not None else _NO_REACH, receivers,
                -1.0 if max_path_length_m is None else float(max_path_length_m),
                max_candidates, parent, plane, new_pos, new_side, spheres, gain, floor,
                direct_m, region_gain, new_gain, dropped, hull_pts, hull_start, margin,
                last, float(tol))
        if count > max_candidates:
            warnings.warn(
                f"image sources: order {order} needs more than {max_candidates} candidates; "
                f"stopping at order {order - 1}; hint: lower the image-source order for this "
                "scene — the ray tracer covers the rest",
                SonicspecWarning,
                stacklevel=2,
            )
            stopped = f"order {order} needs more than {max_candidates:,} candidates"
            break
        parent, plane, new_pos, new_side, gain = (
            x[:count] for x in (parent, plane, new_pos, new_side, new_gain))
        searched.append(int(count))
        levels.append((parent, new_pos, plane))
        iso = _mirrored(iso[parent], normals[plane], regions.plane_d[plane])
        side, last_pos = new_side, new_pos
        completed = order
        if len(last_pos) == 0:
            break
        _validate_order(
            scene,
            regions,
            src,
            receivers,
            levels,
            side,
            iso,
            air,
            speed_of_sound_m_s,
            max_path_length_m,
            per_receiver,
        )
    if max_order > 0 and completed < max_order and len(last_pos) == 0:
        completed = max_order  # no image survives: higher orders are empty, hence complete
    arrivals = tuple(
        Arrivals.concatenate(parts) if parts else Arrivals.empty(scene.n_bands)
        for parts in per_receiver
    )
    return ImageSourceResult(arrivals=arrivals, max_order=completed,
                             stopped=stopped if completed < max_order else None,
                             candidates=tuple(searched), inaudible=int(dropped[0]))


def _mirrored(iso: np.ndarray, normal: np.ndarray, plane_d: np.ndarray) -> np.ndarray:
    """``[M | b]`` of each image's map followed by the mirror in its plane ``n · x = d``:
    ``x ↦ x − 2 (n · x − d) n``."""
    reflect = np.eye(3)[None] - 2.0 * normal[:, :, None] * normal[:, None, :]
    out = reflect @ iso
    out[:, :, 3] += 2.0 * plane_d[:, None] * normal
    return out


@dataclass(frozen=True, eq=False)
class _CandidateTest:
    """Which (parent image, region) pairs make candidate images: the region planes, the
    off-plane tolerance, the reach table (None: every region is reachable) and its row sums
    ``reach_counts[side, q]``, the regions reachable from each side of ``q``; the regions'
    bounding spheres for beam pruning (``(0, 4)``: none), the audibility floor (an amplitude
    ratio, 0: none) and the direct distance to each receiver."""

    normals: np.ndarray
    plane_d: np.ndarray
    tol: float
    reach: np.ndarray | None
    reach_counts: np.ndarray | None
    spheres: np.ndarray
    floor: float
    direct_m: np.ndarray
    hull_pts: np.ndarray
    hull_start: np.ndarray
    margin: float


def _region_outlines(scene: AcousticScene, regions: PlanarRegions
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Each region's convex outline on its plane, corners in order: ``points (K, 3)`` and
    ``starts (P+1,)``; a degenerate region (fewer than 3 corners) gets none."""
    from scipy.spatial import ConvexHull, QhullError

    chunks, counts = [], []
    for p in range(regions.n_regions):
        fcs = regions.region_faces[regions.region_start[p]:regions.region_start[p + 1]]
        n = regions.normals[p]
        pts = scene.vertices[np.unique(scene.faces[fcs])]
        pts = pts - np.outer(pts @ n - regions.plane_d[p], n)  # onto the plane
        u = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        try:
            pts = pts[ConvexHull(np.column_stack([pts @ u, pts @ v])).vertices]
        except (QhullError, ValueError):
            pts = pts[:0]
        chunks.append(pts)
        counts.append(len(pts))
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return np.ascontiguousarray(np.concatenate(chunks)), starts


def _region_spheres(scene: AcousticScene, regions: PlanarRegions) -> np.ndarray:
    """``(P, 4)``: a sphere enclosing each region (centre, radius), from its widened bounding
    box (:func:`_region_boxes`), for beam pruning."""
    boxes = _region_boxes(scene, regions)
    centre = boxes.mean(axis=1)
    radius = 0.5 * np.linalg.norm(boxes[:, 1] - boxes[:, 0], axis=1)
    return np.ascontiguousarray(np.column_stack([centre, radius * (1.0 + 1e-9) + 1e-9]))


def _own_planes(last_pos: np.ndarray, last_plane: np.ndarray | None) -> np.ndarray:
    """Each parent's last region (-1 for the source itself), as the kernels take it."""
    if last_plane is None:
        return np.full(len(last_pos), -1, dtype=np.int64)
    return last_plane.astype(np.int64)


def _pair_bound(candidates: _CandidateTest, last_pos: np.ndarray,
                last_plane: np.ndarray | None, side: np.ndarray) -> int:
    """How many (parent, region) pairs the reach table allows: a bound on the candidates."""
    if last_plane is not None and candidates.reach is not None:
        return int(candidates.reach_counts[side, last_plane].sum())
    return len(last_pos) * len(candidates.plane_d)


def _provably_too_many(
    candidates: _CandidateTest,
    last_pos: np.ndarray,
    last_plane: np.ndarray | None,
    side: np.ndarray,
    gain: np.ndarray,
    receivers: np.ndarray,
    max_path_length_m: float | None,
    limit: int,
    last: bool,
) -> bool:
    """Whether the next order has more than ``limit`` candidates, decided without building
    the images (in a scan, order 3 overflows after ~0.5 s of building them otherwise).

    Candidates are counted by the same tests as :func:`image_sources`; under a path-length
    limit only those it provably keeps count (``|image − r| <= |parent − r| + 2|d|``), so
    True is always right; False leaves the decision to the exact count.
    """
    if _pair_bound(candidates, last_pos, last_plane, side) <= limit:
        return False
    reach = candidates.reach if candidates.reach is not None else _NO_REACH
    return bool(KI.more_candidates_than(
        np.ascontiguousarray(last_pos, dtype=np.float64), _own_planes(last_pos, last_plane),
        side.astype(np.int64), candidates.normals, candidates.plane_d, candidates.tol, reach,
        receivers, -1.0 if max_path_length_m is None else float(max_path_length_m), limit,
        candidates.spheres, gain, candidates.floor, candidates.direct_m, candidates.hull_pts,
        candidates.hull_start, candidates.margin, last, candidates.tol))


def _chains(levels: list[tuple[np.ndarray, np.ndarray, np.ndarray]], rows: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The images ``chain (n, order, 3)`` after each reflection and the regions ``planes (n,
    order)`` reflected in, of the images ``rows`` of the last level, followed back through
    their parents."""
    order = len(levels)
    chain = np.empty((len(rows), order, 3))
    planes = np.empty((len(rows), order), dtype=np.int64)
    for j in range(order - 1, -1, -1):
        parent, pos, plane = levels[j]
        chain[:, j] = pos[rows]
        planes[:, j] = plane[rows]
        rows = parent[rows]
    return chain, planes


def _validate_order(
    scene: AcousticScene,
    regions: PlanarRegions,
    src: np.ndarray,
    receivers: np.ndarray,
    levels: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
    side: np.ndarray,
    iso: np.ndarray,
    air: np.ndarray,
    c: float,
    max_path_length_m: float | None,
    per_receiver: list[list[Arrivals]],
) -> None:
    """Backtrack every (image, receiver) pair of one order (the last of ``levels``); append
    the valid arrivals."""
    _, last_pos, last_plane = levels[-1]
    n_img = len(last_pos)
    normals, plane_d = regions.normals, regions.plane_d
    # A compiled prefilter drops most pairs (a superset of the valid ones is kept); the exact
    # tests below then decide on the rest, as they would on all of them.
    keep = np.empty(n_img * len(receivers), dtype=bool)
    KI.last_reflection_prefilter(
        receivers, np.ascontiguousarray(last_pos), np.ascontiguousarray(last_plane),
        side.astype(np.int64), normals, plane_d, scene.eps_m,
        -1.0 if max_path_length_m is None else float(max_path_length_m),
        _region_boxes(scene, regions), regions.region_start, regions.region_faces,
        scene.faces, scene.vertices, _MAX_TRIANGLES_FOR_BARYCENTRIC, keep)
    pairs = np.flatnonzero(keep)
    img, rcv = pairs // len(receivers), pairs % len(receivers)
    # From here on, images are rows of the chains of those the prefilter kept.
    kept, img = np.unique(img, return_inverse=True)
    chain, planes = _chains(levels, kept)
    side, iso = side[kept], iso[kept]
    order = len(levels)
    # The receiver must be on the side the last reflection sends sound to.
    dist_r = (
        np.einsum("ij,ij->i", receivers[rcv], normals[planes[img, -1]]) - plane_d[planes[img, -1]]
    )
    sgn = np.where(side[img] == 0, 1.0, -1.0)
    keep = dist_r * sgn > scene.eps_m
    img, rcv = img[keep], rcv[keep]
    if max_path_length_m is not None:
        length = np.linalg.norm(chain[img, -1] - receivers[rcv], axis=1)
        keep = length <= max_path_length_m
        img, rcv = img[keep], rcv[keep]
    # Backtrack: x runs from the receiver to the reflection points, last to first.
    # Visibility is tested from reflection points lifted off their plane towards the path
    # (by twice the coplanarity tolerance), so a region's own triangles, which may lie up to
    # that far off the mean plane, do not occlude the path. They are kept per step for the
    # surviving pairs only: most candidates fail the first step.
    lifted_points: list[np.ndarray] = []  # last reflection first
    lift = max(scene.eps_m, 2.0 * regions.distance_tol_m)
    x = receivers[rcv]
    for j in range(order - 1, -1, -1):
        p = planes[img, j]
        target = chain[img, j]
        vec = target - x
        den = np.einsum("ij,ij->i", vec, normals[p])
        t = (plane_d[p] - np.einsum("ij,ij->i", x, normals[p])) / np.where(den != 0, den, 1.0)
        good = (den != 0) & (t > 0) & (t < 1)
        q = x + t[:, None] * vec
        # The path arrives from x's side of the plane.
        x_side = np.where(np.einsum("ij,ij->i", x, normals[p]) - plane_d[p] >= 0, 1.0, -1.0)
        good &= _inside_regions(scene, regions, q, p, x_side)
        img, rcv, x = img[good], rcv[good], q[good]
        lifted_points = [pts[good] for pts in lifted_points]
        lifted_points.append(x + (lift * x_side[good])[:, None] * normals[p[good]])
        if len(img) == 0:
            return
    lifted = np.empty((len(img), order + 2, 3))
    lifted[:, 0] = src
    lifted[:, -1] = receivers[rcv]
    for k, pts in enumerate(lifted_points):  # reflection order - k, counted from the source
        lifted[:, order - k] = pts
    # Every segment must be free or transmitting: energy factor per band of all crossings.
    n_pairs = len(img)
    seg_start = lifted[:, :-1].reshape(-1, 3)
    seg_end = lifted[:, 1:].reshape(-1, 3)
    trans = scene.segment_transmission(seg_start, seg_end).reshape(n_pairs, order + 1, -1)
    trans_energy = trans.prod(axis=1)
    refl_energy = regions.reflection_energy[planes[img]].prod(axis=1)
    energy = trans_energy * refl_energy
    alive = np.any(energy > 0, axis=1)
    img, rcv, energy = img[alive], rcv[alive], energy[alive]
    path_iso = iso[img]
    vec = chain[img, -1] - receivers[rcv]
    length = np.linalg.norm(vec, axis=1)
    amp = (
        np.sqrt(energy)
        * np.exp(-0.5 * air[None, :] * length[:, None])
        / (4.0 * np.pi * length[:, None])
    )
    for r in np.unique(rcv):
        sel = rcv == r
        per_receiver[r].append(
            Arrivals(
                times_s=length[sel] / c,
                amplitudes=amp[sel],
                directions=vec[sel] / length[sel, None],
                order=np.full(int(sel.sum()), order, dtype=np.int64),
                kind=np.full(int(sel.sum()), KIND_SPECULAR, dtype=np.int8),
                path_length_m=length[sel],
                isometry=path_iso[sel],
            )
        )
