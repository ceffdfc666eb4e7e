"""When does the braid reach steady state? (paper eq. 1: dalpha/dL = dH/dL = 0)

Steady state is read against the value the run approaches, not against the value it happened
to end on. The start-up transient decays exponentially in braided length (Du & Popper: over
about one convergence length), so over the later part of the run (the fit window: the last
``fit_fraction`` of the braided length, at least ``tail_convergence_lengths`` convergence
lengths) each of the mean convergence length and the two braid angles is fitted by

    y(L) = y_inf + b exp(-L / lambda)

(least squares in ``y_inf`` and ``b`` for each decay length ``lambda`` of a geometric grid,
the best refined by a golden-section search). ``y_inf`` is the asymptote: the steady value.
The run is steady from the braided length on which every recorded value stays within the
tolerance of its asymptote (``rel_H`` of H, ``angle_deg`` of each angle) to the end of the run;
the fit must describe the window (root-mean-square residual within half the tolerance). Where
the window does not show steady state it is halved, down to ``tail_convergence_lengths``
convergence lengths: a section change inside the window is left behind, and the stretch after
it read alone. A run whose curve is still further than the tolerance from its asymptote at its
end (still rising or falling) in every window, or that no fit describes, or that is shorter
than the shortest window, is not steady; what is reported instead (from the longest window) is
how fast it was still changing at its end (the drift: least-squares slopes, per metre braided).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SteadySettings:
    """Tolerances of the steady-state reading."""

    #: H within this fraction of its asymptote: the paper's convergence plots settle to ~1 %
    rel_H: float = 0.01
    #: braid angles within this many degrees of their asymptotes: below a measurable angle
    angle_deg: float = 0.25
    #: fraction of the braided length at the end of the run the asymptote is fitted over: the
    #: later half, past the wind-up from the tie points, which is not exponential
    fit_fraction: float = 0.5
    #: ... and at least this many convergence lengths of braid: the start-up transient decays
    #: over one convergence length (Du & Popper), so a shorter stretch proves nothing
    tail_convergence_lengths: float = 0.5
    #: decay lengths tried, as fractions of the fit window (geometric grid): from a transient
    #: over in a hundredth of the window to one three times longer than it (then indistinguishable
    #: from a straight line over the window, and the asymptote is an extrapolation)
    decay_min_fraction: float = 0.01
    decay_max_fraction: float = 3.0
    #: points of that grid: neighbouring decay lengths 10 % apart
    decay_grid: int = 60
    #: golden-section steps refining the best decay length between its grid neighbours: each
    #: shrinks the bracket by 0.618, 30 steps from 20 % to below 1e-7 relative
    decay_refinements: int = 30


STEADY = SteadySettings()
#: history rows the fit window needs before a run can be called steady
MIN_TAIL_ROWS = 3
#: the series the reading fits: (history column, name in the result)
SERIES = (("convergence_length_mean_m", "convergence_length_m"),
          ("braid_angle_warp_deg", "warp"), ("braid_angle_weft_deg", "weft"))


def _slope(x, y) -> float:
    if len(x) < 2 or np.ptp(x) <= 0:
        return 0.0
    return float(np.polyfit(x, y, 1)[0])


def _fit_at(x, y, decay):
    """Least squares y ~ a + b exp(-x / decay): (a, b, sum of squared residuals)."""
    e = np.exp(-(x - x[0]) / decay)
    A = np.column_stack([np.ones_like(x), e])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    return float(coef[0]), float(coef[1]), float(r @ r)


def fit_asymptote(L, y, settings: SteadySettings = STEADY) -> dict:
    """The exponential approach ``y = y_inf + b exp(-(L - L[0]) / lambda)`` fitted to (L, y).

    L : (n,) float, m, increasing braided length; y : (n,) float.
    Returns {"asymptote", "amplitude" (b, at L[0]), "decay_length_m" (lambda), "rms"} (the
    root-mean-square residual, in y's unit). A flat y gives amplitude 0 and its mean.
    """
    L = np.asarray(L, dtype=float)
    y = np.asarray(y, dtype=float)
    span = float(L[-1] - L[0])
    if np.ptp(y) == 0 or span <= 0:
        return {"asymptote": float(np.mean(y)), "amplitude": 0.0, "decay_length_m": float("inf"),
                "rms": 0.0}
    grid = np.geomspace(settings.decay_min_fraction * span, settings.decay_max_fraction * span,
                        settings.decay_grid)
    sse = np.array([_fit_at(L, y, d)[2] for d in grid])
    k = int(np.argmin(sse))
    # golden-section search in log(lambda) between the best point's neighbours
    lo, hi = np.log(grid[max(k - 1, 0)]), np.log(grid[min(k + 1, len(grid) - 1)])
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    c, d = hi - g * (hi - lo), lo + g * (hi - lo)
    fc, fd = _fit_at(L, y, np.exp(c))[2], _fit_at(L, y, np.exp(d))[2]
    for _ in range(settings.decay_refinements):
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - g * (hi - lo)
            fc = _fit_at(L, y, np.exp(c))[2]
        else:
            lo, c, fc = c, d, fd
            d = lo + g * (hi - lo)
            fd = _fit_at(L, y, np.exp(d))[2]
    decay = float(np.exp(c if fc < fd else d))
    a, b, err = _fit_at(L, y, decay)
    if err > sse[k]:
        decay = float(grid[k])
        a, b, err = _fit_at(L, y, decay)
    return {"asymptote": a, "amplitude": b, "decay_length_m": float(decay),
            "rms": float(np.sqrt(err / len(y)))}


def steady_state(history, settings: SteadySettings = STEADY) -> dict:
    """The steady state of a run's history (``Result.history`` columns).

    Returns {"reached": bool, "definition": str, "fits": {"convergence_length_m", "warp",
    "weft"} (each :func:`fit_asymptote`'s, with "tolerance", "describes_run": whether its
    residual is within half the tolerance, and "decays_in_window": whether its decay length is
    within the fit window, so the asymptote is read from the run rather than extrapolated;
    absent for a run too short to fit),
    and, if reached, "braided_length_m" (where it starts), "convergence_length_m" and
    "braid_angle_deg" {"warp", "weft"} (the asymptotes); if not, "drift":
    {"convergence_length_m_per_m", "braid_angle_warp_deg_per_m", "braid_angle_weft_deg_per_m"}
    over the fit window, or None for a run too short to say}.
    """
    rel_H, angle_deg = settings.rel_H, settings.angle_deg
    L = np.asarray(history["braided_length_m"], dtype=float)
    columns = {name: np.asarray(history[column], dtype=float) for column, name in SERIES}
    H = columns["convergence_length_m"]
    out = {"reached": False,
           "definition": f"H within {rel_H:.0%} and braid angles within {angle_deg} deg of the "
                         "values they approach (fitted exponential approach over the later part "
                         "of the run) from this braided length to the end",
           "drift": None}
    if len(L) < 3 or L[-1] <= L[0]:
        return out
    shortest = settings.tail_convergence_lengths * abs(H[-1])
    window = max(settings.fit_fraction * (L[-1] - L[0]), shortest)
    if window > L[-1] - L[0]:
        return out   # the run is shorter than the stretch that must be fitted
    first_try = None
    while window >= shortest * (1 - 1e-9):
        end = L >= L[-1] - window
        if np.count_nonzero(end) < MIN_TAIL_ROWS or np.ptp(L[end]) <= 0:
            break    # too few steps at the end to say
        tried = _read(L, columns, end, settings)
        first_try = first_try or tried
        if tried["reached"]:
            del out["drift"]
            return {**out, **tried}
        window *= 0.5    # a section change inside the window: try the stretch after it
    if first_try is not None:
        out.update(first_try)
    return out


def _read(L, columns, end, settings):
    """The steady-state reading with the asymptotes fitted over the rows ``end``: {"reached",
    "fits", "fit_window_m", and "braided_length_m" ... or "drift"}."""
    H = columns["convergence_length_m"]
    fits, ok = {}, np.ones(len(L), dtype=bool)
    described = True
    for name, y in columns.items():
        fit = fit_asymptote(L[end], y[end], settings)
        tol = settings.rel_H * abs(fit["asymptote"]) if name == "convergence_length_m" else settings.angle_deg
        fit["tolerance"] = tol
        fit["describes_run"] = bool(fit["rms"] <= 0.5 * tol)
        # the asymptote is read, not extrapolated, where the transient decays inside the window
        fit["decays_in_window"] = bool(fit["decay_length_m"] <= float(np.ptp(L[end])))
        fits[name] = fit
        described &= fit["describes_run"]
        ok &= np.abs(y - fit["asymptote"]) <= tol
    rows = np.flatnonzero(end)
    out = {"reached": False, "fits": fits, "fit_window_m": [float(L[rows[0]]), float(L[rows[-1]])]}
    bad = np.nonzero(~ok)[0]
    first = 0 if len(bad) == 0 else bad[-1] + 1
    if not described or first >= len(L):
        # the last value not within tolerance of the asymptote: still approaching it
        out["drift"] = {"convergence_length_m_per_m": _slope(L[end], H[end]),
                        "braid_angle_warp_deg_per_m": _slope(L[end], columns["warp"][end]),
                        "braid_angle_weft_deg_per_m": _slope(L[end], columns["weft"][end])}
        return out
    out.update(reached=True, braided_length_m=float(L[first]),
               convergence_length_m=fits["convergence_length_m"]["asymptote"],
               braid_angle_deg={"warp": fits["warp"]["asymptote"], "weft": fits["weft"]["asymptote"]})
    return out


def setting_changes(config) -> list[dict]:
    """Where the run's settings change (their tables over the braided length, ``[machine]
    angular_speed``, ``[process] take_up_speed`` and ``eccentricity``): per change the setting,
    the braided length where its value starts changing and where it has its new value (the
    table's rows around a run of rows with differing values: a ramp over several rows is one
    change), and the values before and after in the config's units, sorted by start."""
    import math

    tables = {"angular_speed": [(row[0], (math.degrees(row[1]),))
                                for row in config.machine.angular_speeds],
              "take_up_speed": [(row[0], tuple(row[1:])) for row in config.process.take_up_speed],
              "eccentricity": [(row[0], tuple(row[1:])) for row in config.process.eccentricities]}
    units = {"angular_speed": "deg/s", "take_up_speed": "m/s", "eccentricity": "m"}
    changes = []
    for name, rows in tables.items():
        k = 0
        while k + 1 < len(rows):
            if rows[k + 1][1] == rows[k][1]:
                k += 1
                continue
            j = k + 1
            while j + 1 < len(rows) and rows[j + 1][1] != rows[j][1]:
                j += 1
            value = (lambda v: v[0] if len(v) == 1 else list(v))
            changes.append({"setting": name, "unit": units[name], "starts_at_m": rows[k][0],
                            "ends_at_m": rows[j][0], "from": value(rows[k][1]),
                            "to": value(rows[j][1])})
            k = j
    return sorted(changes, key=lambda c: (c["starts_at_m"], c["setting"]))


def transients(history, changes, settings: SteadySettings = STEADY) -> list[dict]:
    """The transient after each of ``changes`` (:func:`setting_changes`): the history from the
    change's end to the next change's start (or the run's end) read as :func:`steady_state`
    reads a run; per change, with its own keys, whether the braid ``settled`` there, where
    (``settled_at_m``, braided length) and the transient's ``length_m`` from the change's start,
    with the steady braid angles and convergence length after it (null where not settled)."""
    L = np.asarray(history["braided_length_m"], dtype=float)
    out = []
    for k, change in enumerate(changes):
        later = [c["starts_at_m"] for c in changes[k + 1:] if c["starts_at_m"] > change["ends_at_m"]]
        stop = min(later) if later else np.inf
        rows = (L >= change["ends_at_m"]) & (L < stop)
        part = {name: np.asarray(values)[rows] for name, values in history.items()}
        steady = steady_state(part, settings) if np.count_nonzero(rows) >= MIN_TAIL_ROWS else {}
        settled = bool(steady.get("reached"))
        at = steady["braided_length_m"] if settled else None
        out.append({**change, "settled": settled, "settled_at_m": at,
                    "length_m": None if at is None else at - change["starts_at_m"],
                    "braid_angle_deg": steady["braid_angle_deg"] if settled else None,
                    "convergence_length_m": steady["convergence_length_m"] if settled else None})
    return out
