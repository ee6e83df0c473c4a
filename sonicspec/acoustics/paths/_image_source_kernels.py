"""Compiled loops of the image-source method (numba, GIL released).

* Point-in-region test: backtracking a path checks each reflection point against the
  triangles of its planar region. In numpy that was one group of array operations per
  distinct region; a furnished scan has thousands of small regions (every box side, every
  table top), so the loop over them, not the arithmetic, was half the cost of an order-2
  pass. Here each point tests its own region's triangles, with the same barycentric formulas
  in the same order.
* A prefilter of each order's (image, receiver) pairs: in a scan most of an order's ~10⁵
  pairs fail at their last reflection; one loop drops them (never a valid one: every test is
  loosened by a slack) before the exact array tests run on the rest.
* The candidate count that stops an order too large to build: it counts pairs until the
  limit is passed, without the (images × regions) masks.
* The next order's candidate images themselves, written row by row in (parent, region)
  order: the numpy version built (images × regions) distance and mask arrays, then images,
  then their distances to every receiver, for a few percent of the pairs kept.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _in_region(px, py, pz, p, region_start, region_faces, faces, vertices, tol
               ):  # pragma: no cover - compiled; via image_sources
    """Whether point (px, py, pz) lies within ``tol`` (barycentric units) of one of region
    ``p``'s triangles."""
    for j in range(region_start[p], region_start[p + 1]):
        f = region_faces[j]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ax, ay, az = vertices[a, 0], vertices[a, 1], vertices[a, 2]
        v0x, v0y, v0z = vertices[b, 0] - ax, vertices[b, 1] - ay, vertices[b, 2] - az
        v1x, v1y, v1z = vertices[c, 0] - ax, vertices[c, 1] - ay, vertices[c, 2] - az
        v2x, v2y, v2z = px - ax, py - ay, pz - az
        d00 = v0x * v0x + v0y * v0y + v0z * v0z
        d01 = v0x * v1x + v0y * v1y + v0z * v1z
        d11 = v1x * v1x + v1y * v1y + v1z * v1z
        d20 = v2x * v0x + v2y * v0y + v2z * v0z
        d21 = v2x * v1x + v2y * v1y + v2z * v1z
        den = d00 * d11 - d01 * d01
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        if v >= -tol and w >= -tol and v + w <= 1.0 + tol:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _outside_box(px, py, pz, box, margin):  # pragma: no cover - compiled
    return (px < box[0, 0] - margin or py < box[0, 1] - margin or pz < box[0, 2] - margin
            or px > box[1, 0] + margin or py > box[1, 1] + margin or pz > box[1, 2] + margin)


# error_model="numpy": a degenerate triangle (den = 0) gives NaN, never inside, as in numpy.
@njit(cache=True, nogil=True, error_model="numpy")
def inside_small_regions(points, region, rows, boxes, region_start, region_faces, faces,
                         vertices, tol, inside):  # pragma: no cover - compiled; via image_sources
    """Sets ``inside[i]`` for every row ``i`` in ``rows``: whether ``points[i]`` (on the plane
    of ``region[i]``) lies within ``tol`` of one of that region's triangles (barycentric).

    ``boxes[p]`` (lower and upper corner) encloses region ``p`` with a margin: a point outside
    it is outside every triangle (most backtracked points are), so they are skipped.
    """
    for i in rows:
        p = region[i]
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        if _outside_box(px, py, pz, boxes[p], 0.0):
            inside[i] = False
            continue
        inside[i] = _in_region(px, py, pz, p, region_start, region_faces, faces, vertices, tol)


# Slack of the prefilter below: it must never drop a pair the exact test keeps, so every
# comparison is loosened by far more than the rounding differences between its scalar
# arithmetic and numpy's (~1e-15 relative).
_SLACK_M = 1e-7
_SLACK_T = 1e-9
_SLACK_BARY = 1e-6


@njit(cache=True, nogil=True, error_model="numpy")
def last_reflection_prefilter(receivers, image, plane, side, normals, plane_d, eps, max_len,
                              boxes, region_start, region_faces, faces, vertices,
                              max_triangles, keep):  # pragma: no cover - via image_sources
    """A superset of the (image, receiver) pairs of one order whose last reflection is valid:
    ``keep[i * n_receivers + r]`` (the order of ``np.repeat`` / ``np.tile``) unless receiver
    ``r`` is behind image ``i``'s last plane, the path is longer than ``max_len`` (< 0: no
    limit), or the segment from the receiver to the image misses the plane or meets it
    outside its region (regions of more than ``max_triangles`` triangles: not tested here).
    Every test is the exact one loosened by a slack, so the exact pass that follows decides
    alone; most candidates of a scan fail here, in one compiled loop instead of a dozen
    array operations over all of them."""
    n_rcv = receivers.shape[0]
    for i in range(image.shape[0]):
        p = plane[i]
        nx, ny, nz, dp = normals[p, 0], normals[p, 1], normals[p, 2], plane_d[p]
        sgn = 1.0 if side[i] == 0 else -1.0
        ix, iy, iz = image[i, 0], image[i, 1], image[i, 2]
        big = region_start[p + 1] - region_start[p] > max_triangles
        for r in range(n_rcv):
            k = i * n_rcv + r
            keep[k] = False
            xx, xy, xz = receivers[r, 0], receivers[r, 1], receivers[r, 2]
            x_dist = xx * nx + xy * ny + xz * nz - dp
            if x_dist * sgn <= eps - _SLACK_M:
                continue
            vx, vy, vz = ix - xx, iy - xy, iz - xz
            if max_len >= 0.0 and math.sqrt(vx * vx + vy * vy + vz * vz) > max_len + _SLACK_M:
                continue
            den = vx * nx + vy * ny + vz * nz
            if den == 0.0:
                keep[k] = True  # undecided here
                continue
            t = -x_dist / den
            if t <= -_SLACK_T or t >= 1.0 + _SLACK_T:
                continue
            if big:
                keep[k] = True
                continue
            qx, qy, qz = xx + t * vx, xy + t * vy, xz + t * vz
            if _outside_box(qx, qy, qz, boxes[p], _SLACK_M):
                continue
            keep[k] = _in_region(qx, qy, qz, p, region_start, region_faces, faces, vertices,
                                 _SLACK_BARY)


@njit(cache=True, nogil=True, inline="always")
def _nearest(x, y, z, receivers):  # pragma: no cover - compiled
    """Distance from (x, y, z) to the nearest receiver (as numpy's norm computes it)."""
    best = math.inf
    for r in range(receivers.shape[0]):
        dx, dy, dz = x - receivers[r, 0], y - receivers[r, 1], z - receivers[r, 2]
        best = min(best, math.sqrt(dx * dx + dy * dy + dz * dz))
    return best


@njit(cache=True, nogil=True)
def more_candidates_than(last_pos, last_plane, side, normals, plane_d, tol, reach, receivers,
                         max_path_length_m, limit):  # pragma: no cover - via image_sources
    """Whether more than ``limit`` (parent image, region) pairs provably make candidates of
    the next order: off the region's plane by more than ``tol``, not the parent's own last
    region (``last_plane[i] < 0``: none), reachable from its side (``reach`` empty: all are),
    and — when ``max_path_length_m >= 0`` — provably within it (the parent's distance to its
    nearest receiver plus ``2|d|`` no longer than it; others are not counted). Stops counting
    once the limit is passed, so a scan's overflowing order costs its first ``limit`` pairs,
    not all of them. The loop over regions has no branch (each test adds 0 or 1), so it runs
    on vector units: a scan's 2 M pairs in under a millisecond."""
    count = 0
    check_reach = reach.shape[1] > 0
    n_p = normals.shape[0]
    nx, ny, nz = normals[:, 0].copy(), normals[:, 1].copy(), normals[:, 2].copy()
    for i in range(last_pos.shape[0]):
        x, y, z = last_pos[i, 0], last_pos[i, 1], last_pos[i, 2]
        own = last_plane[i]
        use_reach = check_reach and own >= 0
        s, row = side[i], max(own, 0)
        slack = max_path_length_m
        if max_path_length_m >= 0.0:
            slack = max_path_length_m - _nearest(x, y, z, receivers)
        n_ok = 0
        for p in range(n_p):
            d = abs(x * nx[p] + y * ny[p] + z * nz[p] - plane_d[p])
            ok = (p != own) & (d > tol)
            if use_reach:
                ok = ok & reach[s, row, p]
            if max_path_length_m >= 0.0:
                ok = ok & (2.0 * d <= slack)
            n_ok += ok
        count += n_ok
        if count > limit:
            return True
    return False


@njit(cache=True, nogil=True)
def next_order(last_pos, last_plane, side, normals, plane_d, tol, reach, receivers,
               max_path_length_m, limit, par, pln, pos, new_side):  # pragma: no cover
    """The next order's candidate images, in (parent, region) order: every pair off the
    region's plane by more than ``tol``, not the parent's own last region (``last_plane[i] <
    0``: none), reachable from its side (``reach`` empty: all are), and — when
    ``max_path_length_m >= 0`` — whose image is within it of the nearest receiver. Writes the
    parent, region, image and the side of the region the parent lies on (1: behind) to the
    output rows while they last; returns the number of candidates, or ``limit + 1`` as soon
    as there are more than ``limit`` (the outputs need ``limit`` rows)."""
    count = 0
    check_reach = reach.shape[1] > 0
    n_p = normals.shape[0]
    for i in range(last_pos.shape[0]):
        x, y, z = last_pos[i, 0], last_pos[i, 1], last_pos[i, 2]
        own = last_plane[i]
        for p in range(n_p):
            if p == own:
                continue
            if check_reach and own >= 0 and not reach[side[i], own, p]:
                continue
            d = x * normals[p, 0] + y * normals[p, 1] + z * normals[p, 2] - plane_d[p]
            if abs(d) <= tol:
                continue
            ix = x - 2.0 * d * normals[p, 0]
            iy = y - 2.0 * d * normals[p, 1]
            iz = z - 2.0 * d * normals[p, 2]
            if max_path_length_m >= 0.0 and _nearest(ix, iy, iz, receivers) > max_path_length_m:
                continue
            if count >= limit:
                return limit + 1
            par[count], pln[count] = i, p
            pos[count, 0], pos[count, 1], pos[count, 2] = ix, iy, iz
            new_side[count] = 1 if d < 0.0 else 0
            count += 1
    return count
