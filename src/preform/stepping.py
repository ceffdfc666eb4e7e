"""Time stepping of a braiding run: pose, step control, deposition, the time loop
(docs/architecture.md §2, §4).

A :class:`Stepper` ties every yarn to the mandrel's tip and advances the process step by step:
each step the mandrel moves on by the take-up speed, the zone (``preform.zone.Zone``) says where
each free yarn runs to, and the depositor walks the fell points over the mandrel
(``preform.kinematic``). What each step leaves is kept by a ``preform.recording.Recording``;
``state_arrays`` / ``restore`` give and take the whole state as plain arrays for checkpoints.
"""

from __future__ import annotations

import dataclasses
import time as _time
import warnings
from dataclasses import dataclass

import numpy as np

from . import plain
from .config import DEFAULT_SNAPSHOTS
from .laid import CenterlineProjector, mandrel_friction
from .errors import PreformError, SimulationError
from .geometry.pose import Pose, pose_at
from .kinematic import Depositor
from .recording import Recording
from .result import Result
from .tolerances import Tolerances, tol
from .trajectory import PathInterpolant, read_trajectory, rotation_to_quaternion
from .zone import ZoneStep, zone_class


class CheckpointWriteWarning(UserWarning):
    """A checkpoint could not be written; the run goes on."""

#: seconds of wall time between checkpoints
CHECKPOINT_EVERY_S = 30.0


@dataclass(frozen=True)
class Clock:
    """Process state advanced by the stepper: time t (s), the centerline length fed, travel (m)
    (driven by a trajectory: the tip's distance past the spool plane), and the carriers' clock
    ``carrier_t`` (s): the time the carriers would take at the machine's reference speed
    (``Machine.omega``) to turn as far as they have; the zones place the carriers by it, so a
    changing angular speed moves them as it should. With a constant speed it is ``t``."""

    t: float
    travel: float
    carrier_t: float = 0.0


def take_up_speed(table, braided_length):
    """Take-up speed (m/s) from the config table ((length, speed), ...) at a braided length
    (:func:`setting_at`)."""
    return float(setting_at(table, braided_length)[0])


def setting_at(table, braided_length) -> np.ndarray:
    """A setting's values (the table's columns after the first) at a braided length, from a
    table ((length, value, ...), ...) over the braided length: linear between rows, the end rows'
    values beyond them."""
    table = np.asarray(table, dtype=float)
    if len(table) == 1:
        return table[0, 1:].copy()
    return np.array([np.interp(braided_length, table[:, 0], table[:, j])
                     for j in range(1, table.shape[1])])


#: the columns of the process rows a Stepper keeps (``Result.process``): time, take-up speed,
#: angular speed, the mandrel frame's origin (machine frame) and the orientation's quaternion
PROCESS_ROW = ("time_s", "take_up_speed_m_s", "angular_speed_rad_s", "x_m", "y_m", "z_m",
               "qw", "qx", "qy", "qz")


def default_time_step(config, machine, mandrel, centerline, tolerances: Tolerances = tol):
    """Step control (s) where ``[model] time_step`` is not given: the model's own
    (``Zone.default_time_step`` of the class of ``[model] kind``), from how long the fell points
    take to advance a yarn width, ``w / (omega r_max + v_max)``. The measurements behind the
    bounds are in docs/decisions.md.
    """
    omega = machine.omega
    v_max = max(v for _, v in config.process.take_up_speed)
    r_max = float(np.max(centerline.project(mandrel.vertices)[1]))
    # s for the fell points to advance a width (mixed yarns: the narrowest type's)
    per_width = float(yarn_dimensions(config)[1].min()) / (omega * r_max + v_max)
    return zone_class(config.model.kind).default_time_step(machine, per_width, tolerances)


def yarn_dimensions(config) -> tuple[np.ndarray, np.ndarray]:
    """(thickness (ny,), width (ny,)), m: every yarn's, its type's (``Config.carrier_types``);
    [yarn]'s on every carrier of a uniform config."""
    ny = config.machine.carriers
    if not getattr(config, "is_mixed", False):
        return np.full(ny, float(config.yarn.thickness)), np.full(ny, float(config.yarn.width))
    kinds = config.carrier_types()
    types = config.types
    return (np.array([t.thickness for t in types])[kinds], np.array([t.width for t in types])[kinds])


def tie_points(config, machine, mandrel, centerline, pose, rng, tolerances: Tolerances = tol):
    """Initial fell points (ny, 3) mandrel frame and faces (ny,): on the section near the tip, at
    each carrier's azimuth (docs/theory.md §4); ``[model] start = "random"`` spreads them."""
    s_tie = tolerances.tie_offset_widths * config.yarn.width
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


def end_passed(travel: float, length: float, lead: float) -> bool:
    """Whether the mandrel's end has passed the machine once its tip is ``travel`` m past the
    spool plane: the pose holds the centerline point ``lead`` m ahead of the supply plane on the
    machine axis (``geometry.pose_at``), and past ``length + lead`` there is no centerline left
    for it. The run stops there (:meth:`Stepper.run`); ``preform check`` asks the same of the
    travel the run will need (``checks.mandrel_end_problem``)."""
    return travel - lead > length


def end_message(config, length: float, lead: float, h: float, offset: float) -> str:
    """Why the mandrel's end passes the machine before ``braid_length`` is braided, and what the
    part can do about it: the fell points reach braid_length with the tip about
    ``braid_length + h + offset`` past the spool plane (``h`` the convergence length then,
    ``offset`` the guide ring's from the spool plane), which must not exceed ``length + lead``."""
    p = config.process
    need = p.braid_length + h + offset
    most = length + lead - h - offset
    ring = f" plus the guide ring's offset {offset:.3g} m" if offset else ""
    lead_text = f" plus the pose lead {lead:.3g} m" if lead else ""
    fix = (f"shorten [process] braid_length to at most about {most:.3g} m or lengthen the mandrel"
           if most > 0 else "lengthen the mandrel")
    return (f"the mandrel's end passes the machine before [process] braid_length = {p.braid_length:g} m "
            f"is braided: the fell points get there with the tip {need:.3g} m past the spool plane "
            f"(braid_length plus the convergence length, about {h:.3g} m by then{ring}), beyond the "
            f"{length:.4g} m centerline{lead_text}; {fix}")


class Stepper:
    """Holds the run's state; ``run`` advances it, ``result`` packs it (also after a stop).

    config : preform.config.Config; machine : preform.machine.Machine; mandrel, centerline :
    preform.geometry (mandrel frame, SI); zone : a fresh preform.zone.Zone of ``[model] kind``;
    tolerances : the step control and geometry settings.
    """

    def __init__(self, config, machine, mandrel, centerline, zone, tolerances: Tolerances = tol):
        s = tolerances
        self.config = config
        self.machine = machine
        self.mandrel = mandrel
        self.centerline = centerline
        self.tolerances = tolerances
        self.project = CenterlineProjector(centerline, spacing=s.projector_spacing)
        self.dt = config.model.time_step or default_time_step(config, machine, mandrel, centerline, s)
        #: the constant angular speed (rad/s) of a run without a table or a trajectory
        self.machine_speed = float(config.machine.angular_speed)
        # every yarn's own thickness (mixed yarns: its type's); the walk's piece of the narrowest
        thickness, width = yarn_dimensions(config)
        clearance = np.maximum(s.catch_clearance_thickness * thickness,
                               s.catch_clearance_diagonal * mandrel.diagonal)
        self.depositor = Depositor(mandrel, clearance=clearance,
                                   h_max=s.walk_piece_widths * float(width.min()),
                                   bridge_depth=s.bridge_depth_thickness * thickness)
        p = config.process
        self.ecc_table = p.eccentricity_table or None
        self.ecc = np.asarray(p.eccentricity if self.ecc_table is None
                              else setting_at(self.ecc_table, 0.0), dtype=float)
        self.omega_table = config.machine.angular_speed_table or None
        self.lead = p.pose_lead
        self.path = (None if p.trajectory is None else PathInterpolant(read_trajectory(
            p.trajectory, max_take_up_speed=np.inf, max_angular_speed_deg=np.inf)))
        # travel counts from the spool plane; initial_position from the supply plane (the guide
        # ring's, offset from the spool plane, when there is one)
        self.clock = Clock(0.0, p.initial_position + machine.supply_z, 0.0)
        pose = self.pose(self.clock.travel) if self.path is None else self.path_pose(0.0)
        rng = np.random.default_rng(config.model.seed)
        self.F, self.face = tie_points(config, machine, mandrel, centerline, pose, rng, s)
        self.recording = Recording(len(self.F))
        n_snap = (config.output.snapshot_count(config.model.kind) if config.output is not None
                  else DEFAULT_SNAPSHOTS[config.model.kind])
        self.snapshot_stride = 0 if n_snap <= 0 else self._snapshot_stride(n_snap)
        self.zone = zone
        self.zone.start(0.0, pose.to_machine(self.F), pose)
        self.step = 0
        self.braided = self.braided_length_estimate()
        self.process_rows = []
        self._speeds = self.speeds()    # row 0 holds the speeds of the first step
        self._record(pose, ZoneStep.kinematic(machine.supply_points(0.0)))
        self.stop_requested = False
        self.stop_signal = ""        # the signal that asked for the stop ("SIGINT", "SIGTERM", ...)
        self.checkpoint_failed = False
        self.consistent = True   # False while a step is half applied

    # -- process kinematics -------------------------------------------------------------------
    def pose(self, travel):
        return pose_at(self.centerline, travel, eccentricity=self.ecc, lead=self.lead)

    def path_pose(self, t):
        """The pose of a run driven by a trajectory at time ``t`` (s)."""
        R, origin = self.path.pose(t)
        return Pose(R=R, t=origin)

    def speeds(self) -> tuple[float, float | None]:
        """(take-up speed m/s, angular speed rad/s or None where it is the machine's constant
        one) of the step from the present state: the config's tables at the braided length, or
        the trajectory's speeds at the time."""
        if self.path is not None:
            return self.path.speeds(self.clock.t)
        v = take_up_speed(self.config.process.take_up_speed, self.braided)
        omega = None if self.omega_table is None else float(setting_at(self.omega_table, self.braided)[0])
        return v, omega

    def braided_length_estimate(self):
        """Cheap braided length for the stopping test: mean arc length of the fell points."""
        return float(np.mean(self.project(self.F)))

    # -- stepping -----------------------------------------------------------------------------
    def run(self, progress=True, checkpoint=None, checkpoint_every_s=CHECKPOINT_EVERY_S,
            max_steps=None):
        """Step until ``braid_length`` is braided (or the step count reaches ``max_steps``);
        ``checkpoint`` (a preform.checkpoint.Checkpoint or None) saves the state every
        ``checkpoint_every_s`` s of wall time. SimulationError when a step fails or the mandrel
        runs out; KeyboardInterrupt once a stop was requested."""
        cfg = self.config
        target = cfg.process.braid_length
        L = self.centerline.length
        bar = progress_bar(target, progress, start=self.braided)
        last_save = _time.perf_counter()
        try:
            bar(self.braided)
            while self.braided < target and (max_steps is None or self.step < max_steps):
                if self.stop_requested:
                    raise KeyboardInterrupt
                v, omega = self.speeds()
                if self.path is not None and self.clock.t + self.dt > self.path.end * (1 + 1e-12):
                    raise SimulationError(
                        f"[process] trajectory {self.path.trajectory.path} ends at "
                        f"t = {self.path.end:.6g} s with {self.braided:.4g} m braided, before "
                        f"[process] braid_length = {target:g} m: extend the path or shorten "
                        "braid_length")
                self.advance(v, omega)
                if self.step % self.tolerances.braided_length_every == 0:
                    self.braided = self.braided_length_estimate()
                    bar(self.braided)
                if end_passed(self.clock.travel, L, self.lead):
                    # the convergence length now: the tip's travel past the supply plane less
                    # the braided length
                    h = self.clock.travel - self.machine.supply_z - self.braided
                    raise SimulationError(
                        end_message(cfg, L, self.lead, h, self.machine.supply_z)
                        + f" (the run stopped at t = {self.clock.t:.4g} s with {self.braided:.4g} m braided)")
                if checkpoint is not None and _time.perf_counter() - last_save > checkpoint_every_s:
                    self.save_checkpoint(checkpoint)
                    last_save = _time.perf_counter()
        finally:
            bar(None)

    def save_checkpoint(self, checkpoint) -> bool:
        """Save the state; a write that fails (disk full, read-only) does not stop the run: the
        first failure warns (CheckpointWriteWarning), the partial file is already removed
        (``checkpoint.write_exclusive``), and later saves are tried again. True if it saved."""
        try:
            checkpoint.save(self.state_arrays())
            return True
        except OSError as err:
            if not self.checkpoint_failed:
                warnings.warn(f"could not save the checkpoint {checkpoint.path} ({err.strerror or err}); "
                              "the run goes on, but an interruption now loses the work since the "
                              "last good checkpoint", CheckpointWriteWarning, stacklevel=2)
            self.checkpoint_failed = True
            return False

    def advance(self, v, omega=None):
        """One time step at take-up speed ``v`` (m/s) and angular speed ``omega`` (rad/s; None:
        the machine's constant one); the state changes only at the end (an error leaves the
        last good step)."""
        self.consistent = False   # a zone with state (interaction) changes during its step
        s = self.tolerances
        t0, dt = self.clock.t, self.dt
        t1 = t0 + dt
        if self.path is None:
            if self.ecc_table is not None:
                self.ecc = setting_at(self.ecc_table, self.braided)
            travel_end = self.clock.travel + v * dt
            pose_mid = self.pose(self.clock.travel + 0.5 * v * dt)
            pose_end = self.pose(travel_end)
        else:
            pose_mid, pose_end = self.path_pose(t0 + 0.5 * dt), self.path_pose(t1)
            travel_end = float(pose_end.to_machine(self.centerline.frame_values(0.0)[0])[2])
        # the carriers' clock (Clock): the zones place the carriers by it
        tau0, dtau = self.clock.carrier_t, dt
        if self.path is not None:
            dtau = self.path.turn(t1) / self.machine.omega - tau0
        elif omega is not None:
            dtau = dt * (omega / self.machine.omega)
        tau1 = t1 if self.path is None and omega is None else tau0 + dtau
        self._speeds = (v, omega)
        model = f"the {self.config.model.kind} model"
        # the zone keeps the state it solves for the snapshot the record takes after this step
        self.zone.snapshot_due = bool(self.snapshot_stride) and (
            self.recording.n_rows % self.snapshot_stride == 0)
        try:
            zs = self.zone.step(tau0, dtau, pose_end.to_machine(self.F), pose_end)
        except PreformError:
            raise
        except Exception as exc:
            raise self._fault(exc, f"{model}'s convergence zone"
                              + (f" ({self.zone.stage})" if getattr(self.zone, "stage", "") else ""),
                              t1) from exc
        try:
            F, face, deposited = self._deposit(zs.deposits, pose_end)
            G_mid = pose_mid.to_mandrel(zs.G_mid)
            G_end = pose_end.to_mandrel(zs.G_end)
            max_len = max(s.walk_reach_factor * (self.machine.omega * self.mandrel.diagonal + v) * dt,
                          s.walk_reach_widths * self.config.yarn.width)
            laid = self.depositor.step(F, face, G_mid, G_end, max_len)
        except PreformError:
            raise
        except Exception as exc:
            raise self._fault(exc, f"{model}'s deposit (the fell points' walk over the mandrel "
                              "to where the free yarns leave it)", t1) from exc
        if not np.all(np.isfinite(laid.final_F)):
            bad = int(np.nonzero(~np.all(np.isfinite(laid.final_F), axis=1))[0][0])
            raise SimulationError(f"non-finite fell point of yarn {bad} at step {self.step + 1}, t = {t1:.6g} s")
        extra = [(k, -1.0, p, f, t1, 0) for k, p, f in deposited]
        for k, items in laid.extra.items():
            for order, (p, f, fl) in enumerate(items):
                extra.append((k, order, p, f, t1, fl))
        self.recording.lay(laid.moved, laid.end_flag, extra)
        self.F, self.face = laid.final_F, laid.final_face
        self.clock = Clock(t1, travel_end, tau1)
        self.step += 1
        self._record(pose_end, zs, G_end)
        self.consistent = True

    def _fault(self, exc, part, t1) -> SimulationError:
        """A fault inside a step (a kernel's division, a singular matrix, a bug) as the error a
        user reads: the step, the part of the model, the fault; the results up to the last good
        step are kept (``simulation.simulate``)."""
        return SimulationError(
            f"step {self.step + 1} (t = {t1:.6g} s, {self.braided:.4g} m braided) failed in {part}: "
            f"{type(exc).__name__}: {exc or 'no message'} (an internal fault, not an input error; "
            "the results up to the last good step are kept: please report it with the config)")

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

    def _record(self, pose, zs, G_end=None):
        """One history row at the pose; G_end: the supply points in the mandrel frame when known."""
        F_machine = pose.to_machine(self.F)
        H = F_machine[:, 2] - self.machine.supply_z
        rec = self.recording
        if G_end is None:
            G_end = pose.to_mandrel(zs.G_end)
        rec.record(self.clock.t, self.F, self.face, H, G_end - self.F,
                   zs.contacts, zs.iterations, zs.residual)
        v, omega = self._speeds
        omega = self.machine_speed if omega is None else omega
        self.process_rows.append((self.clock.t, v, omega, *pose.t, *rotation_to_quaternion(pose.R)))
        if self.snapshot_stride and (rec.n_rows - 1) % self.snapshot_stride == 0:
            snap = self.zone.snapshot(self.clock.carrier_t, F_machine)
            if snap.time_s != self.clock.t:     # the zone places by the carriers' clock
                snap = dataclasses.replace(snap, time_s=self.clock.t)
            rec.snapshots.append(snap)

    def _snapshot_stride(self, n_snap):
        """Steps between snapshots so that a run writes about n_snap of them."""
        cfg = self.config
        v = max(s for _, s in cfg.process.take_up_speed)
        n_steps_est = cfg.process.braid_length / (v * self.dt) + 1
        return int(max(1, n_steps_est // n_snap))

    # -- packing ------------------------------------------------------------------------------
    def result(self, status, message, wall) -> Result:
        rec = self.recording
        surface = self.depositor.surface
        group = self.machine.group
        history, fell_s = rec.history(surface, self.project, self.centerline, group)
        yarns = rec.yarn_paths(surface, self.project, self.centerline, group,
                               mandrel_friction(self.config), self.tolerances.slip_curvature, fell_s=fell_s)
        return Result(config=self.config, mandrel=self.mandrel, centerline=self.centerline,
                      yarns=yarns, history=history, snapshots=list(rec.snapshots), fell_s=fell_s,
                      convergence_length=rec.H.array.copy(), status=status, message=message,
                      wall_time_s=wall, process=self.process_array())

    def process_array(self) -> np.ndarray:
        """(rows, len(PROCESS_ROW)) float64: the process of every history row (``PROCESS_ROW``:
        the speeds of the step that ended there, row 0 those of the first step; the pose at the
        row)."""
        return np.array(self.process_rows, dtype=np.float64).reshape(-1, len(PROCESS_ROW))

    # -- checkpoints --------------------------------------------------------------------------
    def state_arrays(self) -> dict:
        """The run's whole state as named plain arrays: the stepper's own (``stepper.*``: clock,
        fell points, step count, braided length, the carriers' clock, the process rows, and the
        time step and snapshot stride it runs with, so that a run resumed by a version with
        other step control goes on as it started),
        the record (``recording.*``) and the zone's (``zone.*``)."""
        out = {"clock": np.array([self.clock.t, self.clock.travel]), "F": self.F.copy(),
               "face": self.face.copy(), "step": np.int64(self.step),
               "braided": np.float64(self.braided), "dt": np.float64(self.dt),
               "snapshot_stride": np.int64(self.snapshot_stride),
               "carrier_t": np.float64(self.clock.carrier_t), "process": self.process_array()}
        return {**plain.prefixed("stepper.", {k: np.asarray(v) for k, v in out.items()}),
                **plain.prefixed("recording.", self.recording.to_arrays()),
                **plain.prefixed("zone.", self.zone.export_state())}

    def restore(self, arrays) -> None:
        """Continue from ``state_arrays`` of a run of the same inputs; every array is checked
        (shapes, dtypes, finite values, indices in range) before any is used: ValueError."""
        ny = len(self.F)
        n_faces = len(self.mandrel.faces)
        own = plain.unprefixed("stepper.", arrays)
        clock = plain.finite("clock", plain.take(own, "clock", (2,), np.float64))
        F = plain.finite("F", plain.take(own, "F", (ny, 3), np.float64))
        face = plain.in_range("face", plain.take(own, "face", (ny,), np.int64), 0, n_faces)
        step = plain.scalar(own, "step", np.int64)
        braided = plain.finite("braided", plain.take(own, "braided", (), np.float64)).item()
        dt = plain.scalar(own, "dt", np.float64)
        stride = plain.scalar(own, "snapshot_stride", np.int64)
        carrier_t = plain.finite("carrier_t", plain.take(own, "carrier_t", (), np.float64)).item()
        process = plain.finite("process", plain.take(own, "process", (step + 1, len(PROCESS_ROW)),
                                                     np.float64))
        if not (np.isfinite(dt) and dt > 0.0) or stride < 0:
            raise ValueError(f"time step {dt} s or snapshot stride {stride} out of range")
        recording = Recording.from_arrays(plain.unprefixed("recording.", arrays), ny, n_faces)
        if recording.n_rows != step + 1 or recording.moved.n != step:
            raise ValueError(f"{recording.n_rows} history rows for {step} steps")
        self.zone.import_state(plain.unprefixed("zone.", arrays))
        self.clock = Clock(float(clock[0]), float(clock[1]), float(carrier_t))
        self.process_rows = [tuple(row) for row in process.tolist()]
        self.F, self.face, self.step, self.braided = F, face, step, braided
        self.dt, self.snapshot_stride, self.recording = dt, stride, recording


#: what the bar says until the first steps are done: a first run compiles its numba kernels
#: there (cached for later runs), which takes seconds with no braided length to show
STARTING = "starting (compiling the kernels on a first run)"


def progress_bar(total, enabled, start=0.0):
    """A callable updated with the braided length; None closes it.

    ``start``: the braided length a resumed run starts from. The remaining time is estimated from
    the length braided since the first steps (tqdm's ``initial`` and start time, reset there): not
    as if the resumed part took no time, and not slowed by the kernels' compilation.
    """
    if not enabled:
        return lambda value: None
    from tqdm import tqdm

    start = round(min(max(start, 0.0), total), 6)
    bar = tqdm(total=round(total, 6), initial=start, unit="m", desc=STARTING, leave=True,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.3f}/{total:.3f} m braided [{elapsed}<{remaining}]")
    calls = [0]

    def update(value):
        if value is None:
            bar.close()
            return
        calls[0] += 1
        bar.n = round(min(value, total), 6)
        if calls[0] == 2:   # the first steps are done: kernels compiled, braiding under way
            bar.set_description_str("braiding", refresh=False)
            # the rate counts from here: the compilation and the tie-up before it are no part of
            # the braiding pace, and counted in they make the first ETAs hours for a run of minutes
            bar.start_t, bar.initial = bar._time(), bar.n
        bar.refresh()

    update.bar = bar
    return update
