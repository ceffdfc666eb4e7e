"""The frictionless limit of the yarn-interaction model, as a crossing network (experimental).

With ``mu_y = 0`` no tangential force acts at a crossing, so every yarn keeps one tension from
its top point (ring or spool point) to its fell point, and force balance at crossing C,
``f_X (u_X_low + u_X_up) + f_O (u_O_low + u_O_up) = 0`` (DESIGN.md §3.3), says that C is the
tension-weighted geometric median of its four neighbours. The network as a whole minimises
``sum(tension x segment length)``, a convex function of the crossing positions, so Gauss-Seidel
sweeps of Weiszfeld steps converge from any start; warm-started from the previous time step they
need few sweeps. This is the paper's frictionless limit, solved as a minimisation rather than by
the force/position fixed point of its Fig. 10, which diverges when new crossings sit close to the
supply points (see the closing note of issue 4). Friction (stick/slip) is not in this version.

Crossings are created at carrier passes (``machine.pass_times``), at the top of both yarns, and
deposited when the lowest crossing of a yarn comes within a yarn thickness of the mandrel: it then
becomes the fell point of its yarns (``ZoneStep.deposits``).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .._kernels import network as K
from ..errors import SimulationError
from ..result import Snapshot
from ..zone import ZoneStep

#: convergence of the sweeps (m of crossing movement) and their budget
EPS = 1e-8
MAX_SWEEPS = 2000
INNER = 2


class _Distance:
    """Signed distance (m, positive outside) to the mandrel through the nearest face centroid's plane."""

    def __init__(self, mandrel):
        v = np.asarray(mandrel.vertices, dtype=float)
        f = np.asarray(mandrel.faces)
        self.centroids = v[f].mean(axis=1)
        self.normals = np.asarray(mandrel.face_normals, dtype=float)
        self.tree = cKDTree(self.centroids)

    def __call__(self, points):
        _, i = self.tree.query(np.atleast_2d(points))
        return np.einsum("ij,ij->i", np.atleast_2d(points) - self.centroids[i], self.normals[i])


class NetworkZone:
    """Crossings between free yarns in the frictionless limit (see the module docstring)."""

    def __init__(self, config, machine, mandrel=None):
        self.config = config
        self.machine = machine
        self.distance = _Distance(mandrel) if mandrel is not None else None
        self.h = 0.5 * float(config.yarn.thickness)
        self.n = machine.n_per_group
        ny = machine.n_yarns
        cap = 1024
        self.pos = np.zeros((cap, 3))
        self.alive = np.zeros(cap, dtype=np.bool_)
        self.side = np.zeros(cap, dtype=np.int64)
        self.yw = np.zeros(cap, dtype=np.int64)
        self.yf = np.zeros(cap, dtype=np.int64)
        self.low_w = np.full(cap, -1, dtype=np.int64)
        self.up_w = np.full(cap, -1, dtype=np.int64)
        self.low_f = np.full(cap, -1, dtype=np.int64)
        self.up_f = np.full(cap, -1, dtype=np.int64)
        self.count = 0
        self.top_c = np.full(ny, -1, dtype=np.int64)     # highest crossing of each yarn
        self.bottom_c = np.full(ny, -1, dtype=np.int64)  # lowest crossing of each yarn
        self.tension = np.full(ny, float(config.yarn.tension))
        self.fell = None
        self.pose = None

    # -- bookkeeping --------------------------------------------------------------------------
    def _grow(self):
        cap = 2 * len(self.alive)
        for name in ("pos", "alive", "side", "yw", "yf", "low_w", "up_w", "low_f", "up_f"):
            a = getattr(self, name)
            new = np.full((cap,) + a.shape[1:], -1 if a.dtype == np.int64 else 0, dtype=a.dtype)
            new[:len(a)] = a
            setattr(self, name, new)

    def _links(self, yarn, c):
        """(low array, up array) of c seen from yarn."""
        return (self.low_w, self.up_w) if self.yw[c] == yarn else (self.low_f, self.up_f)

    def _add(self, i, j, over, top):
        if self.count == len(self.alive):
            self._grow()
        c = self.count
        self.count += 1
        wy, fy = i, self.n + j
        self.yw[c], self.yf[c] = wy, fy
        self.side[c] = 1 if over else -1
        self.alive[c] = True
        for yarn, low, up in ((wy, self.low_w, self.up_w), (fy, self.low_f, self.up_f)):
            below = self.top_c[yarn]
            low[c] = below
            up[c] = -1
            if below >= 0:
                self._links(yarn, below)[1][below] = c
            else:
                self.bottom_c[yarn] = c
            self.top_c[yarn] = c
        # start just below the (coinciding) top points, between the two yarns' lower points
        lw = self._point_below(wy, c)
        lf = self._point_below(fy, c)
        self.pos[c] = top + 0.02 * (0.5 * (lw + lf) - top)
        return c

    def _point_below(self, yarn, c):
        low = self._links(yarn, c)[0][c]
        return self.pos[low] if low >= 0 else self.fell[yarn]

    def _remove(self, c):
        """Deposit c: it leaves both chains (it must be the lowest on both)."""
        self.alive[c] = False
        for yarn in (self.yw[c], self.yf[c]):
            low, up = self._links(yarn, c)
            above = up[c]
            if above >= 0:
                self._links(yarn, above)[0][above] = -1
            else:
                self.top_c[yarn] = -1
            self.bottom_c[yarn] = above

    # -- interface ----------------------------------------------------------------------------
    def start(self, t, F_machine, pose):
        self.fell = np.array(F_machine, dtype=float)
        self.pose = pose
        self.t = t

    def step(self, t0, dt, F_machine, pose_end) -> ZoneStep:
        m = self.machine
        t1 = t0 + dt
        self.fell = np.array(F_machine, dtype=float)
        self.pose = pose_end
        top = m.supply_points(t1)
        passes = m.pass_times(t0, t1)
        for i, j, over in zip(passes.warp, passes.weft, passes.warp_over):
            self._add(int(i), int(j), bool(over), top[int(i)])
        sweeps, move = self._solve(top)
        deposits = self._deposit()
        if deposits:
            sweeps2, move = self._solve(top)
            sweeps += sweeps2
        G = self._lowest_points(top)
        self.t = t1
        return ZoneStep(G_mid=G, G_end=G, deposits=deposits, contacts=int(self.alive[:self.count].sum()),
                        iterations=int(sweeps), residual=float(move))

    def _segments(self, top):
        """Per segment of every yarn: end crossings (-1: fixed point), the fixed points, signs, tension."""
        a_c, b_c, a_fix, b_fix, a_sig, b_sig, f = [], [], [], [], [], [], []
        for yarn in range(self.machine.n_yarns):
            prev_c, prev_p, prev_s = -1, self.fell[yarn], 0.0
            c = self.bottom_c[yarn]
            while True:
                if c >= 0:
                    sig = float(self.side[c]) if self.yw[c] == yarn else -float(self.side[c])
                    cur_c, cur_p, cur_s = c, self.fell[yarn], sig
                else:
                    cur_c, cur_p, cur_s = -1, top[yarn], 0.0
                a_c.append(prev_c)
                b_c.append(cur_c)
                a_fix.append(prev_p)
                b_fix.append(cur_p)
                a_sig.append(prev_s)
                b_sig.append(cur_s)
                f.append(self.tension[yarn])
                if c < 0:
                    break
                prev_c, prev_p, prev_s = cur_c, cur_p, cur_s
                c = self._links(yarn, c)[1][c]
        return (np.array(a_c), np.array(b_c), np.array(a_fix), np.array(b_fix), np.array(a_sig),
                np.array(b_sig), np.array(f))

    def _solve(self, top):
        """Newton's method with a line search on sum(tension x length) (convex)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.linalg import spsolve

        live = np.nonzero(self.alive[:self.count])[0]
        if len(live) == 0:
            return 0, 0.0
        var = np.full(self.count, -1, dtype=np.int64)
        var[live] = np.arange(len(live))
        a_c, b_c, a_fix, b_fix, a_sig, b_sig, f = self._segments(top)
        ia = np.where(a_c >= 0, var[np.maximum(a_c, 0)], -1)
        ib = np.where(b_c >= 0, var[np.maximum(b_c, 0)], -1)
        n = len(live)

        def ends(C):
            r = np.hypot(C[:, 0], C[:, 1])
            nrm = np.zeros_like(C)
            nrm[:, 0] = C[:, 0] / np.maximum(r, 1e-300)
            nrm[:, 1] = C[:, 1] / np.maximum(r, 1e-300)
            Pa = np.where((ia >= 0)[:, None], C[np.maximum(ia, 0)] + (a_sig * self.h)[:, None] * nrm[np.maximum(ia, 0)], a_fix)
            Pb = np.where((ib >= 0)[:, None], C[np.maximum(ib, 0)] + (b_sig * self.h)[:, None] * nrm[np.maximum(ib, 0)], b_fix)
            return Pa, Pb

        def energy(C):
            Pa, Pb = ends(C)
            return float(np.sum(f * np.linalg.norm(Pa - Pb, axis=1)))

        C = self.pos[live].copy()
        it = 0
        step = np.inf
        for it in range(1, 51):
            Pa, Pb = ends(C)
            d = Pa - Pb
            L = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
            u = d / L[:, None]
            g = np.zeros((n, 3))
            np.add.at(g, ia[ia >= 0], (f[:, None] * u)[ia >= 0])
            np.add.at(g, ib[ib >= 0], -(f[:, None] * u)[ib >= 0])
            K = (f / L)[:, None, None] * (np.eye(3)[None] - u[:, :, None] * u[:, None, :])
            rows, cols, vals = [], [], []
            for i1, i2, sgn in ((ia, ia, 1.0), (ib, ib, 1.0), (ia, ib, -1.0), (ib, ia, -1.0)):
                ok = (i1 >= 0) & (i2 >= 0)
                if not np.any(ok):
                    continue
                r = (3 * i1[ok])[:, None, None] + np.arange(3)[None, :, None]
                c = (3 * i2[ok])[:, None, None] + np.arange(3)[None, None, :]
                rows.append(np.broadcast_to(r, (ok.sum(), 3, 3)).ravel())
                cols.append(np.broadcast_to(c, (ok.sum(), 3, 3)).ravel())
                vals.append((sgn * K[ok]).ravel())
            diag = np.concatenate([np.diagonal(K, axis1=1, axis2=2).sum(axis=1)])
            lam = 1e-6 * float(np.max(f / L))
            H = coo_matrix((np.concatenate(vals + [np.full(3 * n, lam)]),
                            (np.concatenate(rows + [np.arange(3 * n)]), np.concatenate(cols + [np.arange(3 * n)]))),
                           shape=(3 * n, 3 * n)).tocsc()
            delta = spsolve(H, -g.ravel()).reshape(n, 3)
            E0 = energy(C)
            t = 1.0
            while t > 1e-6 and energy(C + t * delta) > E0 + 1e-4 * t * float(np.sum(g * delta)):
                t *= 0.5
            C = C + t * delta
            step = float(np.max(np.linalg.norm(t * delta, axis=1)))
            if step < EPS:
                break
        if not np.all(np.isfinite(C)) or step > 1e-4:
            raise SimulationError(f"the crossing network did not converge at t = {self.t:.6g} s: "
                                  f"crossings still move {step:.3g} m after {it} Newton iterations")
        self.pos[live] = C
        return it, step

    def _deposit(self):
        """Lowest crossings within a yarn thickness of the mandrel become fell points."""
        if self.distance is None:
            return []
        deposits = []
        for _ in range(4):
            cands = np.unique(self.bottom_c[self.bottom_c >= 0])
            if len(cands) == 0:
                break
            d = self.distance(self.pose.to_mandrel(self.pos[cands]))
            near = cands[d < 2 * self.h]
            done = False
            for c in near:
                if self.bottom_c[self.yw[c]] == c and self.bottom_c[self.yf[c]] == c:
                    for yarn, is_warp in ((self.yw[c], True), (self.yf[c], False)):
                        p = np.empty(3)
                        K.centerline_point(self.pos, self.side, c, is_warp, self.h, p)
                        deposits.append((int(yarn), p))
                        self.fell[yarn] = p
                    self._remove(c)
                    done = True
            if not done:
                break
        return deposits

    def _lowest_points(self, top):
        G = top.copy()
        for yarn in np.nonzero(self.bottom_c >= 0)[0]:
            c = self.bottom_c[yarn]
            K.centerline_point(self.pos, self.side, c, self.yw[c] == yarn, self.h, G[yarn])
        return G

    def snapshot(self, t, F_machine) -> Snapshot:
        m = self.machine
        top = m.supply_points(t)
        spool = m.spool_points(t) if self.config.machine.guide_ring is not None else None
        points, offsets, cid, tension = [], [0], [], []
        for yarn in range(m.n_yarns):
            chain = [np.asarray(F_machine[yarn], dtype=float)]
            ids = [-1]
            c = self.bottom_c[yarn]
            while c >= 0:
                p = np.empty(3)
                K.centerline_point(self.pos, self.side, c, self.yw[c] == yarn, self.h, p)
                chain.append(p)
                ids.append(int(c))
                c = self._links(yarn, c)[1][c]
            chain.append(top[yarn])
            ids.append(-1)
            if spool is not None:
                chain.append(spool[yarn])
                ids.append(-1)
            points += chain
            cid += ids
            tension += [self.tension[yarn]] * (len(chain) - 1)
            offsets.append(offsets[-1] + len(chain))
        n = len(points)
        return Snapshot(time_s=t, points=np.array(points), offsets=np.array(offsets, dtype=np.int64),
                        tension_N=np.array(tension), contact_id=np.array(cid, dtype=np.int64),
                        slip=np.where(np.array(cid) >= 0, 1, 0).astype(np.int8), group=m.group.copy())
