"""Numba kernels of the relaxation's block LDL^T (``preform/interaction/relax.py``): the pattern of
a matrix of blocks per pair of crossings linked by a segment, its elimination orders (the band
dissection), its symbolic analysis, and one factorisation and one solve kernel generic in the
block size (``_block_ldl``), compiled for 3 x 3 blocks (the crossings' positions,
``ldl_numeric3`` / ``ldl_solve3``) and 5 x 5 blocks (with their materials, the ``"full"``
preconditioner, ``ldl_numeric5`` / ``ldl_solve5``). QDLDL's up-looking algorithm (Davis 2005;
QDLDL, Apache-2.0) with every scalar a block. The slow twins are in
``tests/support/naive_relax.py`` and the dense solves of ``tests/validation/test_relax.py`` and
``tests/validation/test_relax_ring.py``.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def _flat_tuple(typingctx, arr, start, size):
    """The tuple (arr.flat[start], ..., arr.flat[start + size - 1]) of a C-contiguous array, size
    a compile-time constant: a block held in locals (registers), which loads from the array
    would not be, as stores to another array may alias it."""
    if not (isinstance(arr, types.Array) and arr.layout == "C"
            and isinstance(size, types.IntegerLiteral)):
        return None
    n = size.literal_value
    tup = types.UniTuple(arr.dtype, n)

    def codegen(context, builder, sig, args):
        data = context.make_array(sig.args[0])(context, builder, args[0]).data
        first = args[1]
        vals = [builder.load(builder.gep(data, [builder.add(first, ir.Constant(first.type, i))]))
                for i in range(n)]
        return context.make_tuple(builder, tup, vals)

    return tup(arr, start, size), codegen


@njit(cache=True)
def block_pattern(m, low, perm, Ap, Ai, slot_diag, slot_below, below_first):
    """The pattern of the block preconditioners in the order perm (perm[i]: the crossing at
    position i): the upper triangle, CSC of blocks, of one block per crossing and one per pair
    (c, low[c, side]) (a pair given twice shares its block). Ap (m + 1,) the column starts,
    Ai (3m,) the rows, sorted within each column (the first Ap[m] used); slot_diag (m,) the
    slot of c's diagonal block, slot_below (m, 2) the slot of the pair (c, low[c, side]) (-1
    none), below_first (m, 2) True where low[c, side] comes first in the order (the slot holds
    the block (low, c)). Returns the number of slots."""
    pinv = np.empty(m, dtype=np.int64)
    for i in range(m):
        pinv[perm[i]] = i
    count = np.zeros(m + 1, dtype=np.int64)
    for c in range(m):
        count[pinv[c] + 1] += 1
        for side in range(2):
            lo = low[c, side]
            if lo >= 0:
                count[max(pinv[c], pinv[lo]) + 1] += 1
    for j in range(m):
        count[j + 1] += count[j]
    rows = np.empty(count[m], dtype=np.int64)
    owner = np.empty(count[m], dtype=np.int64)     # -1 - c: c's diagonal; 2 c + side: a pair
    fill = count[:m].copy()
    for c in range(m):
        pc = pinv[c]
        rows[fill[pc]] = pc
        owner[fill[pc]] = -1 - c
        fill[pc] += 1
        for side in range(2):
            lo = low[c, side]
            slot_below[c, side] = -1
            below_first[c, side] = False
            if lo >= 0:
                pl = pinv[lo]
                j = max(pc, pl)
                rows[fill[j]] = min(pc, pl)
                owner[fill[j]] = 2 * c + side
                fill[j] += 1
                below_first[c, side] = pl < pc
    nslots = 0
    Ap[0] = 0
    for j in range(m):
        a, b = count[j], count[j + 1]
        # insertion sort of the column's few entries by row
        for i in range(a + 1, b):
            r, o = rows[i], owner[i]
            k = i - 1
            while k >= a and rows[k] > r:
                rows[k + 1] = rows[k]
                owner[k + 1] = owner[k]
                k -= 1
            rows[k + 1] = r
            owner[k + 1] = o
        for i in range(a, b):
            if i == a or rows[i] != rows[i - 1]:
                Ai[nslots] = rows[i]
                nslots += 1
            o = owner[i]
            if o < 0:
                slot_diag[-1 - o] = nslots - 1
            else:
                slot_below[o // 2, o % 2] = nslots - 1
        Ap[j + 1] = nslots
    return nslots


@njit(cache=True)
def ldl_symbolic(n, Ap, Ai, work, Lnz, etree):
    """Elimination tree etree (n,) and column counts Lnz (n,) of the block LDL^T of a symmetric
    matrix given by the pattern of its upper triangle (CSC: Ap (n+1,), Ai, rows <= column; one
    entry per 3 x 3 block), QDLDL's ``QDLDL_etree`` (Davis 2005, section 4.1). work (n,) is
    scratch. Returns the number of blocks of L below the diagonal, -1 if an entry lies below
    the diagonal."""
    for i in range(n):
        work[i] = 0
        Lnz[i] = 0
        etree[i] = -1
    for j in range(n):
        work[j] = j
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            if i > j:
                return -1
            while work[i] != j:
                if etree[i] == -1:
                    etree[i] = j
                Lnz[i] += 1
                work[i] = j
                i = etree[i]
    total = 0
    for i in range(n):
        total += Lnz[i]
    return total


@njit(cache=True)
def _inverse3(A, out):
    """out = A^-1 of a symmetric 3 x 3 block; False if A is not positive definite (a leading
    minor or the determinant not positive)."""
    a00, a01, a02 = A[0, 0], A[0, 1], A[0, 2]
    a11, a12, a22 = A[1, 1], A[1, 2], A[2, 2]
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if not (a00 > 0.0 and a00 * a11 - a01 * a01 > 0.0 and det > 0.0):
        return False
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[0, 1] = out[1, 0] = c01 * inv
    out[0, 2] = out[2, 0] = c02 * inv
    out[1, 1] = (a00 * a22 - a02 * a02) * inv
    out[1, 2] = out[2, 1] = (a01 * a02 - a00 * a12) * inv
    out[2, 2] = (a00 * a11 - a01 * a01) * inv
    return True


@njit(cache=True)
def _inverse_spd(A, nb, out, L):
    """out = A^-1 of a symmetric nb x nb block by its Cholesky factor (L (nb, nb) scratch);
    False if A is not positive definite."""
    for j in range(nb):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        L[j, j] = d
        for i in range(j + 1, nb):
            v = A[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / d
    # out = L^-T L^-1, column by column of the identity
    for col in range(nb):
        for i in range(nb):
            v = 1.0 if i == col else 0.0
            for k in range(i):
                v -= L[i, k] * out[k, col]
            out[i, col] = v / L[i, i]
        for i in range(nb - 1, -1, -1):
            v = out[i, col]
            for k in range(i + 1, nb):
                v -= L[k, i] * out[k, col]
            out[i, col] = v / L[i, i]
    return True


@njit(cache=True, inline="always")
def _reach(i, k, etree, marker, elim, y_idx, nnz_y):
    """Append to y_idx[nnz_y:] the rows of row k's pattern reached from i up the elimination tree
    (unmarked rows below k, marked on the way), in topological order (QDLDL's ``QDLDL_factor``);
    returns the new count."""
    marker[i] = True
    elim[0] = i
    ne = 1
    j = etree[i]
    while j != -1 and j < k:
        if marker[j]:
            break
        marker[j] = True
        elim[ne] = j
        ne += 1
        j = etree[j]
    while ne:
        ne -= 1
        y_idx[nnz_y] = elim[ne]
        nnz_y += 1
    return nnz_y


def _block_ldl(nb):
    """The factorisation and solve kernels of a block LDL^T with nb x nb blocks (``ldl_numeric``,
    ``ldl_solve``), compiled for that nb: nb is a constant of the closure, so every block loop
    has a fixed trip count that LLVM unrolls, and the numba cache keys each size apart (the
    closure's contents are part of its index key)."""
    nb2 = nb * nb

    @njit(cache=True, fastmath=True)
    def ldl_numeric(n, Ap, Ai, Ax, Lp, Li, Lx, Dinv, etree, Lnz, marker, y_idx, elim, next_space,
                    y, D):
        """Block LDL^T factorisation A = L D L^T of a symmetric positive definite matrix of
        nb x nb blocks: QDLDL's up-looking ``QDLDL_factor`` with every scalar a block (for each
        row k of L, its pattern from the elimination tree, then a sparse triangular solve:
        y_j -= L_ji y_i, L_ki = y_i^T D_i^-1, D_k -= L_ki y_i). A: upper triangle, CSC of blocks
        (Ap, Ai, Ax (nnz, nb, nb), Ax[p] the block (Ai[p], column)); out: Lp (n+1,), Li, Lx
        (nnz_L, nb, nb) the strictly lower blocks by column, Dinv (n, nb, nb) the inverses of
        the diagonal blocks of D (3 x 3: in closed form, ``_inverse3``; larger: by their
        Cholesky factors, ``_inverse_spd``). etree, Lnz from ``ldl_symbolic``; marker (n,) bool,
        y_idx, elim, next_space (n,) int64, y (n, nb, nb), D (nb, nb) scratch; Lx and y
        C-contiguous (their blocks are read as tuples, ``_flat_tuple``). Returns False if a
        pivot block is not positive definite."""
        T = np.empty((nb, nb))
        Lc = np.empty((nb, nb))
        Lp[0] = 0
        for i in range(n):
            marker[i] = False
            for a in range(nb):
                for b in range(nb):
                    y[i, a, b] = 0.0
            Lp[i + 1] = Lp[i] + Lnz[i]
            next_space[i] = Lp[i]
        for k in range(n):
            nnz_y = 0
            for a in range(nb):
                for b in range(nb):
                    D[a, b] = 0.0
            for p in range(Ap[k], Ap[k + 1]):
                i = Ai[p]
                if i == k:
                    for a in range(nb):
                        for b in range(nb):
                            D[a, b] = Ax[p, a, b]
                    continue
                for a in range(nb):
                    for b in range(nb):
                        y[i, a, b] = Ax[p, a, b]
                if not marker[i]:
                    nnz_y = _reach(i, k, etree, marker, elim, y_idx, nnz_y)
            for t in range(nnz_y - 1, -1, -1):
                ci = y_idx[t]
                end = next_space[ci]
                # y_ci as a tuple of locals: kept in registers across the stores to y_r
                yc = _flat_tuple(y, ci * nb2, nb2)
                for q in range(Lp[ci], end):
                    r = Li[q]
                    # y_r -= L_{r, ci} y_ci
                    for a in range(nb):
                        la = _flat_tuple(Lx, (q * nb + a) * nb, nb)
                        for b in range(nb):
                            v = la[0] * yc[b]
                            for c in range(1, nb):
                                v += la[c] * yc[c * nb + b]
                            y[r, a, b] -= v
                Li[end] = k
                # L_{k, ci} = y_ci^T Dinv_ci ; D_k -= L_{k, ci} y_ci
                for a in range(nb):
                    for b in range(nb):
                        v = yc[a] * Dinv[ci, 0, b]
                        for c in range(1, nb):
                            v += yc[c * nb + a] * Dinv[ci, c, b]
                        Lx[end, a, b] = v
                for a in range(nb):
                    la = _flat_tuple(Lx, (end * nb + a) * nb, nb)
                    for b in range(nb):
                        v = la[0] * yc[b]
                        for c in range(1, nb):
                            v += la[c] * yc[c * nb + b]
                        D[a, b] -= v
                next_space[ci] = end + 1
                for a in range(nb):
                    for b in range(nb):
                        y[ci, a, b] = 0.0
                marker[ci] = False
            # symmetrise the pivot against round-off before inverting it
            for a in range(nb):
                for b in range(a + 1, nb):
                    D[a, b] = D[b, a] = 0.5 * (D[a, b] + D[b, a])
            if nb == 3:
                ok = _inverse3(D, T)
            else:
                ok = _inverse_spd(D, nb, T, Lc)
            if not ok:
                return False
            for a in range(nb):
                for b in range(nb):
                    Dinv[k, a, b] = T[a, b]
        return True

    @njit(cache=True, fastmath=True)
    def ldl_solve(n, Lp, Li, Lx, Dinv, perm, rhs, out, x):
        """out (n, nb) = A^-1 rhs (n, nb) for the factor of ``ldl_numeric``, A in the order perm
        (perm[i]: the crossing at position i): L z = P rhs, then D^-1 in the same pass, then
        L^T y = D^-1 z, each row written back to out as it is final; x (n, nb) is scratch,
        C-contiguous."""
        for i in range(n):
            for a in range(nb):
                x[i, a] = rhs[perm[i], a]
        for i in range(n):
            # x_i is final here: L's column i updates the rows below, then D_i^-1 scales x_i
            # (the forward solve and the diagonal in one pass)
            xi = _flat_tuple(x, i * nb, nb)
            for q in range(Lp[i], Lp[i + 1]):
                r = Li[q]
                for a in range(nb):
                    v = Lx[q, a, 0] * xi[0]
                    for b in range(1, nb):
                        v += Lx[q, a, b] * xi[b]
                    x[r, a] -= v
            for a in range(nb):
                v = Dinv[i, a, 0] * xi[0]
                for b in range(1, nb):
                    v += Dinv[i, a, b] * xi[b]
                x[i, a] = v
        for i in range(n - 1, -1, -1):
            for q in range(Lp[i], Lp[i + 1]):
                r = Li[q]
                for a in range(nb):
                    v = Lx[q, 0, a] * x[r, 0]
                    for b in range(1, nb):
                        v += Lx[q, b, a] * x[r, b]
                    x[i, a] -= v
            c = perm[i]
            for a in range(nb):
                out[c, a] = x[i, a]

    return ldl_numeric, ldl_solve


#: the block LDL^T of the block preconditioner (3 x 3 blocks: the crossings' positions)
ldl_numeric3, ldl_solve3 = _block_ldl(3)
#: of the full preconditioner (5 x 5 blocks: the positions and the two materials)
ldl_numeric5, ldl_solve5 = _block_ldl(5)
#: the kernels by block size
LDL_KERNELS = {3: (ldl_numeric3, ldl_solve3), 5: (ldl_numeric5, ldl_solve5)}


@njit(cache=True)
def _neighbour_ranks(c, low, up, owner, sid, rank, n):
    """(lowest, highest) rank among the lattice neighbours (``low``/``up``) of crossing c that
    belong to the set ``sid`` (``owner``); (n, -1) if none."""
    mn = n
    mx = -1
    for s in range(2):
        for q in range(2):
            nb = low[c, s] if q == 0 else up[c, s]
            if nb >= 0 and owner[nb] == sid:
                r = rank[nb]
                if r < mn:
                    mn = r
                if r > mx:
                    mx = r
    return mn, mx


@njit(cache=True)
def _best_cut(a, b, order, low, up, owner, sid, rank, lo_r, hi_r, cnt1, cnt2, lo_t, hi_t):
    """The smallest vertex separator of the set ``sid`` (sorted in order[a:b]) among the cuts
    at ranks t in [lo_t, hi_t] (first part: ranks < t): variant 0, the first part's crossings
    with a neighbour at rank >= t; variant 1, the second part's with one at rank < t. A
    crossing at rank i with neighbours at ranks mn..mx is in variant 0's separator for t in
    (i, mx] and in variant 1's for t in (mn, i], so both counts for every t come from one
    pass and a running sum (cnt1, cnt2 (n + 2,) scratch). rank, lo_r, hi_r (m,) receive each
    crossing's rank and its neighbours' lowest and highest. Returns (size, t, variant); ties go
    to the cut nearest the middle."""
    n = b - a
    for i in range(a, b):
        rank[order[i]] = i - a
    for t in range(n + 2):
        cnt1[t] = 0
        cnt2[t] = 0
    for i in range(n):
        c = order[a + i]
        mn, mx = _neighbour_ranks(c, low, up, owner, sid, rank, n)
        lo_r[c] = mn
        hi_r[c] = mx
        if mx > i:
            cnt1[i + 1] += 1
            cnt1[mx + 1] -= 1
        if mn < i:
            cnt2[mn + 1] += 1
            cnt2[i + 1] -= 1
    best = n + 1
    bt = n // 2
    bv = 0
    s1 = 0
    s2 = 0
    for t in range(hi_t + 1):
        s1 += cnt1[t]
        s2 += cnt2[t]
        if t < lo_t:
            continue
        for var in range(2):
            size = s1 if var == 0 else s2
            if size < best or (size == best and abs(2 * t - n) < abs(2 * bt - n)):
                best = size
                bt = t
                bv = var
    return best, bt, bv


@njit(cache=True)
def _partition(a, b, order, side, n_l, n_r, buf):
    """Stable partition of order[a:b] into the first part's crossings off the separator (side
    0, n_l of them), the second part's (2, n_r), then the separator's (1)."""
    k0, k2, k1 = 0, n_l, n_l + n_r
    for i in range(a, b):
        c = order[i]
        g = side[c]
        if g == 0:
            buf[k0] = c
            k0 += 1
        elif g == 2:
            buf[k2] = c
            k2 += 1
        else:
            buf[k1] = c
            k1 += 1
    for i in range(b - a):
        order[a + i] = buf[i]


@njit(cache=True)
def band_dissection(m, low, up, u, v, leaf, window, perm):
    """Fill-reducing order of a lattice of crossings on a band around an axis, by geometric
    nested dissection (George 1973): a set of crossings, sorted by u (the angle around the
    axis) and by v (the height along it), is cut at the rank t in each sort, within ``window``
    of the set's size from its middle, that gives the smallest vertex separator, the crossings
    of one part with a lattice neighbour (``low``/``up``, (m, 2)) in the other, either part's
    (``_best_cut``); the order is the first part's, the second's, then the separator's, each
    part dissected in turn. Sets up to ``leaf`` crossings keep their order. On the whole band
    a cut in u makes two arcs at two seams, whose crossings are the first separator. The
    crossings are sorted by u and by v once and every cut partitions both sorts stably, so
    each set's crossings stay sorted: O(m) a level, O(m log m) in all. perm (m,) receives the
    order (perm[i]: the crossing at position i)."""
    owner = np.zeros(m, dtype=np.int64)
    side = np.zeros(m, dtype=np.int8)
    buf = np.empty(m, dtype=np.int64)
    rank = np.empty((2, m), dtype=np.int64)
    lo_r = np.empty((2, m), dtype=np.int64)
    hi_r = np.empty((2, m), dtype=np.int64)
    cnt1 = np.empty(m + 2, dtype=np.int64)
    cnt2 = np.empty(m + 2, dtype=np.int64)
    by_u = np.argsort(u)
    by_v = np.argsort(v)
    stack = np.empty((2 * m + 2, 3), dtype=np.int64)
    stack[0, 0] = 0
    stack[0, 1] = m
    stack[0, 2] = 0
    top = 1
    next_id = 1
    while top:
        top -= 1
        a, b, sid = stack[top, 0], stack[top, 1], stack[top, 2]
        n = b - a
        if n <= leaf:
            continue
        lo_t = max(1, int(math.ceil((0.5 - window) * n)))
        hi_t = min(n - 1, int(math.floor((0.5 + window) * n)))
        if hi_t < lo_t:
            lo_t = hi_t = n // 2
        s_v, t_v, var_v = _best_cut(a, b, by_v, low, up, owner, sid, rank[0], lo_r[0],
                                    hi_r[0], cnt1, cnt2, lo_t, hi_t)
        s_u, t_u, var_u = _best_cut(a, b, by_u, low, up, owner, sid, rank[1], lo_r[1],
                                    hi_r[1], cnt1, cnt2, lo_t, hi_t)
        if s_v <= s_u:
            d, t, var, n_s = 0, t_v, var_v, s_v
        else:
            d, t, var, n_s = 1, t_u, var_u, s_u
        id_l, id_r = next_id, next_id + 1
        next_id += 2
        for i in range(a, b):
            c = by_u[i]
            if rank[d, c] < t:
                side[c] = 1 if (var == 0 and hi_r[d, c] >= t) else 0
            else:
                side[c] = 1 if (var == 1 and lo_r[d, c] < t) else 2
            owner[c] = id_l if side[c] == 0 else (id_r if side[c] == 2 else -1)
        n_l = t - n_s if var == 0 else t
        _partition(a, b, by_u, side, n_l, n - n_l - n_s, buf)
        _partition(a, b, by_v, side, n_l, n - n_l - n_s, buf)
        stack[top, 0] = a
        stack[top, 1] = a + n_l
        stack[top, 2] = id_l
        stack[top + 1, 0] = a + n_l
        stack[top + 1, 1] = b - n_s
        stack[top + 1, 2] = id_r
        top += 2
    for i in range(m):
        perm[i] = by_u[i]
