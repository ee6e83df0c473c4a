"""Compiled flat-area simplification (numba): half-edge collapses that keep the surface, its
creases and its material boundaries where they are (see :mod:`.simplify`).

Each vertex keeps a linked list of its face corners, updated in place by every collapse, so
one call works through a queue of vertices to the end without rebuilding any table: a
collapse puts the removed vertex's neighbours (the one it moved onto among them) back in the
queue, since their faces changed. Geometry is done on scalars: small numpy temporaries in
these loops were allocated on every call and made the pass ten times slower.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MAX_DEGREE = 128  # faces around one vertex; busier vertices are left alone


@njit(cache=True, nogil=True, inline="always")
def _plane(vertices, a, b, c):  # pragma: no cover - compiled
    """Unit normal (nx, ny, nz), offset d and twice the area of triangle (a, b, c), as
    scalars (small arrays would be allocated on every call)."""
    ax, ay, az = vertices[a, 0], vertices[a, 1], vertices[a, 2]
    e1x, e1y, e1z = vertices[b, 0] - ax, vertices[b, 1] - ay, vertices[b, 2] - az
    e2x, e2y, e2z = vertices[c, 0] - ax, vertices[c, 1] - ay, vertices[c, 2] - az
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    area2 = np.sqrt(nx * nx + ny * ny + nz * nz)
    if area2 > 0:
        nx, ny, nz = nx / area2, ny / area2, nz / area2
    return nx, ny, nz, nx * ax + ny * ay + nz * az, area2


@njit(cache=True, nogil=True, inline="always")
def _squared_edges(vertices, a, b, c):  # pragma: no cover - compiled
    """Sum of the squared edge lengths of triangle (a, b, c)."""
    total = 0.0
    for p, q in ((a, b), (b, c), (c, a)):
        dx = vertices[q, 0] - vertices[p, 0]
        dy = vertices[q, 1] - vertices[p, 1]
        dz = vertices[q, 2] - vertices[p, 2]
        total += dx * dx + dy * dy + dz * dz
    return total


@njit(cache=True, nogil=True)
def _gather(v, faces, alive, head, tail, nxt, out):  # pragma: no cover - compiled
    """Writes the live faces around ``v`` to ``out`` (up to its length) and returns how many
    there are; drops dead corners from ``v``'s list on the way."""
    count = 0
    prev = -1
    c = head[v]
    while c >= 0:
        f = c // 3
        following = nxt[c]
        if alive[f] and faces[f, c % 3] == v:
            if count < out.shape[0]:
                out[count] = f
            count += 1
            prev = c
        else:  # unlink the dead corner
            if prev < 0:
                head[v] = following
            else:
                nxt[prev] = following
            if tail[v] == c:
                tail[v] = prev
        c = following
    return count


@njit(cache=True, nogil=True)
def simplify(vertices, faces, alive, face_class, face_err, tol_m, cos_min,
             min_area2):  # pragma: no cover - compiled; via simplify
    """Collapses vertices until none qualifies; returns the number removed.

    A vertex ``v`` is removed by moving it onto a neighbour ``u`` (the two faces on edge uv
    vanish, the others are re-pointed to ``u``) when: every edge at ``v`` has two faces
    (closed, manifold); ``u`` lies within the remaining tolerance of every face plane at
    ``v`` and, where an edge at ``v`` separates two materials, of the plane through that
    edge square to its faces (so creases and material boundaries stay put); ``v`` lies
    within it of every re-pointed face's plane; no re-pointed face degenerates or turns by
    more than ``arccos(cos_min)``; and ``u`` and ``v`` share exactly the two neighbours
    opposite their edge (no duplicate faces, no pinched surface). ``face_err`` keeps how far
    each face may already be from the original surface. Among the neighbours that qualify
    the one that moves the surface least wins, then the one with the best-shaped faces.
    """
    nv = vertices.shape[0]
    nf = faces.shape[0]
    head = np.full(nv, -1, dtype=np.int64)
    tail = np.full(nv, -1, dtype=np.int64)
    nxt = np.full(3 * nf, -1, dtype=np.int64)
    for c in range(3 * nf):
        if not alive[c // 3]:
            continue
        w = faces[c // 3, c % 3]
        if head[w] < 0:
            head[w] = c
        else:
            nxt[tail[w]] = c
        tail[w] = c
    # FIFO of vertices to (re)consider, each at most once at a time.
    queue = np.arange(nv + 1, dtype=np.int64)
    in_queue = np.ones(nv, dtype=np.bool_)
    q_head, q_count = 0, nv
    v_faces = np.empty(MAX_DEGREE, dtype=np.int64)
    u_faces = np.empty(MAX_DEGREE, dtype=np.int64)
    nbr = np.empty(2 * MAX_DEGREE, dtype=np.int64)
    nbr_count = np.empty(2 * MAX_DEGREE, dtype=np.int64)
    nbr_face = np.empty((2 * MAX_DEGREE, 2), dtype=np.int64)  # local j: planes[j]
    planes = np.empty((3 * MAX_DEGREE, 4))
    cand_u = np.empty(2 * MAX_DEGREE, dtype=np.int64)
    cand_dev = np.empty(2 * MAX_DEGREE)
    cand_quality = np.empty(2 * MAX_DEGREE)
    # stamp[w] == tested marks w as a neighbour of the vertex under test, at slot[w].
    stamp = np.full(nv, -1, dtype=np.int64)
    tested = 0
    slot = np.zeros(nv, dtype=np.int64)
    removed = 0
    while q_count > 0:
        v = queue[q_head]
        q_head = (q_head + 1) % (nv + 1)
        q_count -= 1
        in_queue[v] = False
        k = _gather(v, faces, alive, head, tail, nxt, v_faces)
        if k == 0 or k > MAX_DEGREE:
            continue
        tested += 1
        # Neighbours of v and the faces on each edge (v, n).
        n_nbr = 0
        base_err = 0.0
        for j in range(k):
            f = v_faces[j]
            base_err = max(base_err, face_err[f])
            for c in range(3):
                w = faces[f, c]
                if w == v:
                    continue
                if stamp[w] == tested:
                    found = slot[w]
                else:
                    stamp[w] = tested
                    slot[w] = n_nbr
                    nbr[n_nbr] = w
                    nbr_count[n_nbr] = 0
                    found = n_nbr
                    n_nbr += 1
                if nbr_count[found] < 2:
                    nbr_face[found, nbr_count[found]] = j
                nbr_count[found] += 1
        manifold = True
        for i in range(n_nbr):
            if nbr_count[i] != 2:
                manifold = False
        if not manifold or base_err > tol_m:
            continue
        # Constraint planes: every face at v (planes[j] is v_faces[j]'s, read again below),
        # and, through every edge at v that separates two materials or folds by more than 90°
        # (up to two faces back to back, whose planes coincide and so cannot pin the edge by
        # themselves), the plane square to each of its faces.
        n_pl = 0
        for j in range(k):
            f = v_faces[j]
            nx, ny, nz, d, _ = _plane(vertices, faces[f, 0], faces[f, 1], faces[f, 2])
            planes[n_pl, 0], planes[n_pl, 1], planes[n_pl, 2], planes[n_pl, 3] = nx, ny, nz, d
            n_pl += 1
        for i in range(n_nbr):
            j0, j1 = nbr_face[i, 0], nbr_face[i, 1]
            if (face_class[v_faces[j0]] == face_class[v_faces[j1]]
                    and planes[j0, 0] * planes[j1, 0] + planes[j0, 1] * planes[j1, 1]
                    + planes[j0, 2] * planes[j1, 2] >= 0.0):
                continue
            ex = vertices[nbr[i], 0] - vertices[v, 0]
            ey = vertices[nbr[i], 1] - vertices[v, 1]
            ez = vertices[nbr[i], 2] - vertices[v, 2]
            for j in (j0, j1):
                nx, ny, nz = planes[j, 0], planes[j, 1], planes[j, 2]
                sx, sy, sz = ey * nz - ez * ny, ez * nx - ex * nz, ex * ny - ey * nx
                length = np.sqrt(sx * sx + sy * sy + sz * sz)
                if length == 0:
                    continue
                sx, sy, sz = sx / length, sy / length, sz / length
                planes[n_pl, 0], planes[n_pl, 1], planes[n_pl, 2] = sx, sy, sz
                planes[n_pl, 3] = sx * vertices[v, 0] + sy * vertices[v, 1] + sz * vertices[v, 2]
                n_pl += 1
        n_cand = 0
        for i in range(n_nbr):
            u = nbr[i]
            ux, uy, uz = vertices[u, 0], vertices[u, 1], vertices[u, 2]
            dev = 0.0
            for p in range(n_pl):
                dev = max(dev, abs(planes[p, 0] * ux + planes[p, 1] * uy + planes[p, 2] * uz
                                   - planes[p, 3]))
            if base_err + dev > tol_m:
                continue
            ok = True
            quality = np.inf
            for j in range(k):
                f = v_faces[j]
                a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
                if a == u or b == u or c == u:
                    continue
                ox, oy, oz = planes[j, 0], planes[j, 1], planes[j, 2]
                a = u if a == v else a
                b = u if b == v else b
                c = u if c == v else c
                nx, ny, nz, new_d, area2 = _plane(vertices, a, b, c)
                if area2 <= min_area2 or nx * ox + ny * oy + nz * oz < cos_min:
                    ok = False
                    break
                dev = max(dev, abs(nx * vertices[v, 0] + ny * vertices[v, 1]
                                   + nz * vertices[v, 2] - new_d))
                quality = min(quality, area2 / _squared_edges(vertices, a, b, c))
            if not ok or base_err + dev > tol_m:
                continue
            cand_u[n_cand], cand_dev[n_cand], cand_quality[n_cand] = u, dev, quality
            n_cand += 1
        # The candidate that moves the surface least, then the best-shaped, that passes the
        # link condition: u and v share exactly the two vertices opposite edge uv.
        best_u, best_dev = -1, 0.0
        while n_cand > 0:
            pick = 0
            for i in range(1, n_cand):
                if cand_dev[i] < cand_dev[pick] or (cand_dev[i] == cand_dev[pick]
                                                    and cand_quality[i] > cand_quality[pick]):
                    pick = i
            u = cand_u[pick]
            k_u = _gather(u, faces, alive, head, tail, nxt, u_faces)
            shared = 0
            if k_u <= MAX_DEGREE:
                for j in range(k_u):
                    f = u_faces[j]
                    for c in range(3):
                        w = faces[f, c]
                        # Each shared neighbour is counted once: un-stamp it.
                        if w != u and w != v and stamp[w] == tested:
                            stamp[w] = -2
                            shared += 1
                for j in range(k_u):  # restore the stamps
                    f = u_faces[j]
                    for c in range(3):
                        w = faces[f, c]
                        if stamp[w] == -2:
                            stamp[w] = tested
            if k_u <= MAX_DEGREE and shared == 2:
                best_u, best_dev = u, cand_dev[pick]
                break
            n_cand -= 1  # drop it: move the last candidate into its place
            cand_u[pick], cand_dev[pick], cand_quality[pick] = (
                cand_u[n_cand], cand_dev[n_cand], cand_quality[n_cand])
        if best_u < 0:
            continue
        for j in range(k):
            f = v_faces[j]
            if faces[f, 0] == best_u or faces[f, 1] == best_u or faces[f, 2] == best_u:
                alive[f] = False
                continue
            for c in range(3):
                if faces[f, c] == v:
                    faces[f, c] = best_u
            face_err[f] = base_err + best_dev
        # v's corners now belong to best_u: append its list.
        if head[v] >= 0:
            if head[best_u] < 0:
                head[best_u] = head[v]
            else:
                nxt[tail[best_u]] = head[v]
            tail[best_u] = tail[v]
        head[v] = -1
        tail[v] = -1
        removed += 1
        # v's old ring (best_u among them) saw its faces change: they may qualify now.
        for i in range(n_nbr):
            w = nbr[i]
            if not in_queue[w]:
                in_queue[w] = True
                queue[(q_head + q_count) % (nv + 1)] = w
                q_count += 1
    return removed
