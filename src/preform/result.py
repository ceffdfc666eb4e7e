"""What a simulation returns: plain arrays in frozen dataclasses (docs/architecture.md §1, §2).

Everything the writers (``preform.io``) and the surface mapping (``preform.analysis.fields``) need is here,
so they never reach into the solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: bit flags of deposited yarn points (YarnPaths.flags)
FLAG_BRIDGE = 1   # the segment ending at this point spans a concave stretch in the air
FLAG_CATCH = 2    # the free yarn caught on an obstacle and jumped to this point
FLAG_SLIP = 4     # slip tendency: |kappa_g| > mu * kappa_n at this point
FLAG_NAMES = {FLAG_BRIDGE: "bridge", FLAG_CATCH: "catch", FLAG_SLIP: "slip"}

HISTORY_COLUMNS = (
    "time_s",
    "braided_length_m",
    "convergence_length_mean_m",
    "convergence_length_min_m",
    "convergence_length_max_m",
    "braid_angle_warp_deg",
    "braid_angle_weft_deg",
    "contacts",
    "iterations",
    "residual",
    "braid_angle_min_deg",
    "braid_angle_max_deg",
)


@dataclass(frozen=True)
class YarnPaths:
    """Deposited yarn centerlines, mandrel frame.

    Yarn ``k`` is ``points[offsets[k]:offsets[k + 1]]``, first point = where it was tied.

    points : (m, 3) float64, m, mandrel frame
    offsets : (n_yarns + 1,) int64
    time_s : (m,) float64, s, time each point was laid
    braid_angle_deg : (m,) float64, deg, magnitude of the braid angle of the yarn at the point
        (angle between the laid direction and the surface projection of the centerline tangent)
    face : (m,) int64, mandrel face the point lies on
    flags : (m,) uint8, FLAG_* bits for the segment ending at the point
    group : (n_yarns,) int8, 0 warp, 1 weft
    """

    points: np.ndarray
    offsets: np.ndarray
    time_s: np.ndarray
    braid_angle_deg: np.ndarray
    face: np.ndarray
    flags: np.ndarray
    group: np.ndarray

    @property
    def n_yarns(self) -> int:
        return len(self.offsets) - 1

    def yarn(self, k: int) -> np.ndarray:
        return self.points[self.offsets[k]:self.offsets[k + 1]]


@dataclass(frozen=True)
class Snapshot:
    """The convergence zone at one time, machine frame (docs/guide/results.md, ``convergence.pvd``).

    Yarn ``k`` is the polyline ``points[offsets[k]:offsets[k + 1]]``, fell point first, supply
    point last (kinematic: 2 points; interaction: fell, crossings..., ring, supply).

    time_s : float, s
    points : (m, 3) float64, m, machine frame
    offsets : (n_yarns + 1,) int64
    tension_N : (m - n_yarns,) float64, N, per segment, yarn-major order
    contact_id : (m,) int64, -1 where the point is no yarn-yarn contact
    slip : (m,) int8, 0 stick, 1 slip
    group : (n_yarns,) int8
    external_force_N : (m, 3) float64, N, every force at the point other than the yarns'
        tensions (jamming and mandrel wall at a crossing, the ring's contact force at a ring
        point; zero at fell and spool points, the held ends), so that the tensions along the
        segments plus these balance at every crossing; None: zeros (the kinematic zone)
    """

    time_s: float
    points: np.ndarray
    offsets: np.ndarray
    tension_N: np.ndarray
    contact_id: np.ndarray
    slip: np.ndarray
    group: np.ndarray
    external_force_N: np.ndarray | None = None
    #: m, the largest distance of a crossing of this state from the same crossing after the
    #: re-balance that checks it (interaction model: ``InteractionZone.snapshot``); nan where
    #: none was made
    rebalance_shift_m: float = float("nan")
    #: why the re-balance found no balanced state ("" where it did or none was made)
    rebalance_error: str = ""
    #: the re-balanced copy, for checks (not written, not kept in checkpoints); None: none made
    rebalanced: "Snapshot | None" = None

    def external_forces(self) -> np.ndarray:
        """external_force_N as an (m, 3) array (zeros where it is None)."""
        if self.external_force_N is None:
            return np.zeros((len(self.points), 3))
        return np.asarray(self.external_force_N, dtype=np.float64).reshape(-1, 3)


@dataclass(frozen=True)
class Result:
    """A finished (or stopped) run.

    config : preform.config.Config
    mandrel : preform.geometry.Mandrel (mandrel frame, SI)
    centerline : preform.geometry.Centerline
    yarns : YarnPaths
    history : dict column name (HISTORY_COLUMNS) -> (n_steps,) float64
    snapshots : list of Snapshot
    fell_s : (n_steps, n_yarns) float64, m, centerline arc length of each yarn's fell point
    convergence_length : (n_steps, n_yarns) float64, m, per-yarn H
    status : "done" | "interrupted" | "failed"
    message : why it stopped when not "done"
    wall_time_s : float
    stop_signal : the signal that stopped an interrupted run ("SIGINT", "SIGTERM", "SIGHUP"), or ""
    process : (n_steps, 10) float64 or None: per history row the process that made it
        (``stepping.PROCESS_ROW``: time s, take-up speed m/s, angular speed rad/s, the mandrel
        frame's origin m and orientation quaternion w, x, y, z in the machine frame)
    """

    config: object
    mandrel: object
    centerline: object
    yarns: YarnPaths
    history: dict
    snapshots: list = field(default_factory=list)
    fell_s: np.ndarray | None = None
    convergence_length: np.ndarray | None = None
    status: str = "done"
    message: str = ""
    wall_time_s: float = 0.0
    stop_signal: str = ""
    process: np.ndarray | None = None

    @property
    def steps(self) -> int:
        return len(self.history["time_s"])
