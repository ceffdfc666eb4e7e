"""The block preconditioner's fixed cost per iteration and its order (the
cost per crossing per iteration flat in the zone's size): the nested dissection
(``_kernels.ldl.band_dissection``) against a slow Python form of the same rule and against
METIS's fill, and the kernels that fold the block driver's array work into single calls
(``anderson_step``, ``block_wall``, ``wall_project``, ``jam_changed``, ``same_flags``) against
the NumPy operations they replace."""

from __future__ import annotations

import math

import numpy as np
import pymetis
import pytest

from support.naive_relax import block_fill, pattern_keys
from preform._kernels import ldl as LDL
from preform._kernels import relax as RK
from preform._kernels import stiffness as SK
from preform._kernels import zone as KZ


def band_lattice(width, rows, seed=0):
    """A braid-like lattice on a cylinder: ``width`` crossings a row around, ``rows`` rows;
    crossing (r, p) = r * width + p has its warp neighbour below at (r - 1, p) and its weft
    neighbour below at (r - 1, p + 1) (around the circle). Returns low, up (m, 2), u (the arc
    length around, with a small jitter that breaks ties of the sorts) and v (the height)."""
    rng = np.random.default_rng(seed)
    m = width * rows
    low = np.full((m, 2), -1, dtype=np.int64)
    up = np.full((m, 2), -1, dtype=np.int64)
    for r in range(rows):
        for p in range(width):
            c = r * width + p
            if r > 0:
                low[c, 0] = (r - 1) * width + p
                low[c, 1] = (r - 1) * width + (p + 1) % width
            if r + 1 < rows:
                up[c, 0] = (r + 1) * width + p
                up[c, 1] = (r + 1) * width + (p - 1) % width
    r, p = np.divmod(np.arange(m), width)
    angle = np.angle(np.exp(2j * np.pi * (p + 0.5 * r) / width))
    u = 0.075 * angle + 1e-7 * rng.random(m)
    v = 2e-3 * r + 1e-9 * rng.random(m)
    return low, up, u, v


def slow_dissection(low, up, u, v, leaf, window):
    """The rule ``band_dissection`` documents, written out on Python sets: every cut at rank t
    within ``window`` of the middle in the sort by v and by u, the separator either part's
    crossings with a neighbour in the other, the smallest (ties: nearest the middle, then the
    lower t, the first part's separator, v before u); the parts in turn, the separator last;
    a set up to ``leaf`` crossings sorted by u."""
    nbrs = [{x for x in (*low[c], *up[c]) if x >= 0} for c in range(len(u))]

    def order(S):
        n = len(S)
        if n <= leaf:
            return sorted(S, key=lambda c: u[c])
        lo_t = max(1, math.ceil((0.5 - window) * n))
        hi_t = min(n - 1, math.floor((0.5 + window) * n))
        if hi_t < lo_t:
            lo_t = hi_t = n // 2
        inside = set(S)
        found = []
        for coord in (v, u):
            srt = sorted(S, key=lambda c: coord[c])
            best = None
            for t in range(lo_t, hi_t + 1):
                first, second = set(srt[:t]), set(srt[t:])
                for var in (0, 1):
                    mine, other = (first, second) if var == 0 else (second, first)
                    sep = {c for c in mine if nbrs[c] & inside & other}
                    key = (len(sep), abs(2 * t - n))
                    if best is None or key < best[0]:
                        best = (key, first - sep, second - sep, sep)
            found.append(best)
        (_, a, b, sep) = found[0] if found[0][0][0] <= found[1][0][0] else found[1]
        return order(a) + order(b) + sorted(sep, key=lambda c: u[c])

    return np.array(order(list(range(len(u)))), dtype=np.int64)


@pytest.mark.parametrize("width, rows, leaf, window", [(12, 7, 4, 0.15), (24, 12, 4, 0.15),
                                                       (16, 9, 8, 0.0), (20, 10, 1, 0.3)])
def test_band_dissection_is_the_documented_rule(width, rows, leaf, window):
    """``band_dissection`` gives the order of the slow form of its rule, exactly."""
    low, up, u, v = band_lattice(width, rows)
    m = low.shape[0]
    perm = np.empty(m, dtype=np.int64)
    LDL.band_dissection(m, low, up, u, v, leaf, window, perm)
    assert np.array_equal(perm, slow_dissection(low, up, u, v, leaf, window))


def test_band_dissection_fill_at_most_metis():
    """On a lattice of case A's size at 144 carriers (72 crossings around, 40 rows) the factor
    in the default order (leaf 4, window 0.15) fills no more than in METIS's nested
    dissection (measured on captured case A steps: 11.5-11.8 blocks a column against METIS's
    12.3), and less than with the median cut (leaf 8, window 0: 14.6-14.8)."""
    low, up, u, v = band_lattice(72, 40)
    m = low.shape[0]
    perm = np.empty(m, dtype=np.int64)
    LDL.band_dissection(m, low, up, u, v, 4, 0.15, perm)
    assert np.array_equal(np.sort(perm), np.arange(m))
    ours = block_fill(low, perm)
    LDL.band_dissection(m, low, up, u, v, 8, 0.0, perm)
    median_cut = block_fill(low, perm)
    both = np.concatenate([low, up], axis=1)
    xadj = np.zeros(m + 1, dtype=np.int32)
    adj = [sorted({x for x in both[c] if x >= 0}) for c in range(m)]
    xadj[1:] = np.cumsum([len(a) for a in adj])
    metis, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(
        xadj, np.concatenate(adj).astype(np.int32)))
    theirs = block_fill(low, np.asarray(metis, dtype=np.int64))
    assert ours <= theirs
    assert ours < median_cut


def _wall_problem(seed, release=1e-4):
    """A lattice with random positions, forces, force densities, planes (unit normals) and
    resting crossings, and a block update of the size of the release distance (some
    crossings join, some leave)."""
    rng = np.random.default_rng(seed)
    low, up, _, _ = band_lattice(10, 6, seed)
    m = low.shape[0]
    pos = rng.normal(size=(m, 3)) * 1e-2
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    active = rng.random(m) < 0.4
    gap = np.where(active, 0.0, rng.uniform(0.0, 3 * release, m))
    plane = np.concatenate([pos - gap[:, None] * n, n], axis=1)
    delta = rng.normal(size=(m, 3)) * 2 * release
    force = rng.normal(size=(m, 3)) * 1e-2
    w_below = rng.uniform(1.0, 10.0, (m, 2))
    W = rng.uniform(20.0, 40.0, m)
    return low, up, pos, plane, active, delta, force, w_below, W, release


@pytest.mark.parametrize("seed", range(6))
def test_block_wall_matches_the_array_form(seed):
    """``block_wall`` gives the update, active set, wall forces and change flag of the NumPy
    operations it replaces (the block driver's wall step), bit for bit."""
    low, up, pos, plane, active, delta, force, w_below, W, release = _wall_problem(seed)
    m = low.shape[0]
    # the array form
    d = delta.copy()
    a = active.copy()
    wf = np.empty(m)
    dist = np.empty(m)
    moved = d.copy()
    d[a] = 0.0
    RK.wall_update(m, low, up, w_below, force, pos, d, W, plane, a, release, wf)
    RK.wall_distance(m, pos + d, plane, dist)
    stay = a & (dist <= release)
    d[stay] = moved[stay]
    want = pos + d
    RK.wall_distance(m, want, plane, dist)
    join = ~a & (dist < -release)
    leave = a & (dist > release)
    want[join] -= dist[join, None] * plane[join, 3:]
    want_active = (a | join) & ~leave
    assert join.any() and leave.any()       # the problem exercises both
    # the kernel
    d2 = delta.copy()
    a2 = active.copy()
    wf2 = np.empty(m)
    new = np.empty((m, 3))
    changed = RK.block_wall(m, low, up, w_below, force, pos, d2, W, plane, a2, release, wf2,
                            np.empty((m, 3)), new)
    assert changed == bool(join.any() or leave.any())
    assert np.array_equal(new, want)
    assert np.array_equal(d2, d)
    assert np.array_equal(a2, want_active)
    assert np.array_equal(wf2, wf)
    # nothing changes where nothing crosses the thresholds
    a3 = np.zeros(m, dtype=np.bool_)
    far = plane.copy()
    far[:, :3] = pos - 1.0 * plane[:, 3:]
    assert not RK.block_wall(m, low, up, w_below, force, pos, delta.copy(), W, far, a3,
                             release, wf2, np.empty((m, 3)), new)
    assert np.array_equal(new, pos + delta) and not a3.any()


@pytest.mark.parametrize("seed", range(4))
def test_wall_project_matches_the_array_form(seed):
    """``wall_project`` projects and joins as the NumPy operations it replaces, bit for bit."""
    low, up, pos, plane, active, delta, _, _, _, release = _wall_problem(seed)
    m = low.shape[0]
    x = pos + delta
    dist = np.empty(m)
    RK.wall_distance(m, x, plane, dist)
    behind = (dist < 0.0) & active | (dist < -release)
    want = x.copy()
    want[behind] -= dist[behind, None] * plane[behind, 3:]
    assert (behind & ~active).any() and (behind & active).any()
    a2 = active.copy()
    joined = RK.wall_project(m, x, plane, a2, release)
    assert joined == bool((behind & ~active).any())
    assert np.array_equal(x, want)
    assert np.array_equal(a2, active | behind)


def test_jam_changed_and_same_flags():
    """``jam_changed``: the jammed segments ``(l < l_jam) & (low >= 0)`` and whether they
    differ from the factorised set (any change, or only a newly jammed segment);
    ``same_flags`` is ``np.array_equal``."""
    rng = np.random.default_rng(3)
    low, _, _, _ = band_lattice(8, 5)
    m = low.shape[0]
    l_below = rng.uniform(0.0, 2.0, (m, 2))
    want = (l_below < 1.0) & (low >= 0)
    jammed = np.empty((m, 2), dtype=np.bool_)
    assert not RK.jam_changed(m, low, l_below, 1.0, want.copy(), False, jammed)
    assert np.array_equal(jammed, want)
    fewer = want.copy()
    fewer[np.argwhere(want)[0][0], np.argwhere(want)[0][1]] = False
    more = want | (low >= 0)
    assert RK.jam_changed(m, low, l_below, 1.0, fewer, False, jammed)
    assert RK.jam_changed(m, low, l_below, 1.0, fewer, True, jammed)
    assert RK.jam_changed(m, low, l_below, 1.0, more, False, jammed)
    assert not RK.jam_changed(m, low, l_below, 1.0, more, True, jammed)
    a = rng.random(m) < 0.5
    b = a.copy()
    assert RK.same_flags(m, a, b)
    b[m // 2] = not b[m // 2]
    assert not RK.same_flags(m, a, b)


@pytest.mark.parametrize("k", [1, 3, 10])
def test_anderson_step_matches_the_numpy_solve(k):
    """``anderson_step``: the Gram pass of ``anderson_gram``, gamma = (G + reg I)^-1 b (reg =
    1e-12 trace G + 1e-300) as NumPy's solve (to 1e-10 relative: a solve of a system of
    condition ~1e2 by a different elimination order), and out = gx - (DX + DR) gamma;
    status 0 with no difference held."""
    rng = np.random.default_rng(k)
    n, depth = 40, 10
    x, gx = rng.normal(size=n), rng.normal(size=n)
    DX, DR = rng.normal(size=(n, depth)), rng.normal(size=(n, depth))
    x_prev, r_prev = rng.normal(size=n), rng.normal(size=n)
    G = np.zeros((depth, depth))
    G[:k, :k] = DR[:, :k].T @ DR[:, :k]
    j = k - 1
    args = [arr.copy() for arr in (x_prev, r_prev, DX, DR, G)]
    b_ref = np.empty(depth)
    RK.anderson_gram(n, x, gx, *args, k, j, True, b_ref)
    Gk = args[4][:k, :k]
    gamma = np.linalg.solve(Gk + (1e-12 * np.trace(Gk) + 1e-300) * np.eye(k), b_ref[:k])
    want = gx - (args[2][:, :k] + args[3][:, :k]) @ gamma
    mine = [arr.copy() for arr in (x_prev, r_prev, DX, DR, G)]
    b, out = np.empty(depth), np.empty(n)
    status = RK.anderson_step(n, x, gx, *mine, k, j, True, b, np.empty((depth, depth)),
                              np.empty(depth), out)
    assert status == 1
    for got, ref in zip(mine, args):
        assert np.array_equal(got, ref)
    assert np.allclose(out, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())
    assert RK.anderson_step(n, x, gx, *[arr.copy() for arr in (x_prev, r_prev, DX, DR, G)],
                            0, 0, False, b, np.empty((depth, depth)), np.empty(depth),
                            out) == 0
    # the same iterate and residual again: zero differences, gamma 0 (reg keeps the pivot
    # off zero, as in NumPy's solve), the mix is gx
    zero = np.zeros((n, depth))
    assert RK.anderson_step(n, np.zeros(n), r_prev, np.zeros(n), r_prev.copy(), zero.copy(),
                            zero.copy(), np.zeros((depth, depth)), 1, 0, True, b,
                            np.empty((depth, depth)), np.empty(depth), out) == 1
    assert np.array_equal(out, r_prev)


def _pattern_by_unique(low, perm):
    """The block pattern by NumPy's unique on the keys column * m + row (the form
    ``block_pattern`` replaces): Ap, Ai, slot_diag, slot_below, below_first."""
    m = low.shape[0]
    keys, pc, plo, link = pattern_keys(low, perm)
    uniq, inv = np.unique(keys, return_inverse=True)
    slot_below = np.full(low.shape, -1, dtype=np.int64)
    slot_below[link] = inv[m:]
    Ap = np.zeros(m + 1, dtype=np.int64)
    np.add.at(Ap, uniq // m + 1, 1)
    return np.cumsum(Ap), uniq % m, inv[:m], slot_below, link & (plo < pc)


@pytest.mark.parametrize("seed", range(3))
def test_block_pattern_matches_unique(seed):
    """``block_pattern`` gives the pattern and slots of the keys' unique (a pair given twice,
    both yarns of a crossing running to the same crossing below, shares one block)."""
    rng = np.random.default_rng(seed)
    low, up, u, v = band_lattice(9, 6, seed)
    m = low.shape[0]
    low[20, 1] = low[20, 0]      # the same pair twice
    perm = rng.permutation(m).astype(np.int64)
    Ap, Ai = np.empty(m + 1, dtype=np.int64), np.empty(3 * m, dtype=np.int64)
    sd, sb = np.empty(m, dtype=np.int64), np.empty((m, 2), dtype=np.int64)
    bf = np.empty((m, 2), dtype=np.bool_)
    n = LDL.block_pattern(m, low, perm, Ap, Ai, sd, sb, bf)
    want = _pattern_by_unique(low, perm)
    assert n == want[1].size and sb[20, 0] == sb[20, 1]
    for got, ref in zip((Ap, Ai[:n], sd, sb, bf), want):
        assert np.array_equal(got, ref)


@pytest.fixture(scope="module")
def step16():
    """A 16-carrier case A step with friction 0.25 after 60 steps (``simcase.capture_step``),
    perturbed by 2 mm so that the materials and tensions are away from balance."""
    from support.simcase import advanced_stepper, capture_step, case_a_interaction_config

    st, bc, f_top, s_old = capture_step(*advanced_stepper(case_a_interaction_config(16, 0.25), 60))
    st = st.copy()
    st.pos[:st.m] += np.random.default_rng(5).normal(scale=2e-3, size=(st.m, 3))
    return st, bc, f_top, s_old


def test_fused_sweep_forces_and_block_step_match_the_separate_calls(step16):
    """``sweep`` (``segment_vectors``, ``material_sweep`` with and without the predicted
    start, the lengths kept), ``forces_residual`` (``forces``, ``wall_residual``) and
    ``block_step`` (``tangent_part``, ``ldl_solve3``, ``cap_moves``) give what the calls they
    fold together give: bit for bit, the solve (fastmath) to its round-off."""
    from preform.interaction import relax as R
    from preform.interaction import preconditioners as PC
    from preform.interaction.settings import DEFAULT

    st, bc, f_top, s_old = step16
    e, fr = DEFAULT.energy, DEFAULT.frontal
    m, ny = st.m, st.n_yarns
    lat = R.lattice_of(st)
    fell, top = np.ascontiguousarray(bc.fell), np.ascontiguousarray(bc.top)
    pos = np.ascontiguousarray(st.pos[:m])
    g, f_top = R.start_bounds(st, bc)
    EA = bc.f_spool / e.tow_strain
    rng = np.random.default_rng(8)
    active = rng.random(m) < 0.2
    nrm = rng.normal(size=(m, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    plane = np.hstack([pos, nrm])
    l_prev0 = np.empty((m, 2))
    RK.segment_vectors(m, ny, lat.yarn, pos - 1e-3, lat.normal, lat.over, lat.low, lat.highest,
                       fell, top, bc.h, e.length_smoothing, e.top_smoothing2, np.empty((m, 2, 3)),
                       l_prev0, np.empty((ny, 3)), np.empty(ny))

    def buffers():
        return dict(d_below=np.empty((m, 2, 3)), l_below=np.empty((m, 2)),
                    d_top=np.empty((ny, 3)), l_top=np.empty(ny), tension=np.empty((m, 2)),
                    chain=np.zeros(m, dtype=np.int64), work=np.zeros((m, 6)),
                    stats=np.zeros(2, dtype=np.int64), s=np.array(st.material[:m]),
                    l_prev=l_prev0.copy())

    for predict in (False, True):
        a, b = buffers(), buffers()
        RK.segment_vectors(m, ny, lat.yarn, pos, lat.normal, lat.over, lat.low, lat.highest,
                           fell, top, bc.h, e.length_smoothing, e.top_smoothing2, a["d_below"],
                           a["l_below"], a["d_top"], a["l_top"])
        wa = RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, a["l_below"], a["s"],
                               st.material_fell, s_old[:m], g, f_top, EA, e.compression,
                               fr.friction_creep, e.kappa0, 1e-10, 60, a["tension"], a["chain"],
                               a["work"], a["stats"], a["l_prev"] if predict else None)
        a["l_prev"][:] = a["l_below"]
        wb = RK.sweep(lat, KZ.law(EA, e.compression, fr.friction_creep, e.kappa0, bc.h,
                                  e.length_smoothing, e.top_smoothing2, 0.0, 0.0, 1e-3),
                      KZ.problem(fell, top, st.material_fell, s_old[:m], g, f_top), pos, b["s"],
                      KZ.Segments(b["d_below"], b["l_below"], b["d_top"], b["l_top"]),
                      b["tension"], b["chain"], b["work"], b["stats"], b["l_prev"], predict,
                      True, 1e-10, 60)
        assert wa == wb
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    l_jam = float(np.quantile(a["l_below"][lat.low >= 0], 0.3))
    k_jam = 50.0
    out = [dict(force=np.empty((m, 3)), w_below=np.empty((m, 2)), w_top=np.empty(ny),
                total=np.empty(m), W=np.empty(m), res=np.empty(m)) for _ in range(2)]
    common = (m, ny, lat.yarn, lat.low, lat.highest, a["d_below"], a["l_below"], a["d_top"],
              a["l_top"], a["tension"], f_top, l_jam, k_jam, 1e-3)
    o = out[0]
    RK.forces(*common, o["force"], o["w_below"], o["w_top"], o["total"], o["W"])
    ra = RK.wall_residual(m, o["force"], o["total"], plane, active, o["W"], 1e-7, o["res"])
    o = out[1]
    law = KZ.law(EA, e.compression, fr.friction_creep, e.kappa0, bc.h, e.length_smoothing,
                 e.top_smoothing2, l_jam, k_jam, 1e-3)
    prob = KZ.problem(fell, top, st.material_fell, s_old[:m], g, f_top)
    seg = KZ.Segments(a["d_below"], a["l_below"], a["d_top"], a["l_top"])
    rb = RK.forces_residual(lat, law, prob, seg, a["tension"], plane, active, 1e-7,
                            KZ.Forces(o["force"], o["w_below"], o["w_top"], o["total"], o["W"],
                                      o["res"]))
    assert ra == rb
    for key in out[0]:
        assert np.array_equal(out[0][key], out[1][key]), key
    blk = PC.BlockStiffness(lat, pos)
    SK.block_values(lat, law, prob, seg, a["tension"], 1e-3, plane, active, blk.slots, blk.vals,
                    blk.Dg)
    assert blk.factor()
    force = out[0]["force"]
    for cap in (1e9, 1e-3):         # no scaling, and a cap that scales the update down
        rhs, want = np.empty((m, 3)), np.empty((m, 3))
        RK.tangent_part(m, force, plane, active, rhs)
        blk.solve(rhs, want)
        sa = RK.cap_moves(m, lat.low, a["l_below"], cap, np.empty(m), want)
        got = np.empty((m, 3))
        sb = SK.block_step(m, force, plane, active, lat.low, a["l_below"], cap, blk.Lp, blk.Li,
                           blk.Lx, blk.Dinv, blk.perm, np.empty((m, 3)), np.empty((m, 3)),
                           np.empty(m), got)
        # the solve is compiled with fastmath: its loops may be vectorised differently, and
        # summed in another order, inlined into block_step and with other array alignments;
        # K's condition number here is about 1e6 (reg 1e-3), so 1e-16 x 1e6 with margin
        assert np.isclose(sa, sb, rtol=1e-9, atol=0.0)
        assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
    assert sb < 1.0
