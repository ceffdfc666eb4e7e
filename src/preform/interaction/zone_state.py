"""State of the convergence zone of the interaction model (docs/theory.md §4): crossings and chains.

A *crossing* is where warp yarn ``X`` (yarn index ``0 .. n-1``) and weft yarn ``O`` (yarn index
``n .. 2n-1``) touch. Crossings are stored in flat arrays **in creation order** (oldest first), so
that on every yarn the crossings further from the mandrel (newer) come later: iterating the arrays
backwards is a topological order from the supply side to the fell points (the force sweep), forwards
from the fell points to the supply side (the position sweep). Deposited crossings are removed by
compaction, which keeps that order. Rows may be ragged: nothing here assumes that the crossings
created at one carrier pass line up.

Per crossing ``c`` (first ``m`` rows of arrays of capacity ``cap``, grown by doubling):

- ``yarn (cap, 2) int64``: warp yarn index, weft yarn index (side 0 warp, side 1 weft);
- ``pos (cap, 3) float64, m, machine frame``: the contact interface point ``C``;
- ``normal (cap, 3) float64``: unit contact normal ``N`` (outward, away from the machine axis);
- ``over (cap,) float64``: +1 if the warp is the outer (over) yarn at this crossing, else -1. The
  yarn centerline points are ``C + over * h * N`` (warp) and ``C - over * h * N`` (weft),
  ``h = thickness / 2`` (paper eq. 16, with one normal per crossing);
- ``material (cap, 2) float64, m``: material coordinate of each yarn at the crossing (m of yarn
  from a point of the yarn's deposited part; ``interaction/frontal.py``): what a sticking yarn
  keeps;
- ``bound (cap, 2) float64, N``: friction bound of each yarn at the crossing from the last solve
  (NaN before the first), the start of the next;
- ``slip (cap, 2) int8``: friction state per yarn in the last step: 0 stick, +1 slipping with the
  tension below the crossing larger (the yarn slides towards the mandrel through the crossing), -1
  the other way (the crossing runs down the yarn faster than the yarn is drawn);
- ``offset (cap, 2) float64, m``: the elastic part of the friction slip that carries the friction
  force of each yarn over to the next step (``interaction/frontal.py``, ``friction_memory``): the
  next step's friction term is centred at ``material - offset``;
- ``low (cap, 2) int64`` / ``up (cap, 2) int64``: array index of the next crossing towards the
  mandrel / towards the supply on the warp (column 0) and weft (column 1) yarn; -1 for the fell
  point below / the supply side above;
- ``tension (cap, 2) float64, N``: tension of the segment below the crossing on each yarn;
- ``uid (cap,) int64``: stable crossing id (``contact_id`` in snapshots); ``t_create (cap,)`` s.

Not state, a cache of the mandrel look-ups (``mandrel_distance.MandrelDistance.near``; not in ``to_arrays``,
unknown after ``from_arrays`` and for a new crossing): ``near_lo``, ``near_hi (cap,) float64, m``,
bounds from below and above of the crossing's distance to the nearest face sample when it was at
``near_at (cap, 3) float64`` (mandrel frame); ``-inf``, ``inf``: none known. That distance is
1-Lipschitz, so at a point ``p`` it lies within ``[near_lo - |p - near_at|, near_hi + |p -
near_at|]``.
"""

from __future__ import annotations

import numpy as np

from .. import plain

#: initial capacity (crossings); the arrays double when full
INITIAL_CAPACITY = 256

_FIELDS = {
    # name: (trailing shape, dtype, fill)
    "yarn": ((2,), np.int64, -1),
    "pos": ((3,), np.float64, 0.0),
    "normal": ((3,), np.float64, 0.0),
    "over": ((), np.float64, 1.0),
    "material": ((2,), np.float64, 0.0),
    "bound": ((2,), np.float64, np.nan),
    "slip": ((2,), np.int8, 0),
    "offset": ((2,), np.float64, 0.0),
    "low": ((2,), np.int64, -1),
    "up": ((2,), np.int64, -1),
    "tension": ((2,), np.float64, 0.0),
    "uid": ((), np.int64, -1),
    "t_create": ((), np.float64, 0.0),
}

#: the look-up cache (module docstring): copied, grown, compacted with the crossings, not saved
_CACHE = {
    "near_lo": ((), np.float64, -np.inf),
    "near_hi": ((), np.float64, np.inf),
    "near_at": ((3,), np.float64, 0.0),
}
_ALL = {**_FIELDS, **_CACHE}


class ZoneState:
    """Crossings of the convergence zone plus each yarn's lowest and highest crossing."""

    def __init__(self, n_yarns: int, capacity: int = INITIAL_CAPACITY):
        self.n_yarns = int(n_yarns)
        self.m = 0
        self.next_uid = 0
        for name, (shape, dtype, fill) in _ALL.items():
            setattr(self, name, np.full((capacity,) + shape, fill, dtype=dtype))
        self.lowest = np.full(self.n_yarns, -1, dtype=np.int64)
        self.highest = np.full(self.n_yarns, -1, dtype=np.int64)
        self.material_fell = np.zeros(self.n_yarns)

    @property
    def capacity(self) -> int:
        return len(self.uid)

    def _yarn_arrays(self) -> list[str]:
        """Names of the per-yarn arrays (``lowest``, ``highest``, the fell points' material
        coordinates): every array attribute that is not a crossing field of ``_FIELDS``."""
        return [k for k, v in vars(self).items() if isinstance(v, np.ndarray) and k not in _ALL]

    def copy(self) -> "ZoneState":
        """An independent copy (same capacity; every array copied)."""
        new = ZoneState(self.n_yarns, capacity=self.capacity)
        new.m, new.next_uid = self.m, self.next_uid
        for name in (*_ALL, *self._yarn_arrays()):
            setattr(new, name, getattr(self, name).copy())
        return new

    def to_arrays(self) -> dict:
        """The state as plain arrays (checkpoints): every field of ``_FIELDS`` for the ``m``
        crossings, the per-yarn arrays, and ``next_uid`` (0-d int64). Rows past ``m`` are not
        state (``add`` sets every field of a new crossing), nor is the capacity."""
        out = {name: getattr(self, name)[: self.m].copy() for name in _FIELDS}
        out.update({name: getattr(self, name).copy() for name in self._yarn_arrays()})
        out["next_uid"] = np.int64(self.next_uid)
        return {k: np.asarray(v) for k, v in out.items()}

    @classmethod
    def from_arrays(cls, arrays, n_yarns: int) -> "ZoneState":
        """The state ``to_arrays`` gave, checked before any kernel sees it: shapes and dtypes of
        ``_FIELDS`` and of the per-yarn arrays of a new state, finite floats (NaN only in a field
        whose fill is NaN: not yet solved), yarn indices on their side (warp ``0 .. n-1``, weft
        ``n .. 2n-1``), links within the crossings and consistent with the chains (module
        docstring). ValueError names what is wrong."""
        n_yarns = int(n_yarns)
        m = len(plain.take(arrays, "uid", (None,), np.int64))
        capacity = INITIAL_CAPACITY
        while capacity < m:
            capacity *= 2
        st = cls(n_yarns, capacity=capacity)
        for name, (shape, dtype, fill) in _FIELDS.items():
            a = plain.take(arrays, name, (m,) + shape, dtype)
            if a.dtype.kind == "f":
                plain.finite(name, a, allow_nan=bool(np.isnan(fill)))
            getattr(st, name)[:m] = a
        st.m = m
        st.next_uid = plain.scalar(arrays, "next_uid", np.int64)
        for name in st._yarn_arrays():
            like = getattr(st, name)
            a = plain.take(arrays, name, like.shape, like.dtype)
            if a.dtype.kind == "f":
                plain.finite(name, a)
            setattr(st, name, a)
        for name in ("lowest", "highest"):
            plain.in_range(name, getattr(st, name), -1, m)
        st._validate()
        return st

    def _validate(self) -> None:
        """ValueError unless indices and links are those of a state ``add`` and ``remove`` make."""
        m, n = self.m, self.n_yarns // 2
        yarn = self.yarn[:m]
        plain.in_range("yarn (warp)", yarn[:, 0], 0, n)
        plain.in_range("yarn (weft)", yarn[:, 1], n, 2 * n)
        uid = self.uid[:m]
        plain.in_range("uid", uid, 0, max(self.next_uid, 0))
        if len(np.unique(uid)) != m:
            raise ValueError("array 'uid' repeats a crossing id")
        if not np.all(np.abs(self.over[:m]) == 1.0):
            raise ValueError("array 'over' holds values other than +1 and -1")
        if not np.all(np.isin(self.slip[:m], (-1, 0, 1))):
            raise ValueError("array 'slip' holds values other than -1, 0 and +1")
        c = np.arange(m)
        for side in range(2):
            for name, links, older in (("low", self.low, True), ("up", self.up, False)):
                v = plain.in_range(name, links[:m, side], -1, m)
                linked = v >= 0
                # creation order: a crossing's neighbour towards the mandrel is older, its
                # neighbour towards the supply newer, both on the same yarn, linked back to it
                back = (self.up if older else self.low)[v[linked], side]
                if (np.any((v[linked] < c[linked]) != older) or np.any(back != c[linked])
                        or np.any(yarn[v[linked], side] != yarn[linked, side])):
                    raise ValueError(f"array {name!r} does not link crossings along their yarns")
                ends = self.lowest if older else self.highest
                if np.any(ends[yarn[~linked, side]] != c[~linked]):
                    raise ValueError(f"the {'lowest' if older else 'highest'} crossings do not "
                                     f"match the links {name!r}")
        for name, ends, links in (("lowest", self.lowest, self.low), ("highest", self.highest, self.up)):
            k = np.nonzero(ends >= 0)[0]
            side = (k >= n).astype(np.int64)
            if np.any(yarn[ends[k], side] != k) or np.any(links[ends[k], side] != -1):
                raise ValueError(f"array {name!r} names crossings that are not the ends of its yarns")

    def _grow(self, need: int):
        cap = self.capacity
        while cap < need:
            cap *= 2
        if cap == self.capacity:
            return
        for name, (shape, dtype, fill) in _ALL.items():
            old = getattr(self, name)
            new = np.full((cap,) + shape, fill, dtype=dtype)
            new[: self.m] = old[: self.m]
            setattr(self, name, new)

    def add(self, warp: int, weft: int, pos, normal, over: bool, t: float) -> int:
        """Append a crossing at the top of warp yarn ``warp`` and weft yarn ``weft``; its index.
        Its material coordinates and tensions are the caller's to set (``frontal.new_material``)."""
        self._grow(self.m + 1)
        c = self.m
        self.m += 1
        self.yarn[c] = (warp, weft)
        self.pos[c] = pos
        self.normal[c] = normal
        self.over[c] = 1.0 if over else -1.0
        self.slip[c] = 0
        self.offset[c] = 0.0
        self.material[c] = 0.0
        self.bound[c] = np.nan
        self.tension[c] = 0.0
        self.uid[c] = self.next_uid
        self.next_uid += 1
        self.t_create[c] = t
        self.near_lo[c] = -np.inf
        self.near_hi[c] = np.inf
        for side, k in enumerate((warp, weft)):
            below = self.highest[k]
            self.low[c, side] = below
            self.up[c, side] = -1
            if below >= 0:
                self.up[below, self._side(below, k)] = c
            else:
                self.lowest[k] = c
            self.highest[k] = c
        return c

    def _side(self, c: int, k: int) -> int:
        return 0 if self.yarn[c, 0] == k else 1

    def chain(self, k: int) -> np.ndarray:
        """Array indices of yarn ``k``'s crossings, lowest (mandrel side) first."""
        out = []
        c = self.lowest[k]
        while c >= 0:
            out.append(c)
            c = self.up[c, self._side(c, k)]
        return np.array(out, dtype=np.int64)

    def centerline_point(self, c: int, side: int, half_thickness: float) -> np.ndarray:
        """Yarn centerline point of side ``side`` at crossing ``c`` (module docstring), (3,)."""
        o = self.over[c] if side == 0 else -self.over[c]
        return self.pos[c] + o * half_thickness * self.normal[c]

    def remove(self, dead) -> None:
        """Remove crossings (array indices ``dead``, each the lowest on both its yarns once the
        others below it are removed) and compact, keeping creation order and relinking chains."""
        dead = np.asarray(dead, dtype=np.int64)
        if len(dead) == 0:
            return
        m = self.m
        keep = np.ones(m, dtype=bool)
        keep[dead] = False
        new_index = np.full(m + 1, -1, dtype=np.int64)   # index m + ... maps -1 -> -1 below
        new_index[:m][keep] = np.arange(int(keep.sum()))
        for name in _ALL:
            a = getattr(self, name)
            a[: int(keep.sum())] = a[:m][keep]
        self.m = int(keep.sum())
        mm = self.m
        for links in (self.low, self.up):
            v = links[:mm]
            # a removed neighbour below means the fell point now; above cannot be removed
            links[:mm] = np.where(v >= 0, new_index[np.where(v >= 0, v, m)], -1)
        for ends in (self.lowest, self.highest):
            ends[:] = np.where(ends >= 0, new_index[np.where(ends >= 0, ends, m)], -1)
        # a yarn whose lowest crossing was removed: its new lowest is the first kept one above,
        # its oldest (chains run in creation order), the first row naming it
        lost = np.nonzero((self.lowest == -1) & (self.highest >= 0))[0]
        if len(lost):
            n = self.n_yarns // 2
            for side in range(2):
                ks = lost[(lost >= n) == bool(side)]
                if len(ks):
                    yarns, first = np.unique(self.yarn[:mm, side], return_index=True)
                    self.lowest[ks] = first[np.searchsorted(yarns, ks)]

    def check(self) -> None:
        """Consistency of chains and links (for tests): raises AssertionError."""
        seen = np.zeros(self.m, dtype=np.int64)
        for k in range(self.n_yarns):
            ch = self.chain(k)
            seen[ch] += 1
            if len(ch) == 0:
                assert self.highest[k] == -1
                continue
            assert self.highest[k] == ch[-1]
            assert np.all(np.diff(ch) > 0), "chain not in creation order"
            for a, b in zip(ch[:-1], ch[1:]):
                assert self.low[b, self._side(b, k)] == a
        assert np.all(seen == 2), "every crossing sits on exactly two chains"
