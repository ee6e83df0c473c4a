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
* Beam pruning of those candidates (``_in_beam``): sound reflected at region ``p`` leaves
  along the rays from the image through ``p``, so the next reflection can only be on a region
  that cone of rays meets. Each region is enclosed in a sphere; a candidate region whose
  sphere lies wholly outside the cone from the image round the last region's sphere, or
  outside the pyramid from the image through the last region's convex outline (widened by
  the outline's uncertainty, in proportion to the distance), can hold no valid reflection
  point, whatever comes after it (exact pruning: never a valid path).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Regions whose convex outline has more corners than this are pruned by their sphere alone.
_MAX_OUTLINE = 32


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


# Slack of the beam test in radians: it must never drop a region the exact test would keep.
_SLACK_ANGLE = 1e-9


@njit(cache=True, nogil=True, inline="always")
def _beam(x, y, z, own, spheres):  # pragma: no cover - compiled
    """The cone of rays from the image (x, y, z) through its last region ``own``'s bounding
    sphere: its unit axis and half-angle (radians); half-angle ``pi`` when there is no cone
    (``own < 0``: the source itself, or the image inside the sphere)."""
    if own < 0:
        return 0.0, 0.0, 0.0, math.pi
    ax, ay, az = spheres[own, 0] - x, spheres[own, 1] - y, spheres[own, 2] - z
    dist = math.sqrt(ax * ax + ay * ay + az * az)
    if dist <= spheres[own, 3]:
        return 0.0, 0.0, 0.0, math.pi
    return ax / dist, ay / dist, az / dist, math.asin(spheres[own, 3] / dist)


@njit(cache=True, nogil=True, inline="always")
def _in_beam(x, y, z, ax, ay, az, half, p, spheres):  # pragma: no cover - compiled
    """Whether region ``p``'s bounding sphere meets the cone from (x, y, z) with unit axis
    (ax, ay, az) and half-angle ``half`` (:func:`_beam`)."""
    if half >= math.pi:
        return True
    vx, vy, vz = spheres[p, 0] - x, spheres[p, 1] - y, spheres[p, 2] - z
    dist = math.sqrt(vx * vx + vy * vy + vz * vz)
    if dist <= spheres[p, 3]:
        return True
    cos_g = (vx * ax + vy * ay + vz * az) / dist
    gamma = math.acos(min(1.0, max(-1.0, cos_g)))
    return gamma <= half + math.asin(spheres[p, 3] / dist) + _SLACK_ANGLE


@njit(cache=True, nogil=True)
def _side_planes(x, y, z, own, hull_pts, hull_start, out):  # pragma: no cover - compiled
    """The inward unit normals of the faces of the pyramid from the image (x, y, z) through
    region ``own``'s convex outline (``hull_pts[hull_start[own]:hull_start[own+1]]``, in
    order, on its plane) into ``out``; returns how many (0: no pyramid)."""
    if own < 0:
        return 0
    a, b = hull_start[own], hull_start[own + 1]
    m = b - a
    if m < 3 or m > out.shape[0]:
        return 0
    mx = my = mz = 0.0
    for j in range(a, b):
        mx += hull_pts[j, 0] / m
        my += hull_pts[j, 1] / m
        mz += hull_pts[j, 2] / m
    n = 0
    for j in range(m):
        p0, p1 = a + j, a + (j + 1) % m
        ux, uy, uz = hull_pts[p0, 0] - x, hull_pts[p0, 1] - y, hull_pts[p0, 2] - z
        vx, vy, vz = hull_pts[p1, 0] - x, hull_pts[p1, 1] - y, hull_pts[p1, 2] - z
        cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        norm = math.sqrt(cx * cx + cy * cy + cz * cz)
        if norm == 0.0:
            continue
        cx, cy, cz = cx / norm, cy / norm, cz / norm
        if cx * (mx - x) + cy * (my - y) + cz * (mz - z) < 0.0:
            cx, cy, cz = -cx, -cy, -cz
        out[n, 0], out[n, 1], out[n, 2] = cx, cy, cz
        n += 1
    return n


@njit(cache=True, nogil=True, inline="always")
def _in_pyramid(x, y, z, planes, n_planes, reach_m, p, spheres):  # pragma: no cover
    """Whether region ``p``'s bounding sphere can hold a point of the pyramid (``planes``,
    :func:`_side_planes`) widened by ``reach_m`` per metre from its apex (x, y, z): the
    region's outline is known to ``margin``, and a point ``λ`` times as far as the outline
    moves ``λ`` times that."""
    cx, cy, cz, r = spheres[p, 0] - x, spheres[p, 1] - y, spheres[p, 2] - z, spheres[p, 3]
    far = math.sqrt(cx * cx + cy * cy + cz * cz) + r
    for j in range(n_planes):
        if planes[j, 0] * cx + planes[j, 1] * cy + planes[j, 2] * cz < -r - reach_m * far:
            return False
    return True


@njit(cache=True, nogil=True, inline="always")
def _heard(ix, iy, iz, d, p, normals, plane_d, receivers, spheres, eps
           ):  # pragma: no cover - compiled
    """Whether the last-order image (ix, iy, iz), mirrored in region ``p`` from a parent at
    signed distance ``d`` from its plane, can send a path to some receiver: the receiver on
    the parent's side by more than ``eps`` and the segment from it to the image crossing the
    plane within ``p``'s bounding sphere (the exact tests of the backtracking, loosened)."""
    nx, ny, nz, dp = normals[p, 0], normals[p, 1], normals[p, 2], plane_d[p]
    sgn = 1.0 if d >= 0.0 else -1.0
    for r in range(receivers.shape[0]):
        rx, ry, rz = receivers[r, 0], receivers[r, 1], receivers[r, 2]
        d_r = rx * nx + ry * ny + rz * nz - dp
        if d_r * sgn <= eps - _SLACK_M:
            continue
        t = d_r / (d_r + d)  # the image lies at -d
        qx, qy, qz = rx + t * (ix - rx), ry + t * (iy - ry), rz + t * (iz - rz)
        cx, cy, cz = qx - spheres[p, 0], qy - spheres[p, 1], qz - spheres[p, 2]
        if math.sqrt(cx * cx + cy * cy + cz * cz) <= spheres[p, 3] + _SLACK_M:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _audible(x, y, z, gain, receivers, direct_m):  # pragma: no cover - compiled
    """The most any path through the image (x, y, z) can reach a receiver with, relative to
    the free-field direct sound there: ``gain`` (its reflections' product, bounded over the
    bands) times ``direct / length`` for the receiver where that is largest (a later path is
    never shorter than the image's distance, nor its reflections' product larger)."""
    best = 0.0
    for r in range(receivers.shape[0]):
        dx, dy, dz = x - receivers[r, 0], y - receivers[r, 1], z - receivers[r, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        best = max(best, gain * direct_m[r] / max(length, 1e-12))
    return best


@njit(cache=True, nogil=True)
def more_candidates_than(last_pos, last_plane, side, normals, plane_d, tol, reach, receivers,
                         max_path_length_m, limit, spheres, gain, floor, direct_m, hull_pts,
                         hull_start, margin, last, eps):  # pragma: no cover - via image_sources
    """Whether more than ``limit`` (parent image, region) pairs provably make candidates of
    the next order: off the region's plane by more than ``tol``, not the parent's own last
    region (``last_plane[i] < 0``: none), reachable from its side (``reach`` empty: all are),
    and — when ``max_path_length_m >= 0`` — provably within it (the parent's distance to its
    nearest receiver plus ``2|d|`` no longer than it; others are not counted); with ``spheres``
    (``(P, 4)``: centre, radius; none when empty) only regions in the parent's beam count, and
    with ``floor > 0`` only audible parents, with ``last`` only heard images (see
    :func:`next_order`). Stops counting once the
    limit is passed, so a scan's overflowing order costs its first ``limit`` pairs, not all
    of them. The loop over regions has no
    branch (each test adds 0 or 1), so it runs on vector units when there are no spheres."""
    count = 0
    check_reach = reach.shape[1] > 0
    n_p = normals.shape[0]
    nx, ny, nz = normals[:, 0].copy(), normals[:, 1].copy(), normals[:, 2].copy()
    use_beam = spheres.shape[0] > 0
    planes = np.empty((_MAX_OUTLINE, 3))
    for i in range(last_pos.shape[0]):
        x, y, z = last_pos[i, 0], last_pos[i, 1], last_pos[i, 2]
        if floor > 0.0 and _audible(x, y, z, gain[i], receivers, direct_m) < floor:
            continue
        own = last_plane[i]
        n_planes, reach_m = 0, 0.0
        if use_beam and own >= 0:
            n_planes = _side_planes(x, y, z, own, hull_pts, hull_start, planes)
            reach_m = margin / max(abs(x * nx[own] + y * ny[own] + z * nz[own] - plane_d[own]),
                                   1e-12)
        use_reach = check_reach and own >= 0
        s, row = side[i], max(own, 0)
        slack = max_path_length_m
        if max_path_length_m >= 0.0:
            slack = max_path_length_m - _nearest(x, y, z, receivers)
        ax, ay, az, half = 0.0, 0.0, 0.0, math.pi
        if use_beam:
            ax, ay, az, half = _beam(x, y, z, own, spheres)
        n_ok = 0
        for p in range(n_p):
            d = abs(x * nx[p] + y * ny[p] + z * nz[p] - plane_d[p])
            ok = (p != own) & (d > tol)
            if use_reach:
                ok = ok & reach[s, row, p]
            if max_path_length_m >= 0.0:
                ok = ok & (2.0 * d <= slack)
            if half < math.pi and ok:
                ok = _in_beam(x, y, z, ax, ay, az, half, p, spheres)
            if n_planes and ok:
                ok = _in_pyramid(x, y, z, planes, n_planes, reach_m, p, spheres)
            if last and ok:
                dd = x * nx[p] + y * ny[p] + z * nz[p] - plane_d[p]
                ok = _heard(x - 2.0 * dd * nx[p], y - 2.0 * dd * ny[p], z - 2.0 * dd * nz[p],
                            dd, p, normals, plane_d, receivers, spheres, eps)
            n_ok += ok
        count += n_ok
        if count > limit:
            return True
    return False


@njit(cache=True, nogil=True)
def next_order(last_pos, last_plane, side, normals, plane_d, tol, reach, receivers,
               max_path_length_m, limit, par, pln, pos, new_side, spheres, gain, floor,
               direct_m, region_gain, new_gain, dropped, hull_pts, hull_start,
               margin, last, eps):  # pragma: no cover
    """The next order's candidate images, in (parent, region) order: every pair off the
    region's plane by more than ``tol``, not the parent's own last region (``last_plane[i] <
    0``: none), reachable from its side (``reach`` empty: all are), and — when
    ``max_path_length_m >= 0`` — whose image is within it of the nearest receiver; with
    ``spheres`` (``(P, 4)``: each region's bounding sphere, centre and radius; none when
    empty) only regions the parent's beam meets (:func:`_in_beam`). Audibility: ``gain[i]``
    is the product of parent ``i``'s reflection amplitudes (bounded over the bands),
    ``region_gain[p]`` region ``p``'s, ``direct_m`` the direct distance to each receiver;
    with ``floor > 0`` a parent or candidate whose paths cannot reach any receiver within
    ``floor`` of the direct sound (:func:`_audible`) is dropped, the candidates counted in
    ``dropped[0]``; ``new_gain`` gets each candidate's product.
    ``last``: this is the last order searched, so only images a receiver can hear through
    their region count (:func:`_heard`, with the spheres). Writes the parent, region, image
    and the side of the region the parent lies on (1: behind) to the output rows while they
    last; returns the number of candidates, or
    ``limit + 1`` as soon as there are more than ``limit`` (the outputs need ``limit``
    rows)."""
    count = 0
    check_reach = reach.shape[1] > 0
    use_beam = spheres.shape[0] > 0
    n_p = normals.shape[0]
    planes = np.empty((_MAX_OUTLINE, 3))
    for i in range(last_pos.shape[0]):
        x, y, z = last_pos[i, 0], last_pos[i, 1], last_pos[i, 2]
        if floor > 0.0 and _audible(x, y, z, gain[i], receivers, direct_m) < floor:
            continue
        own = last_plane[i]
        ax, ay, az, half = 0.0, 0.0, 0.0, math.pi
        n_planes, reach_m = 0, 0.0
        if use_beam:
            ax, ay, az, half = _beam(x, y, z, own, spheres)
            if own >= 0:
                n_planes = _side_planes(x, y, z, own, hull_pts, hull_start, planes)
                reach_m = margin / max(abs(x * normals[own, 0] + y * normals[own, 1]
                                           + z * normals[own, 2] - plane_d[own]), 1e-12)
        for p in range(n_p):
            if p == own:
                continue
            if check_reach and own >= 0 and not reach[side[i], own, p]:
                continue
            if half < math.pi and not _in_beam(x, y, z, ax, ay, az, half, p, spheres):
                continue
            if n_planes and not _in_pyramid(x, y, z, planes, n_planes, reach_m, p, spheres):
                continue
            d = x * normals[p, 0] + y * normals[p, 1] + z * normals[p, 2] - plane_d[p]
            if abs(d) <= tol:
                continue
            ix = x - 2.0 * d * normals[p, 0]
            iy = y - 2.0 * d * normals[p, 1]
            iz = z - 2.0 * d * normals[p, 2]
            if max_path_length_m >= 0.0 and _nearest(ix, iy, iz, receivers) > max_path_length_m:
                continue
            if last and not _heard(ix, iy, iz, d, p, normals, plane_d, receivers, spheres,
                                   eps):
                continue
            if floor > 0.0 and _audible(ix, iy, iz, gain[i] * region_gain[p], receivers,
                                        direct_m) < floor:
                dropped[0] += 1
                continue
            if count >= limit:
                return limit + 1
            par[count], pln[count] = i, p
            new_gain[count] = gain[i] * region_gain[p]
            pos[count, 0], pos[count, 1], pos[count, 2] = ix, iy, iz
            new_side[count] = 1 if d < 0.0 else 0
            count += 1
    return count


@njit(cache=True, nogil=True)
def grow_regions(seeds, adj_start, adj, normals, areas, vertices, faces, cos_min, tol,
                 label):  # pragma: no cover - compiled; via planar_regions
    """Planar regions grown from ``seeds`` in turn (largest face first): an unassigned seed
    starts a region, which takes every unassigned face reachable through ``adj`` (CSR:
    ``adj[adj_start[f]:adj_start[f+1]]`` are f's neighbours) whose normal is within
    ``cos_min`` of the region's plane and whose three vertices lie within ``tol`` of it. The
    plane is the area-weighted mean of the faces taken so far (a noisy seed's tilt would stop
    a long wall short), refitted as each face joins. Writes ``label``, returns the count."""
    label[:] = -1
    stack = [0] * 0
    n = 0
    for seed in seeds:
        if label[seed] >= 0:
            continue
        wx, wy, wz = (normals[seed, 0] * areas[seed], normals[seed, 1] * areas[seed],
                      normals[seed, 2] * areas[seed])
        cx = cy = cz = 0.0
        for k in range(3):
            cx += vertices[faces[seed, k], 0] * areas[seed] / 3.0
            cy += vertices[faces[seed, k], 1] * areas[seed] / 3.0
            cz += vertices[faces[seed, k], 2] * areas[seed] / 3.0
        wa = areas[seed]
        label[seed] = n
        stack.append(seed)
        while len(stack) > 0:
            f = stack.pop()
            for j in range(adj_start[f], adj_start[f + 1]):
                g = adj[j]
                if label[g] >= 0:
                    continue
                norm = math.sqrt(wx * wx + wy * wy + wz * wz)
                sx, sy, sz = wx / norm, wy / norm, wz / norm
                sd = (sx * cx + sy * cy + sz * cz) / wa
                if normals[g, 0] * sx + normals[g, 1] * sy + normals[g, 2] * sz < cos_min:
                    continue
                ok = True
                for k in range(3):
                    v = faces[g, k]
                    if abs(vertices[v, 0] * sx + vertices[v, 1] * sy + vertices[v, 2] * sz
                           - sd) > tol:
                        ok = False
                if ok:
                    label[g] = n
                    stack.append(g)
                    w = areas[g]
                    wx += normals[g, 0] * w
                    wy += normals[g, 1] * w
                    wz += normals[g, 2] * w
                    wa += w
                    for k in range(3):
                        cx += vertices[faces[g, k], 0] * w / 3.0
                        cy += vertices[faces[g, k], 1] * w / 3.0
                        cz += vertices[faces[g, k], 2] * w / 3.0
        n += 1
    return n
