"""Compiled pass of the flat-area simplification (numba): half-edge collapses that keep the
surface, its creases and its material boundaries where they are (see :mod:`.simplify`)."""

from __future__ import annotations

import numpy as np
from numba import njit

MAX_DEGREE = 128  # faces around one vertex; busier vertices are left alone


@njit(cache=True, nogil=True)
def _plane(vertices, a, b, c):  # pragma: no cover - compiled
    """Unit normal, offset and twice the area of triangle (a, b, c)."""
    e1 = vertices[b] - vertices[a]
    e2 = vertices[c] - vertices[a]
    n = np.cross(e1, e2)
    area2 = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    if area2 > 0:
        n = n / area2
    return n, n[0] * vertices[a, 0] + n[1] * vertices[a, 1] + n[2] * vertices[a, 2], area2


@njit(cache=True, nogil=True)
def collapse_pass(vertices, faces, alive, face_class, face_err, vstart, vfaces, tol_m,
                  cos_min, min_area2):  # pragma: no cover - compiled; via simplify
    """One pass over the vertices; returns the number of vertices removed.

    A vertex ``v`` is removed by moving it onto a neighbour ``u`` (the two faces on edge uv
    vanish, the others are re-pointed to ``u``) when: every edge at ``v`` has two faces
    (closed, manifold); ``u`` lies within the remaining tolerance of every face plane at
    ``v`` and, where an edge at ``v`` separates two materials, of the plane through that
    edge square to its faces (so creases and material boundaries stay put); ``v`` lies
    within it of every re-pointed face's plane; no re-pointed face degenerates or turns by
    more than ``arccos(cos_min)``; and ``u`` and ``v`` share exactly the two neighbours
    opposite their edge (no duplicate faces, no pinched surface). ``face_err`` keeps how far
    each face may already be from the original surface; a pass locks the neighbourhood of
    every collapse, so each decision reads faces that this pass has not changed.
    """
    nv = vertices.shape[0]
    locked = np.zeros(nv, dtype=np.bool_)
    nbr = np.empty(2 * MAX_DEGREE, dtype=np.int64)
    nbr_count = np.empty(2 * MAX_DEGREE, dtype=np.int64)
    nbr_face = np.empty((2 * MAX_DEGREE, 2), dtype=np.int64)
    planes = np.empty((3 * MAX_DEGREE, 4))
    u_nbr = np.empty(2 * MAX_DEGREE, dtype=np.int64)
    removed = 0
    for v in range(nv):
        k = vstart[v + 1] - vstart[v]
        if locked[v] or k == 0 or k > MAX_DEGREE:
            continue
        # Neighbours of v and the faces on each edge (v, n).
        n_nbr = 0
        base_err = 0.0
        for j in range(vstart[v], vstart[v + 1]):
            f = vfaces[j]
            base_err = max(base_err, face_err[f])
            for c in range(3):
                w = faces[f, c]
                if w == v:
                    continue
                found = -1
                for i in range(n_nbr):
                    if nbr[i] == w:
                        found = i
                        break
                if found < 0:
                    nbr[n_nbr] = w
                    nbr_count[n_nbr] = 0
                    found = n_nbr
                    n_nbr += 1
                if nbr_count[found] < 2:
                    nbr_face[found, nbr_count[found]] = f
                nbr_count[found] += 1
        manifold = True
        for i in range(n_nbr):
            if nbr_count[i] != 2:
                manifold = False
        if not manifold or base_err > tol_m:
            continue
        # Constraint planes: every face at v, and edges between materials.
        n_pl = 0
        for j in range(vstart[v], vstart[v + 1]):
            f = vfaces[j]
            nrm, d, _ = _plane(vertices, faces[f, 0], faces[f, 1], faces[f, 2])
            planes[n_pl, 0], planes[n_pl, 1], planes[n_pl, 2], planes[n_pl, 3] = (
                nrm[0], nrm[1], nrm[2], d)
            n_pl += 1
        for i in range(n_nbr):
            f0, f1 = nbr_face[i, 0], nbr_face[i, 1]
            if face_class[f0] == face_class[f1]:
                continue
            edge = vertices[nbr[i]] - vertices[v]
            for f in (f0, f1):
                nrm, _, _ = _plane(vertices, faces[f, 0], faces[f, 1], faces[f, 2])
                side = np.cross(edge, nrm)
                length = np.sqrt(side[0] ** 2 + side[1] ** 2 + side[2] ** 2)
                if length == 0:
                    continue
                side = side / length
                planes[n_pl, 0], planes[n_pl, 1], planes[n_pl, 2] = side[0], side[1], side[2]
                planes[n_pl, 3] = (side[0] * vertices[v, 0] + side[1] * vertices[v, 1]
                                   + side[2] * vertices[v, 2])
                n_pl += 1
        best_u, best_quality, best_dev = -1, 0.0, 0.0
        for i in range(n_nbr):
            u = nbr[i]
            if locked[u]:
                continue
            pu = vertices[u]
            dev = 0.0
            for p in range(n_pl):
                dev = max(dev, abs(planes[p, 0] * pu[0] + planes[p, 1] * pu[1]
                                   + planes[p, 2] * pu[2] - planes[p, 3]))
            if base_err + dev > tol_m:
                continue
            ok = True
            quality = np.inf
            for j in range(vstart[v], vstart[v + 1]):
                f = vfaces[j]
                a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
                if a == u or b == u or c == u:
                    continue
                old_n, _, _ = _plane(vertices, a, b, c)
                a = u if a == v else a
                b = u if b == v else b
                c = u if c == v else c
                new_n, new_d, area2 = _plane(vertices, a, b, c)
                if area2 <= min_area2 or (new_n[0] * old_n[0] + new_n[1] * old_n[1]
                                          + new_n[2] * old_n[2]) < cos_min:
                    ok = False
                    break
                pv = vertices[v]
                dev = max(dev, abs(new_n[0] * pv[0] + new_n[1] * pv[1] + new_n[2] * pv[2]
                                   - new_d))
                e0 = vertices[b] - vertices[a]
                e1 = vertices[c] - vertices[b]
                e2 = vertices[a] - vertices[c]
                quality = min(quality, area2 / (e0 @ e0 + e1 @ e1 + e2 @ e2))
            if not ok or base_err + dev > tol_m:
                continue
            # Link condition: u and v share exactly the two vertices opposite edge uv.
            k_u = vstart[u + 1] - vstart[u]
            if k_u > MAX_DEGREE:
                continue
            n_u = 0
            for j in range(vstart[u], vstart[u + 1]):
                f = vfaces[j]
                for c in range(3):
                    w = faces[f, c]
                    if w == u:
                        continue
                    seen = False
                    for q in range(n_u):
                        if u_nbr[q] == w:
                            seen = True
                            break
                    if not seen:
                        u_nbr[n_u] = w
                        n_u += 1
            shared = 0
            for q in range(n_u):
                for r in range(n_nbr):
                    if u_nbr[q] == nbr[r]:
                        shared += 1
            if shared != 2:
                continue
            if best_u < 0 or dev < best_dev or (dev == best_dev and quality > best_quality):
                best_u, best_quality, best_dev = u, quality, dev
        if best_u < 0:
            continue
        for j in range(vstart[v], vstart[v + 1]):
            f = vfaces[j]
            if faces[f, 0] == best_u or faces[f, 1] == best_u or faces[f, 2] == best_u:
                alive[f] = False
                continue
            for c in range(3):
                if faces[f, c] == v:
                    faces[f, c] = best_u
            face_err[f] = base_err + best_dev
        locked[v] = True
        for i in range(n_nbr):
            locked[nbr[i]] = True
        removed += 1
    return removed
