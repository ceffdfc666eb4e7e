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
   convergence lengths, after ``stall_passes`` passes that did not improve on the best, or after
   ``max_passes``; the best pass is the answer.
3. **Say whether the promise is kept**: :attr:`Design.met` tells whether the best pass is within
   the tolerance, and :func:`shortfall` says where the largest error is and why it stays (the tail
   of the start-up transient, a change of section, or the forward model's own scatter).

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
    #: stop after this many passes in a row that do not improve on the best: the lag's part of the
    #: error halves each pass, so passes that do not shrink it mean what is left is not the speed's
    stall_passes: int = 2
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
    #: a relative change of the section's perimeter-equivalent radius larger than this within one
    #: convergence length of the largest error names the section change as its cause: the zone
    #: follows a new section over about one convergence length, which no speed removes
    section_change: float = 0.02


DESIGN = DesignSettings()


@dataclass
class Design:
    """length: (n,) m braided; speed: (n,) m/s; target_deg, achieved_deg: (n,) deg; passes: runs;
    h_inf: float, m, the kinematic steady convergence length used for the judged region;
    errors_deg: the largest judged error of each pass; best_pass: the pass whose speed is the
    answer; radius: (n,) m, the sections' perimeter-equivalent radius on ``length``; settings:
    the DesignSettings used."""

    length: np.ndarray
    speed: np.ndarray
    target_deg: np.ndarray
    achieved_deg: np.ndarray
    passes: int
    h_inf: float
    result: object = None
    errors_deg: tuple = ()
    best_pass: int = 0
    radius: np.ndarray | None = None
    settings: DesignSettings = DESIGN

    @property
    def judged_from(self) -> float:
        """The braided length (m) from which the angle is judged: past the start-up transient."""
        return self.settings.judged_after * self.h_inf

    def max_error_deg(self, judged_after=None) -> float:
        after = self.settings.judged_after if judged_after is None else judged_after
        sel = self.length >= after * self.h_inf
        return float(np.max(np.abs(self.achieved_deg[sel] - self.target_deg[sel]), initial=0.0))

    @property
    def met(self) -> bool:
        """Whether the achieved angle is within the tolerance wherever it is judged."""
        return self.max_error_deg() <= self.settings.tolerance_deg

    def worst_length(self) -> float:
        """The braided length (m) of the largest judged error."""
        sel = self.length >= self.judged_from
        if not np.any(sel):
            return float(self.length[-1])
        err = np.abs(self.achieved_deg - self.target_deg)
        return float(self.length[sel][np.argmax(err[sel])])


def shortfall(design: Design) -> str:
    """Why the largest judged error stays above the tolerance, where it is (one sentence).

    The tail of the start-up transient when the error sits within one convergence length of
    where judging starts; a change of the section (a relative change of the perimeter-equivalent
    radius above ``section_change`` within one convergence length of it) when there is one;
    otherwise the forward model's response, which the passes stopped improving."""
    s = design.settings
    L = design.worst_length()
    h = design.h_inf
    where = f"at L = {L:.2f} m"
    if L <= design.judged_from + h:
        return (f"{where}, within one convergence length ({h:.2f} m) of where judging starts "
                f"({design.judged_from:.2f} m): the tail of the start-up transient, which is set by "
                f"the initial position, not by the speed (a start nearer the steady convergence "
                f"length, or a larger --tolerance, is what helps)")
    if design.radius is not None:
        near = np.abs(design.length - L) <= h
        r = design.radius[near]
        change = float((r.max() - r.min()) / max(r.mean(), 1e-300))
        if change > s.section_change:
            return (f"{where}, where the section changes (its perimeter-equivalent radius by "
                    f"{100 * change:.0f} % within one convergence length, {h:.2f} m): the zone "
                    f"follows a new section over about one convergence length, whatever the speed")
    return (f"{where}: the forward runs stopped improving after pass {design.best_pass} "
            f"(errors per pass {', '.join(f'{e:.2f}' for e in design.errors_deg)} deg); what is left "
            f"is the model's response, not the speed's to fix")


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
    best = None   # (error, speed, achieved, result, pass): the best pass is the answer
    errors = []
    for passes in range(1, settings.max_passes + 1):
        result = simulate(with_speed_table(config, grid, speed), progress=False, mandrel=mandrel,
                          centerline=centerline)
        if result.status != "done":
            raise PreformError(f"design: forward run {passes} {result.status}: {result.message}")
        achieved, reached = _achieved(result, grid)
        error = np.abs(achieved - target_deg)[judged & reached]
        worst = float(np.max(error, initial=0.0))
        errors.append(worst)
        if progress is not None:
            progress(passes, worst)
        if best is None or worst < best[0]:
            best = (worst, speed.copy(), achieved.copy(), result, passes)
        if worst <= settings.tolerance_deg:
            break
        if passes == settings.max_passes or passes - best[4] >= settings.stall_passes:
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
    _, speed, achieved, result, best_pass = best
    return Design(length=grid, speed=speed, target_deg=target_deg, achieved_deg=achieved,
                  passes=passes, h_inf=h_inf, result=result, errors_deg=tuple(errors),
                  best_pass=best_pass, radius=np.interp(grid, fine, radius), settings=settings)


#: significant digits of the designed speeds: ``d(alpha) = -sin(alpha) cos(alpha) dv / v``, so a
#: relative rounding of 5e-6 moves the angle by at most 2.5e-6 rad (1.4e-4 deg), far below any
#: tolerance of the design
SPEED_DIGITS = 6
#: decimals (m) of the designed table's braided lengths: 0.1 mm, a thousandth of the shortest
#: convergence length the table is made for, or more where rows are closer than that
LENGTH_DECIMALS = 4


def _speed_rows(design: Design) -> list[tuple[str, str]]:
    """The table's (length, speed) as rounded text, lengths strictly increasing."""
    decimals = LENGTH_DECIMALS
    while len({round(float(a), decimals) for a in design.length}) < len(design.length) and decimals < 12:
        decimals += 1
    return [(f"{float(a):.{decimals}f}", f"{float(v):.{SPEED_DIGITS}g}")
            for a, v in zip(design.length, design.speed)]


def designed_output_dir(out) -> str:
    """The results folder of a designed config written to ``out``: ``results/<stem>`` beside it
    (relative to the file, so running the designed config never overwrites the source's)."""
    return f"results/{Path(out).stem}"


def write_design_config(config, design: Design, out) -> Path:
    """The input config with ``take_up_speed`` = the designed table, as a runnable TOML file.

    Input paths become absolute, so the file runs from wherever it is written; ``[output] dir``
    is its own results folder beside it (:func:`designed_output_dir`). The table is one
    ``[L, v]`` pair a line, rounded to what changes the angle (:data:`SPEED_DIGITS`)."""
    if config.layers:
        raise ConfigError(f"design: {config.source}: a config with [[layer]] tables: design the "
                          "speed of one layer at a time (a config without [[layer]])")
    data = dump_config(config)
    data["process"].pop("take_up_speed", None)
    data = {section: {k: v for k, v in table.items() if v is not None}
            for section, table in data.items() if isinstance(table, dict)}
    if data.get("machine", {}).get("guide_ring") is None:
        data.get("machine", {}).pop("guide_ring", None)
    data.setdefault("output", {})["dir"] = designed_output_dir(out)
    verdict = "within" if design.met else "NOT within"
    header = (f"# Designed by preform design: take-up speed for the target braid angle "
              f"({design.passes} forward runs, {config.model.kind} model, the best is run "
              f"{design.best_pass}).\n# Achieved {verdict} the tolerance "
              f"{design.settings.tolerance_deg:g} deg: largest error {design.max_error_deg():.2f} deg "
              f"beyond {design.judged_from:.2f} m ({design.settings.judged_after:g} convergence lengths); "
              f"every row in {Path(out).stem}_design.csv\n")
    rows = _speed_rows(design)
    width = max(len(a) for a, _ in rows)
    table = ("take_up_speed = [   # [braided length m, take-up speed m/s]\n"
             + "".join(f"    [{a.rjust(width)}, {v}],\n" for a, v in rows) + "]\n")
    text = tomli_w.dumps(data)
    marker = "[process]\n"
    if marker not in text:
        text += "\n" + marker
    at = text.index(marker) + len(marker)
    return atomic_write_text(out, header + text[:at] + table + text[at:])


#: the columns of the designed table's CSV
DESIGN_CSV_COLUMNS = ("braided_length_m", "take_up_speed_m_s", "target_deg", "achieved_deg", "error_deg",
                      "judged")


def write_design_table(design: Design, path) -> Path:
    """Every row of the design: length, speed, target, achieved angle, their difference, and
    whether the row is judged (past the start-up transient), as a CSV."""
    lines = [",".join(DESIGN_CSV_COLUMNS)]
    for L, v, t, a in zip(design.length, design.speed, design.target_deg, design.achieved_deg):
        lines.append(f"{L:.6g},{v:.{SPEED_DIGITS}g},{t:.4f},{a:.4f},{a - t:.4f},"
                     f"{int(L >= design.judged_from)}")
    return atomic_write_text(path, "\n".join(lines) + "\n")


def write_design_process(design: Design, path) -> Path:
    """The process of the designed speed table (``process.csv``'s columns: the time, braided
    length, speeds and the mandrel's pose per step) from the best forward run, the run of the
    table before its rounding to :data:`SPEED_DIGITS` digits: the robot program of the design,
    which ``[process] trajectory`` also reads."""
    from ..io.tables import write_process

    return write_process(design.result, path)


def write_design_runs(design: Design, path) -> Path:
    """One row per forward run: its number, its largest error where judged (deg), and whether its
    speed is the answer (the best run), as a CSV."""
    lines = ["run,largest_error_deg,best"]
    lines += [f"{k},{e:.4f},{int(k == design.best_pass)}" for k, e in enumerate(design.errors_deg, start=1)]
    return atomic_write_text(path, "\n".join(lines) + "\n")


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
    ax_e.axvspan(0.0, design.judged_from, color="0.9",
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
