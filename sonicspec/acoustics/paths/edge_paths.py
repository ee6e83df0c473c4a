"""Edge-diffracted paths in a scene, as arrivals: source → edge → receiver, over two edges
(a door frame in a thick wall), and over one edge with one specular reflection before or
after it (the floor's reflection of a source round a corner), on the largest planar regions.

For every diffracting edge of the traced mesh (:mod:`~sonicspec.acoustics.paths.edges`) the path
over the edge is the one Keller's law makes stationary: its apex on the edge's line divides
the unfolded path in the ratio of the source's and receiver's distances from the line (for two
edges, the two apexes are found alternately, each the apex of its neighbours). A path exists
when both ends see their edge from the air side, the apex lies on the finite edge and every
leg is clear. Its amplitude is the
UTD band amplitude (:mod:`~sonicspec.acoustics.paths.diffraction`) with the faces' specular
reflection factors, times the air's ``exp(−m L / 2)``; its direction of arrival points from
the receiver to the last apex, so directional receivers weight it like any other arrival.

Paths are kept on the lit side too: there the diffracted wave is what cancels half of the
direct sound (or of a face's reflection) at the boundary, so the total stays continuous when a
source walks out of sight.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from sonicspec.acoustics.arrivals import KIND_DIFFRACTED, Arrivals
from sonicspec.acoustics.paths.diffraction import (
    first_order_band_amplitudes,
    second_order_band_amplitudes,
)
from sonicspec.acoustics.paths.edges import DiffractingEdges
from sonicspec.acoustics.paths.image_sources import PlanarRegions, planar_regions
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S

__all__ = ["MAX_PAIR_DISTANCE_M", "REFLECTORS", "close_pairs", "diffracted_sound"]

#: Second-order pairs are edges whose segments come this close (m): a door frame's jambs, a
#: thick wall's corners, a cupboard's two front edges. Farther pairs are left to first order.
MAX_PAIR_DISTANCE_M = 1.0
_SOURCE_CHUNK = 32
_APEX_ITERATIONS = 12  # exact after one for parallel edges; skew ones converge linearly
_ON_EDGE_TOL_M = 1e-6
#: Planar regions (the largest) whose reflections are bent round edges: the floor, the
#: ceiling and the big walls carry the strong first reflections.
REFLECTORS = 12


def _cylindrical(edges: DiffractingEdges, idx: np.ndarray, x: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r, θ, z)`` of points ``x`` about edges ``idx`` (broadcast), z from the edge start."""
    r, z, radial = _radial(edges, idx, x)
    e, f0 = edges.direction[idx], edges.face0[idx]
    th = np.arctan2(np.einsum("...i,...i->...", np.cross(f0, radial), e),
                    np.einsum("...i,...i->...", f0, radial)) % (2 * math.pi)
    th = np.where(th > 2 * math.pi - 1e-9, 0.0, th)  # on face 0's plane, from the air side
    return r, th, z


def _radial(edges: DiffractingEdges, idx: np.ndarray, x: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r, z, radial vector)`` of points ``x`` about edges ``idx``: :func:`_cylindrical`
    without the angle."""
    d = x - edges.start[idx]
    e = edges.direction[idx]
    z = np.einsum("...i,...i->...", d, e)
    radial = d - z[..., None] * e
    return np.linalg.norm(radial, axis=-1), z, radial


def _apex(edges: DiffractingEdges, idx: np.ndarray, a: np.ndarray, b: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """The stationary point on edge ``idx``'s line of a path a → edge → b; and its z."""
    ra, za, _ = _radial(edges, idx, a)
    rb, zb, _ = _radial(edges, idx, b)
    z = za + (zb - za) * ra / np.maximum(ra + rb, 1e-300)
    return edges.start[idx] + z[..., None] * edges.direction[idx], z


def _bisector(edges: DiffractingEdges, idx: np.ndarray) -> np.ndarray:
    half = edges.open_angle[idx][..., None] / 2
    f0, e = edges.face0[idx], edges.direction[idx]
    return np.cos(half) * f0 + np.sin(half) * np.cross(e, f0)


def _face_reflection(scene: AcousticScene, edges: DiffractingEdges) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """Pressure reflection factor ``√((1 − τ)(1 − α)(1 − s))`` of each edge's two faces (the
    specular share, as for image sources); a sheet's rim reflects alike on both sides."""
    def factor(face: np.ndarray) -> np.ndarray:
        return np.sqrt((1 - scene.transmission[face]) * (1 - scene.absorption[face])
                       * (1 - scene.scattering[face]))
    f0 = edges.faces[:, 0]
    f1 = np.where(edges.faces[:, 1] >= 0, edges.faces[:, 1], f0)
    return factor(f0), factor(f1)


def close_pairs(edges: DiffractingEdges, max_distance_m: float | None = None) -> np.ndarray:
    """``(p, 2)`` ordered pairs of distinct edges that a path can take one after the other:
    segments within ``max_distance_m`` (default :data:`MAX_PAIR_DISTANCE_M`) and each in
    front of the other (some point of edge 2 on edge 1's air side, and the reverse)."""
    max_distance_m = MAX_PAIR_DISTANCE_M if max_distance_m is None else max_distance_m
    m = len(edges)
    if m < 2:
        return np.zeros((0, 2), np.int64)
    lo = np.minimum(edges.start, edges.end) - max_distance_m
    hi = np.maximum(edges.start, edges.end) + max_distance_m
    i, j = np.triu_indices(m, 1)
    boxes = np.all((lo[i] <= np.maximum(edges.start[j], edges.end[j]))
                   & (np.minimum(edges.start[j], edges.end[j]) <= hi[i]), axis=1)
    i, j = i[boxes], j[boxes]
    t = np.linspace(0, 1, 9)
    pts = edges.start[:, None] + t[None, :, None] * (edges.end - edges.start)[:, None]
    # the closest pair of sample points, less half a sample step of each: a lower bound
    gap = np.linalg.norm(pts[i][:, :, None] - pts[j][:, None, :], axis=-1).min(axis=(1, 2))
    slack = (edges.length_m[i] + edges.length_m[j]) / 16
    close = gap - slack <= max_distance_m
    i, j = i[close], j[close]

    def in_front(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Some sample point of edge b (off its ends) on edge a's air side."""
        inner = pts[b][:, 1:-1]
        r, th, _ = _cylindrical(edges, a[:, None], inner)
        return np.any((r > _ON_EDGE_TOL_M) & (th <= edges.open_angle[a][:, None]), axis=1)

    both = in_front(i, j) & in_front(j, i)
    i, j = i[both], j[both]
    return np.concatenate([np.column_stack([i, j]), np.column_stack([j, i])])


def diffracted_sound(
    scene: AcousticScene,
    edges: DiffractingEdges,
    sources: np.ndarray,
    receiver: np.ndarray,
    bands_hz,
    air_m_per_band: np.ndarray | None = None,
    speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S,
    second_order: bool = True,
    reflections: bool = True,
    regions: PlanarRegions | None = None,
    pairs: np.ndarray | None = None,
) -> list[Arrivals]:
    """Edge-diffracted arrivals at ``receiver`` from every source position.

    Parameters
    ----------
    scene : AcousticScene
        The traced scene (visibility, materials).
    edges : DiffractingEdges
        Its diffracting edges (:func:`~sonicspec.acoustics.paths.edges.diffracting_edges`).
    sources : (N, 3) float
        Source positions, metres.
    receiver : (3,) float
        Receiver position, metres.
    bands_hz : sequence of float
        Octave band centres (as many as the scene's bands).
    air_m_per_band : (n_bands,) float, optional
        Air energy attenuation per metre; None: none.
    speed_of_sound_m_s : float
        Speed of sound.
    second_order : bool
        Add paths over two edges (pairs closer than :data:`MAX_PAIR_DISTANCE_M`).
    reflections : bool
        Add paths over one edge with one specular reflection before or after it, on the
        :data:`REFLECTORS` largest planar regions.
    regions : PlanarRegions, optional
        The scene's planar regions, when the caller has them.
    pairs : (p, 2) int, optional
        :func:`close_pairs` of ``edges``, when the caller keeps them.

    Returns
    -------
    list of Arrivals
        One per source, kind ``KIND_DIFFRACTED``, order the edges plus reflections, amplitudes
        for a unit point source (free field ``1/(4πr)``).
    """
    from sonicspec.acoustics.paths.direct import check_air, check_points

    sources = check_points("sources", sources)
    receiver = check_points("receiver", receiver)
    if len(receiver) != 1:
        raise AcousticsError(f"receiver: expected one position, got {len(receiver)}")
    bands = tuple(float(b) for b in bands_hz)
    if len(bands) != scene.n_bands:
        raise AcousticsError(f"bands_hz: expected {scene.n_bands} bands like the scene, got "
                             f"{len(bands)}")
    air = check_air(air_m_per_band, scene.n_bands)
    c = speed_of_sound_m_s
    parts: list[list[Arrivals]] = [[] for _ in range(len(sources))]
    if len(edges) == 0:
        return [Arrivals.empty(scene.n_bands) for _ in sources]
    refl0, refl1 = _face_reflection(scene, edges)
    reflectors = np.zeros(0, np.int64)
    if reflections:
        regions = regions if regions is not None else planar_regions(scene)
        area = np.zeros(regions.n_regions)
        np.add.at(area, regions.face_region, scene.face_areas_m2)
        reflectors = np.argsort(-area, kind="stable")[:REFLECTORS]
    if second_order:
        pairs = close_pairs(edges) if pairs is None else pairs
    # Sources in chunks: the candidate arrays grow as sources × edges (× pairs, × planes).
    for lo in range(0, len(sources), _SOURCE_CHUNK):
        chunk = sources[lo:lo + _SOURCE_CHUNK]
        sub: list[list[Arrivals]] = parts[lo:lo + _SOURCE_CHUNK]
        _first_order(scene, edges, chunk, receiver[0], bands, air, c, refl0, refl1, sub)
        if len(reflectors):
            _reflected_first_order(scene, edges, regions, reflectors, chunk, receiver[0],
                                   bands, air, c, refl0, refl1, sub)
        if second_order:
            _second_order(scene, edges, pairs, chunk, receiver[0], bands, air, c, refl0,
                          refl1, sub)
    return [Arrivals.concatenate(p) if p else Arrivals.empty(scene.n_bands) for p in parts]


def _legs_clear(scene: AcousticScene, points: list[np.ndarray]) -> np.ndarray:
    """Whether every leg of the polylines ``points[0] → points[1] → …`` is clear, ``(n,)``.

    A leg through a transmitting wall does not count: sound through the wall is the direct
    path's (``direct_sound``), and an edge heard through a wall is weaker than both."""
    out = np.ones(len(points[0]), dtype=bool)
    for a, b in itertools.pairwise(points):
        idx = np.flatnonzero(out)
        out[idx] = ~scene.occluded(a[idx], b[idx])
    return out


# Arrivals.path_id of a diffracted path: its kind and its edges and reflector, 20 bits each.
_FIRST, _REFLECTED_BEFORE, _REFLECTED_AFTER, _SECOND = 1, 2, 3, 4
_ID_BITS = 20


def path_ids(kind: int, edge1: np.ndarray, edge2: np.ndarray | None = None,
             region=None) -> np.ndarray:
    """The :attr:`~sonicspec.acoustics.arrivals.Arrivals.path_id` of diffracted paths: the
    same for one geometric path (its edges, its reflector) wherever its ends are."""
    e1 = np.asarray(edge1, dtype=np.int64)
    e2 = np.full_like(e1, -1) if edge2 is None else np.asarray(edge2, dtype=np.int64)
    r = np.full_like(e1, -1) if region is None else np.broadcast_to(
        np.asarray(region, dtype=np.int64), e1.shape)
    if e1.size and (max(e1.max(), e2.max(), r.max()) + 1 >= 1 << _ID_BITS):
        raise AcousticsError(f"edges: path ids hold at most {1 << _ID_BITS} edges and regions")
    return (kind + 8 * (e1 + 1) + (8 << _ID_BITS) * (e2 + 1)
            + (8 << 2 * _ID_BITS) * (r + 1)).astype(np.int64)


def _arrivals(source_idx, lengths, amp, apex_last, receiver, air, c, order, parts,
              ids: np.ndarray, reflections: int = 0, sources=None, first=None) -> None:
    """``first``: the first point after the source (apex or reflection point), for the
    direction the path leaves ``sources[source_idx]`` in (a directional source)."""
    amp = amp * np.exp(-0.5 * air[None, :] * lengths[:, None])
    direction = apex_last - receiver[None]
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    departure = np.zeros_like(direction)
    if first is not None:
        departure = first - sources[source_idx]
        departure /= np.maximum(np.linalg.norm(departure, axis=1), 1e-300)[:, None]
    for k in np.unique(source_idx):
        sel = source_idx == k
        parts[k].append(Arrivals(
            times_s=lengths[sel] / c, amplitudes=amp[sel], directions=direction[sel],
            order=np.full(int(sel.sum()), order + reflections, dtype=np.int64),
            kind=np.full(int(sel.sum()), KIND_DIFFRACTED, dtype=np.int8),
            path_length_m=lengths[sel], path_id=ids[sel], departures=departure[sel]))


def _over_edges(edges: DiffractingEdges, a: np.ndarray, b: np.ndarray, lift_m: float
                ) -> dict[str, np.ndarray]:
    """Every (point pair, edge) whose path ``a → edge → b`` is geometrically possible: both
    ends on the air side of the wedge, the stationary apex on the finite edge."""
    n, m = len(a), len(edges)
    pair, edge_i = np.repeat(np.arange(n), m), np.tile(np.arange(m), n)
    r_s, th_s, z_s = _cylindrical(edges, edge_i, a[pair])
    r_r, th_r, z_r = _cylindrical(edges, edge_i, b[pair])
    tw = edges.open_angle[edge_i]
    z_a = z_s + (z_r - z_s) * r_s / np.maximum(r_s + r_r, 1e-300)
    ok = ((r_s > _ON_EDGE_TOL_M) & (r_r > _ON_EDGE_TOL_M) & (th_s <= tw) & (th_r <= tw)
          & (z_a >= -_ON_EDGE_TOL_M) & (z_a <= edges.length_m[edge_i] + _ON_EDGE_TOL_M))
    out = {"pair": pair, "edge": edge_i, "r_s": r_s, "th_s": th_s, "z_s": z_s, "r_r": r_r,
           "th_r": th_r, "z_r": z_r, "tw": tw, "z_a": z_a}
    out = {k: v[ok] for k, v in out.items()}
    out["apex"] = edges.start[out["edge"]] + out["z_a"][:, None] * edges.direction[out["edge"]]
    out["lifted"] = out["apex"] + lift_m * _bisector(edges, out["edge"])
    return out


def _amplitudes(cand: dict[str, np.ndarray], sel: np.ndarray, bands, c, refl0, refl1
                ) -> tuple[np.ndarray, np.ndarray]:
    e = cand["edge"][sel]
    return first_order_band_amplitudes(
        cand["r_s"][sel], cand["th_s"][sel], cand["r_r"][sel], cand["th_r"][sel],
        cand["z_r"][sel] - cand["z_s"][sel], cand["tw"][sel], bands, c, refl0[e], refl1[e])


def _first_order(scene, edges, sources, receiver, bands, air, c, refl0, refl1, parts) -> None:
    cand = _over_edges(edges, sources, np.broadcast_to(receiver, sources.shape), 4 * scene.eps_m)
    if len(cand["edge"]) == 0:
        return
    src = sources[cand["pair"]]
    sel = np.flatnonzero(_legs_clear(scene, [src, cand["lifted"],
                                             np.broadcast_to(receiver, src.shape)]))
    if len(sel) == 0:
        return
    amp, length = _amplitudes(cand, sel, bands, c, refl0, refl1)
    _arrivals(cand["pair"][sel], length, amp, cand["apex"][sel], receiver, air, c, 1, parts,
              path_ids(_FIRST, cand["edge"][sel]), sources=sources, first=cand["apex"][sel])


def _on_region(scene: AcousticScene, regions, region: np.ndarray, origin: np.ndarray,
               target: np.ndarray) -> np.ndarray:
    """Whether the first surface from ``origin`` towards ``target`` is region ``region`` (one
    per row, or one for all), hit at ``target`` (the reflection point lies on the region and
    the leg to it is clear)."""
    vec = target - origin
    dist = np.linalg.norm(vec, axis=1)
    face, hit = scene.intersect(origin, vec / np.maximum(dist, 1e-300)[:, None])
    return ((face >= 0) & (regions.face_region[np.maximum(face, 0)] == region)
            & (np.abs(hit - dist) < 1e-6 + 4 * scene.eps_m))


def _reflected_first_order(scene, edges, regions, reflectors, sources, receiver, bands, air,
                           c, refl0, refl1, parts) -> None:
    """Paths with one specular reflection before or after the edge (its image-source path
    bent into the shadow: what keeps a floor reflection continuous where an edge hides it).

    (a) source → reflector → edge → receiver: the image source over the edge; (b) source →
    edge → reflector → receiver: the edge seen in the reflector. Every reflector's candidates
    go through each test together (one Embree call per test, one amplitude evaluation), in
    rows ordered by reflector, source and edge."""
    normals, plane_d = regions.normals[reflectors], regions.plane_d[reflectors]
    gains = np.sqrt(regions.reflection_energy[reflectors])
    live = np.any(gains > 0, axis=1)
    rcv_front = receiver @ normals.T - plane_d > _ON_EDGE_TOL_M  # (R,)
    # (a): every (reflector, source in front of it) pair, the source mirrored in it
    src_side = sources @ normals.T - plane_d[None, :]  # (S, R)
    refl_a, src_a = np.nonzero((src_side > _ON_EDGE_TOL_M).T & (live & rcv_front)[:, None])
    image = _mirror_rows(sources[src_a], normals[refl_a], plane_d[refl_a])
    cand = _over_edges(edges, image, np.broadcast_to(receiver, image.shape), 4 * scene.eps_m)
    row = cand["pair"]
    ok, point = _plane_point_rows(image[row], cand["apex"], normals[refl_a[row]],
                                  plane_d[refl_a[row]])
    keep = np.flatnonzero(ok)
    point = point[keep]
    on = _on_region(scene, regions, reflectors[refl_a[row[keep]]], sources[src_a[row[keep]]],
                    point)
    keep, point = keep[on], point[on]
    lifted_point = point + scene.eps_m * normals[refl_a[row[keep]]]
    clear = _legs_clear(scene, [lifted_point, cand["lifted"][keep],
                                np.broadcast_to(receiver, lifted_point.shape)])
    keep = keep[clear]
    found = [(refl_a[row[keep]], 0, src_a[row[keep]], cand, keep, cand["apex"][keep],
              point[clear])]
    # (b): every (reflector, source) pair, the receiver mirrored in the reflector
    refl_b = np.flatnonzero(live & rcv_front)
    image_r = _mirror_rows(np.broadcast_to(receiver, (len(refl_b), 3)), normals[refl_b],
                           plane_d[refl_b])
    refl_b, src_b = np.repeat(refl_b, len(sources)), np.tile(np.arange(len(sources)),
                                                              len(refl_b))
    image_b = np.repeat(image_r, len(sources), axis=0)
    cand = _over_edges(edges, sources[src_b], image_b, 4 * scene.eps_m)
    row = cand["pair"]
    ok, point = _plane_point_rows(cand["apex"], image_b[row], normals[refl_b[row]],
                                  plane_d[refl_b[row]])
    keep = np.flatnonzero(ok)
    point = point[keep]
    on = _on_region(scene, regions, reflectors[refl_b[row[keep]]],
                    np.broadcast_to(receiver, point.shape), point)
    keep, point = keep[on], point[on]
    clear = _legs_clear(scene, [sources[src_b[row[keep]]], cand["lifted"][keep],
                                point + scene.eps_m * normals[refl_b[row[keep]]]])
    keep, point = keep[clear], point[clear]
    found.append((refl_b[row[keep]], 1, src_b[row[keep]], cand, keep, point,
                  cand["apex"][keep]))
    # One amplitude evaluation for both kinds; arrivals by reflector, (a) before (b).
    amps, lengths = [], []
    for refl, _, _, cand, keep, _, _ in found:
        if len(keep) == 0:
            amps.append(np.zeros((0, len(bands))))
            lengths.append(np.zeros(0))
            continue
        amp, length = _amplitudes(cand, keep, bands, c, refl0, refl1)
        amps.append(amp * gains[refl])
        lengths.append(length)
    ids = [path_ids(_REFLECTED_AFTER if kind else _REFLECTED_BEFORE, cand["edge"][keep],
                    region=reflectors[refl]) for refl, kind, _, cand, keep, _, _ in found]
    refl = np.concatenate([f[0] for f in found])
    if len(refl) == 0:
        return
    order = np.lexsort((np.concatenate([np.full(len(f[0]), f[1]) for f in found]), refl))
    _arrivals(np.concatenate([f[2] for f in found])[order], np.concatenate(lengths)[order],
              np.concatenate(amps)[order], np.concatenate([f[5] for f in found])[order],
              receiver, air, c, 1, parts, np.concatenate(ids)[order], reflections=1,
              sources=sources, first=np.concatenate([f[6] for f in found])[order])


def _mirror_rows(points: np.ndarray, normals: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Each point mirrored in its own plane ``normals[i]·x = d[i]``."""
    side = np.einsum("ij,ij->i", points, normals) - d
    return points - 2 * side[:, None] * normals


def _plane_point_rows(a: np.ndarray, b: np.ndarray, normals: np.ndarray, d: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Where segments ``a → b`` cross each row's plane ``normals[i]·x = d[i]`` (strictly
    inside), and whether."""
    da = np.einsum("ij,ij->i", a, normals) - d
    db = np.einsum("ij,ij->i", b, normals) - d
    denom = np.where(np.abs(da - db) > 1e-300, da - db, 1.0)
    t = da / denom
    ok = (da * db < 0) & (t > 0) & (t < 1)
    return ok, a + t[:, None] * (b - a)


def _second_order(scene, edges, pairs, sources, receiver, bands, air, c, refl0, refl1, parts
                  ) -> None:
    if len(pairs) == 0:
        return
    # the source on edge 1's air side, the receiver on edge 2's
    r_in, th_in, _ = _cylindrical(edges, pairs[None, :, 0], sources[:, None, :])
    r_out, th_out, _ = _cylindrical(edges, pairs[:, 1], receiver[None])
    ok = ((r_in > _ON_EDGE_TOL_M) & (th_in <= edges.open_angle[pairs[:, 0]][None])
          & ((r_out > _ON_EDGE_TOL_M) & (th_out <= edges.open_angle[pairs[:, 1]]))[None])
    src_i, pair_i = np.nonzero(ok)
    if len(src_i) == 0:
        return
    e1, e2 = pairs[pair_i, 0], pairs[pair_i, 1]
    s = sources[src_i]
    r = np.broadcast_to(receiver, s.shape)
    a2 = 0.5 * (edges.start[e2] + edges.end[e2])
    a1, z1, z2 = np.empty_like(a2), np.empty(len(a2)), np.empty(len(a2))
    live = np.arange(len(a2))
    for _ in range(_APEX_ITERATIONS):
        # A path whose second apex did not move is at its fixed point: later rounds would
        # give it the same apexes, so it leaves the iteration (parallel edges: after one).
        b1, y1 = _apex(edges, e1[live], s[live], a2[live])
        b2, y2 = _apex(edges, e2[live], b1, r[live])
        moved = np.any(b2 != a2[live], axis=1)
        a1[live], z1[live], a2[live], z2[live] = b1, y1, b2, y2
        live = live[moved]
        if not live.size:
            break
    _, th_in1, _ = _cylindrical(edges, e1, s)
    _, th_out1, _ = _cylindrical(edges, e1, a2)
    _, th_in2, _ = _cylindrical(edges, e2, a1)
    _, th_out2, _ = _cylindrical(edges, e2, r)
    tw1, tw2 = edges.open_angle[e1], edges.open_angle[e2]
    s1 = np.linalg.norm(a1 - s, axis=1)
    d12 = np.linalg.norm(a2 - a1, axis=1)
    s2 = np.linalg.norm(r - a2, axis=1)
    tol = _ON_EDGE_TOL_M
    ok = ((th_in1 <= tw1) & (th_out1 <= tw1) & (th_in2 <= tw2) & (th_out2 <= tw2)
          & (z1 >= -tol) & (z1 <= edges.length_m[e1] + tol)
          & (z2 >= -tol) & (z2 <= edges.length_m[e2] + tol)
          & (s1 > tol) & (d12 > tol) & (s2 > tol))
    if not np.any(ok):
        return
    sel = np.flatnonzero(ok)
    lift1 = a1[sel] + 4 * scene.eps_m * _bisector(edges, e1[sel])  # off the faces
    lift2 = a2[sel] + 4 * scene.eps_m * _bisector(edges, e2[sel])
    sel = sel[_legs_clear(scene, [s[sel], lift1, lift2, r[sel]])]
    if len(sel) == 0:
        return

    def sin_beta(edge_idx: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        v = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
        return np.sqrt(np.clip(1 - np.einsum("ij,ij->i", v, edges.direction[edge_idx])**2,
                               1e-12, 1))

    amp = second_order_band_amplitudes(
        s1[sel], d12[sel], s2[sel], sin_beta(e1[sel], s[sel], a1[sel]),
        sin_beta(e2[sel], a2[sel], r[sel]), tw1[sel], th_in1[sel], th_out1[sel], tw2[sel],
        th_in2[sel], th_out2[sel], bands, c,
        (refl0[e1[sel]], refl1[e1[sel]], refl0[e2[sel]], refl1[e2[sel]]))
    length = s1[sel] + d12[sel] + s2[sel]
    _arrivals(src_i[sel], length, amp, a2[sel], receiver, air, c, 2, parts,
              path_ids(_SECOND, e1[sel], e2[sel]), sources=sources, first=a1[sel])
