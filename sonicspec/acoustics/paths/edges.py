"""The diffracting edges of a triangle mesh: wedges that stick out into the air.

An edge between two faces diffracts when the air around it spans more than a half turn
(``θ_w > π``: a box's corners seen from the room, a door jamb, a wall's end); a concave crease
(``θ_w < π``, a room's corners) does not (its sound is the reflections'), and a flat one
(``θ_w = π``) diffracts nothing (``sin(π/n) = 0``). An edge with one face is the free rim of a
thin sheet, a half-plane (``θ_w = 2π``). Edges bent by less than :data:`MIN_TURN_DEG` are left
out: on a scan they are the surface's noise, and their diffraction is weak (UTD's coefficient
carries ``sin(π/n)``, ``n = θ_w/π``, which vanishes as the wedge flattens).

An edge with one face is a rim only when it is free: an open edge that another open edge
overlaps (the same segment, or a part of it, within ``seam_tolerance_m``) is a seam between two
pieces of one surface whose vertices were not joined — a material or object boundary of a file
written one object per material, or the two sides of a T-junction — and diffracts nothing.

A wedge of a closed solid is a diffracting edge only where its air is air: a box standing on
the floor or against a wall has edges there whose air another surface cuts through (an inner
corner of the room, not an edge in the air); the RIR engine leaves those out
(:meth:`DiffractingEdges.arc_points`, ``engine._unburied``), and counts them in
:attr:`DiffractingEdges.buried`.

Segments that continue one another (collinear, same two planes) are merged into one edge, so a
wall cut into many triangles still has one edge per corner. A scan may have thousands of
creases: ``max_edges`` keeps the most important (the budget the RIR stage passes), and the
result says how many were found and by which rule they were kept (:func:`edge_importance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sonicspec.errors import AcousticsError

__all__ = ["HIDDEN_WEIGHT", "MIN_TURN_DEG", "NEAR_SCALE_M", "DiffractingEdges",
           "EdgeChoice", "diffracting_edges", "edge_importance"]

#: Smallest turn of the surface (θ_w − π, degrees) that counts as a diffracting edge.
MIN_TURN_DEG = 15.0
_PARALLEL_COS = math.cos(math.radians(0.5))
#: Distance scale of :func:`edge_importance`, metres: edges closer than this to a source or a
#: receiver count about as much as one at this distance (a path's level does not grow without
#: bound as its edge comes near).
NEAR_SCALE_M = 1.0
#: Radius (m) and number of chords of the arcs round an edge that test whether another surface
#: cuts through its air (:meth:`DiffractingEdges.arc_points`): 2 cm, below a room's features and
#: above a scan's noise.
BURIED_RADIUS_M = 0.02
BURIED_STEPS = 8
#: Weight of an edge that no source or receiver position sees (heard only after a
#: reflection) against one that every position sees, in :func:`edge_importance`.
HIDDEN_WEIGHT = 0.1


@dataclass(frozen=True, eq=False)
class DiffractingEdges:
    """Finite straight edges, each a wedge in the convention of ``theory.Wedge``.

    Attributes
    ----------
    start, end : (m, 3) float
        End points, metres; ``end − start`` is along ``direction``.
    direction : (m, 3) float
        Unit edge direction ``e``; face 1 is face 0 turned by ``open_angle`` about ``e``.
    face0 : (m, 3) float
        Unit vector from the edge into face 0, perpendicular to the edge.
    open_angle : (m,) float
        Air angle θ_w, radians, in (π, 2π].
    faces : (m, 2) int
        A mesh face on side 0 and on side 1 (−1 for a half-plane's missing second face): the
        materials of the edge.
    n_found : int
        Diffracting edges found before the ``max_edges`` budget.
    importance : (m,) float
        Each edge's :func:`edge_importance` (the edges are in decreasing order of it).
    near_points : int
        How many source and receiver positions the importance was measured from (0: by
        length and exposure alone).
    seams : int
        Open edges left out because another open edge overlaps them (unjoined seams).
    by_sight : bool
        Whether the importance counted which positions see each edge.
    buried : int
        Wedges left out because another surface cuts through the air around them (a box
        standing on the floor or against a wall: its edges there are inner corners of the
        room, not edges in the air; :meth:`buried_mask`).
    """

    start: np.ndarray
    end: np.ndarray
    direction: np.ndarray
    face0: np.ndarray
    open_angle: np.ndarray
    faces: np.ndarray
    n_found: int
    importance: np.ndarray | None = None
    near_points: int = 0
    seams: int = 0
    by_sight: bool = False
    buried: int = 0

    def __len__(self) -> int:
        return len(self.open_angle)

    @property
    def length_m(self) -> np.ndarray:
        return np.linalg.norm(self.end - self.start, axis=1)

    def air_points(self, per_edge: int = 3, offset_m: float = 0.01) -> np.ndarray:
        """``(m, per_edge, 3)`` points along each edge, ``offset_m`` off it into the air
        (along the bisector of its open angle): where visibility from the edge is tested."""
        half = 0.5 * self.open_angle[:, None]
        into_air = (np.cos(half) * self.face0
                    + np.sin(half) * np.cross(self.direction, self.face0))
        t = (np.arange(per_edge) + 0.5) / per_edge
        along = self.start[:, None, :] + t[None, :, None] * (self.end - self.start)[:, None, :]
        return along + offset_m * into_air[:, None, :]

    def ranked(self, max_edges: int | None = None, near_m: np.ndarray | None = None,
               seen: np.ndarray | None = None) -> DiffractingEdges:
        """These edges in decreasing :func:`edge_importance` for sources and receivers at
        ``near_m`` (ties by position), the first ``max_edges``; ``n_found`` and ``seams``
        kept. ``seen``: the share of those positions each edge is in sight of. Ranking all
        of a scene's edges once per group costs far less than finding them."""
        score = edge_importance(self.start, self.end, self.open_angle, near_m, seen)
        mid = 0.5 * (self.start + self.end)
        keep = np.lexsort((mid[:, 2], mid[:, 1], mid[:, 0], -score))
        if max_edges is not None:
            keep = keep[:max_edges]
        near_points = 0 if near_m is None else len(np.asarray(near_m).reshape(-1, 3))
        return DiffractingEdges(self.start[keep], self.end[keep], self.direction[keep],
                                self.face0[keep], self.open_angle[keep], self.faces[keep],
                                self.n_found, score[keep], near_points, self.seams,
                                seen is not None, self.buried)

    def arc_points(self, radius_m: float = BURIED_RADIUS_M, per_edge: int = 3,
                   steps: int = BURIED_STEPS) -> np.ndarray:
        """``(m, per_edge, steps, 3)`` points on arcs round each edge, ``radius_m`` from it,
        spread evenly over its air angle (none on its own faces): at ``per_edge`` places
        along it."""
        phi = self.open_angle[:, None] * (np.arange(steps) + 0.5)[None, :] / steps  # (m, s)
        side = np.cross(self.direction, self.face0)
        ring = (np.cos(phi)[..., None] * self.face0[:, None, :]
                + np.sin(phi)[..., None] * side[:, None, :])  # (m, s, 3)
        t = (np.arange(per_edge) + 0.5) / per_edge
        along = self.start[:, None, :] + t[None, :, None] * (self.end - self.start)[:, None, :]
        return along[:, :, None, :] + radius_m * ring[:, None, :, :]

    def without(self, mask: np.ndarray) -> DiffractingEdges:
        """These edges less those where ``mask`` is true, counted as :attr:`buried` (and no
        longer in :attr:`n_found`)."""
        keep = ~np.asarray(mask, dtype=bool)
        gone = int(np.count_nonzero(~keep))
        importance = None if self.importance is None else self.importance[keep]
        return DiffractingEdges(self.start[keep], self.end[keep], self.direction[keep],
                                self.face0[keep], self.open_angle[keep], self.faces[keep],
                                self.n_found - gone, importance, self.near_points, self.seams,
                                self.by_sight, self.buried + gone)

    def choice(self) -> EdgeChoice:
        """How the edges were chosen (the RIR facts' ``diffraction_edges``)."""
        kept = len(self)
        sight = (f" x ({HIDDEN_WEIGHT:g} + {1 - HIDDEN_WEIGHT:g} x share of them in sight)"
                 if self.by_sight else "")
        rule = ("importance: length x exposure / (1 m + distance to the nearest of "
                f"{self.near_points} source and receiver positions)^2{sight}"
                if self.near_points else "importance: length x exposure")
        return EdgeChoice(found=int(self.n_found), kept=kept, rule=rule,
                          near_points=int(self.near_points), seams_left_out=int(self.seams),
                          buried_left_out=int(self.buried),
                          length_kept_m=float(self.length_m.sum()) if kept else 0.0)


@dataclass(frozen=True)
class EdgeChoice:
    """How a set of diffracting edges was chosen, as the RIR facts and the rir artifact keep
    it (a plain frozen dataclass: the artifact models validate and store it field by field).

    Attributes
    ----------
    found : int
        Diffracting edges of the scene (seams and buried wedges not counted).
    kept : int
        Edges kept (at most ``acoustics.diffraction_max_edges``).
    rule : str
        The importance the kept ones rank highest by.
    near_points : int
        Source and receiver positions the importance measured distances to (0: none).
    seams_left_out, buried_left_out : int
        Edges left out as seams between coplanar faces, and as wedges buried in geometry.
    length_kept_m : float
        Total length of the kept edges, metres.
    """

    found: int
    kept: int
    rule: str
    near_points: int
    seams_left_out: int
    buried_left_out: int
    length_kept_m: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return dict(vars(self))


def _empty(n_found: int = 0, near_points: int = 0, seams: int = 0) -> DiffractingEdges:
    z3 = np.zeros((0, 3))
    return DiffractingEdges(z3, z3, z3, z3, np.zeros(0), np.zeros((0, 2), np.int64), n_found,
                            np.zeros(0), near_points, seams)


def edge_importance(start: np.ndarray, end: np.ndarray, open_angle: np.ndarray,
                    near_m: np.ndarray | None = None, seen: np.ndarray | None = None
                    ) -> np.ndarray:
    """How much an edge is likely to be heard:
    ``length × exposure × (w + (1 − w) × seen) / (1 m + d)²``.

    ``exposure = (θ_w − π) / π`` is how far the wedge sticks out into the air (1 for a
    half-plane, 0.5 for a right-angled corner, 0.08 for a 15° bend), which UTD's coefficient
    follows; ``d`` is the distance from the edge (the segment) to the nearest of ``near_m``,
    the sources and receivers of the job (a diffracted path's level falls with both of its
    legs), and is left out without them (then the longest, most exposed edges come first);
    ``seen`` is the share of those positions that have the edge in sight (an edge behind a
    wall is heard only after a reflection: weight ``w`` = :data:`HIDDEN_WEIGHT`), 1 when not
    given.
    """
    length = np.linalg.norm(end - start, axis=1)
    score = length * (open_angle - math.pi) / math.pi
    if seen is not None:
        score = score * (HIDDEN_WEIGHT + (1 - HIDDEN_WEIGHT) * np.asarray(seen, np.float64))
    if near_m is None or len(near_m) == 0 or len(start) == 0:
        return score
    near = np.asarray(near_m, dtype=np.float64).reshape(-1, 3)
    axis = end - start
    # distance from every point to every segment, in blocks to bound the memory
    nearest = np.full(len(start), np.inf)
    step = max(1, 2_000_000 // max(len(start), 1))
    safe = np.maximum(length, 1e-300) ** 2
    for k in range(0, len(near), step):
        p = near[k:k + step]
        rel = p[:, None, :] - start[None, :, :]
        t = np.clip(np.einsum("pij,ij->pi", rel, axis) / safe, 0.0, 1.0)
        d = np.linalg.norm(rel - t[..., None] * axis[None], axis=2)
        nearest = np.minimum(nearest, d.min(axis=0))
    return score / (NEAR_SCALE_M + nearest) ** 2


def diffracting_edges(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, *,
                      max_edges: int | None = None, min_turn_deg: float = MIN_TURN_DEG,
                      min_length_m: float = 0.0, near_m: np.ndarray | None = None,
                      seam_tolerance_m: float = 1e-4) -> DiffractingEdges:
    """Find the diffracting edges of a mesh whose face normals point into the air.

    Parameters
    ----------
    vertices : (V, 3) float
        Vertex positions, metres.
    faces : (F, 3) int
        Triangles.
    normals : (F, 3) float
        Unit normals into the air (``AcousticScene.normals``).
    max_edges : int, optional
        Keep at most this many edges, the most important (:func:`edge_importance`); None
        keeps all.
    min_turn_deg : float
        Smallest ``θ_w − 180°`` that diffracts.
    min_length_m : float
        Merged edges shorter than this are dropped (a scan's crumbs).
    near_m : (P, 3) float, optional
        The sources and receivers the edges are for (metres): the importance falls with the
        distance to the nearest of them.
    seam_tolerance_m : float
        Open edges that another open edge overlaps within this distance (metres) are seams,
        not rims.

    Returns
    -------
    DiffractingEdges
        Most important first (ties: by position). Edges with more than two faces
        (non-manifold) are skipped.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    normals = np.asarray(normals, dtype=np.float64)
    if faces.ndim != 2 or faces.shape[1] != 3 or normals.shape != faces.shape:
        raise AcousticsError(f"faces/normals: expected (F, 3) arrays of equal shape, got "
                             f"{faces.shape} and {normals.shape}")
    if max_edges is not None and (not isinstance(max_edges, int) or max_edges < 0):
        raise AcousticsError(f"max_edges: expected an integer >= 0 or None, got {max_edges!r}")
    if not (0 < min_turn_deg < 180):
        raise AcousticsError(f"min_turn_deg: expected a value in (0, 180), got {min_turn_deg}")
    near_count = 0 if near_m is None else len(np.asarray(near_m).reshape(-1, 3))
    if len(faces) == 0:
        return _empty(near_points=near_count)

    # Every face's three edges as sorted vertex pairs, with the face and its opposite vertex.
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    opposite = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    owner = np.tile(np.arange(len(faces)), 3)
    key = np.sort(pairs, axis=1)
    uniq, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])

    a, b = vertices[uniq[:, 0]], vertices[uniq[:, 1]]
    axis = b - a
    length = np.linalg.norm(axis, axis=1)
    ok = length > 0
    axis = axis / np.where(ok, length, 1.0)[:, None]

    def inward(slot: np.ndarray, edge: np.ndarray) -> np.ndarray:
        """Unit vector from the edge into the face, perpendicular to the edge."""
        d = vertices[opposite[slot]] - a[edge]
        d = d - np.einsum("ij,ij->i", d, axis[edge])[:, None] * axis[edge]
        return d / np.linalg.norm(d, axis=1)[:, None]

    # Two faces: the air angle from the two inward directions and the normals.
    two = np.flatnonzero((counts == 2) & ok)
    fa_slot, fb_slot = order[first[two]], order[first[two] + 1]
    ta, tb = inward(fa_slot, two), inward(fb_slot, two)
    na, nb = normals[owner[fa_slot]], normals[owner[fb_slot]]
    between = np.arccos(np.clip(np.einsum("ij,ij->i", ta, tb), -1, 1))
    # Face B behind face A's air side: the solid is the narrow side, the air the wide one.
    convex = np.einsum("ij,ij->i", tb, na) < 0
    open_two = np.where(convex, 2 * math.pi - between, between)
    # Both faces must see the same air (consistent normals): B's normal, turned into A's
    # frame, points into the same region.
    consistent = np.einsum("ij,ij->i", ta, nb) < 1e-9 if len(two) else np.zeros(0, bool)
    keep = convex & consistent & (open_two > math.pi + math.radians(min_turn_deg))
    two, ta, na, fa_slot, fb_slot, open_two = (
        two[keep], ta[keep], na[keep], fa_slot[keep], fb_slot[keep], open_two[keep])

    # One face: the rim of a sheet, a half-plane, unless another open edge overlaps it.
    one = np.flatnonzero((counts == 1) & ok)
    seam = _overlapped(a[one], b[one], seam_tolerance_m)
    n_seams = int(np.count_nonzero(seam))
    one = one[~seam]
    one_slot = order[first[one]]
    t1, n1 = inward(one_slot, one), normals[owner[one_slot]]

    edge_ids = np.concatenate([two, one])
    t0 = np.concatenate([ta, t1])
    n0 = np.concatenate([na, n1])
    tw = np.concatenate([open_two, np.full(len(one), 2 * math.pi)])
    face_pair = np.column_stack([
        np.concatenate([owner[fa_slot], owner[one_slot]]),
        np.concatenate([owner[fb_slot], np.full(len(one), -1)])])
    if len(edge_ids) == 0:
        return _empty(near_points=near_count, seams=n_seams)
    # θ grows from face 0 into the air: e = t0 × n0.
    e = np.cross(t0, n0)
    e /= np.linalg.norm(e, axis=1)[:, None]
    p0, p1 = a[edge_ids], b[edge_ids]
    flip = np.einsum("ij,ij->i", p1 - p0, e) < 0
    p0, p1 = np.where(flip[:, None], p1, p0), np.where(flip[:, None], p0, p1)

    groups = _merge_collinear(uniq[edge_ids], p0, e, t0, tw)
    out_start, out_end, out_e, out_t, out_tw, out_faces = [], [], [], [], [], []
    for members in groups:
        m0 = members[0]
        s = np.einsum("ij,j->i", np.concatenate([p0[members], p1[members]]) - p0[m0], e[m0])
        out_start.append(p0[m0] + s.min() * e[m0])
        out_end.append(p0[m0] + s.max() * e[m0])
        out_e.append(e[m0])
        out_t.append(t0[m0])
        out_tw.append(tw[m0])
        out_faces.append(face_pair[m0])
    start, end = np.array(out_start), np.array(out_end)
    lengths = np.linalg.norm(end - start, axis=1)
    keep = np.flatnonzero(lengths >= min_length_m)
    found = DiffractingEdges(start[keep], end[keep], np.array(out_e)[keep],
                             np.array(out_t)[keep], np.array(out_tw)[keep],
                             np.array(out_faces, np.int64)[keep], len(keep), None, 0, n_seams)
    # most important first; equal scores by position, so the choice depends on the geometry
    # only, not on how the mesh's vertices and faces happen to be numbered
    return found.ranked(max_edges, near_m)


def _overlapped(a: np.ndarray, b: np.ndarray, tolerance_m: float) -> np.ndarray:
    """Which segments ``a[i]–b[i]`` another segment of the set overlaps along a length.

    Two overlapping segments lie on one line and one's midpoint lies inside the other (the
    shorter's inside the longer), so each segment's ball (its midpoint, half its length plus
    the tolerance) is searched for the other midpoints, and every candidate is checked: its
    midpoint on the segment's line within ``tolerance_m``, strictly inside its extent, and
    the two parallel."""
    n = len(a)
    if n < 2:
        return np.zeros(n, bool)
    from scipy.spatial import cKDTree

    mid = 0.5 * (a + b)
    axis = b - a
    length = np.linalg.norm(axis, axis=1)
    unit = axis / np.maximum(length, 1e-300)[:, None]
    balls = cKDTree(mid).query_ball_point(mid, 0.5 * length + tolerance_m)
    sizes = np.fromiter(map(len, balls), np.int64, n)
    i = np.repeat(np.arange(n), sizes)
    j = np.fromiter((k for ball in balls for k in ball), np.int64, int(sizes.sum()))
    other = i != j
    i, j = i[other], j[other]
    rel = mid[j] - a[i]
    along = np.einsum("ij,ij->i", rel, unit[i])
    across = np.linalg.norm(rel - along[:, None] * unit[i], axis=1)
    parallel = np.abs(np.einsum("ij,ij->i", unit[i], unit[j])) > _PARALLEL_COS
    hit = (parallel & (across <= tolerance_m) & (along > tolerance_m)
           & (along < length[i] - tolerance_m))
    out = np.zeros(n, bool)
    out[i[hit]] = True
    out[j[hit]] = True
    return out


def _merge_collinear(pairs: np.ndarray, p0: np.ndarray, e: np.ndarray, t0: np.ndarray,
                     tw: np.ndarray) -> list[np.ndarray]:
    """Groups of segments that share a vertex, lie on one line and join the same two planes."""
    n = len(pairs)
    parent = np.arange(n)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    by_vertex: dict[int, list[int]] = {}
    for i, (u, v) in enumerate(pairs.tolist()):
        by_vertex.setdefault(u, []).append(i)
        by_vertex.setdefault(v, []).append(i)
    for members in by_vertex.values():
        for x in range(len(members)):
            for y in range(x + 1, len(members)):
                i, j = members[x], members[y]
                if (np.dot(e[i], e[j]) > _PARALLEL_COS and np.dot(t0[i], t0[j]) > _PARALLEL_COS
                        and abs(tw[i] - tw[j]) < 1e-3):
                    parent[find(i)] = find(j)
    roots = np.array([find(i) for i in range(n)])
    return [np.flatnonzero(roots == r) for r in np.unique(roots)]
