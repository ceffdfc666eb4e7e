"""Numba kernel clipping deposited yarn polylines to the faces of a mesh (docs/theory.md §5).

Arrays and scalars only; the wrapper is :func:`preform.analysis.fields.map_to_surface`, the slow
NumPy reference lives in ``tests/unit/test_fields_kernels.py``.

Which face owns a point in space: face ``f`` owns the wedge bounded by its three *edge planes*.
The edge plane of the edge shared by faces ``f`` and ``g`` contains that edge and the mean of the
two unit face normals (the bisector of the dihedral angle); on a boundary edge it contains the edge
and ``f``'s normal. Both faces use the *same* plane with opposite orientation, so the wedges of
neighbouring faces never overlap or leave a gap: every piece of a yarn that lies on (or slightly off)
the surface is assigned to exactly one face, and the per-face lengths sum to the yarn's length.
Along a straight segment ``P(t) = P0 + t (P1 - P0)`` the signed distance to a plane is affine in
``t``, so clipping is exact: the walk leaves ``f`` at the smallest ``t`` where a distance that is
falling reaches zero and continues in the neighbour across that edge.

Mesh arrays (m, mandrel frame):
  plane_normal (nf, 3, 3) float64: unit normal of edge plane j of face f (edge = corners j, j + 1),
      pointing into f;  plane_offset (nf, 3) float64: ``plane_normal . x`` of points on the plane;
  neighbour (nf, 3) int64: face across edge j, -1 on a boundary;
  centroid (nf, 3) float64.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import INNER


@njit(**INNER)
def _walk(plane_normal, plane_offset, neighbour, f, x0, y0, z0, x1, y1, z1, group,
          length, moment, first, accumulate, max_hops):
    """Walk the segment (x0, y0, z0) -> (x1, y1, z1) starting in face f.

    If ``accumulate``, add each clipped piece's length to ``length[face, group]``, its
    length-weighted direction moment ``l d d^T`` (xx, yy, zz, xy, xz, yz) to ``moment[face, group]``
    and its first moment ``l x_mid`` (x_mid the piece's midpoint) to ``first[face, group]``.
    Returns (face holding the end point or -1 if the walk left the mesh, length not assigned, m).
    """
    dx = x1 - x0
    dy = y1 - y0
    dz = z1 - z0
    seg = np.sqrt(dx * dx + dy * dy + dz * dz)
    if seg == 0.0:
        return f, 0.0
    ux = dx / seg
    uy = dy / seg
    uz = dz / seg
    t = 0.0
    for _ in range(max_hops):
        t_exit = 1.0
        exit_edge = -1
        for j in range(3):
            mx = plane_normal[f, j, 0]
            my = plane_normal[f, j, 1]
            mz = plane_normal[f, j, 2]
            rate = mx * dx + my * dy + mz * dz
            if rate < 0.0:
                dist0 = mx * x0 + my * y0 + mz * z0 - plane_offset[f, j]
                tj = -dist0 / rate
                if tj < t_exit:
                    t_exit = tj
                    exit_edge = j
        if t_exit < t:  # already (numerically) past that plane: hand over at once
            t_exit = t
        piece = (t_exit - t) * seg
        if accumulate and piece > 0.0:
            length[f, group] += piece
            moment[f, group, 0] += piece * ux * ux
            moment[f, group, 1] += piece * uy * uy
            moment[f, group, 2] += piece * uz * uz
            moment[f, group, 3] += piece * ux * uy
            moment[f, group, 4] += piece * ux * uz
            moment[f, group, 5] += piece * uy * uz
            t_mid = 0.5 * (t + t_exit)
            first[f, group, 0] += piece * (x0 + t_mid * dx)
            first[f, group, 1] += piece * (y0 + t_mid * dy)
            first[f, group, 2] += piece * (z0 + t_mid * dz)
        if exit_edge < 0:
            return f, 0.0
        g = neighbour[f, exit_edge]
        if g < 0:
            return -1, (1.0 - t_exit) * seg
        f = g
        t = t_exit
    return -1, (1.0 - t) * seg


@njit(cache=True)
def clip_polylines(points, offsets, group, seed_face, centroid, plane_normal, plane_offset,
                   neighbour, n_faces, max_hops):
    """Per-face, per-group yarn length and direction moment of all polylines.

    points : (m, 3) float64, m, polyline points; polyline k is points[offsets[k]:offsets[k + 1]]
    offsets : (n + 1,) int64;  group : (n,) int64, 0 or 1
    seed_face : (m,) int64, a face near each point (its nearest centroid): where the first point
        of a polyline (or the first point after the walk left the mesh) is located, by walking
        from that face's centroid to the point
    returns : length (n_faces, 2) float64 m; moment (n_faces, 2, 6) float64 m (sum of l d d^T,
        components xx, yy, zz, xy, xz, yz); first (n_faces, 2, 3) float64 m^2 (sum of l x_mid);
        unmapped (float64, m, yarn length that lies beyond
        a boundary edge of an open mesh or was not located)
    """
    # np.bool_, not a bare True / False: numba types a bare one as a literal and compiles _walk
    # once for each value (about 1 s more on a first run); the branch costs nothing here
    LOCATE = np.bool_(False)
    ACCUMULATE = np.bool_(True)
    length = np.zeros((n_faces, 2))
    moment = np.zeros((n_faces, 2, 6))
    first = np.zeros((n_faces, 2, 3))
    unmapped = 0.0
    for k in range(offsets.size - 1):
        g = group[k]
        f = -1
        for i in range(offsets[k], offsets[k + 1] - 1):
            x0 = points[i, 0]
            y0 = points[i, 1]
            z0 = points[i, 2]
            x1 = points[i + 1, 0]
            y1 = points[i + 1, 1]
            z1 = points[i + 1, 2]
            if f < 0:  # locate the start point: walk there from a nearby centroid
                s = seed_face[i]
                f, _ = _walk(plane_normal, plane_offset, neighbour, s, centroid[s, 0], centroid[s, 1],
                             centroid[s, 2], x0, y0, z0, g, length, moment, first, LOCATE,
                             max_hops)
            if f < 0:
                dx = x1 - x0
                dy = y1 - y0
                dz = z1 - z0
                unmapped += np.sqrt(dx * dx + dy * dy + dz * dz)
                continue
            f, lost = _walk(plane_normal, plane_offset, neighbour, f, x0, y0, z0, x1, y1, z1, g,
                            length, moment, first, ACCUMULATE, max_hops)
            unmapped += lost
    return length, moment, first, unmapped


#: below this many entries a range is finished by insertion sort (numba's ``SMALL_QUICKSORT``)
_SMALL_SORT = 15


@njit(cache=True)
def cell_order(keys):
    """``np.argsort(keys)`` of an int64 array as numba compiles it (its quicksort: median-of-three
    pivot, the larger part pushed on a stack, ranges below ``_SMALL_SORT`` by insertion sort), step
    for step, so equal keys come out in numba's order and the pooled sums keep their summation
    order. Written out here as one function: numba's generic sort compiles seven (about 1 s on a
    first run)."""
    n = keys.shape[0]
    R = np.arange(n)
    if n < 2:
        return R
    stack_lo = np.empty(100, dtype=np.int64)
    stack_hi = np.empty(100, dtype=np.int64)
    stack_lo[0] = 0
    stack_hi[0] = n - 1
    top = 1
    while top > 0:
        top -= 1
        low = stack_lo[top]
        high = stack_hi[top]
        while high - low >= _SMALL_SORT:
            mid = (low + high) >> 1
            if keys[R[mid]] < keys[R[low]]:
                R[low], R[mid] = R[mid], R[low]
            if keys[R[high]] < keys[R[mid]]:
                R[high], R[mid] = R[mid], R[high]
            if keys[R[mid]] < keys[R[low]]:
                R[low], R[mid] = R[mid], R[low]
            pivot = keys[R[mid]]
            R[high], R[mid] = R[mid], R[high]
            i = low
            j = high - 1
            while True:
                while i < high and keys[R[i]] < pivot:
                    i += 1
                while j >= low and pivot < keys[R[j]]:
                    j -= 1
                if i >= j:
                    break
                R[i], R[j] = R[j], R[i]
                i += 1
                j -= 1
            R[i], R[high] = R[high], R[i]
            if high - i > i - low:
                if high > i:
                    stack_lo[top] = i + 1
                    stack_hi[top] = high
                    top += 1
                high = i - 1
            else:
                if i > low:
                    stack_lo[top] = low
                    stack_hi[top] = i - 1
                    top += 1
                low = i + 1
        for i in range(low + 1, high + 1):
            k = R[i]
            v = keys[k]
            j = i
            while j > low and v < keys[R[j - 1]]:
                R[j] = R[j - 1]
                j -= 1
            R[j] = k
    return R


@njit(cache=True)
def pool_sums(centroids, sources, normals, radius, values, cos_crease):
    """Kernel-weighted sums of per-face values over each face's neighbourhood.

    out[f] = values[f] + sum over g != f with |s_g - c_f| < radius[f] and n_f . n_g >= cos_crease
    of (1 - (d / radius[f])^2)^2 values[g]  (biweight kernel of the distance d = |s_g - c_f|
    from the window's centre, face f's centroid c_f, to where face g's value sits, s_g: its
    centroid for areas, the centre of its yarn pieces for yarn sums).
    Neighbours are found on a uniform grid of cell size max(radius) (sorted cell keys, binary
    search), so memory stays O(nf) however many neighbours a face has.

    centroids, sources, normals : (nf, 3) float64;  radius : (nf,) float64, m, > 0
    values : (nf, c) float64;  returns (nf, c) float64
    """
    nf = centroids.shape[0]
    nc = values.shape[1]
    out = np.zeros((nf, nc))
    if nf == 0:
        return out
    # the grid's cell, origin and extent by plain loops (min and max are exact, so these are
    # the values of radius.max() and the columns' min / max; the array methods on column views
    # compile numba's generic reductions for two layouts, about 2 s on a first run)
    cell = radius[0]
    for f in range(1, nf):
        cell = max(cell, radius[f])
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = min(centroids[0, a], sources[0, a])
        hi[a] = max(centroids[0, a], sources[0, a])
        for f in range(1, nf):
            lo[a] = min(lo[a], centroids[f, a], sources[f, a])
            hi[a] = max(hi[a], centroids[f, a], sources[f, a])
    dims = np.empty(3, dtype=np.int64)
    for a in range(3):
        dims[a] = int((hi[a] - lo[a]) / cell) + 1
    idx = np.empty((nf, 3), dtype=np.int64)
    keys = np.empty(nf, dtype=np.int64)
    for f in range(nf):
        for a in range(3):
            idx[f, a] = int((sources[f, a] - lo[a]) / cell)
        keys[f] = idx[f, 0] + dims[0] * (idx[f, 1] + dims[1] * idx[f, 2])
    order = cell_order(keys)
    sorted_keys = keys[order]
    cidx = np.empty(3, dtype=np.int64)
    for f in range(nf):
        r = radius[f]
        r2 = r * r
        reach = int(np.ceil(r / cell))
        for a in range(3):
            cidx[a] = int((centroids[f, a] - lo[a]) / cell)
        for cz in range(max(0, cidx[2] - reach), min(dims[2], cidx[2] + reach + 1)):
            for cy in range(max(0, cidx[1] - reach), min(dims[1], cidx[1] + reach + 1)):
                for cx in range(max(0, cidx[0] - reach), min(dims[0], cidx[0] + reach + 1)):
                    key = cx + dims[0] * (cy + dims[1] * cz)
                    # q: the first index with sorted_keys[q] >= key, np.searchsorted(sorted_keys,
                    # key) by bisection (numba's searchsorted compiles its generic comparisons,
                    # complex numbers included: about 1.5 s on a first run)
                    q = 0
                    top = nf
                    while q < top:
                        mid = (q + top) // 2
                        if sorted_keys[mid] < key:
                            q = mid + 1
                        else:
                            top = mid
                    while q < nf and sorted_keys[q] == key:
                        g = order[q]
                        q += 1
                        if g == f:
                            weight = 1.0
                        else:
                            ex = sources[g, 0] - centroids[f, 0]
                            ey = sources[g, 1] - centroids[f, 1]
                            ez = sources[g, 2] - centroids[f, 2]
                            d2 = ex * ex + ey * ey + ez * ez
                            if d2 >= r2:
                                continue
                            facing = (normals[f, 0] * normals[g, 0] + normals[f, 1] * normals[g, 1]
                                      + normals[f, 2] * normals[g, 2])
                            if facing < cos_crease:
                                continue
                            u = 1.0 - d2 / r2
                            weight = u * u
                        for c in range(nc):
                            out[f, c] += weight * values[g, c]
    return out
