"""Compiled point-in-region test of the image-source method (numba, GIL released).

Backtracking a path checks each reflection point against the triangles of its planar region.
In numpy that was one group of array operations per distinct region; a furnished scan has
thousands of small regions (every box side, every table top), so the loop over them, not the
arithmetic, was half the cost of an order-2 image-source pass. Here each point tests its own
region's triangles directly, with the same barycentric formulas in the same order.
"""

from __future__ import annotations

from numba import njit


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
        found = False
        if (px < boxes[p, 0, 0] or py < boxes[p, 0, 1] or pz < boxes[p, 0, 2]
                or px > boxes[p, 1, 0] or py > boxes[p, 1, 1] or pz > boxes[p, 1, 2]):
            inside[i] = False
            continue
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
                found = True
                break
        inside[i] = found
