"""Time stepping of a braiding run: pose, supply points, deposition, history (DESIGN.md §2, §3).

``simulate(config)`` loads the mandrel and centerline, ties every yarn to the mandrel's tip and
steps the process until ``braid_length`` of centerline is braided. It returns a
:class:`preform.result.Result`; an interrupted (Ctrl-C) or failed run returns what it computed up
to the last good step, with ``status`` saying so.
"""

from __future__ import annotations

import json
import os
import pickle
import signal
import threading
import time as _time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from . import geometry
from . import __version__
from .errors import ConfigError, SimulationError
from .kinematic import Depositor, smooth_normals
from .zone import ZoneStep, make_zone
from .machine import Machine
from .reference import resolve_pose_lead
from .result import HISTORY_COLUMNS, FLAG_SLIP, Result, YarnPaths
from .tolerances import tol

#: tie the yarns this far (in yarn widths) from the tip along the centerline, clear of the tip edge
TIE_OFFSET_WIDTHS = 2.0


def load_geometry(config):
    """(Mandrel, Centerline) of a config, in metres, mandrel frame."""
    mc = config.mandrel
    mandrel = geometry.load_mandrel(mc.stl, unit=mc.stl_unit)
    if isinstance(mc.centerline, str) and mc.centerline == "auto":
        centerline = geometry.auto_centerline(mandrel, roll_reference=mc.roll_reference)
    else:
        centerline = geometry.read_centerline_csv(mc.centerline, unit=mc.stl_unit,
                                                  roll_reference=mc.roll_reference)
    return mandrel, centerline


class CenterlineProjector:
    """Fast arc length of points near a centerline: KD-tree on a dense resampling.

    Accurate to ``spacing / 2`` in s before refinement; the nearest sample's two segments are then
    projected exactly, so the result is the polyline's closest point up to ties between branches.
    """

    def __init__(self, centerline, spacing=5e-4):
        L = centerline.length
        n = max(int(np.ceil(L / spacing)) + 1, 2)
        self.s = np.linspace(0.0, L, n)
        self.points = centerline.frames_at(self.s)[0]
        self.tree = cKDTree(self.points)

    def __call__(self, points):
        points = np.atleast_2d(points)
        _, i = self.tree.query(points)
        n = len(self.s)
        best_s = self.s[i].copy()
        best_d = np.full(len(points), np.inf)
        for lo in (np.maximum(i - 1, 0), i):
            hi = np.minimum(lo + 1, n - 1)
            a = self.points[lo]
            ab = self.points[hi] - a
            L2 = np.einsum("ij,ij->i", ab, ab)
            u = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
            d = np.linalg.norm(a + u[:, None] * ab - points, axis=1)
            better = d < best_d
            best_d[better] = d[better]
            best_s[better] = (self.s[lo] + u * (self.s[hi] - self.s[lo]))[better]
        return best_s


@dataclass
class _Clock:
    """Process state advanced by the stepper: time and the centerline length fed (travel)."""

    t: float
    travel: float


def take_up_speed(table, braided_length):
    """Take-up speed (m/s) from the config table ((length, speed), ...) at a braided length."""
    table = np.asarray(table, dtype=float)
    if len(table) == 1:
        return float(table[0, 1])
    return float(np.interp(braided_length, table[:, 0], table[:, 1]))


def default_time_step(config, machine, mandrel, centerline):
    """Step control: bound the carrier rotation and the fell-point advance per step.

    The kinematic model integrates the fell points' equation of motion (second order in the
    step: ``max_carrier_rotation``, ``max_fell_advance``). The interaction model is quasi-static:
    a step is one solve of the zone with the friction history of the last, and its cost is that
    solve; what it must resolve is the arrival of new crossings (at most
    ``interaction_pass_fraction`` of the pass period per step: a yarn meets a new crossing every
    third step at most) and the mandrel's shape under the fell points (``interaction_fell_advance``
    widths per step). Measured on case A with friction 0.25 against the kinematic model's step
    (``benchmarks/bench_interaction.py --step-factor``):

    * 144 carriers (this step is 1.45x the kinematic one): twice the kinematic step moves the
      convergence length by at most 0.5 % and the braid angle by at most 0.35 deg over 0.3 m;
      four times moves them by 2.5 % and 1.3 deg (a yarn then meets a new crossing almost every
      step). Newton steps per step 7.4, 9.0, 19.6 for 1, 2, 4 times the step. The full 1 m took
      1891 steps of 10.0 Newton steps instead of 2751 of 7.5: 8 % fewer Newton steps;
    * 48 carriers (4.4x): four times the kinematic step moves them by 0.9 % and 0.5 deg at 0.4 m,
      with 8.0 Newton steps per step instead of 6.9: 9 s instead of 31 s;
    * tests/test_interaction_sim.py: 0.6 % of the convergence length against a quarter of the step.

    Behind a guide ring the interaction model keeps the kinematic step: its ring points slide
    explicitly once a step (``InteractionZone.slide_rings``), so a longer step moves them further
    between solves, and case B (96 carriers, friction 0.25) with 2.2x the kinematic step stopped
    at 0.48 m, its Newton solve failing (residual 0.9) where the kinematic step runs through
    (the staged re-solve of a failed step now takes it through). The bent tube (96 carriers,
    guide ring) with 2.2x the kinematic step stops at t = 26.5 s, also with the staged re-solve,
    and did so too when an experiment made the failed step again in halves down to 1/8: a weft
    yarn has gone slack over its whole zone (0.005 to 0.1 N below a top tension of 4.3 N), a
    state no step length solves. With the kinematic step no segment of its snapshots falls
    below 2.4 N.
    """
    omega = machine.omega
    v_max = max(v for _, v in config.process.take_up_speed)
    r_max = float(np.max(centerline.project(mandrel.vertices)[1]))
    per_width = config.yarn.width / (omega * r_max + v_max)   # s for the fell points to advance a width
    if config.model.kind == "interaction" and not machine.has_ring:
        return min(tol.interaction_pass_fraction * machine.pass_period(),
                   tol.interaction_fell_advance * per_width)
    return min(tol.max_carrier_rotation / omega, tol.max_fell_advance * per_width)


def _tie_points(config, machine, mandrel, centerline, pose, rng):
    """Initial fell points: on the section near the tip, at each carrier's azimuth (DESIGN.md §3.3)."""
    s_tie = TIE_OFFSET_WIDTHS * config.yarn.width
    phi = machine.azimuths(0.0)
    if config.model.start == "random":
        phi = phi + rng.uniform(-np.pi, np.pi, size=phi.shape) / machine.n_per_group
        s_tie = s_tie + rng.uniform(0.0, 2.0 * config.yarn.width, size=phi.shape)
    s_tie = np.broadcast_to(np.asarray(s_tie, dtype=float), phi.shape)
    c, T, _, _ = centerline.frames_at(s_tie)
    u_machine = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
    u = u_machine @ pose.R  # rows: R^T u
    u -= np.einsum("ij,ij->i", u, T)[:, None] * T
    u /= np.linalg.norm(u, axis=1)[:, None]
    far = c + u * mandrel.diagonal
    # cast from outside inwards so the hit is the outer surface, whatever the section shape
    hit, point, face, _ = mandrel.intersect_segments(far, c)
    if not np.all(hit):
        raise SimulationError(
            f"could not tie {np.sum(~hit)} yarn(s) to the mandrel at {s_tie[0]:.4g} m from the tip: "
            "the centerline there does not lie inside the mandrel")
    return point, face.astype(np.int64)


def simulate(config, progress=True, mandrel=None, centerline=None, checkpoint=None, resume=False) -> Result:
    """Run the configured model and return a Result (see module docstring).

    ``mandrel`` and ``centerline`` may be passed when already loaded (the CLI checks them first).
    ``checkpoint``: a file where the run's state is saved every ``CHECKPOINT_EVERY_S`` seconds of
    wall time and when it is interrupted; with ``resume=True`` the run continues from it and
    gives the same results as a run that was never stopped. Ctrl-C stops after the current step
    (a second Ctrl-C stops at once).
    """
    wall0 = _time.perf_counter()
    if mandrel is None or centerline is None:
        mandrel, centerline = load_geometry(config)
    config = resolve_pose_lead(config, mandrel, centerline)   # [process] pose_lead = "auto"
    machine = Machine.from_config(config.machine)
    stepper = _Stepper(config, machine, mandrel, centerline)
    if resume:
        if checkpoint is None or not Path(checkpoint).is_file():
            raise ConfigError(f"--resume: no checkpoint to resume from at {checkpoint}; run without --resume")
        stepper.restore(checkpoint)
    status, message = "done", ""
    with _graceful_interrupt(stepper):
        try:
            stepper.run(progress=progress, checkpoint=checkpoint)
        except KeyboardInterrupt:
            status = "interrupted"
            message = f"interrupted by the user at t = {stepper.clock.t:.4g} s"
            if checkpoint is not None and stepper.consistent:
                stepper.save(checkpoint)
                message += "; resume with --resume"
            elif checkpoint is not None and Path(checkpoint).is_file():
                message += "; stopped inside a step: --resume continues from the last checkpoint"
        except SimulationError as exc:
            status, message = "failed", str(exc)
    if status == "done" and checkpoint is not None:
        Path(checkpoint).unlink(missing_ok=True)
    return stepper.result(status, message, _time.perf_counter() - wall0)


@contextmanager
def _graceful_interrupt(stepper):
    """First Ctrl-C: stop after the current step (state stays consistent); second: at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if stepper.stop_requested:
            raise KeyboardInterrupt
        stepper.stop_requested = True

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


#: seconds of wall time between checkpoints
CHECKPOINT_EVERY_S = 30.0
#: attributes of _Stepper that make its state (saved and restored by checkpoints); the time step
#: and the snapshot stride too, so that a run resumed by a version with another step control goes
#: on with the step it started with
_STATE = ("clock", "F", "face", "tie", "laid_steps", "laid_extra", "rows", "fell_hist", "face_hist",
          "lay_dir_hist", "H_hist", "snapshots", "zone", "step", "braided", "dt", "snapshot_stride")


class _Stepper:
    """Holds the run's state; ``run`` advances it, ``result`` packs it (also after a stop)."""

    def __init__(self, config, machine, mandrel, centerline):
        self.config = config
        self.machine = machine
        self.mandrel = mandrel
        self.centerline = centerline
        self.project = CenterlineProjector(centerline)
        self.dt = config.model.time_step or default_time_step(config, machine, mandrel, centerline)
        w = config.yarn.width
        clearance = max(0.5 * config.yarn.thickness, 1e-5 * mandrel.diagonal)
        self.depositor = Depositor(mandrel, clearance=clearance, h_max=0.5 * w)
        self.ecc = np.asarray(config.process.eccentricity, dtype=float)
        self.lead = config.process.pose_lead
        self.clock = _Clock(0.0, config.process.initial_position)
        pose = self.pose(self.clock.travel)
        rng = np.random.default_rng(config.model.seed)
        self.F, self.face = _tie_points(config, machine, mandrel, centerline, pose, rng)
        self.tie = (self.F.copy(), self.face.copy())
        ny = len(self.F)
        # laid points: the tie points, then per step the arrays of the depositor (packed at the end)
        self.laid_steps = []     # (step time, final_F, final_face, moved, end_flag) per step
        self.laid_extra = []     # (yarn, step index, order, point, face, time, flag) for jumps
        self.rows = []           # (t, H mean, H min, H max, contacts, iterations, residual)
        self.fell_hist = []      # (ny, 3) mandrel-frame fell points per recorded step
        self.face_hist = []      # (ny,) their faces
        self.lay_dir_hist = []   # (ny, 3) mandrel-frame laying direction per recorded step
        self.H_hist = []
        self.snapshots = []
        n_snap = config.output.snapshots if config.output is not None else 20
        self.snapshot_stride = 0 if n_snap <= 0 else self._snapshot_stride(n_snap)
        self.zone = make_zone(config, machine, mandrel)
        self.zone.start(0.0, pose.to_machine(self.F), pose)
        self._record(pose, ZoneStep.kinematic(machine.supply_points(0.0)))
        self.step = 0
        self.braided = self.braided_length_estimate()
        self.stop_requested = False
        self.consistent = True   # False while a step is half applied

    # -- checkpoints --------------------------------------------------------------------------
    def _fingerprint(self):
        from .config import dump_config

        d = dump_config(self.config)
        d.pop("output", None)
        return json.dumps(d, sort_keys=True, default=str)

    def save(self, path):
        """Pickle the state atomically (temporary file in the same folder, then rename)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        state = {name: getattr(self, name) for name in _STATE}
        payload = {"version": __version__, "config": self._fingerprint(), "state": state}
        tmp = path.with_name(f".{path.name}.tmp")
        with open(tmp, "wb") as fh:
            pickle.dump(payload, fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)

    def restore(self, path):
        try:
            with open(path, "rb") as fh:
                payload = pickle.load(fh)
        except Exception as exc:
            raise ConfigError(f"--resume: the checkpoint {path} cannot be read ({exc}); run without --resume") from None
        if payload.get("config") != self._fingerprint():
            raise ConfigError(f"--resume: the checkpoint {path} was made with other inputs; "
                              "run without --resume to start again")
        for name, value in payload["state"].items():
            setattr(self, name, value)

    # -- process kinematics -------------------------------------------------------------------
    def pose(self, travel):
        return geometry.pose_at(self.centerline, travel, eccentricity=self.ecc, lead=self.lead)

    def braided_length_estimate(self):
        """Cheap braided length for the stopping test: mean arc length of the fell points."""
        return float(np.mean(self.project(self.F)))

    # -- stepping -----------------------------------------------------------------------------
    def run(self, progress=True, checkpoint=None):
        cfg = self.config
        target = cfg.process.braid_length
        L = self.centerline.length
        bar = _progress_bar(target, progress)
        last_save = _time.perf_counter()
        try:
            bar(self.braided)
            while self.braided < target:
                if self.stop_requested:
                    raise KeyboardInterrupt
                v = take_up_speed(cfg.process.take_up_speed, self.braided)
                self.advance(v)
                if self.step % 10 == 0:
                    self.braided = self.braided_length_estimate()
                    bar(self.braided)
                if self.clock.travel - self.lead > L:
                    raise SimulationError(
                        f"the mandrel's end passed the machine at t = {self.clock.t:.4g} s before "
                        f"{target} m were braided ({self.braided:.4g} m): shorten [process] braid_length "
                        "or lengthen the mandrel")
                if checkpoint is not None and _time.perf_counter() - last_save > CHECKPOINT_EVERY_S:
                    self.save(checkpoint)
                    last_save = _time.perf_counter()
        finally:
            bar(None)

    def advance(self, v):
        """One time step; the state changes only at the end (an error leaves the last good step)."""
        self.consistent = False   # a zone with state (interaction) changes during its step
        t0, dt = self.clock.t, self.dt
        travel_end = self.clock.travel + v * dt
        pose_mid = self.pose(self.clock.travel + 0.5 * v * dt)
        pose_end = self.pose(travel_end)
        zs = self.zone.step(t0, dt, pose_end.to_machine(self.F), pose_end)
        F, face, deposited = self._deposit(zs.deposits, pose_end)
        G_mid = pose_mid.to_mandrel(zs.G_mid)
        G_end = pose_end.to_mandrel(zs.G_end)
        max_len = max(20.0 * (self.machine.omega * self.mandrel.diagonal + v) * dt, 10 * self.config.yarn.width)
        laid = self.depositor.step(F, face, G_mid, G_end, max_len)
        t1 = t0 + dt
        if not np.all(np.isfinite(laid.final_F)):
            bad = int(np.nonzero(~np.all(np.isfinite(laid.final_F), axis=1))[0][0])
            raise SimulationError(f"non-finite fell point of yarn {bad} at step {self.step + 1}, t = {t1:.6g} s")
        step = len(self.laid_steps)
        extra = [(k, step, -1.0, p, f, t1, 0) for k, p, f in deposited]
        for k, items in laid.extra.items():
            for order, (p, f, fl) in enumerate(items):
                extra.append((k, step, order, p, f, t1, fl))
        self.laid_extra.extend(extra)
        self.laid_steps.append((t1, laid.final_F, laid.final_face, laid.moved, laid.end_flag))
        self.F, self.face = laid.final_F, laid.final_face
        self.clock = _Clock(t1, travel_end)
        self.step += 1
        self._record(pose_end, zs)
        self.consistent = True

    def _deposit(self, deposits, pose):
        """Crossings that reached the mandrel become fell points (interaction model).

        Returns new (F, face) arrays and the list of (yarn, point, face) laid this way.
        """
        if not deposits:
            return self.F, self.face, []
        last = {int(kk): p for kk, p in deposits}     # a yarn's deposits come lowest first: keep the last
        k = np.array(list(last), dtype=np.int64)
        points = pose.to_mandrel(np.array(list(last.values()), dtype=float))
        on_surface, faces = self.mandrel.closest_points(points)
        F = self.F.copy()
        face = self.face.copy()
        F[k] = on_surface
        face[k] = np.asarray(faces, dtype=np.int64)
        return F, face, [(int(kk), F[kk].copy(), int(face[kk])) for kk in k]

    def _record(self, pose, zs):
        F_machine = pose.to_machine(self.F)
        H = F_machine[:, 2] - self.machine.supply_z
        self.H_hist.append(H)
        self.fell_hist.append(self.F.copy())
        self.face_hist.append(self.face.copy())
        self.lay_dir_hist.append(pose.to_mandrel(zs.G_end) - self.F)
        self.rows.append((self.clock.t, float(np.mean(H)), float(np.min(H)), float(np.max(H)),
                          zs.contacts, zs.iterations, zs.residual))
        if self.snapshot_stride and (len(self.rows) - 1) % self.snapshot_stride == 0:
            self.snapshots.append(self.zone.snapshot(self.clock.t, F_machine))

    def _snapshot_stride(self, n_snap):
        """Steps between snapshots so that a run writes about n_snap of them."""
        cfg = self.config
        v = max(s for _, s in cfg.process.take_up_speed)
        n_steps_est = cfg.process.braid_length / (v * self.dt) + 1
        return int(max(1, n_steps_est // n_snap))

    # -- packing ------------------------------------------------------------------------------
    def result(self, status, message, wall):
        yarns = self._yarn_paths()
        history, fell_s = self._history()
        return Result(config=self.config, mandrel=self.mandrel, centerline=self.centerline,
                      yarns=yarns, history=history, snapshots=self.snapshots, fell_s=fell_s,
                      convergence_length=np.array(self.H_hist), status=status, message=message,
                      wall_time_s=wall)

    def _yarn_paths(self):
        ny = len(self.F)
        F0, face0 = self.tie
        # records (yarn, step, order): tie points first, jump points in order, each step's end last
        yarn = [np.arange(ny)]
        step = [np.full(ny, -1)]
        order = [np.zeros(ny)]
        pts = [F0]
        fcs = [face0]
        tms = [np.zeros(ny)]
        fls = [np.zeros(ny, dtype=np.uint8)]
        for i, (t1, F, face, moved, flag) in enumerate(self.laid_steps):
            k = np.nonzero(moved)[0]
            yarn.append(k)
            step.append(np.full(len(k), i))
            order.append(np.full(len(k), np.inf))
            pts.append(F[k])
            fcs.append(face[k])
            tms.append(np.full(len(k), t1))
            fls.append(flag[k])
        if self.laid_extra:
            k, i, o, p, f, t, fl = zip(*self.laid_extra)
            yarn.append(np.array(k))
            step.append(np.array(i))
            order.append(np.array(o, dtype=float))
            pts.append(np.array(p))
            fcs.append(np.array(f))
            tms.append(np.array(t))
            fls.append(np.array(fl, dtype=np.uint8))
        yarn, step, order = (np.concatenate(a) for a in (yarn, step, order))
        sort = np.lexsort((order, step, yarn))
        points = np.concatenate(pts)[sort].reshape(-1, 3)
        face = np.concatenate(fcs)[sort].astype(np.int64)
        times = np.concatenate(tms)[sort]
        flags = np.concatenate(fls)[sort].astype(np.uint8)
        offsets = np.searchsorted(yarn[sort], np.arange(ny + 1)).astype(np.int64)
        angles, slip = laid_braid_angles(self.depositor.surface, self.project, self.centerline,
                                         points, face, offsets,
                                         mandrel_friction(self.config))
        flags = flags | np.where(slip, FLAG_SLIP, 0).astype(np.uint8)
        return YarnPaths(points=points, offsets=offsets, time_s=times, braid_angle_deg=angles,
                         face=face, flags=flags, group=self.machine.group.astype(np.int8))

    def _history(self):
        fell = np.array(self.fell_hist)            # (steps, ny, 3)
        lay = np.array(self.lay_dir_hist)
        steps, ny, _ = fell.shape
        flat_fell = fell.reshape(-1, 3)
        s = self.project(flat_fell)
        T = self.centerline.frames_at(s)[1]
        faces = np.array(self.face_hist).reshape(-1)
        n = smooth_normals(self.depositor.surface, faces, flat_fell)
        alpha = braid_angle(lay.reshape(-1, 3), T, n).reshape(steps, ny)
        group = self.machine.group
        rows = np.array(self.rows)
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
        }
        assert tuple(history) == HISTORY_COLUMNS
        return history, s.reshape(steps, ny)


def mandrel_friction(config):
    """Yarn-mandrel friction for the slip tendency: [yarn] mandrel_friction, else friction."""
    mu = getattr(config.yarn, "mandrel_friction", None)
    return config.yarn.friction if mu is None else mu


def braid_angle(direction, tangent, normal):
    """Braid angle (rad, magnitude in [0, pi/2]) between directions and the surface projection of
    the centerline tangent (DESIGN.md §2). All (m, 3); normal unit."""
    d = direction - np.einsum("ij,ij->i", direction, normal)[:, None] * normal
    t = tangent - np.einsum("ij,ij->i", tangent, normal)[:, None] * normal
    dn = np.linalg.norm(d, axis=1)
    tn = np.linalg.norm(t, axis=1)
    c = np.abs(np.einsum("ij,ij->i", d, t)) / np.where(dn * tn > 0, dn * tn, 1.0)
    return np.arccos(np.clip(c, 0.0, 1.0))


def laid_braid_angles(surface, project, centerline, points, face, offsets, mu):
    """Braid angle (deg) of the laid yarn at every point, and its slip tendency (bool).

    The laid direction at a point is the chord between its neighbours along the yarn (one-sided at
    the ends). Slip tendency (DESIGN.md §3.2): ``|kappa_g| > mu kappa_n``, with the curvature
    vector from a three-point stencil and the normal curvature from the smooth normal field.
    """
    m = len(points)
    angles = np.zeros(m)
    slip = np.zeros(m, dtype=bool)
    if m == 0:
        return angles, slip
    prev_i = np.arange(m) - 1
    next_i = np.arange(m) + 1
    starts = offsets[:-1]
    ends = offsets[1:] - 1
    prev_i[starts] = starts
    next_i[ends] = ends
    d = points[next_i] - points[prev_i]
    s = project(points)
    T = centerline.frames_at(s)[1]
    n = smooth_normals(surface, face, points)
    single = np.linalg.norm(d, axis=1) == 0
    angles = np.degrees(braid_angle(np.where(single[:, None], T, d), T, n))
    # curvatures (interior points with both neighbours distinct)
    a = points[prev_i]
    b = points[next_i]
    l1 = np.linalg.norm(points - a, axis=1)
    l2 = np.linalg.norm(b - points, axis=1)
    ok = (l1 > 0) & (l2 > 0)
    if np.any(ok):
        t1 = (points[ok] - a[ok]) / l1[ok, None]
        t2 = (b[ok] - points[ok]) / l2[ok, None]
        tm = t1 + t2
        tm /= np.maximum(np.linalg.norm(tm, axis=1), 1e-300)[:, None]
        kvec = (t2 - t1) / (0.5 * (l1[ok] + l2[ok]))[:, None]
        nn = n[ok]
        kappa_g = np.einsum("ij,ij->i", kvec, np.cross(nn, tm))
        na = smooth_normals(surface, face[prev_i][ok], a[ok])
        nb = smooth_normals(surface, face[next_i][ok], b[ok])
        kappa_n = np.einsum("ij,ij->i", nb - na, tm) / (l1[ok] + l2[ok])
        slip[np.nonzero(ok)[0]] = np.abs(kappa_g) > mu * np.abs(kappa_n) + 1e-9
    return angles, slip


def _progress_bar(total, enabled):
    """A callable updated with the braided length; None closes it."""
    if not enabled:
        return lambda value: None
    from tqdm import tqdm

    bar = tqdm(total=round(total, 6), unit="m", desc="braiding", leave=True,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.3f}/{total:.3f} m braided [{elapsed}<{remaining}]")

    def update(value):
        if value is None:
            bar.close()
            return
        bar.n = round(min(value, total), 6)
        bar.refresh()

    return update
