"""What a run keeps of every step, and how it becomes the Result's history and yarn paths
(docs/guide/results.md, ``history.csv``, ``yarns.vtp``, ``convergence.pvd``).

:class:`Recording` holds plain arrays that grow by rows: per recorded step (the start, then one
per time step) the history row, the fell points, their faces, laying directions and convergence
lengths; per time step which yarns moved and the flag of their end point; per point laid inside
a step (a deposited crossing, a catch or bridge jump) its yarn, step, order, point, face, time and
flag; and the convergence-zone snapshots. ``to_arrays`` / ``from_arrays`` give and take them as
named arrays for checkpoints (snapshots concatenated, with offsets).
"""

from __future__ import annotations

import numpy as np

from . import plain
from .laid import braid_angles_at, laid_braid_angles
from .result import FLAG_SLIP, HISTORY_COLUMNS, Snapshot, YarnPaths

#: columns of Recording.rows: time, H mean, H min, H max, contacts, iterations, residual
ROW_COLUMNS = ("time_s", "H_mean_m", "H_min_m", "H_max_m", "contacts", "iterations", "residual")


class Rows:
    """Rows of one trailing shape and dtype, appended one or many at a time (capacity doubles).

    ``array`` is the (n,) + shape view of the rows so far."""

    def __init__(self, shape, dtype, capacity=16):
        self.data = np.empty((capacity,) + tuple(shape), dtype=dtype)
        self.n = 0

    @property
    def array(self) -> np.ndarray:
        return self.data[: self.n]

    def _reserve(self, extra):
        need = self.n + extra
        if need > len(self.data):
            cap = max(2 * len(self.data), need)
            grown = np.empty((cap,) + self.data.shape[1:], dtype=self.data.dtype)
            grown[: self.n] = self.data[: self.n]
            self.data = grown

    def append(self, row):
        self._reserve(1)
        self.data[self.n] = row
        self.n += 1

    def extend(self, rows):
        rows = np.asarray(rows, dtype=self.data.dtype).reshape((-1,) + self.data.shape[1:])
        self._reserve(len(rows))
        self.data[self.n: self.n + len(rows)] = rows
        self.n += len(rows)

    @classmethod
    def of(cls, array):
        """Rows holding a copy of ``array`` (n,) + shape."""
        out = cls(array.shape[1:], array.dtype, capacity=max(len(array), 16))
        out.extend(array)
        return out


#: the laid points of a step other than each yarn's end point: name -> (trailing shape, dtype)
_LAID = {"yarn": ((), np.int64), "step": ((), np.int64), "order": ((), np.float64),
         "point": ((3,), np.float64), "face": ((), np.int64), "time": ((), np.float64),
         "flag": ((), np.uint8)}


class Recording:
    """The run's record (module docstring) for ``n_yarns`` yarns."""

    def __init__(self, n_yarns: int):
        ny = int(n_yarns)
        self.n_yarns = ny
        self.rows = Rows((len(ROW_COLUMNS),), np.float64)
        self.fell = Rows((ny, 3), np.float64)       # fell points, m, mandrel frame
        self.face = Rows((ny,), np.int64)           # their faces
        self.lay_dir = Rows((ny, 3), np.float64)    # laying direction (free yarn), mandrel frame
        self.H = Rows((ny,), np.float64)            # convergence length per yarn, m
        self.moved = Rows((ny,), np.bool_)          # per time step: the yarn laid its end point
        self.end_flag = Rows((ny,), np.uint8)       # per time step: FLAG_* of that end point
        self.laid = {name: Rows(shape, dtype) for name, (shape, dtype) in _LAID.items()}
        self.snapshots: list[Snapshot] = []

    @property
    def n_rows(self) -> int:
        return self.rows.n

    def record(self, t, fell, face, H, lay_dir, contacts, iterations, residual):
        """One history row: time t (s), fell points (ny, 3) and faces (ny,) mandrel frame,
        convergence lengths H (ny,) m, laying directions (ny, 3), the zone's solve figures."""
        self.rows.append((t, float(np.mean(H)), float(np.min(H)), float(np.max(H)),
                          contacts, iterations, residual))
        self.fell.append(fell)
        self.face.append(face)
        self.H.append(H)
        self.lay_dir.append(lay_dir)

    def lay(self, moved, end_flag, extra):
        """What time step ``self.moved.n`` laid: ``moved`` (ny,) bool, ``end_flag`` (ny,) uint8,
        and ``extra`` a list of (yarn, order, point (3,), face, time, flag) laid before the ends
        (order -1 for a deposited crossing, then the jumps in order)."""
        step = self.moved.n
        self.moved.append(moved)
        self.end_flag.append(end_flag)
        for k, order, p, f, t, fl in extra:
            for name, value in zip(_LAID, (k, step, order, p, f, t, fl)):
                self.laid[name].append(value)

    # -- packing ------------------------------------------------------------------------------
    def yarn_paths(self, surface, project, centerline, group, mu, curvature_tol, fell_s=None) -> YarnPaths:
        """Deposited yarn per yarn: its tie point, then per step the points laid inside the step
        in order and its end point, with the braid angle and slip tendency of the laid yarn
        (``laid.laid_braid_angles``; surface: kinematic.SurfaceArrays, project:
        laid.CenterlineProjector, group (ny,) 0 warp 1 weft, mu: yarn-mandrel friction,
        curvature_tol: ``Tolerances.slip_curvature``; fell_s: the fell points' arc lengths
        (steps, ny) from ``history``, so that only the points laid inside steps are projected)."""
        ny = self.n_yarns
        fell, face = self.fell.array, self.face.array
        step_i, k = np.nonzero(self.moved.array)        # step-major, yarns ascending
        laid = {name: rows.array for name, rows in self.laid.items()}
        # records (yarn, step, order): tie points first, jump points in order, each step's end last
        yarn = np.concatenate([np.arange(ny), k, laid["yarn"]])
        step = np.concatenate([np.full(ny, -1), step_i, laid["step"]])
        order = np.concatenate([np.zeros(ny), np.full(len(k), np.inf), laid["order"]])
        sort = np.lexsort((order, step, yarn))
        points = np.concatenate([fell[0], fell[step_i + 1, k], laid["point"]])[sort].reshape(-1, 3)
        faces = np.concatenate([face[0], face[step_i + 1, k], laid["face"]])[sort].astype(np.int64)
        times = np.concatenate([np.zeros(ny), self.rows.array[step_i + 1, 0], laid["time"]])[sort]
        flags = np.concatenate([np.zeros(ny, dtype=np.uint8), self.end_flag.array[step_i, k],
                                laid["flag"]])[sort].astype(np.uint8)
        offsets = np.searchsorted(yarn[sort], np.arange(ny + 1)).astype(np.int64)
        if fell_s is None:
            fell_s = project(fell.reshape(-1, 3)).reshape(fell.shape[:2])
        laid_s = project(laid["point"]) if len(laid["point"]) else np.zeros(0)
        s = np.concatenate([fell_s[0], fell_s[step_i + 1, k], laid_s])[sort]
        angles, slip = laid_braid_angles(surface, project, centerline, points, faces, offsets, mu,
                                         curvature_tol, s=s)
        flags = flags | np.where(slip, FLAG_SLIP, 0).astype(np.uint8)
        return YarnPaths(points=points, offsets=offsets, time_s=times, braid_angle_deg=angles,
                         face=faces, flags=flags, group=np.asarray(group).astype(np.int8))

    def history(self, surface, project, centerline, group):
        """(history dict of HISTORY_COLUMNS, fell_s (steps, ny) m): braided length and braid
        angles of every recorded step from its fell points and laying directions."""
        fell = self.fell.array
        steps, ny, _ = fell.shape
        flat_fell = fell.reshape(-1, 3)
        s = project(flat_fell)
        alpha = braid_angles_at(surface, centerline, flat_fell, self.face.array.reshape(-1), s,
                                self.lay_dir.array.reshape(-1, 3)).reshape(steps, ny)
        rows = self.rows.array.copy()
        history = {
            "time_s": rows[:, 0],
            "braided_length_m": s.reshape(steps, ny).mean(axis=1),
            "convergence_length_mean_m": rows[:, 1],
            "convergence_length_min_m": rows[:, 2],
            "convergence_length_max_m": rows[:, 3],
            "braid_angle_warp_deg": np.degrees(alpha[:, group == 0].mean(axis=1)),
            "braid_angle_weft_deg": np.degrees(alpha[:, group == 1].mean(axis=1)),
            "contacts": rows[:, 4],
            "iterations": rows[:, 5],
            "residual": rows[:, 6],
            # the spread round the section: the least and largest angle over all yarns
            "braid_angle_min_deg": np.degrees(alpha.min(axis=1)),
            "braid_angle_max_deg": np.degrees(alpha.max(axis=1)),
        }
        assert tuple(history) == HISTORY_COLUMNS
        return history, s.reshape(steps, ny)

    # -- checkpoints --------------------------------------------------------------------------
    def to_arrays(self) -> dict:
        """Every record as a named plain array; snapshots concatenated along their points with
        ``snapshot_points`` (k + 1,) offsets into them."""
        out = {name: getattr(self, name).array.copy()
               for name in ("rows", "fell", "face", "lay_dir", "H", "moved", "end_flag")}
        out.update({f"laid_{name}": rows.array.copy() for name, rows in self.laid.items()})
        snaps = self.snapshots
        counts = [len(s.points) for s in snaps]
        cat = (lambda name, dtype, shape:
               np.concatenate([getattr(s, name) for s in snaps]).astype(dtype) if snaps
               else np.zeros((0,) + shape, dtype=dtype))
        out.update(
            snapshot_time=np.array([s.time_s for s in snaps], dtype=np.float64),
            snapshot_points=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            snapshot_point=cat("points", np.float64, (3,)),
            snapshot_offsets=np.array([s.offsets for s in snaps], dtype=np.int64).reshape(-1, self.n_yarns + 1),
            snapshot_tension=cat("tension_N", np.float64, ()),
            snapshot_contact_id=cat("contact_id", np.int64, ()),
            snapshot_slip=cat("slip", np.int8, ()),
            snapshot_external_force=(np.concatenate([s.external_forces() for s in snaps])
                                     if snaps else np.zeros((0, 3))),
            snapshot_group=np.array([s.group for s in snaps], dtype=np.int8).reshape(-1, self.n_yarns),
            snapshot_rebalance_shift=np.array([s.rebalance_shift_m for s in snaps], dtype=np.float64))
        return out

    @classmethod
    def from_arrays(cls, arrays, n_yarns: int, n_faces: int) -> "Recording":
        """The record ``to_arrays`` gave, checked (shapes, dtypes, finite floats, yarn, step and
        face indices in range, snapshot offsets within their points): ValueError otherwise."""
        ny = int(n_yarns)
        take, finite, in_range = plain.take, plain.finite, plain.in_range
        rec = cls(ny)
        rows = finite("rows", take(arrays, "rows", (None, len(ROW_COLUMNS)), np.float64))
        n = len(rows)
        if n == 0:
            raise ValueError("array 'rows' is empty: a run records its start")
        arr = {"rows": rows,
               "fell": finite("fell", take(arrays, "fell", (n, ny, 3), np.float64)),
               "face": in_range("face", take(arrays, "face", (n, ny), np.int64), 0, n_faces),
               "lay_dir": finite("lay_dir", take(arrays, "lay_dir", (n, ny, 3), np.float64)),
               "H": finite("H", take(arrays, "H", (n, ny), np.float64)),
               "moved": take(arrays, "moved", (n - 1, ny), np.bool_),
               "end_flag": take(arrays, "end_flag", (n - 1, ny), np.uint8)}
        for name, a in arr.items():
            setattr(rec, name, Rows.of(a))
        m = len(take(arrays, "laid_yarn", (None,), np.int64))
        laid = {name: take(arrays, f"laid_{name}", (m,) + shape, dtype)
                for name, (shape, dtype) in _LAID.items()}
        in_range("laid_yarn", laid["yarn"], 0, ny)
        in_range("laid_step", laid["step"], 0, n - 1)
        in_range("laid_face", laid["face"], 0, n_faces)
        for name in ("order", "point", "time"):
            finite(f"laid_{name}", laid[name])
        rec.laid = {name: Rows.of(a) for name, a in laid.items()}
        rec.snapshots = _snapshots_from_arrays(arrays, ny)
        return rec


def _snapshots_from_arrays(arrays, ny):
    take, finite = plain.take, plain.finite
    times = finite("snapshot_time", take(arrays, "snapshot_time", (None,), np.float64))
    k = len(times)
    bounds = take(arrays, "snapshot_points", (k + 1,), np.int64)
    point = finite("snapshot_point", take(arrays, "snapshot_point", (None, 3), np.float64))
    total = len(point)
    if bounds[0] != 0 or bounds[-1] != total or np.any(np.diff(bounds) < ny + 1):
        raise ValueError("array 'snapshot_points' does not split the snapshot points")
    offsets = take(arrays, "snapshot_offsets", (k, ny + 1), np.int64)
    tension = finite("snapshot_tension", take(arrays, "snapshot_tension", (total - k * ny,), np.float64))
    cid = take(arrays, "snapshot_contact_id", (total,), np.int64)
    slip = take(arrays, "snapshot_slip", (total,), np.int8)
    external = finite("snapshot_external_force",
                      take(arrays, "snapshot_external_force", (total, 3), np.float64))
    group = plain.in_range("snapshot_group", take(arrays, "snapshot_group", (k, ny), np.int8), 0, 2)
    shift = (finite("snapshot_rebalance_shift", take(arrays, "snapshot_rebalance_shift", (k,),
                                                     np.float64), allow_nan=True)
             if "snapshot_rebalance_shift" in arrays else np.full(k, np.nan))
    out, t0 = [], 0
    for i in range(k):
        a, b = bounds[i], bounds[i + 1]
        o = offsets[i]
        # each yarn of a snapshot is a polyline of at least two points
        if o[0] != 0 or o[-1] != b - a or np.any(np.diff(o) < 2):
            raise ValueError(f"array 'snapshot_offsets' does not split snapshot {i} into yarns")
        t1 = t0 + (b - a) - ny
        out.append(Snapshot(time_s=float(times[i]), points=point[a:b].copy(), offsets=o.copy(),
                            tension_N=tension[t0:t1].copy(), contact_id=cid[a:b].copy(),
                            slip=slip[a:b].copy(), group=group[i].copy(),
                            external_force_N=external[a:b].copy(),
                            rebalance_shift_m=float(shift[i])))
        t0 = t1
    return out
