"""Kinematic deposition: fell points wrap, bridge and catch (docs/theory.md §3).

The free yarn is straight from its supply point ``G`` to its fell point ``F`` on the mandrel;
deposited yarn sticks. Each time step (mandrel frame, where laid yarn is at rest):

1. ``F`` walks over the surface along the projected free-yarn direction until the free yarn is
   tangent, ``g = (G - F) . n(F) = 0`` (kernel ``walk_to_tangency``). Time integration is the
   midpoint rule: the walk direction uses the supply point at the middle of the step, tangency the
   one at its end. Heun's predictor-corrector is the usual second-order reference; the
   midpoint rule is second order too (the test suite fits the rate) and needs one walk per step
   instead of two.
2. If the free yarn from ``F`` (lifted by half the yarn thickness, the yarn's own centerline) to
   ``G`` hits the mandrel, it has caught on an obstacle: the yarn spans straight to the hit point
   and wraps on from there (flag ``catch``). If the walk meets a concave stretch (``g`` falls as it
   walks) the yarn cannot follow the surface: it spans straight across to where the free yarn
   meets the surface again (flag ``bridge``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._kernels import kinematic as K
from .result import FLAG_BRIDGE, FLAG_CATCH, Snapshot
from .zone import ZoneStep

#: how many catch/bridge jumps one yarn may take in one step
MAX_JUMPS = 16
#: points along a bridged span at which its stand-off from the surface is measured
_SPAN_SAMPLES = 7


@dataclass(frozen=True)
class SurfaceArrays:
    """The mandrel arrays the kernels take (see ``_kernels/kinematic.py``)."""

    V: np.ndarray
    T: np.ndarray
    FN: np.ndarray
    CN: np.ndarray
    NB: np.ndarray

    @classmethod
    def from_mandrel(cls, mandrel) -> "SurfaceArrays":
        c = np.ascontiguousarray
        return cls(c(mandrel.vertices, dtype=np.float64), c(mandrel.faces, dtype=np.int64),
                   c(mandrel.face_normals, dtype=np.float64), c(mandrel.corner_normals, dtype=np.float64),
                   c(mandrel.neighbors, dtype=np.int64))


@dataclass
class StepLaid:
    """What one step laid: for each yarn, the points after its start (may be empty).

    final_F (ny, 3), final_face (ny,), moved (ny,) bool, and ``laid[k]`` a list of
    (point (3,), face, flag) in laying order for the yarns that laid more than their end point.
    """

    final_F: np.ndarray
    final_face: np.ndarray
    moved: np.ndarray
    end_flag: np.ndarray
    extra: dict


def smooth_normals(surface: SurfaceArrays, faces, points) -> np.ndarray:
    """Smooth unit normals at points on given faces. faces (m,), points (m, 3) -> (m, 3)."""
    out = np.empty((len(faces), 3))
    _smooth_normals_into(surface, np.asarray(faces, dtype=np.int64), np.asarray(points, dtype=float), out)
    return out


def _smooth_normals_into(s, faces, points, out):
    K.smooth_normals_batch(s.V, s.T, s.CN, faces, np.ascontiguousarray(points), out)


class Depositor:
    """Advances the fell points of all yarns by one time step on one mandrel.

    clearance (m): how far above the surface a fell point's free yarn starts for the catch test;
    bridge_depth (m): a span over a dip shallower than this lies on the surface; each one number
    or (ny,), per yarn (mixed yarns: its type's thickness); h_max (m): the walk's piece."""

    def __init__(self, mandrel, clearance, h_max: float, bridge_depth=0.0):
        self.mandrel = mandrel
        self.surface = SurfaceArrays.from_mandrel(mandrel)
        self.clearance = np.asarray(clearance, dtype=float)
        self.h_max = float(h_max)
        self.bridge_depth = np.asarray(bridge_depth, dtype=float)

    def span_depth(self, a, b) -> np.ndarray:
        """How far (m) the straight spans from ``a`` to ``b`` ((k, 3) each, points on the
        surface) stand off the mandrel at most: the largest distance to the surface of the points
        at 1/8 ... 7/8 of each span (exact closest points)."""
        t = np.arange(1, _SPAN_SAMPLES + 1) / (_SPAN_SAMPLES + 1)
        pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
        near, _ = self.mandrel.closest_points(pts.reshape(-1, 3))
        d = np.linalg.norm(pts.reshape(-1, 3) - near, axis=1)
        return d.reshape(len(a), _SPAN_SAMPLES).max(axis=1)

    def step(self, F, face, G_mid, G_end, max_len: float) -> StepLaid:
        """One step. F (ny, 3), face (ny,), G_mid / G_end (ny, 3) mandrel frame."""
        s = self.surface
        ny = len(F)
        F_out = np.empty_like(F)
        face_out = np.empty_like(face)
        status = np.empty(ny, dtype=np.int64)
        walked = np.empty(ny)
        active = np.ones(ny, dtype=np.bool_)
        K.advance_fell_points(s.V, s.T, s.FN, s.CN, s.NB, F, face, G_mid, G_end, active,
                              self.h_max, max_len, F_out, face_out, status, walked)
        moved = walked > 0.0
        end_flag = np.zeros(ny, dtype=np.uint8)
        extra: dict[int, list] = {}
        # the free yarns of every yarn first: most steps nothing is hit and the step is done
        starts = np.empty_like(F_out)
        clearance = np.ascontiguousarray(np.broadcast_to(self.clearance, (ny,)))
        bridge_depth = np.broadcast_to(self.bridge_depth, (ny,))
        K.lifted_points(s.V, s.T, s.CN, face_out, F_out, clearance, starts)
        first = self.mandrel.intersect_segments(starts, G_end)
        if not np.any(first[0]):
            return StepLaid(F_out, face_out, moved, end_flag, extra)
        pending = np.ones(ny, dtype=np.bool_)
        # True where F_out is already a laid point (the step's start for a yarn that did not move)
        recorded = ~moved
        for _ in range(MAX_JUMPS):
            idx = np.nonzero(pending)[0]
            if len(idx) == 0:
                break
            if first is not None:
                hit, point, hit_face, _dist = first
                first = None
            else:
                starts = np.empty((len(idx), 3))
                K.lifted_points(s.V, s.T, s.CN, face_out[idx], F_out[idx], clearance[idx], starts)
                hit, point, hit_face, _dist = self.mandrel.intersect_segments(starts, G_end[idx])
            if not np.any(hit):
                break
            jumpers = idx[hit]
            flags = np.where(status[jumpers] == K.WALK_CONCAVE, FLAG_BRIDGE, FLAG_CATCH).astype(np.uint8)
            bridged = flags == FLAG_BRIDGE
            if np.any(bridge_depth > 0.0) and bridged.any():
                # a span over a dip shallower than bridge_depth lies on the surface: not a bridge
                kb = jumpers[bridged]
                shallow = self.span_depth(F_out[kb], point[hit][bridged]) <= bridge_depth[kb]
                flags[np.nonzero(bridged)[0][shallow]] = 0
            for k, fl in zip(jumpers, flags):
                # the point reached so far is laid; the jump to the hit point is a straight span
                if not recorded[k]:
                    extra.setdefault(int(k), []).append((F_out[k].copy(), int(face_out[k]), int(end_flag[k])))
                end_flag[k] = fl
                recorded[k] = False
            F_out[jumpers] = point[hit]
            face_out[jumpers] = hit_face[hit]
            moved[jumpers] = True
            sub_F = np.ascontiguousarray(F_out[jumpers])
            sub_face = np.ascontiguousarray(face_out[jumpers])
            sub_G = np.ascontiguousarray(G_end[jumpers])
            m = len(jumpers)
            o_F = np.empty_like(sub_F)
            o_face = np.empty_like(sub_face)
            o_status = np.empty(m, dtype=np.int64)
            o_walked = np.empty(m)
            K.advance_fell_points(s.V, s.T, s.FN, s.CN, s.NB, sub_F, sub_face, sub_G, sub_G,
                                  np.ones(m, dtype=np.bool_), self.h_max, max_len,
                                  o_F, o_face, o_status, o_walked)
            for j, k in enumerate(jumpers):
                if o_walked[j] > 0.0:
                    extra.setdefault(int(k), []).append((F_out[k].copy(), int(face_out[k]), int(end_flag[k])))
                    end_flag[k] = 0
                    recorded[k] = False
            F_out[jumpers] = o_F
            face_out[jumpers] = o_face
            status[jumpers] = o_status
            pending[:] = False
            pending[jumpers] = True
        return StepLaid(F_out, face_out, moved, end_flag, extra)


class KinematicZone:
    """The kinematic model's zone (``preform.zone.Zone``): free yarns straight from fell point to
    supply point (spool, or guide-ring point), docs/theory.md §3. It has no state of its own."""

    #: seconds a run: nothing to say before it starts (``Zone.cost_note``)
    cost_note = ""
    #: the first-run worker's jobs are this model's kernels (``Zone.first_run_worker``)
    first_run_worker = True

    def __init__(self, config, machine, mandrel=None):
        self.config = config
        self.machine = machine
        # Machine.supply_points's factors, formed once: azimuth phase0 + (direction omega) t
        self._rate = machine.direction() * machine.omega

    @classmethod
    def for_run(cls, config, machine, mandrel, settings=None):
        """The zone of a run (``Zone.for_run``): the kinematic model has no settings of its own."""
        return cls(config, machine, mandrel)

    @classmethod
    def default_time_step(cls, machine, per_width, tolerances):
        """The fell points' equation of motion is integrated to second order in the step: bound
        the carrier rotation and the fell-point advance per step,
        ``min(max_carrier_rotation / omega, max_fell_advance * per_width)``."""
        return min(tolerances.max_carrier_rotation / machine.omega,
                   tolerances.max_fell_advance * per_width)

    def start(self, t, F_machine, pose):
        """Called once with the tie points (machine frame) and the mandrel pose at time t."""

    def step(self, t0, dt, F_machine, pose_end) -> ZoneStep:
        """The step from t0 to t0 + dt; F_machine: fell points at its end; pose_end: the mandrel's.

        The supply points at the middle and the end of the step, ``Machine.supply_points`` for
        both times in one pass (the same operations, so the same values to the last bit)."""
        m = self.machine
        phi = m.phase0 + self._rate * np.array([[t0 + 0.5 * dt], [t0 + dt]])
        r = m.supply_radius
        G = np.empty(phi.shape + (3,))
        G[..., 0] = r * np.cos(phi)
        G[..., 1] = r * np.sin(phi)
        G[..., 2] = m.supply_z
        return ZoneStep(G_mid=G[0], G_end=G[1])

    def snapshot(self, t, F_machine) -> Snapshot:
        """Fell point, supply point (and spool point behind a guide ring) of every yarn."""
        ends = [F_machine, self.machine.supply_points(t)]
        if self.config.machine.guide_ring is not None:
            ends.append(self.machine.spool_points(t))
        ny = len(F_machine)
        per = len(ends)
        points = np.stack(ends, axis=1).reshape(-1, 3)
        if getattr(self.config, "is_mixed", False):   # every yarn at its type's spool tension
            types = np.array([y.tension for y in self.config.types], dtype=float)
            tension = np.repeat(types[self.config.carrier_types()], per - 1)
        else:
            tension = np.full(ny * (per - 1), float(self.config.yarn.tension))
        return Snapshot(time_s=t, points=points, offsets=np.arange(ny + 1, dtype=np.int64) * per,
                        tension_N=tension,
                        contact_id=np.full(len(points), -1, dtype=np.int64),
                        slip=np.zeros(len(points), dtype=np.int8), group=self.machine.group.copy())

    def export_state(self) -> dict:
        """No state: the zone is the machine at every time."""
        return {}

    def import_state(self, arrays) -> None:
        """No state to restore; a checkpoint of this zone holds no arrays of it."""
        if arrays:
            raise ValueError(f"the kinematic zone has no state, the checkpoint gives {sorted(arrays)}")
