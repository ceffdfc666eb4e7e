"""Take-up speed design for a target braid angle (``preform design``).

Given a config and a target braid angle (constant, or a table against centerline arc length),
find the take-up speed table ``[[L, v], ...]`` (braided length -> speed) that lays it:

1. **Quasi-static start** (docs/theory.md §2): on a slowly varying section of perimeter-equivalent
   radius ``r = P / 2 pi``, ``tan(alpha) = omega r / (v sqrt(1 + r'^2))``, so
   ``v0(L) = omega r(L) / (tan(alpha_target(L)) sqrt(1 + r'(L)^2))``.
2. **Iterate the forward model** (kinematic or interaction): the angle laid at braided length
   ``L`` follows the speed with the lag of the convergence zone. The fell points move over the
   mandrel at ``u = v + dH/dt``, and ``tan(alpha) = omega r / u``; on a cylinder ``H`` relaxes to
   ``H_inf = v sqrt(R^2 - r^2) / (omega r)`` as ``dH/dt = v - H omega r / sqrt(R^2 - r^2)`` (Du &
   Popper), so ``u = 2 v - H omega r / sqrt(R^2 - r^2)``: a change of speed changes ``u`` at once by
   twice as much, and then, as ``H`` follows over about one convergence length, by half of that
   again. Each pass therefore changes the speed by ``gain (u_target - u_achieved)`` with
   ``u = omega r / tan(alpha)`` read from the run and ``gain = 1/2`` (the immediate response), and
   lets the next run show what the lag leaves. The part the lag leaves halves each pass. It stops
   when the achieved angle is within ``tolerance_deg`` of the target beyond ``judged_after``
   convergence lengths, or after ``max_passes``.

What is achievable: the start-up transient (the first convergence length or two, while the yarns
wind from their tie points to their steady convergence zone) cannot be removed by the speed
alone, because it is set by the initial position; beyond it a smooth target is followed to a
fraction of a degree, a step in the target only as fast as the zone can follow (about one
convergence length).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomli_w

from ..config import dump_config
from ..errors import ConfigError, PreformError
from ..geometry.centerline import section_perimeters
from ..io.atomic import atomic_path, atomic_write_text
from ..reference import references
from ..simulation import load_geometry, simulate


@dataclass(frozen=True)
class DesignSettings:
    """Numerical settings of the speed design."""

    #: forward runs at most: what the lag leaves of the error halves each pass
    max_passes: int = 8
    #: stop when the achieved angle is this close to the target (deg) where it is judged
    tolerance_deg: float = 0.2
    #: the angle is judged beyond this many convergence lengths of braid (the start-up transient)
    judged_after: float = 2.0
    #: speed change per unit of fell-point speed error: 1/2, the immediate response u = 2 v - ...
    gain: float = 0.5
    #: largest change of the speed in one pass (factor), against the wind-up's wild angles
    max_factor: float = 1.5
    #: no correction within this many convergence lengths of the start (the wind-up's angles
    #: say nothing about the speed there); it fades in up to judged_after
    correct_after: float = 1.0
    #: rows of the designed speed table per convergence length (and at least 20 in all): the
    #: angle responds over one convergence length, so finer rows resolve nothing more
    rows_per_convergence_length: float = 16.0


DESIGN = DesignSettings()


@dataclass
class Design:
    """length: (n,) m braided; speed: (n,) m/s; target_deg, achieved_deg: (n,) deg; passes: runs;
    h_inf: float, m, the kinematic steady convergence length used for the judged region."""

    length: np.ndarray
    speed: np.ndarray
    target_deg: np.ndarray
    achieved_deg: np.ndarray
    passes: int
    h_inf: float
    result: object = None

    def max_error_deg(self, judged_after=None) -> float:
        after = DESIGN.judged_after if judged_after is None else judged_after
        sel = self.length >= after * self.h_inf
        return float(np.max(np.abs(self.achieved_deg[sel] - self.target_deg[sel]), initial=0.0))


def read_target_table(path) -> np.ndarray:
    """A CSV of ``s_m, angle_deg`` rows (a header line allowed): (n, 2), s increasing."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as err:
        raise ConfigError(f"--target-table {path}: cannot be read ({err.strerror or err})") from None
    rows = []
    for k, line in enumerate(text.splitlines(), 1):
        parts = [p.strip() for p in line.split(",")]
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            rows.append((float(parts[0]), float(parts[1])))
        except (ValueError, IndexError):
            if rows or k > 1:
                raise ConfigError(f"--target-table {path} line {k}: {line!r}: expected "
                                  "'arc_length_m, braid_angle_deg'") from None
    table = np.array(rows, dtype=float)
    if len(table) < 1 or np.any(np.diff(table[:, 0]) <= 0):
        raise ConfigError(f"--target-table {path}: expected rows of increasing arc length")
    if np.any((table[:, 1] <= 0) | (table[:, 1] >= 90)):
        raise ConfigError(f"--target-table {path}: braid angles must lie in (0, 90) deg")
    return table


def _target(target, s):
    if np.ndim(target) == 0:
        angle = float(target)
        if not 0.0 < angle < 90.0:
            raise ConfigError(f"--target-angle {angle:g}: expected a braid angle in (0, 90) deg")
        return np.full_like(s, angle)
    table = np.asarray(target, dtype=float)
    return np.interp(s, table[:, 0], table[:, 1])


def quasi_static_speed(omega, radius, dradius_ds, alpha_rad):
    """``v = omega r / (tan(alpha) sqrt(1 + r'^2))`` (m/s)."""
    return omega * radius / (np.tan(alpha_rad) * np.sqrt(1.0 + dradius_ds ** 2))


def _achieved(result, grid):
    h = result.history
    L = np.asarray(h["braided_length_m"], dtype=float)
    alpha = 0.5 * (np.asarray(h["braid_angle_warp_deg"]) + np.asarray(h["braid_angle_weft_deg"]))
    L_run, first = np.unique(L[::-1], return_index=True)   # the last row at each braided length
    alpha_run = alpha[::-1][first]
    reached = grid <= L_run[-1]
    return np.interp(grid, L_run, alpha_run), reached


def with_speed_table(config, length, speed):
    table = tuple((float(a), float(b)) for a, b in zip(length, speed))
    return dataclasses.replace(config, process=dataclasses.replace(config.process, take_up_speed=table))


def design_speed(config, target, *, model=None, settings: DesignSettings = DESIGN,
                 mandrel=None, centerline=None, progress=None) -> Design:
    """The take-up speed table for ``target`` (deg, or an (n, 2) table of s_m, deg)."""
    if model is not None:
        config = dataclasses.replace(config, model=dataclasses.replace(config.model, kind=model))
    if mandrel is None or centerline is None:
        mandrel, centerline = load_geometry(config)
    end = float(config.process.braid_length)
    omega = float(config.machine.angular_speed)
    fine = np.linspace(0.0, end, 201)
    perimeter = section_perimeters(mandrel, centerline, fine)
    ok = perimeter > 0
    if np.count_nonzero(ok) < 2:
        raise PreformError("design: no cross-sections of the mandrel found along the braided part")
    radius = np.interp(fine, fine[ok], perimeter[ok]) / (2.0 * math.pi)
    alpha_fine = np.radians(_target(target, fine))
    v_fine = quasi_static_speed(omega, radius, np.gradient(radius, fine), alpha_fine)
    h_inf = float(np.nanmedian(references(with_speed_table(config, fine, v_fine), fine, 2 * math.pi * radius).h_inf))
    n = max(20, int(math.ceil(settings.rows_per_convergence_length * end / max(h_inf, 1e-6))) + 1)
    grid = np.linspace(0.0, end, n)
    target_deg = _target(target, grid)
    speed = np.interp(grid, fine, v_fine)
    achieved = np.full_like(grid, np.nan)
    result = None
    passes = 0
    judged = grid >= settings.judged_after * h_inf
    best = None   # (error, speed, achieved, result): the best pass is the answer
    for passes in range(1, settings.max_passes + 1):
        result = simulate(with_speed_table(config, grid, speed), progress=False, mandrel=mandrel,
                          centerline=centerline)
        if result.status != "done":
            raise PreformError(f"design: forward run {passes} {result.status}: {result.message}")
        achieved, reached = _achieved(result, grid)
        error = np.abs(achieved - target_deg)[judged & reached]
        worst = float(np.max(error, initial=0.0))
        if progress is not None:
            progress(passes, worst)
        if best is None or worst < best[0]:
            best = (worst, speed.copy(), achieved.copy(), result)
        if worst <= settings.tolerance_deg:
            break
        if passes == settings.max_passes:
            break
        correct = reached & (grid > settings.correct_after * h_inf) & (achieved > 0) & (achieved < 90)
        r = np.interp(grid, fine, radius)
        u_target = omega * r / np.tan(np.radians(target_deg))
        u_achieved = np.where(correct, omega * r / np.tan(np.radians(np.where(correct, achieved, 45.0))),
                              u_target)
        # the correction fades in from correct_after to judged_after convergence lengths: the
        # start-up transient's errors are not the speed's to fix, and a full correction there
        # throws the zone off just where it settles
        lo, hi = settings.correct_after * h_inf, settings.judged_after * h_inf
        weight = np.clip((grid - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
        new = speed + settings.gain * weight * (u_target - u_achieved)
        speed = np.clip(new, speed / settings.max_factor, speed * settings.max_factor)
    _, speed, achieved, result = best
    return Design(length=grid, speed=speed, target_deg=target_deg, achieved_deg=achieved,
                  passes=passes, h_inf=h_inf, result=result)


def write_design_config(config, design: Design, out) -> Path:
    """The input config with ``take_up_speed`` = the designed table, as a runnable TOML file.

    Paths become absolute, so the file runs from wherever it is written."""
    data = dump_config(config)
    data["process"]["take_up_speed"] = [[float(a), float(b)] for a, b in zip(design.length, design.speed)]
    data = {section: {k: v for k, v in table.items() if v is not None}
            for section, table in data.items() if isinstance(table, dict)}
    if data.get("machine", {}).get("guide_ring") is None:
        data.get("machine", {}).pop("guide_ring", None)
    header = (f"# Designed by preform design: take-up speed for the target braid angle "
              f"({design.passes} forward runs, {config.model.kind} model); achieved within "
              f"{design.max_error_deg():.2f} deg beyond {DESIGN.judged_after:g} convergence lengths "
              f"({DESIGN.judged_after * design.h_inf:.2f} m)\n")
    return atomic_write_text(out, header + tomli_w.dumps(data))


def plot_design(design: Design, path, title: str) -> Path:
    """Target against achieved braid angle, the error, and the speed, along the braided length."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.2, 8.0), layout="constrained")
    ax_a, ax_e, ax_v = fig.subplots(3, 1, sharex=True)
    L = design.length
    ax_a.plot(L, design.target_deg, color="0.3", linestyle="--", label="target")
    ax_a.plot(L, design.achieved_deg, color="tab:blue", label="achieved")
    ax_a.set_ylabel("braid angle α (deg)")
    ax_a.legend()
    ax_a.set_title(title)
    ax_e.plot(L, design.achieved_deg - design.target_deg, color="tab:red")
    ax_e.axvspan(0.0, DESIGN.judged_after * design.h_inf, color="0.9",
                 label="start-up transient (not judged)")
    ax_e.axhline(0.0, color="0.5", linewidth=0.8)
    ax_e.set_ylim(-3.0, 3.0)
    ax_e.set_ylabel("achieved − target (deg)")
    ax_e.legend(loc="upper right")
    ax_v.plot(L, design.speed * 1e3, color="tab:green")
    ax_v.set_ylabel("take-up speed (mm/s)")
    ax_v.set_xlabel("braided length L (m)")
    for ax in (ax_a, ax_e, ax_v):
        ax.grid(True, alpha=0.3)
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130)
    return Path(path)
