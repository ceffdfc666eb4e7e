"""The mandrel's path through the machine as a table: ``process.csv`` out, ``[process]
trajectory`` in (docs/guide/results.md, docs/guide/configuration.md).

A row is one instant of the process: the time (s), the braided length (m), the take-up speed
(m/s), the carriers' angular speed (deg/s) and the mandrel's pose in the machine frame
(docs/architecture.md §2): the position ``x_m, y_m, z_m`` of the mandrel frame's origin and the
orientation as a unit quaternion ``qw, qx, qy, qz`` (Hamilton convention, scalar first) of the
rotation ``R`` that takes mandrel-frame vectors to the machine frame, ``x_machine = R x_mandrel
+ (x_m, y_m, z_m)`` (``geometry.Pose``). That is the robot program of a run.

Read back as a trajectory, the path drives a run (:class:`PathInterpolant`) between its rows
(any time spacing): the position and both speeds by monotone piecewise-cubic Hermite
interpolation in time (PCHIP: through every row, no overshoot between rows, continuous first
derivative), the orientation by spherical linear interpolation (SLERP) between consecutive rows
(constant angular velocity between rows, shortest arc), and the carriers' turn as the integral
of the interpolated angular speed.
"""

from __future__ import annotations

import csv
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ConfigError

#: the columns of process.csv and of a trajectory, in this order
COLUMNS = ("time_s", "braided_length_m", "take_up_speed_m_s", "angular_speed_deg_s",
           "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz")
#: a trajectory's quaternion may be this far from unit length (|norm - 1|) and is normalised:
#: a unit quaternion written with 5 decimals (robot controllers write 4 to 6) is within
#: 4 x 0.5e-5 = 2e-5 of unit length; a quaternion further off is not a rotation someone meant
QUATERNION_TOLERANCE = 1e-4


def file_digest(path) -> str:
    """SHA-256 (hex) of a file's bytes: what a checkpoint's inputs hash records of a path."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def rotation_to_quaternion(R) -> np.ndarray:
    """(4,) unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (3, 3) (scipy's
    ``Rotation``, which stores them scalar last)."""
    from scipy.spatial.transform import Rotation

    return np.roll(Rotation.from_matrix(R).as_quat(canonical=True), 1)


def quaternion_to_rotation(q) -> np.ndarray:
    """(3, 3) rotation matrix of a unit quaternion (w, x, y, z)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(np.roll(np.asarray(q, dtype=float), -1)).as_matrix()


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A checked path (:func:`read_trajectory`). path : the CSV; time : (n,) s, strictly
    increasing; braided : (n,) m; take_up : (n,) m/s; angular : (n,) rad/s; position : (n, 3) m,
    machine frame; quaternion : (n, 4) unit (w, x, y, z)."""

    path: Path
    time: np.ndarray
    braided: np.ndarray
    take_up: np.ndarray
    angular: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray

    @property
    def name(self) -> str:
        return self.path.name

    def _over_length(self, values) -> tuple[tuple[float, float], ...]:
        """(braided_length, value) at the rows where the braided length first exceeds every
        earlier row's: a table over the braided length (strictly increasing) for the checks
        and estimates that read the settings that way."""
        keep, top = [], -math.inf
        for k, length in enumerate(self.braided):
            if length > top:
                keep.append(k)
                top = length
        return tuple((float(self.braided[k]), float(values[k])) for k in keep)

    def take_up_speed_table(self) -> tuple[tuple[float, float], ...]:
        """The take-up speed over the braided length (m, m/s), as ``[process] take_up_speed``."""
        return self._over_length(self.take_up)

    def angular_speed_table(self) -> tuple[tuple[float, float], ...]:
        """The angular speed over the braided length (m, rad/s), as ``[machine] angular_speed``."""
        return self._over_length(self.angular)


def _where(path: Path, row: int) -> str:
    """How messages name a row: its number among the data rows and its line in the file."""
    return f"[process] trajectory {path}: row {row + 1} (line {row + 2})"


def read_trajectory(path, *, max_take_up_speed: float, max_angular_speed_deg: float) -> Trajectory:
    """Read and check a trajectory CSV (header: :data:`COLUMNS` in any order, nothing else; at
    least two rows): every value a finite number, time strictly increasing, quaternions of unit
    length within :data:`QUATERNION_TOLERANCE`, take-up and angular speeds positive and below
    the config's plausibility limits (m/s, deg/s), braided lengths not negative. ConfigError
    names the file, the row and the value. Whether the mandrel stays ahead of the supply plane
    needs the mandrel (:func:`tip_behind_problem`)."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            rows = [row for row in csv.reader(handle) if any(cell.strip() for cell in row)]
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"[process] trajectory {path}: cannot be read: {err}") from None
    if not rows:
        raise ConfigError(f"[process] trajectory {path}: empty; expected a header "
                          f"{','.join(COLUMNS)} and a row per instant")
    header = [cell.strip() for cell in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    unknown = [c for c in header if c not in COLUMNS]
    if missing or unknown or len(set(header)) != len(header):
        said = (f"missing {', '.join(missing)}" if missing else
                f"unknown {', '.join(unknown)}" if unknown else "a column given twice")
        raise ConfigError(f"[process] trajectory {path}: header {','.join(header)}: {said}; "
                          f"expected the columns {','.join(COLUMNS)} (those of process.csv)")
    data = rows[1:]
    if len(data) < 2:
        raise ConfigError(f"[process] trajectory {path}: {len(data)} row(s); expected at least "
                          "two instants to interpolate between")
    order = [header.index(c) for c in COLUMNS]
    table = np.empty((len(data), len(COLUMNS)))
    for k, row in enumerate(data):
        if len(row) != len(header):
            raise ConfigError(f"{_where(path, k)} has {len(row)} values; expected "
                              f"{len(header)}, one per column of the header")
        for j, column in zip(order, COLUMNS):
            cell = row[j].strip()
            try:
                value = float(cell)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise ConfigError(f"{_where(path, k)}: {column} = {cell!r}: expected a finite number")
            table[k, COLUMNS.index(column)] = value
    col = {c: table[:, j] for j, c in enumerate(COLUMNS)}
    time = col["time_s"]
    back = np.flatnonzero(np.diff(time) <= 0.0)
    if len(back):
        k = int(back[0]) + 1
        raise ConfigError(f"{_where(path, k)}: time_s = {float(time[k])!r} after "
                          f"{float(time[k - 1])!r}: "
                          "expected times strictly increasing")
    q = table[:, 7:11]
    norm = np.linalg.norm(q, axis=1)
    off = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_TOLERANCE)
    if len(off):
        k = int(off[0])
        raise ConfigError(f"{_where(path, k)}: quaternion (qw, qx, qy, qz) = "
                          f"({', '.join(repr(float(v)) for v in q[k])}) has length {norm[k]:.6g}; "
                          f"expected a unit quaternion (within {QUATERNION_TOLERANCE:g})")
    checks = (("take_up_speed_m_s", max_take_up_speed, "m/s", "mm/s? divide by 1000"),
              ("angular_speed_deg_s", max_angular_speed_deg, "deg/s", "the carrier speed about "
               "the machine axis is in deg/s, 1 rpm = 6 deg/s"))
    for column, limit, unit, hint in checks:
        values = col[column]
        bad = np.flatnonzero((values <= 0.0) | (values > limit))
        if len(bad):
            k = int(bad[0])
            why = ("must be greater than zero" if values[k] <= 0.0 else
                   f"above {limit:g} {unit} is implausible ({hint})")
            raise ConfigError(f"{_where(path, k)}: {column} = {float(values[k])!r}: expected "
                              f"{unit}; {why}")
    negative = np.flatnonzero(col["braided_length_m"] < 0.0)
    if len(negative):
        k = int(negative[0])
        raise ConfigError(f"{_where(path, k)}: braided_length_m = "
                          f"{float(col['braided_length_m'][k])!r}: "
                          "expected a braided length >= 0 (m)")
    return Trajectory(path=path, time=time.copy(), braided=col["braided_length_m"].copy(),
                      take_up=col["take_up_speed_m_s"].copy(),
                      angular=np.radians(col["angular_speed_deg_s"]),
                      position=table[:, 4:7].copy(), quaternion=q / norm[:, None])


def tip_behind_problem(trajectory: Trajectory, tip, supply_z: float) -> str | None:
    """Why the path puts the mandrel behind the supply plane, or None: at every row the mandrel
    tip ``tip`` (3,) m, mandrel frame, must lie at ``z >= supply_z`` (m, machine frame), as a
    run starts with the yarns tied near the tip ahead of the plane they come from."""
    z = np.array([(quaternion_to_rotation(q) @ np.asarray(tip, dtype=float))[2] + p[2]
                  for q, p in zip(trajectory.quaternion, trajectory.position)])
    behind = np.flatnonzero(z < supply_z)
    if not len(behind):
        return None
    k = int(behind[0])
    return (f"{_where(trajectory.path, k)}: the mandrel's tip is at z = {z[k]:.6g} m, behind the "
            f"supply plane z = {supply_z:g} m (machine frame): expected the tip at or ahead of "
            "it at every row (check the position's units, m, and the quaternion's frame: "
            "mandrel to machine)")


class PathInterpolant:
    """A trajectory between its rows (module docstring): run time ``t`` = 0 at the path's first
    row. ``pose(t)``: (R (3, 3), origin (3,) m) in the machine frame; ``speeds(t)``: (take-up
    m/s, angular rad/s); ``turn(t)``: the carriers' rotation (rad) since the first row;
    ``end``: the run time of the last row (s)."""

    def __init__(self, trajectory: Trajectory):
        from scipy.interpolate import PchipInterpolator
        from scipy.spatial.transform import Rotation, Slerp

        self.trajectory = trajectory
        self.time = trajectory.time - trajectory.time[0]
        self.end = float(self.time[-1])
        self._position = PchipInterpolator(self.time, trajectory.position, axis=0)
        self._take_up = PchipInterpolator(self.time, trajectory.take_up)
        angular = PchipInterpolator(self.time, trajectory.angular)
        self._angular = angular
        self._turn = angular.antiderivative()
        # SLERP between consecutive rows, each arc the shorter one (scipy's ``Slerp``)
        self._slerp = Slerp(self.time, Rotation.from_quat(np.roll(trajectory.quaternion, -1, axis=1)))

    def pose(self, t: float):
        k = int(np.searchsorted(self.time, t))
        if k < len(self.time) and self.time[k] == t:    # at a row: its own position, to the bit
            origin = self.trajectory.position[k].copy()
        else:
            origin = np.asarray(self._position(t), dtype=float)
        return self._slerp(float(np.clip(t, 0.0, self.end))).as_matrix(), origin

    def speeds(self, t: float) -> tuple[float, float]:
        return float(self._take_up(t)), float(self._angular(t))

    def turn(self, t: float) -> float:
        return float(self._turn(t))
