"""Compiled per-hit work of the ray tracer (numba, GIL released).

Embree finds the hits and answers the shadow-ray queries (one call per bounce step, from
Python); everything else done per hit — the exact hit distance, receiver-sphere detection, the
geometry and weight of diffuse rain, the next event and direction, the termination test and
the histogram sums — runs here in one pass over the live rays. In numpy the same step was
about a hundred array operations, so a bounce step cost ~2 ms whatever its size and a trace
ran at a few hundred thousand hits per second; fused, a step costs its rays.

The loops run in a fixed order (rays, then receivers), so the sums are the same bytes on every
run, and ``nogil`` lets batches on a thread pool use every core. The model is the one in
:mod:`.raytrace`'s docstring; the formulas here are its implementation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Embree reports a miss as primID -1 with tfar left at the ray's (huge) initial value.
_MISS_T = 1e36
# "Strictly inside" a convex room's face plane, metres.
_INSIDE_M = 1e-9

# Layout of the float and integer parameter vectors passed to :func:`bounce`.
N_FLOAT_PARAMS, N_INT_PARAMS = 14, 10
(F_SPEED, F_BIN, F_RADIUS, F_GROWTH, F_MAX_LEN, F_E_STOP, F_EPS, F_TO_P2, F_RAIN_SCALE,
 F_CHILD_P, F_E0, F_R_MAX, F_E_ROULETTE, F_GUIDE) = range(N_FLOAT_PARAMS)
# Columns of ``u`` holding the roulette draw (after the event, two direction and the split
# draws; present when roulette or guiding is on) and the guiding's proposal pick (present only
# when guiding is on).
U_ROULETTE, U_GUIDE = 4, 5
(I_N_BINS, I_EXCLUDED, I_RAIN, I_DIRECTIONS, I_STRIDE, I_AIR, I_CONVEX, I_SPLIT,
 I_AXIS, I_MAP_N) = range(N_INT_PARAMS)
# With more receivers than this, sphere tests only visit those whose coordinate along the
# receivers' widest axis lies within reach of the segment (receivers sorted along it).
CULL_ABOVE = 8


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _lambert(sx, sy, sz, u1, u2):  # pragma: no cover - compiled
    """A cosine-weighted direction around the unit normal (sx, sy, sz) (branchless basis,
    Duff et al. 2017)."""
    s = 1.0 if sz >= 0.0 else -1.0
    a = -1.0 / (s + sz)
    bb = sx * sy * a
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    x, y = r * math.cos(phi), r * math.sin(phi)
    z = math.sqrt(max(0.0, 1.0 - u1))
    return (x * (1.0 + s * sx * sx * a) + y * bb + z * sx,
            x * (s * bb) + y * (s + sy * sy * a) + z * sy,
            -x * (s * sx) - y * sy + z * sz)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _scatter(sx, sy, sz, u1, u2, pick, beta, widths):  # pragma: no cover - compiled
    """A diffuse direction off a surface with facing unit normal s, and its weight.

    Without guiding (``beta`` 0): a Lambert direction, weight 1. With guiding: drawn from the
    mixture ``(1-β)·Lambert + β/J·Σ_j B_j``, where ``B_j`` is uniform over the horizontal band
    ``|z| < widths[j]`` (a direction behind the surface is mirrored through it), and weighted
    by ``p_Lambert / p_mixture`` (unbiased). ``B_j``'s density at a front direction d counts
    both ways to reach it: drawn in the band, or mirrored from ``R(d) = d - 2(d·s)s`` in it.
    """
    n_w = widths.shape[0]
    if beta > 0.0 and pick < beta:
        w = widths[min(int(pick / beta * n_w), n_w - 1)]
        ez = w * (2.0 * u1 - 1.0)
        rr = math.sqrt(max(0.0, 1.0 - ez * ez))
        ex, ey = rr * math.cos(2.0 * math.pi * u2), rr * math.sin(2.0 * math.pi * u2)
        dot = ex * sx + ey * sy + ez * sz
        if dot < 0.0:
            ex, ey, ez = ex - 2.0 * dot * sx, ey - 2.0 * dot * sy, ez - 2.0 * dot * sz
    else:
        ex, ey, ez = _lambert(sx, sy, sz, u1, u2)
    if beta == 0.0:
        return ex, ey, ez, 1.0  # not normalised: the caller does
    norm = math.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / norm, ey / norm, ez / norm
    cos = max(0.0, ex * sx + ey * sy + ez * sz)
    mirrored_z = ez - 2.0 * cos * sz
    density = (1.0 - beta) * cos / math.pi
    for j in range(n_w):
        hits = (1.0 if abs(ez) < widths[j] else 0.0) + (1.0 if abs(mirrored_z) < widths[j]
                                                        else 0.0)
        density += beta / n_w * hits / (4.0 * math.pi * widths[j])
    return ex, ey, ez, (cos / math.pi) / density if density > 0.0 else 0.0


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _reweigh(row, j, weight):  # pragma: no cover - compiled
    """Multiplies ``row[j]``'s bands by ``weight``."""
    for b in range(row.shape[1]):
        row[j, b] *= weight


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def cube_cell(x, y, z, n):  # pragma: no cover - compiled
    """Index of the cube-map cell (``n × n`` per face) containing direction (x, y, z): face
    ``2a + (x_a < 0)`` of the major axis ``a``, then the cells along axes ``(a+1) % 3`` and
    ``(a+2) % 3`` (the order of :func:`.raytrace._cube_cells`)."""
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        a, major, u, v = 0, x, y, z
    elif ay >= az:
        a, major, u, v = 1, y, z, x
    else:
        a, major, u, v = 2, z, x, y
    m = abs(major)
    if m == 0.0:
        return 0
    i = min(n - 1, max(0, int((u / m + 1.0) * 0.5 * n)))
    j = min(n - 1, max(0, int((v / m + 1.0) * 0.5 * n)))
    return (2 * a + (1 if major < 0.0 else 0)) * n * n + i * n + j


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _scaled(src, i, gain, ev, cls, div, dst, j, air, path, has_air):  # pragma: no cover
    """Writes ``dst[j] = src[i] · gain[ev, cls] / div`` (per band; ``dst`` may be ``src``
    with ``j <= i``) and returns its largest band after air absorption over ``path`` metres:
    the energy the termination and roulette tests see."""
    strongest = 0.0
    for b in range(src.shape[1]):
        e = src[i, b] * gain[ev, cls, b] / div
        dst[j, b] = e
        if has_air == 1:
            e = e * math.exp(-air[b] * path)
        strongest = max(strongest, e)
    return strongest


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _add_bands(hist, k, tb, row, scale):  # pragma: no cover - compiled
    """Adds ``row · scale`` to receiver ``k``'s bin ``tb``; returns the band sum added."""
    total = 0.0
    for b in range(row.shape[0]):
        e = row[b] * scale
        hist[k, tb, b] += e
        total += e
    return total


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _add_directions(dirsum, k, tb, total, ux, uy, uz, departure):  # pragma: no cover
    """Adds the energy-weighted arrival (against travel direction ``u``) and departure
    direction sums of one contribution of band-summed energy ``total``."""
    dirsum[k, tb, 0] -= ux * total
    dirsum[k, tb, 1] -= uy * total
    dirsum[k, tb, 2] -= uz * total
    dirsum[k, tb, 3] += departure[0] * total
    dirsum[k, tb, 4] += departure[1] * total
    dirsum[k, tb, 5] += departure[2] * total


@njit(cache=True, nogil=True, error_model="numpy")
def bounce(
    rays, step, events, receivers, air, fp, ip, widths, acc, requests, children,
):  # pragma: no cover - compiled; exercised through raytrace.trace_rays
    """One bounce step of ``n = len(face)`` live rays, compacting the survivors in place.

    The arrays come in tuples by what they describe (numba unpacks a tuple at compile time,
    so the compiled loop is the one over separate arrays):

    * ``rays``: ``(pos, dirs, energy, length, n_refl, any_diffuse, last_diffuse, departure,
      ref)``, the live rays (updated in place);
    * ``step``: ``(face, tfar, u, rain_offset)``, this step's Embree hits, random draws and
      rain offsets;
    * ``events``: ``(planes, face_class, p_t, p_ts, gain, w_diff, scatters, ps_t,
      split_gain)``, the faces and their event tables;
    * ``receivers``: ``(rcv_pos, rcv_cap, rcv_inside, plane_n, plane_off, rcv_order, rcv_key,
      rcv_clear, vol, depth)``;
    * ``air``, ``fp``, ``ip`` (the parameter vectors, ``F_*`` and ``I_*``), ``widths``;
    * ``acc``: ``(hist, dirsum)``, the histograms the step adds to;
    * ``requests``: ``(req_origin, req_dir, req_len, req_k, req_bin, req_energy, req_dep)``,
      the shadow rays it queues;
    * ``children``: ``(c_pos, c_dirs, c_energy, c_length, c_n_refl, c_dep, c_ref)``, the rays
      it spawns.

    Detects each ray's segment in the receiver spheres, moves it to its hit, queues diffuse-rain
    shadow rays (``req_*``; deposited at once where a convex room needs none), picks the next
    event from ``u`` and updates energy and direction; a splitting ray may also spawn a child
    (``c_*``). Returns ``(survivors, shadow rays queued, rays escaped, surface interactions,
    children)``; survivors occupy rows ``[0, survivors)``, children rows ``[0, children)``.

    ``ref`` is the product of the guiding weights a ray's energy carries (its launch and its
    path's first diffuse reflection, or its birth as a child; 1 without guiding): the
    termination and roulette levels scale with it, so a ray the guiding sent where energy lives
    long, with a weight to match, is not stopped for that weight.
    """
    pos, dirs, energy, length, n_refl, any_diffuse, last_diffuse, departure, ref = rays
    face, tfar, u, rain_offset = step
    planes, face_class, p_t, p_ts, gain, w_diff, scatters, ps_t, split_gain = events
    (rcv_pos, rcv_cap, rcv_inside, plane_n, plane_off, rcv_order, rcv_key, rcv_clear, vol,
     depth) = receivers
    hist, dirsum = acc
    req_origin, req_dir, req_len, req_k, req_bin, req_energy, req_dep = requests
    c_pos, c_dirs, c_energy, c_length, c_n_refl, c_dep, c_ref = children
    n = face.shape[0]
    n_bands = energy.shape[1]
    n_rcv = rcv_pos.shape[0]
    c, bin_s, r0, growth = fp[F_SPEED], fp[F_BIN], fp[F_RADIUS], fp[F_GROWTH]
    max_len, e_stop, eps, to_p2 = fp[F_MAX_LEN], fp[F_E_STOP], fp[F_EPS], fp[F_TO_P2]
    rain_scale, e_roulette, beta = fp[F_RAIN_SCALE], fp[F_E_ROULETTE], fp[F_GUIDE]
    n_bins, excluded, rain, directions = ip[I_N_BINS], ip[I_EXCLUDED], ip[I_RAIN], ip[I_DIRECTIONS]
    stride, has_air, convex, split = ip[I_STRIDE], ip[I_AIR], ip[I_CONVEX], ip[I_SPLIT]
    axis, r_max = ip[I_AXIS], fp[F_R_MAX]
    bin_len = c * bin_s
    inv_bin_len = 1.0 / bin_len
    n_slots = n_rcv if stride == 1 else (n_rcv + stride - 1) // stride
    map_n = ip[I_MAP_N]  # cells per cube-face edge of the visibility maps
    scratch = np.empty(n_bands)
    out = 0
    n_req = 0
    escaped = 0
    hits = 0
    n_child = 0
    for i in range(n):
        ox, oy, oz = pos[i, 0], pos[i, 1], pos[i, 2]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        f = face[i]
        miss = f < 0 or tfar[i] >= _MISS_T
        t = math.inf
        nx = ny = nz = 0.0
        if not miss:
            nx, ny, nz = planes[f, 0], planes[f, 1], planes[f, 2]
            denom = nx * dx + ny * dy + nz * dz
            num = planes[f, 3] - (nx * ox + ny * oy + nz * oz)
            exact = num / denom if abs(denom) > 1e-9 else num
            # Grazing rays: the plane solve is ill-conditioned; keep Embree's float32 distance.
            t = exact if (abs(denom) > 1e-6 and exact > 0.0) else float(tfar[i])
        path = length[i]

        # Receiver spheres: segments whose last reflection is specular, beyond the image
        # sources (an escaping ray's segment is infinite; it is still tested).
        eligible = any_diffuse[i] or n_refl[i] > excluded
        if rain == 1 and last_diffuse[i]:
            eligible = False
        if eligible:
            j0, j1 = 0, n_rcv
            if n_rcv > CULL_ABOVE:  # the receivers whose axis coordinate the segment can reach
                o_a, d_a = pos[i, axis], dirs[i, axis]
                lo, hi = -math.inf, math.inf
                if d_a >= 0.0:
                    lo = o_a - r_max
                    if t < math.inf:
                        hi = o_a + t * d_a + r_max
                if d_a <= 0.0:
                    hi = o_a + r_max
                    if t < math.inf:
                        lo = o_a + t * d_a - r_max
                j0 = np.searchsorted(rcv_key, lo, side="left")
                j1 = np.searchsorted(rcv_key, hi, side="right")
            for j in range(j0, j1):
                k = rcv_order[j]
                wx, wy, wz = rcv_pos[k, 0] - ox, rcv_pos[k, 1] - oy, rcv_pos[k, 2] - oz
                tc = wx * dx + wy * dy + wz * dz
                d2 = wx * wx + wy * wy + wz * wz - tc * tc
                radius = max(r0, min(growth * (path + max(tc, 0.0)), rcv_cap[k]))
                r2 = radius * radius
                if d2 >= r2:
                    continue
                half = math.sqrt(r2 - d2)
                t_in = max(tc - half, 0.0)
                t_out = min(tc + half, t)
                chord = t_out - t_in
                if chord <= 0.0:
                    continue
                tb = int((path + 0.5 * (t_in + t_out)) / bin_len)  # >= 0: floor
                if tb >= n_bins:
                    continue
                if radius <= rcv_clear[k]:
                    volume = 4.0 / 3.0 * math.pi * radius * radius * radius
                else:  # the ball reaches surfaces: count the chord if the receiver sees its
                    # midpoint, and divide by the volume of the air it sees in the ball
                    tm = 0.5 * (t_in + t_out)
                    mx, my, mz = tm * dx - wx, tm * dy - wy, tm * dz - wz
                    cell = cube_cell(mx, my, mz, map_n)
                    if mx * mx + my * my + mz * mz >= depth[k, cell] * depth[k, cell]:
                        continue
                    x = radius / rcv_cap[k] * (vol.shape[1] - 1)
                    jv = min(int(x), vol.shape[1] - 2)
                    frac = x - jv
                    volume = (1.0 - frac) * vol[k, jv] + frac * vol[k, jv + 1]
                total = _add_bands(hist, k, tb, energy[i], chord / volume * to_p2)
                if directions == 1:
                    _add_directions(dirsum, k, tb, total, dx, dy, dz, departure[i])
        if miss:
            escaped += 1
            continue

        # Fly to the hit.
        hx, hy, hz = ox + t * dx, oy + t * dy, oz + t * dz
        travelled = path + t
        cls = face_class[f]
        hits += 1
        cos_in = dx * nx + dy * ny + dz * nz
        sign = 1.0 if cos_in < 0.0 else -1.0  # normal facing the ray
        sx, sy, sz = sign * nx, sign * ny, sign * nz
        alive_time = travelled < max_len

        # Diffuse rain: the scattered share towards every receiver (or every stride-th).
        if rain == 1 and alive_time and scatters[cls]:
            qx, qy, qz = hx + eps * sx, hy + eps * sy, hz + eps * sz  # shadow rays start here
            free_start = False
            if convex == 1:
                free_start = True
                for p in range(plane_n.shape[0]):
                    side = qx * plane_n[p, 0] + qy * plane_n[p, 1] + qz * plane_n[p, 2]
                    if side - plane_off[p] <= _INSIDE_M:
                        free_start = False
                        break
            for b in range(n_bands):
                scratch[b] = energy[i, b] * w_diff[cls, b]
            for j in range(n_slots):
                k = j if stride == 1 else rain_offset[i] + stride * j
                if k >= n_rcv:
                    continue
                vx, vy, vz = rcv_pos[k, 0] - hx, rcv_pos[k, 1] - hy, rcv_pos[k, 2] - hz
                dot = vx * sx + vy * sy + vz * sz
                if dot <= 0.0:  # the receiver is behind the surface
                    continue
                d = math.sqrt(vx * vx + vy * vy + vz * vz)
                tb = int((travelled + d) * inv_bin_len)
                if tb >= n_bins:
                    continue
                # Lambert weight × solid angle of the receiver sphere (2π when inside it).
                sin2 = min(1.0, (r0 / d) ** 2)
                solid = 2.0 * math.pi * (1.0 - math.sqrt(1.0 - sin2))
                geom = dot / d * solid * rain_scale
                ux, uy, uz = vx / d, vy / d, vz / d
                if free_start and rcv_inside[k]:  # nothing can block it: deposit now
                    total = _add_bands(hist, k, tb, scratch, geom)
                    if directions == 1:
                        _add_directions(dirsum, k, tb, total, ux, uy, uz, departure[i])
                    continue
                req_origin[n_req, 0], req_origin[n_req, 1], req_origin[n_req, 2] = qx, qy, qz
                req_dir[n_req, 0], req_dir[n_req, 1], req_dir[n_req, 2] = ux, uy, uz
                req_len[n_req] = d
                req_k[n_req] = k
                req_bin[n_req] = tb
                for b in range(n_bands):
                    req_energy[n_req, b] = scratch[b] * geom
                if directions == 1:
                    req_dep[n_req, 0] = departure[i, 0]
                    req_dep[n_req, 1] = departure[i, 1]
                    req_dep[n_req, 2] = departure[i, 2]
                n_req += 1

        pick = u[i, 0]
        table = gain
        if split == 1 and (not any_diffuse[i] or ref[i] < 1.0):
            # A ray that has only been reflected specularly (or transmitted), or that carries a
            # guiding weight below 1 (a band sent it where energy lives long), splits: it goes on
            # specularly with that share, and the scattered share leaves as a child ray with
            # probability q ∝ the ray's energy (children start with about the same energy,
            # e0 × the scattered share / F_CHILD_P), its gain divided by q: unbiased.
            table = split_gain
            event = 0 if pick < ps_t[cls] else 1
            peak = 0.0
            for b in range(n_bands):
                peak = max(peak, energy[i, b])
            q = min(1.0, fp[F_CHILD_P] * peak / fp[F_E0])
            if event == 1 and alive_time and u[i, 3] < q:
                ex, ey, ez, weight = _scatter(sx, sy, sz, u[i, 1], u[i, 2],
                                              u[i, U_GUIDE] if beta > 0.0 else 1.0, beta,
                                              widths)
                strongest = weight * _scaled(energy, i, split_gain, 2, cls, q, c_energy,
                                             n_child, air, travelled, has_air)
                if strongest >= e_stop * weight and weight > 0.0:
                    _reweigh(c_energy, n_child, weight)
                    norm = math.sqrt(ex * ex + ey * ey + ez * ez)
                    c_pos[n_child, 0] = hx + eps * sx
                    c_pos[n_child, 1] = hy + eps * sy
                    c_pos[n_child, 2] = hz + eps * sz
                    c_dirs[n_child, 0] = ex / norm
                    c_dirs[n_child, 1] = ey / norm
                    c_dirs[n_child, 2] = ez / norm
                    c_ref[n_child] = weight
                    c_length[n_child] = travelled
                    c_n_refl[n_child] = n_refl[i] + 1
                    c_dep[n_child, 0] = departure[i, 0]
                    c_dep[n_child, 1] = departure[i, 1]
                    c_dep[n_child, 2] = departure[i, 2]
                    n_child += 1
        else:
            # The continuing event by band-mean weights (0 transmit, 1 specular, 2 diffuse),
            # reweighted per band (unbiased).
            event = 0 if pick < p_t[cls] else (1 if pick < p_ts[cls] else 2)
        strongest = _scaled(energy, i, table, event, cls, 1.0, energy, out, air, travelled,
                            has_air)
        level = ref[i]
        if event == 1:  # specular mirror
            ex, ey, ez = dx - 2.0 * cos_in * nx, dy - 2.0 * cos_in * ny, dz - 2.0 * cos_in * nz
        elif event == 2 and beta > 0.0 and not any_diffuse[i]:
            # A path's first diffuse reflection is guided too (one more weight factor; later
            # ones are not, so no path multiplies more than two factors).
            ex, ey, ez, weight = _scatter(sx, sy, sz, u[i, 1], u[i, 2], u[i, U_GUIDE], beta,
                                          widths)
            _reweigh(energy, out, weight)
            strongest *= weight
            level *= weight
        elif event == 2:  # Lambert around the facing normal
            ex, ey, ez = _lambert(sx, sy, sz, u[i, 1], u[i, 2])
        else:  # transmitted: straight on
            ex, ey, ez = dx, dy, dz
        norm = math.sqrt(ex * ex + ey * ey + ez * ez)
        if e_roulette > 0.0 and strongest < e_roulette * level and alive_time:
            # Russian roulette: a weak ray goes on with probability strongest / e_roulette,
            # raised back to that level (unbiased); most weak rays stop here, cheaply.
            keep = strongest / (e_roulette * level)
            if u[i, U_ROULETTE] >= keep:
                continue
            for b in range(n_bands):
                energy[out, b] = energy[out, b] / keep
            strongest = e_roulette * level
        if not (strongest >= e_stop * level and alive_time and level > 0.0):
            continue
        off = -eps if event == 0 else eps
        pos[out, 0], pos[out, 1], pos[out, 2] = hx + off * sx, hy + off * sy, hz + off * sz
        dirs[out, 0], dirs[out, 1], dirs[out, 2] = ex / norm, ey / norm, ez / norm
        length[out] = travelled
        reflected = event != 0
        n_refl[out] = n_refl[i] + (1 if reflected else 0)
        any_diffuse[out] = any_diffuse[i] or event == 2
        last_diffuse[out] = (event == 2) if reflected else last_diffuse[i]
        departure[out, 0], departure[out, 1], departure[out, 2] = (
            departure[i, 0], departure[i, 1], departure[i, 2])
        ref[out] = level
        out += 1
    return out, n_req, escaped, hits, n_child


@njit(cache=True, nogil=True, error_model="numpy")
def deposit(req_k, req_bin, req_dir, req_energy, req_dep, blocked, trans, directions,
            hist, dirsum):  # pragma: no cover - compiled; exercised through raytrace.trace_rays
    """Adds the shadow rays that reached their receiver, times their surfaces' ``trans``
    (``(m, bands)``, or ``(0, 0)`` for none), to the histograms, in queue order."""
    n_bands = req_energy.shape[1]
    use_trans = trans.shape[0] > 0
    for m in range(req_k.shape[0]):
        if blocked[m]:
            continue
        k, tb = req_k[m], req_bin[m]
        if use_trans:
            total = 0.0
            for b in range(n_bands):
                e = req_energy[m, b] * trans[m, b]
                hist[k, tb, b] += e
                total += e
        else:
            total = _add_bands(hist, k, tb, req_energy[m], 1.0)
        if directions:
            _add_directions(dirsum, k, tb, total, req_dir[m, 0], req_dir[m, 1], req_dir[m, 2],
                            req_dep[m])
