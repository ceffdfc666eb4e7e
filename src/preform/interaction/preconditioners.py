"""The preconditioners of the force-density relaxation (``relax.py`` says what each does and
why): the position update ``delta = K^-1 F(C)`` of an iteration, its refactorisations, its wall
step and what follows it, behind one :class:`Preconditioner` protocol with a class each:

- :class:`BlockPreconditioner` (``"block"``): the lattice's geometric stiffness in 3 x 3 blocks;
- :class:`FullPreconditioner` (``"full"``): the Hessian in the positions and materials, 5 x 5
  blocks, with the line search on the reduced energy;
- :class:`ScalarPreconditioner` (``"scalar"``): the force-density Laplacian with block-Jacobi
  corrections.

Each keeps its own state (its matrix and factor, the jammed set it was factorised with, the
line search's trial buffers). The iteration itself (``relax._relax_held``) holds the
:class:`Iterate` they read and move, the residual's history, Anderson's mixer and the counts.
Below them the matrices' structures: :class:`Laplacian`, :class:`BlockStiffness` (pattern,
order, symbolic analysis, factor and solves), :func:`metis_order`, and :class:`Anderson`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from .._kernels import ldl as LDL
from .._kernels import relax as RK
from .._kernels import stiffness as SK
from .._kernels import zone as KZ
from .._kernels.zone import Lattice

try:    # permissive sparse LDL^T (Apache-2.0); SciPy's SuperLU otherwise
    import qdldl
except ImportError:     # pragma: no cover - qdldl is a dependency
    qdldl = None


class Laplacian:
    """The scalar Laplacian's fixed pattern (upper triangle, CSC) for a lattice, its slots and a
    factorisation whose symbolic analysis is kept."""

    def __init__(self, lat: Lattice):
        m = lat.m
        c = np.repeat(np.arange(m), 2)
        lo = lat.low.ravel()
        link = lo >= 0
        r0 = np.concatenate([np.arange(m), np.minimum(c[link], lo[link])])
        c0 = np.concatenate([np.arange(m), np.maximum(c[link], lo[link])])
        key = c0 * m + r0
        uniq, inv = np.unique(key, return_inverse=True)
        self.nslots = uniq.size
        self.slot_diag = inv[:m].astype(np.int64)
        self.slot_below = np.full(2 * m, -1, dtype=np.int64)
        self.slot_below[link] = inv[m:]
        self.slot_below = self.slot_below.reshape(m, 2)
        rows = (uniq % m).astype(np.int32)
        cols = (uniq // m).astype(np.int64)
        indptr = np.zeros(m + 1, dtype=np.int32)
        np.add.at(indptr, cols + 1, 1)
        indptr = np.cumsum(indptr).astype(np.int32)
        self.vals = np.zeros(self.nslots)
        self.A = sp.csc_matrix((self.vals.copy(), rows, indptr), shape=(m, m))
        self.solver = None

    def factor(self):
        self.A.data[:] = self.vals
        if qdldl is not None:
            if self.solver is None:
                self.solver = qdldl.Solver(self.A, upper=True)
            else:
                self.solver.update(self.A, upper=True)
        else:       # pragma: no cover
            from scipy.sparse.linalg import splu
            full = self.A + sp.triu(self.A, 1).T
            self.solver = splu(full.tocsc(), permc_spec="MMD_AT_PLUS_A",
                               options=dict(SymmetricMode=True), diag_pivot_thresh=0.0)

    def solve(self, rhs, out):
        for i in range(3):
            out[:, i] = self.solver.solve(np.ascontiguousarray(rhs[:, i]))


def metis_order(lat: Lattice):
    """METIS's nested-dissection order (perm[i]: the crossing at position i) of the lattice's
    graph (crossings, an edge per segment between two crossings)."""
    import pymetis
    m = lat.m
    c = np.repeat(np.arange(m), 2)
    lo = lat.low.ravel()
    link = lo >= 0
    a, b = c[link], lo[link]
    key = np.unique(np.concatenate([a * m + b, b * m + a]))
    rows, cols = key // m, key % m
    indptr = np.zeros(m + 1, dtype=np.int32)
    np.add.at(indptr, rows + 1, 1)
    indptr = np.cumsum(indptr).astype(np.int32)
    perm, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(indptr, cols.astype(np.int32)))
    return np.asarray(perm).astype(np.int64)


class BlockStiffness:
    """The block preconditioner K (``_kernels.stiffness.block_values``; with ``nb`` 5 the full one,
    ``full_values``) of a lattice: its pattern of nb x nb blocks in a nested-dissection order
    of the band of crossings around the machine axis (``order`` "band", ``band_dissection``
    with ``leaf`` and ``window``, ``RelaxSettings.order_leaf``, ``order_window``: the factor's
    fill grows as log m, 6-7 blocks a column at 288 crossings, 11.5-11.8 at 2900) or of the
    lattice's graph ("metis", ``metis_order``), the symbolic analysis of its block LDL^T once
    per solve, the factorisation and solves of its block size (``_kernels.ldl.LDL_KERNELS``)."""

    def __init__(self, lat: Lattice, pos, nb=3, order="band", leaf=4, window=0.15):
        m = lat.m
        self.m = m
        self.nb = nb
        if order == "metis" and m > 8:
            perm = metis_order(lat)
        else:
            r = np.hypot(pos[:, 0], pos[:, 1])
            u = np.arctan2(pos[:, 1], pos[:, 0]) * (float(r.mean()) if m else 1.0)
            perm = np.empty(m, dtype=np.int64)
            LDL.band_dissection(m, lat.low, lat.up, u, np.ascontiguousarray(pos[:, 2]), leaf,
                               window, perm)
        self.perm = perm
        self.Ap = np.empty(m + 1, dtype=np.int64)
        Ai = np.empty(3 * m, dtype=np.int64)
        self.slot_diag = np.empty(m, dtype=np.int64)
        self.slot_below = np.empty((m, 2), dtype=np.int64)
        self.below_first = np.empty((m, 2), dtype=np.bool_)
        self.nslots = LDL.block_pattern(m, lat.low, perm, self.Ap, Ai, self.slot_diag,
                                       self.slot_below, self.below_first)
        self.slots = tuple(KZ.BlockSlots(self.slot_diag, self.slot_below, self.below_first))
        self.Ai = Ai[:self.nslots]
        self.vals = np.zeros((self.nslots, nb, nb))
        self.Dg = np.empty((m, nb, nb))
        self.etree = np.empty(m, dtype=np.int64)
        self.Lnz = np.empty(m, dtype=np.int64)
        nnz = LDL.ldl_symbolic(m, self.Ap, self.Ai, np.empty(m, dtype=np.int64), self.Lnz,
                              self.etree)
        self.Lp = np.empty(m + 1, dtype=np.int64)
        self.Li = np.empty(max(nnz, 1), dtype=np.int64)
        self.Lx = np.empty((max(nnz, 1), nb, nb))
        self.Dinv = np.empty((m, nb, nb))
        self._marker = np.zeros(m, dtype=np.bool_)
        self._iw = np.empty((3, m), dtype=np.int64)
        self._y = np.zeros((m, nb, nb))
        self._D = np.empty((nb, nb))
        self._x = np.empty((m, nb))
        self._rhs = np.zeros((m, nb))
        self._out = np.empty((m, nb))
        self.factored = 0

    #: the last structure built with an order that depends on the lattice alone ("metis"):
    #: (nb, order, low, structure); the frontal iterations of a snapshot solve the same
    #: lattice 60 times over, and its METIS order and symbolic analysis are 20 % of their time
    _last = None

    @classmethod
    def of(cls, lat: Lattice, pos, nb=3, order="band", leaf=4, window=0.15):
        """The structure of ``lat`` (``__init__``), the last one again where it was built for
        the same block size, order ("metis") and lattice (its ``low``; the pattern and the
        order depend on nothing else). Its values and factor are scratch of the solve that
        uses it."""
        last = cls._last
        if (order == "metis" and last is not None and last[0] == nb and last[1] == order
                and last[2].shape == lat.low.shape and np.array_equal(last[2], lat.low)):
            return last[3]
        blk = cls(lat, pos, nb, order, leaf, window)
        if order == "metis":
            cls._last = (nb, order, lat.low.copy(), blk)
        return blk

    def factor(self):
        """Factorise the current ``vals``; False if a pivot is not positive definite. Each
        call counts in ``factored`` (which factor ``Lx``, ``Dinv`` hold: ``FactorCarry``)."""
        numeric = LDL.LDL_KERNELS[self.nb][0]
        self.factored += 1
        return numeric(self.m, self.Ap, self.Ai, self.vals, self.Lp, self.Li, self.Lx, self.Dinv,
                       self.etree, self.Lnz, self._marker, self._iw[0], self._iw[1], self._iw[2],
                       self._y, self._D)

    def update(self, force, plane, active, low, l_below, cap, lmin, rhs, delta):
        """delta (m, 3) = K^-1 P force, the force's tangent part at the crossings resting on
        the wall (``tangent_part``; rhs (m, 3) scratch), scaled down to ``cap`` times each
        crossing's shortest segment (``cap_moves``); with 3 x 3 blocks in one kernel call
        (``block_step``)."""
        if self.nb == 3:
            SK.block_step(self.m, force, plane, active, low, l_below, cap, self.Lp, self.Li,
                          self.Lx, self.Dinv, self.perm, rhs, self._x, lmin, delta)
            return
        RK.tangent_part(self.m, force, plane, active, rhs)
        self.solve(rhs, delta)
        RK.cap_moves(self.m, low, l_below, cap, lmin, delta)

    def solve(self, rhs, out):
        """out (m, 3) = the position part of K^-1 (rhs, 0): with the materials among the
        unknowns (nb 5), their right-hand side is 0 (the material equations hold after every
        sweep)."""
        if self.nb == 3:
            LDL.ldl_solve3(self.m, self.Lp, self.Li, self.Lx, self.Dinv, self.perm, rhs, out,
                           self._x)
            return
        self._rhs[:, :3] = rhs
        LDL.ldl_solve5(self.m, self.Lp, self.Li, self.Lx, self.Dinv, self.perm, self._rhs,
                       self._out, self._x)
        out[:] = self._out[:, :3]


class FactorCarry:
    """The preconditioner's factorisation a relaxation left, for the next solve of the same
    lattice to start from (``RelaxSettings.reuse_factor``): the structure ``blk`` whose ``Lx``,
    ``Dinv`` hold it, which factorisation that was (``BlockStiffness.factored``), and the
    wall's active set and the jammed segments it was made with. A solve takes it where the
    structure still holds that factor and its start has the same active set; K then differs
    from one factorised at its start only by the change of the held bounds and the iterate's
    moves since, and the iteration refreshes K as it would a stale one (``due``)."""

    def __init__(self):
        self.blk = None
        self.count = -1
        self.active = None
        self.jam = None

    def keep(self, blk, active, jam):
        """Record the last factorisation of ``blk``, made with ``active`` (m,) and ``jam``
        (m, 2) bool."""
        self.blk, self.count = blk, blk.factored
        self.active, self.jam = active.copy(), jam.copy()

    def valid_for(self, blk, active) -> bool:
        """Whether ``blk`` still holds the recorded factor, made with the active set
        ``active``."""
        return (blk is not None and blk is self.blk and blk.factored == self.count
                and self.active.shape == active.shape and bool(np.all(self.active == active)))


class Anderson:
    """Type-II Anderson mixing of a fixed-point map x -> G(x) (residual r = G(x) - x) over the
    last ``depth`` iterates: x+ = G(x) - (dX + dR) gamma, gamma = argmin |r - dR gamma| (the
    paper's eq. 17 is the case of one difference). The least-squares problem goes through the
    Gram matrix dR^T dR, kept up to date one column per iteration: two passes over the
    differences and the small solve in one kernel call (``_kernels.relax.anderson_step``)."""

    def __init__(self, depth):
        self.depth = depth
        self.n = -1
        self.reset()

    def reset(self):
        self.k = 0            # differences stored
        self.head = 0         # next ring slot
        self.have_prev = False
        self.G = np.zeros((max(self.depth, 1), max(self.depth, 1)))

    def __call__(self, x, gx):
        if self.depth <= 0:
            return gx
        n = x.size
        if n != self.n:
            self.n = n
            self.DX = np.empty((n, self.depth))
            self.DR = np.empty((n, self.depth))
            self.x_prev = np.empty(n)
            self.r_prev = np.empty(n)
            self.b = np.empty(self.depth)
            self._M = np.empty((self.depth, self.depth))
            self._gamma = np.empty(self.depth)
            self.out = np.empty(n)
            self.reset()
        j = self.head
        if self.have_prev:
            self.head = (j + 1) % self.depth
            self.k = min(self.k + 1, self.depth)
        status = RK.anderson_step(n, x, gx, self.x_prev, self.r_prev, self.DX, self.DR, self.G,
                                  self.k, j, self.have_prev, self.b, self._M, self._gamma,
                                  self.out)
        self.have_prev = True
        if status == 1:
            return self.out
        if status < 0:      # a zero pivot: the history is degenerate
            self.reset()
        return gx



@dataclass
class Iterate:
    """One relaxation's state (``relax._relax_held``) that its preconditioner reads and moves:
    the lattice, the equations' constants and the held problem (``_kernels.zone``); the iterate
    ``pos`` (m, 3), ``s`` (m, 2) and its tensions, segments and forces (of the last sweep); the
    wall's planes (m, 6) and active set (resting crossings); the sweep's scratch; ``predict``:
    the next sweep starts from the strains of the lengths ``l_prev``; ``set_changes``: changes
    of the active set."""

    lat: Lattice
    law: KZ.Law
    prob: KZ.Problem
    settings: object        # relax.RelaxSettings
    pos: np.ndarray
    s: np.ndarray
    tension: np.ndarray
    seg: KZ.Segments
    fo: KZ.Forces
    plane: np.ndarray
    active: np.ndarray
    has_wall: bool
    chain: np.ndarray
    work: np.ndarray
    stats: np.ndarray
    l_prev: np.ndarray
    wall_force: np.ndarray
    dist: np.ndarray
    predict: bool = False
    set_changes: int = 0
    #: m x 3 scratch of the wall step and the block-Jacobi corrections
    moved: np.ndarray = field(default=None)
    lmin: np.ndarray = field(default=None)

    def __post_init__(self):
        m = self.lat.m
        self.moved = np.empty((m, 3))
        self.lmin = np.empty(m)
        # the same as plain tuples, as the kernels take them (``_kernels.zone``): numba types
        # a plain tuple in its dispatcher's C path, a NamedTuple in Python (3 us a call)
        self.klat, self.klaw, self.kprob, self.kseg, self.kfo = map(
            tuple, (self.lat, self.law, self.prob, self.seg, self.fo))


class Preconditioner(Protocol):
    """What the relaxation's loop asks of a preconditioner, in the order of an iteration."""

    #: the material sweeps start from the last sweep's strains (``RelaxSettings.material_predict``)
    predict: bool
    #: iterations without a new lowest residual after which the step is given up (None: none
    #: but ``max_iter``)
    stall: int | None
    #: block-Jacobi corrections an iteration (the loop sets it to 0 where they stall)
    smoothing: int

    def take_sweep(self, x: Iterate) -> bool:
        """Put a sweep of the iterate made already (the line search's) into ``x``; False if
        there is none (the loop sweeps)."""

    def measure(self, x: Iterate) -> None:
        """Whatever it needs of the iterate's sweep and forces before the update (the line
        search's energy)."""

    def due(self, x: Iterate, it: int, best_f_it: int, mixer: Anderson) -> bool:
        """Whether iteration ``it`` factorises K anew (besides a change of the active set);
        may clear Anderson's history (the map changes)."""

    def factor(self, x: Iterate) -> bool:
        """Factorise K at the iterate; False: no definite K (the step is given up)."""

    def update(self, x: Iterate, delta: np.ndarray) -> None:
        """delta (m, 3) = K^-1 F, the position update."""

    def move(self, x: Iterate, delta: np.ndarray, new: np.ndarray) -> bool:
        """new (m, 3) = the moved iterate, the wall's active set updated (``x.active``,
        ``x.set_changes``); True if the set changed."""

    def smooth(self, x: Iterate, new: np.ndarray, delta: np.ndarray) -> None:
        """The block-Jacobi corrections of ``new`` (``smoothing`` of them)."""

    def mix(self, x: Iterate, mixer: Anderson, new: np.ndarray) -> None:
        """The next iterate into ``x.pos`` from ``new`` (Anderson's mixing)."""

    def projected(self, x: Iterate) -> None:
        """``x.pos`` was projected onto the wall after ``mix``."""


def make(name: str, x: Iterate) -> Preconditioner:
    """The preconditioner ``name`` (``RelaxSettings.preconditioner``) for the iterate ``x``."""
    kinds = {"block": BlockPreconditioner, "full": FullPreconditioner,
             "scalar": ScalarPreconditioner}
    if name not in kinds:
        raise ValueError(f"RelaxSettings.preconditioner = {name!r}: expected "
                         "'block', 'full' or 'scalar'")
    return kinds[name](x)


class BlockPreconditioner:
    """``"block"``: the lattice's geometric stiffness in 3 x 3 blocks (``block_values``), in
    ``band_dissection``'s order, factorised at the start and where the jammed set or the wall's
    active set changed (``relax.py``, item 2)."""

    nb = 3
    smoothing = 0

    def __init__(self, x: Iterate):
        st = x.settings
        m = x.lat.m
        self.predict = st.material_predict
        self.stall = self.stall_of(st)
        self.blk = (BlockStiffness.of(x.lat, x.pos, self.nb, self.order_of(st), st.order_leaf,
                                      st.order_window) if m else None)
        self.jammed = np.zeros((m, 2), dtype=np.bool_)
        self.factored_jam = None
        self.rhs = np.empty((m, 3))

    @staticmethod
    def stall_of(st):
        return st.block_stall

    @staticmethod
    def order_of(st):
        return "band"

    def take_sweep(self, x):
        return False

    def measure(self, x):
        pass

    def due(self, x, it, best_f_it, mixer):
        st = x.settings
        due = bool(st.block_refactor_every) and (it - 1) % st.block_refactor_every == 0
        # the jamming stiffness k_jam d d^T enters K where a segment is shorter than a width:
        # where that set changed since the factorisation, K is factorised anew and Anderson's
        # history (of the old map) cleared; with the full preconditioner only a segment jammed
        # anew (a segment that left the jam keeps its k_jam in K, which then is stiffer there
        # than the map: the update falls short rather than beyond)
        changed_jam = RK.jam_changed(x.lat.m, x.lat.low, x.seg.l_below, x.law.l_jam,
                                     self.jammed if self.factored_jam is None
                                     else self.factored_jam,
                                     self.nb == 5, self.jammed) and self.factored_jam is not None
        if changed_jam:
            due = True
            mixer.reset()
        return due

    def factor(self, x):
        self.factored_jam = self.jammed.copy()
        reg = x.settings.block_reg
        blk = self.blk
        while True:
            SK.block_values(x.klat, x.klaw, x.kprob, x.kseg, x.tension, reg, x.plane,
                            x.active, blk.slots, blk.vals, blk.Dg)
            if blk.factor():
                return True
            reg *= 10.0     # a pivot lost to round-off: a stiffer isotropic share

    def update(self, x, delta):
        self.blk.update(x.fo.force, x.plane, x.active, x.lat.low, x.seg.l_below,
                        x.settings.block_cap, x.lmin, self.rhs, delta)

    def move(self, x, delta, new):
        if not x.has_wall:
            np.add(x.pos, delta, out=new)
            return False
        # the block update moved the resting crossings in their planes; the local balance
        # decides who leaves, and who joins (one kernel call: the iteration's fixed cost)
        changed = RK.block_wall(x.lat.m, x.lat.low, x.lat.up, x.fo.w_below, x.fo.force, x.pos,
                                delta, x.fo.W, x.plane, x.active, x.settings.wall_release,
                                x.wall_force, x.moved, new)
        x.set_changes += changed
        return changed

    def smooth(self, x, new, delta):
        pass

    def mix(self, x, mixer, new):
        x.pos[:] = mixer(x.pos.ravel(), new.ravel()).reshape(x.lat.m, 3)

    def projected(self, x):
        pass


class FullPreconditioner(BlockPreconditioner):
    """``"full"``: the Hessian in the positions and materials, 5 x 5 blocks (``full_values``),
    in ``ring_order``; factorised also after a step the line search shortened and after
    ``ring_refactor_stall`` iterations without a new lowest residual; with ``ring_line_search``
    the line search on the reduced energy (``relax.py``, items 2 and 5)."""

    nb = 5

    def __init__(self, x: Iterate):
        super().__init__(x)
        st = x.settings
        lat, m, ny = x.lat, x.lat.m, x.lat.n_yarns
        self.search = st.ring_line_search and m > 0
        self.swept = False
        self.damped_refactor = False
        self.E_cur = 0.0
        if self.search:
            # the top materials at the start: the reference of the energy's payout term
            self.s_ref = np.array([x.s[lat.highest[k], 0 if k < ny // 2 else 1]
                                   if lat.highest[k] >= 0 else 0.0 for k in range(ny)])
            self.seg_t = KZ.segments(m, ny)
            self.kseg_t = tuple(self.seg_t)
            self.s_t, self.ten_t = np.empty((m, 2)), np.empty((m, 2))
            self.cand = None

    @staticmethod
    def stall_of(st):
        return st.ring_stall

    @staticmethod
    def order_of(st):
        return st.ring_order

    def merit(self, x, trial):
        """The reduced energy at ``trial`` (m, 3), as the iterate will be: projected onto its
        plane where behind it; its sweep into the trial buffers."""
        st, lat, law, prob = x.settings, x.lat, x.law, x.prob
        m, ny = lat.m, lat.n_yarns
        if x.has_wall:
            RK.wall_distance(m, trial, x.plane, x.dist)
            behind = (x.dist < 0.0) & x.active | (x.dist < -st.wall_release)
            if behind.any():
                trial = trial.copy()
                trial[behind] -= x.dist[behind, None] * x.plane[behind, 3:]
        t = self.seg_t
        RK.segment_vectors(m, ny, lat.yarn, trial, lat.normal, lat.over, lat.low, lat.highest,
                           prob.fell, prob.top, law.h, law.eps2, law.eps2_top, t.d_below,
                           t.l_below, t.d_top, t.l_top)
        self.s_t[:] = x.s
        RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, t.l_below, self.s_t, prob.s_fell,
                          prob.s_old, prob.g, prob.f_top, law.EA, law.compression, law.eps_f,
                          law.kappa0, st.material_tol, st.material_newton, self.ten_t, x.chain,
                          x.work, x.stats, x.seg.l_below)
        return RK.reduced_energy(x.klat, x.klaw, x.kprob, self.kseg_t, self.s_t, self.s_ref)

    def take_sweep(self, x):
        if not self.swept:
            return False
        # the line search swept the materials at this iterate already
        t, seg = self.seg_t, x.seg
        seg.d_below[:], seg.l_below[:], seg.d_top[:], seg.l_top[:] = (t.d_below, t.l_below,
                                                                      t.d_top, t.l_top)
        x.s[:], x.tension[:] = self.s_t, self.ten_t
        self.swept = False
        if self.predict:
            x.l_prev[:] = seg.l_below
        return True

    def measure(self, x):
        if self.search:
            self.E_cur = RK.reduced_energy(x.klat, x.klaw, x.kprob, x.kseg, x.s, self.s_ref)

    def due(self, x, it, best_f_it, mixer):
        st = x.settings
        due = super().due(x, it, best_f_it, mixer)
        if self.search and self.damped_refactor:
            due = True
            self.damped_refactor = False
        if st.ring_refactor_stall and it - 1 - best_f_it >= st.ring_refactor_stall:
            due = True
            mixer.reset()
        return due

    def factor(self, x):
        self.factored_jam = self.jammed.copy()
        st = x.settings
        reg = st.block_reg
        blk = self.blk
        while True:
            # a pivot lost (a material whose yarn slides freely on both sides has only
            # kappa0): the isotropic share of the positions raised, up to 1e6 times; beyond
            # that the step is not converged (Newton's)
            SK.full_values(x.klat, x.klaw, x.kprob, x.kseg, x.tension, x.s, reg, x.plane,
                           x.active, blk.slots, blk.vals, blk.Dg)
            if blk.factor() or reg > 1e6 * st.block_reg:
                break
            reg *= 10.0
        return not reg > 1e6 * st.block_reg

    def mix(self, x, mixer, new):
        if not self.search:
            super().mix(x, mixer, new)
            return
        st, m, pos = x.settings, x.lat.m, x.pos
        E_cur = self.E_cur
        cand = mixer(pos.ravel(), new.ravel()).reshape(m, 3).copy()
        mixed = mixer.k > 0
        E_c = self.merit(x, cand)
        roundoff = 1e-13 * abs(E_cur)
        step = new - pos
        slope = -float(np.vdot(x.fo.force, step))
        if not (E_c <= E_cur + roundoff) and slope < -10.0 * roundoff:
            # the mixed iterate raised the energy: back along the preconditioned step
            mixer.reset()
            tt = 1.0 if mixed else 0.5
            for _ in range(st.ring_halvings):
                cand = pos + tt * step
                E_c = self.merit(x, cand)
                if E_c <= E_cur + 1e-4 * tt * slope + roundoff:
                    break
                tt *= 0.5
            if tt < 1.0:
                self.damped_refactor = st.ring_refactor_damped
        self.swept = True
        self.cand = cand
        pos[:] = cand

    def projected(self, x):
        if self.swept and x.has_wall and not np.array_equal(x.pos, self.cand):
            self.swept = False       # projected: the line search's sweep was at another iterate


class ScalarPreconditioner:
    """``"scalar"``: the force-density Laplacian shared by x, y and z (``laplacian_values``),
    factorised every ``refactor_every`` iterations, then ``smoothing`` block-Jacobi
    corrections (``relax.py``, item 2); a resting crossing is a Dirichlet row."""

    predict = False
    stall = None

    def __init__(self, x: Iterate):
        st = x.settings
        m = x.lat.m
        self.smoothing = st.smoothing
        self.lap = Laplacian(x.lat) if m else None
        self.diag = np.empty(m)
        self.H3 = np.empty((m, 3, 3))

    def take_sweep(self, x):
        return False

    def measure(self, x):
        pass

    def due(self, x, it, best_f_it, mixer):
        return (it - 1) % x.settings.refactor_every == 0

    def factor(self, x):
        lat, lap = x.lat, self.lap
        SK.laplacian_values(lat.m, lat.n_yarns, lat.low, lat.highest, x.fo.w_below, x.fo.w_top,
                            x.active, lap.slot_diag, lap.slot_below, lap.nslots, lap.vals,
                            self.diag)
        lap.factor()
        return True

    def update(self, x, delta):
        rhs = np.where(x.active[:, None], 0.0, x.fo.force)
        self.lap.solve(rhs, delta)

    def move(self, x, delta, new):
        if not x.has_wall:
            np.add(x.pos, delta, out=new)
            return False
        st, lat, active, plane, dist = x.settings, x.lat, x.active, x.plane, x.dist
        delta[active] = 0.0
        RK.wall_update(lat.m, lat.low, lat.up, x.fo.w_below, x.fo.force, x.pos, delta,
                       self.diag, plane, active, st.wall_release, x.wall_force)
        np.add(x.pos, delta, out=new)
        RK.wall_distance(lat.m, new, plane, dist)
        join = ~active & (dist < -st.wall_release)
        leave = active & (dist > st.wall_release)
        if join.any():
            new[join] -= dist[join, None] * plane[join, 3:]
        if join.any() or leave.any():
            x.active = (active | join) & ~leave
            x.set_changes += 1
            return True
        return False

    def smooth(self, x, new, delta):
        st, lat, law, prob, seg, fo = x.settings, x.lat, x.law, x.prob, x.seg, x.fo
        m, ny = lat.m, lat.n_yarns
        for _ in range(self.smoothing):
            # block-Jacobi correction with each crossing's own anisotropic stiffness (the
            # scalar Laplacian cannot tell a crossing's stiff and soft directions apart)
            RK.segment_vectors(m, ny, lat.yarn, new, lat.normal, lat.over, lat.low,
                               lat.highest, prob.fell, prob.top, law.h, law.eps2, law.eps2_top,
                               seg.d_below, seg.l_below, seg.d_top, seg.l_top)
            RK.material_sweep(ny, lat.lowest, lat.up, lat.yarn, seg.l_below, x.s, prob.s_fell,
                              prob.s_old, prob.g, prob.f_top, law.EA, law.compression,
                              law.eps_f, law.kappa0, st.material_tol, st.material_newton,
                              x.tension, x.chain, x.work, x.stats,
                              x.l_prev if x.predict else None)
            RK.forces(m, ny, lat.yarn, lat.low, lat.highest, seg.d_below, seg.l_below,
                      seg.d_top, seg.l_top, x.tension, prob.f_top, law.l_jam, law.k_jam,
                      law.floor, fo.force, fo.w_below, fo.w_top, fo.total, fo.W)
            SK.block_jacobi(x.klat, x.klaw, x.kprob, x.kseg, x.tension, st.smoothing_reg,
                            st.smoothing_cap, fo.force, x.plane, x.active, self.H3, x.lmin,
                            delta)
            new += st.smoothing_weight * delta

    def mix(self, x, mixer, new):
        x.pos[:] = mixer(x.pos.ravel(), new.ravel()).reshape(x.lat.m, 3)

    def projected(self, x):
        pass
