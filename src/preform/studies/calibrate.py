"""The parameters nobody can measure, fitted to what can be (``preform calibrate``).

The search: a coarse grid over the given ranges (``--param KEY=LO:HI[:N]``), then a refinement
of the parameters the measurements determine: Levenberg-Marquardt rounds from the best point,
each running the slopes of the residuals (a forward difference per parameter, a tenth of the
coarse spacing) and then damped least-squares steps from them (several dampings at once, in
parallel), until a round lowers chi2 by less than half a unit. Every point is an ordinary run
through ``preform sweep``'s machinery (:func:`preform.studies.sweeps.run_spec`: Dask, a LocalCluster
or ``--scheduler``, ``--resume``) without pictures; each stage has its own folder
(``coarse/``, ``refine1_slopes/``, ``refine1_steps/``, ...). Every run is compared with the
measurements (:mod:`preform.studies.compare`).

The misfit. Per measurement kind ``k`` (angle, convergence, yarn) the residuals ``d`` of
``compare`` (simulated minus measured; the yarn's distance) are scaled by the kind's noise
``sigma_k``::

    chi2 = sum_k [ sum_i (d_ki / sigma_k)^2 + n_off_k * OFF^2 ],   misfit = chi2 / N

with ``N`` the number of measured points and ``n_off_k`` the points a run cannot be sampled at
(each counted as a residual of ``OFF`` = 3 noise sigmas, so a run that leaves a measured point
unbraided is not rewarded for it). ``misfit`` is about 1 where the model reproduces the
measurements to their noise. ``sigma_k`` is ``--noise KIND=VALUE`` (deg for angles, m for
lengths) or, not given, the smallest RMS residual of the kind over the evaluated runs (the
noise the best-fitting run leaves; model error that no parameter removes counts as noise then).

The uncertainty. A parameter's interval is where the misfit stays within what the noise
explains: ``chi2 <= chi2_min + D`` along its profile (the other parameters refitted), with
``D = 1`` (one standard deviation of one parameter), or ``chi2_min / (N - p)`` where that is
larger (the noise given explains less than the best fit leaves: scaled, Birge's ratio). It is
computed from the slopes ``J`` of the normalised residuals at the best run, the least-squares
linearisation: ``sigma_j = sqrt(D (J^T J)^-1_jj)``. A parameter whose least chi2 over the
coarse grid changes by less than ``D`` across its whole range, or whose interval covers the
whole range, is **not determined**: no value is given for it, and ``calibrated.toml`` keeps
the base config's.

Files in the output folder: ``calibrate.csv`` (every evaluated point and its misfit),
``calibrate.json`` (noise, best values, uncertainties, what is not determined),
``calibrated.toml`` (the base config with the determined values; runnable),
``plots/misfit_<key>.png`` and ``best/compare.*`` (the best run against the measurements).
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w

from ..errors import ConfigError, PreformError
from ..io.atomic import atomic_path, atomic_write_text, safe_folder
from .compare import KINDS, QUANTITY, MeasurementError, compare, compare_run, read_measurements
from .sweeps import _read_toml, _set, finished, open_client, run_spec, spec_of_points

CALIBRATE_CSV = "calibrate.csv"
CALIBRATE_JSON = "calibrate.json"
CALIBRATED_TOML = "calibrated.toml"


@dataclass(frozen=True)
class CalibrationSettings:
    """How the search is made and the uncertainty read."""

    #: coarse grid points per parameter (``--param KEY=LO:HI:N`` sets one's own): 5 resolve a
    #: single minimum of a smooth misfit without spending a run on every tenth of the range
    coarse_points: int = 5
    #: refinement rounds at most after the coarse grid: each runs the slopes at the best point
    #: (one run per determined parameter) and then the damped least-squares steps from it
    refinements: int = 8
    #: the step of the forward differences of the refinement, in coarse spacings: small enough
    #: for the slope at the point, large against the model's own round-off between runs
    fd_step: float = 0.1
    #: Levenberg-Marquardt damping tried in parallel each round (0: the Gauss-Newton step)
    lambdas: tuple = (0.0, 0.3, 3.0)
    #: a round that lowers chi2 by less than this ends the refinement
    chi2_tolerance: float = 0.5
    #: residual (in noise sigmas) counted for a measured point a run cannot be sampled at
    off_sigmas: float = 3.0
    #: Delta chi2 of a one-standard-deviation interval of one parameter (its profile)
    delta_chi2: float = 1.0
    #: significant digits of the evaluated values: the same point, folder and resume each time
    digits: int = 10


SETTINGS = CalibrationSettings()


@dataclass(frozen=True)
class Param:
    """key: dotted config key; lo, hi: the range searched; points: coarse grid points."""

    key: str
    lo: float
    hi: float
    points: int | None = None


def parse_param(text: str) -> Param:
    """``KEY=LO:HI`` or ``KEY=LO:HI:N`` (N coarse grid points)."""
    key, sep, rng = text.partition("=")
    parts = rng.split(":")
    example = "e.g. --param yarn.friction=0:0.5 (or =0:0.5:6 for 6 coarse points)"
    if not sep or "." not in key.strip() or len(parts) not in (2, 3):
        raise ConfigError(f"--param {text}: expected KEY=LO:HI[:N], {example}")
    try:
        lo, hi = float(parts[0]), float(parts[1])
        n = int(parts[2]) if len(parts) == 3 else None
    except ValueError:
        raise ConfigError(f"--param {text}: LO and HI must be numbers and N an integer, {example}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        raise ConfigError(f"--param {text}: expected LO < HI, {example}")
    if n is not None and n < 2:
        raise ConfigError(f"--param {text}: N = {n}: expected at least 2 coarse points")
    return Param(key=key.strip(), lo=lo, hi=hi, points=n)


def parse_noise(items) -> dict:
    """``KIND=SIGMA`` items -> {kind: sigma}; kinds angle (deg), convergence (m), yarn (m)."""
    out = {}
    for text in items or ():
        kind, _, value = text.partition("=")
        kind = kind.strip()
        if kind not in KINDS:
            raise ConfigError(f"--noise {text}: expected one of {', '.join(KINDS)}=SIGMA "
                              "(e.g. --noise angle=1.0 in deg, --noise convergence=0.005 in m)")
        try:
            sigma = float(value)
        except ValueError:
            sigma = float("nan")
        if not math.isfinite(sigma) or sigma <= 0:
            raise ConfigError(f"--noise {text}: expected a positive standard deviation "
                              f"({QUANTITY[kind][1]})")
        out[kind] = sigma
    return out


# ------------------------------------------------------------------------------ evaluations

@dataclass
class Evaluation:
    """One run: stage, its values, status, results folder, and per kind the compared points
    ``n``, the sum of squared residuals ``ss`` and the points it could not sample ``off``."""

    stage: str
    index: int
    values: dict
    status: str
    results: str
    message: str = ""
    n: dict = field(default_factory=dict)
    ss: dict = field(default_factory=dict)
    off: dict = field(default_factory=dict)
    values_key: tuple = ()
    #: per kind, the residual of every measured point in file order (NaN where off)
    residuals: dict = field(default_factory=dict)

    def rms(self, kind):
        n = self.n.get(kind, 0)
        return math.sqrt(self.ss[kind] / n) if n else None


def _score(evaluation: Evaluation, measurements) -> Evaluation:
    if evaluation.status != "done":
        return evaluation
    try:
        comparisons = compare_run(evaluation.results, measurements)
    except PreformError as err:
        evaluation.status, evaluation.message = "failed", f"compare: {err}"
        return evaluation
    for kind in KINDS:
        these = [c for c in comparisons if c.meas.kind == kind]
        if these:
            d = np.concatenate([c.difference[c.ok] for c in these])
            evaluation.n[kind] = int(len(d))
            evaluation.ss[kind] = float(np.sum(d * d))
            evaluation.off[kind] = int(sum((~c.ok).sum() for c in these))
            evaluation.residuals[kind] = np.concatenate([c.difference for c in these])
    return evaluation


def residual_vector(e: Evaluation, sigma: dict, settings: CalibrationSettings = SETTINGS):
    """Every measured point's residual in noise sigmas (an off point: ``off_sigmas``), the
    kinds in ``sigma``'s order; ``chi2`` is its squared norm."""
    parts = []
    for kind, s in sigma.items():
        r = np.asarray(e.residuals[kind], dtype=float) / s
        parts.append(np.where(np.isfinite(r), r, settings.off_sigmas))
    return np.concatenate(parts)


def chi2(e: Evaluation, sigma: dict, settings: CalibrationSettings = SETTINGS) -> float:
    """The evaluation's chi2 under the noise ``sigma`` (module docstring); inf if it failed."""
    if e.status != "done" or not e.n and not e.off:
        return math.inf
    total = 0.0
    for kind, s in sigma.items():
        total += e.ss.get(kind, 0.0) / s ** 2 + e.off.get(kind, 0) * settings.off_sigmas ** 2
    return total


def estimated_noise(evaluations, kinds, given: dict) -> dict:
    """``given`` where given, else per kind the smallest RMS residual over the runs."""
    out = {}
    for kind in kinds:
        if kind in given:
            out[kind] = given[kind]
            continue
        rms = [e.rms(kind) for e in evaluations if e.status == "done" and e.rms(kind) is not None]
        rms = [r for r in rms if r > 0]
        if not rms:   # every run reproduces the measurements exactly: any positive scale
            out[kind] = {"angle": 1e-6, "convergence": 1e-9, "yarn": 1e-9}[kind]
        else:
            out[kind] = min(rms)
    return out


# ------------------------------------------------------------------------------ the search

def _round(value: float, digits: int) -> float:
    return float(f"{value:.{digits}g}")


def coarse_grid(params, settings: CalibrationSettings = SETTINGS) -> list[dict]:
    axes = [np.linspace(p.lo, p.hi, p.points or settings.coarse_points) for p in params]
    mesh = np.meshgrid(*axes, indexing="ij")
    return [{p.key: _round(float(m.flat[i]), settings.digits) for p, m in zip(params, mesh)}
            for i in range(mesh[0].size)]


def profile(evaluations, key, chis):
    """(values, least chi2 at each) of one parameter over the evaluations."""
    best = {}
    for e, c in zip(evaluations, chis):
        v = e.values[key]
        best[v] = min(best.get(v, math.inf), c)
    values = np.array(sorted(best))
    return values, np.array([best[v] for v in values])


def undetermined(params, evaluations, chis, delta) -> set:
    """The parameters whose profile varies by less than ``delta`` over the range."""
    out = set()
    for p in params:
        v, c = profile(evaluations, p.key, chis)
        c = c[np.isfinite(c)]
        if len(v) < 2 or not len(c) or float(c.max() - c.min()) < delta:
            out.add(p.key)
    return out


@dataclass
class Estimate:
    key: str
    determined: bool
    value: float | None = None
    sigma: float | None = None
    low: float | None = None
    high: float | None = None
    how: str = ""


def jacobian(base: Evaluation, shifted, free, steps, sigma, settings=SETTINGS) -> np.ndarray:
    """(N, p) forward differences of the normalised residuals per unit of each free parameter."""
    r0 = residual_vector(base, sigma, settings)
    cols = []
    for p, e, h in zip(free, shifted, steps):
        cols.append((residual_vector(e, sigma, settings) - r0) / h)
    return np.column_stack(cols)


def lm_steps(J, r, lambdas) -> list[np.ndarray]:
    """Levenberg-Marquardt steps (J^T J + lambda diag(J^T J)) d = -J^T r, one per lambda."""
    JtJ, g = J.T @ J, J.T @ r
    D = np.diag(np.maximum(np.diag(JtJ), 1e-300))
    out = []
    for lam in lambdas:
        try:
            out.append(np.linalg.solve(JtJ + lam * D, -g))
        except np.linalg.LinAlgError:
            out.append(np.linalg.lstsq(JtJ + lam * D, -g, rcond=None)[0])
    return out


def interval(p: Param, value: float, sigma: float, how: str) -> Estimate:
    """The estimate of ``p``, or not determined where value +- sigma covers its whole range."""
    if not math.isfinite(sigma) or (value - sigma <= p.lo and value + sigma >= p.hi):
        return Estimate(p.key, False, how="the interval within the noise spans the whole range: "
                        "the measurements do not determine it")
    return Estimate(p.key, True, value, sigma, max(p.lo, value - sigma), min(p.hi, value + sigma), how)


# ------------------------------------------------------------------------------ the command

def _base_data(config_path: Path) -> dict:
    return _read_toml(config_path, "config file")


def _stage_spec(config_path, base_data, combos, out_dir):
    return spec_of_points(config_path, config_path, base_data, combos, out_dir)


def calibrate(config, measured, params, *, out_dir=None, noise=None, scheduler=None, workers=None,
              resume=False, progress=True, settings: CalibrationSettings = SETTINGS) -> dict:
    """Run the calibration (module docstring); returns what calibrate.json holds."""
    config_path = Path(config).expanduser().resolve()
    measurements = [read_measurements(m) for m in measured]
    if not measurements:
        raise MeasurementError("no measurement files given")
    if not params:
        raise ConfigError("no --param given: name a parameter and its range, e.g. "
                          "--param yarn.friction=0:0.5")
    keys = [p.key for p in params]
    if len(set(keys)) != len(keys):
        raise ConfigError(f"--param: a key given twice ({', '.join(keys)})")
    noise = dict(noise or {})
    kinds = list(dict.fromkeys(m.kind for m in measurements))
    extra = sorted(set(noise) - set(kinds))
    if extra:
        raise ConfigError(f"--noise {', '.join(extra)}: no measurements of that kind given")
    base = _base_data(config_path)
    for key in keys:   # the key must name a value of the config (sweeps._set checks the tables)
        _set(copy.deepcopy(base), key, 0.0, f"--param {key}")
    run_data = copy.deepcopy(base)
    _set(run_data, "output.pictures", False, "calibrate")
    out = (Path(out_dir).expanduser().resolve() if out_dir is not None
           else config_path.parent / "results" / f"{config_path.stem}_calibration")

    safe_folder(out)
    evaluations: list[Evaluation] = []
    seen = {}
    cluster = {}   # one Dask client for every stage, made when the first runs are due

    try:
        return _search(config_path, base, run_data, measurements, params, kinds, noise, out,
                       evaluations, seen, cluster, scheduler, workers, resume, progress, settings)
    finally:
        if cluster:
            cluster["client"].close()
            if cluster["local"] is not None:
                cluster["local"].close()


def _search(config_path, base, run_data, measurements, params, kinds, noise, out, evaluations,
            seen, cluster, scheduler, workers, resume, progress, settings):
    """The stages of :func:`calibrate` and its files; returns the report."""

    def run_stage(name, combos):
        todo = [c for c in combos if _key(c) not in seen]
        if todo:
            spec = _stage_spec(config_path, run_data, todo, out / name)
            if resume:   # the points finished before: no cluster needed for them
                done = [finished(spec, p) for p in spec.points]
            else:
                done = [None]
            if any(d is None for d in done) and not cluster:
                cluster["client"], cluster["local"] = open_client(scheduler, workers)
            rows = run_spec(spec, scheduler=scheduler, workers=workers, resume=resume,
                            progress=progress, label=f"calibrate {name}",
                            client=cluster.get("client"))
            for point, row in zip(spec.points, rows):
                e = Evaluation(stage=name, index=point.index, values=point.values,
                               status=row.get("status", "failed"), results=str(row.get("results")),
                               message=row.get("message") or "", values_key=_key(point.values))
                evaluations.append(_score(e, measurements))
                seen[e.values_key] = e
        return {_key(c) for c in combos}

    run_stage("coarse", coarse_grid(params, settings))
    sigma = estimated_noise(evaluations, kinds, noise)
    chis = [chi2(e, sigma, settings) for e in evaluations]
    if not any(math.isfinite(c) for c in chis):
        failed = [e for e in evaluations if e.status != "done"][:3]
        raise PreformError("calibrate: no run of the coarse grid finished: " + "; ".join(
            f"{e.results}: {e.message}" for e in failed))
    delta = settings.delta_chi2
    flat = undetermined(params, evaluations, chis, delta)
    n_points = sum(len(m) for m in measurements)
    free = [p for p in params if p.key not in flat]
    steps = [settings.fd_step * (p.hi - p.lo) / ((p.points or settings.coarse_points) - 1) for p in free]
    current = evaluations[int(np.argmin(chis))]

    def slopes(at: Evaluation, stage: str):
        """The Jacobian at ``at`` (forward differences, inwards from a bound), or None."""
        x, shifted = at.values, []
        for p, h in zip(free, steps):
            v = dict(x)
            v[p.key] = _round(x[p.key] + h if x[p.key] + h <= p.hi else x[p.key] - h, settings.digits)
            shifted.append(v)
        run_stage(stage, shifted)
        if any(seen[_key(v)].status != "done" for v in shifted):
            return None
        sig = estimated_noise(evaluations, kinds, noise)
        hs = [seen[_key(v)].values[p.key] - x[p.key] for p, v in zip(free, shifted)]
        return jacobian(at, [seen[_key(v)] for v in shifted], free, hs, sig, settings)

    J, J_at = None, None
    for r in range(1, settings.refinements + 1):
        if not free:
            break
        x = current.values
        J, J_at = slopes(current, f"refine{r}_slopes"), current
        if J is None:
            break
        sigma = estimated_noise(evaluations, kinds, noise)
        r0 = residual_vector(current, sigma, settings)
        trials = []
        for d in lm_steps(J, r0, settings.lambdas):
            v = dict(x)
            for p, dj in zip(free, d):
                v[p.key] = _round(min(p.hi, max(p.lo, x[p.key] + dj)), settings.digits)
            if _key(v) != _key(x) and v not in trials:
                trials.append(v)
        if not trials:
            break
        run_stage(f"refine{r}_steps", trials)
        sigma = estimated_noise(evaluations, kinds, noise)
        c_now = chi2(current, sigma, settings)
        best_trial = min((seen[_key(v)] for v in trials), key=lambda e: chi2(e, sigma, settings))
        c_new = chi2(best_trial, sigma, settings)
        if c_new < c_now:
            current = best_trial
        if not c_new < c_now - settings.chi2_tolerance:
            break
    sigma = estimated_noise(evaluations, kinds, noise)
    chis = [chi2(e, sigma, settings) for e in evaluations]
    best_eval = evaluations[int(np.argmin(chis))]
    if free and J_at is not best_eval:   # the uncertainty from the slopes at the best run
        J, J_at = slopes(best_eval, "final_slopes"), best_eval
    sigma = estimated_noise(evaluations, kinds, noise)
    chis = [chi2(e, sigma, settings) for e in evaluations]
    c_min = min(chis)
    delta = _delta(chis, n_points, len(params) - len(flat), settings)
    i_best = int(np.argmin(chis))
    best = evaluations[i_best].values
    estimates = {p.key: Estimate(p.key, False, how="the misfit is flat over the range: the "
                                 "measurements do not determine it") for p in params if p.key in flat}
    if free:
        cov = np.full((len(free), len(free)), np.inf)
        if J is not None:
            JtJ = J.T @ J
            if np.linalg.matrix_rank(JtJ) == len(free):
                cov = np.linalg.inv(JtJ)
        for j, p in enumerate(free):
            if J is None:
                estimates[p.key] = Estimate(p.key, False, how="no uncertainty: a run of the slopes "
                                            "at the best point failed (see calibrate.csv)")
                continue
            s = math.sqrt(delta * cov[j, j]) if np.isfinite(cov[j, j]) and cov[j, j] >= 0 else math.inf
            estimates[p.key] = interval(p, float(best[p.key]), s, "from the misfit's slopes at the "
                                        "best run (least squares: Delta chi2 along the profile)")
    report = {
        "config": str(config_path),
        "measurements": [str(m.path) for m in measurements],
        "points": {k: sum(len(m) for m in measurements if m.kind == k) for k in kinds},
        "noise": {k: {"sigma": sigma[k], "unit": QUANTITY[k][1],
                      "source": "given" if k in noise else "estimated: the least RMS residual of the runs"}
                  for k in kinds},
        "misfit_min": c_min / n_points,
        "chi2_min": c_min,
        "delta_chi2": delta,
        "evaluations": len(evaluations),
        "best_run": evaluations[i_best].results,
        "out": str(out),
        "parameters": {p.key: {"determined": estimates[p.key].determined,
                               "value": estimates[p.key].value, "sigma": estimates[p.key].sigma,
                               "low": estimates[p.key].low, "high": estimates[p.key].high,
                               "range": [p.lo, p.hi], "best_evaluated": best[p.key],
                               "how": estimates[p.key].how} for p in params},
    }
    _write_outputs(out, config_path, base, params, evaluations, chis, n_points, report,
                   estimates, measurements, delta, c_min)
    return report


def _delta(chis, n_points, n_free, settings) -> float:
    """Delta chi2 of the intervals: ``delta_chi2``, or Birge's chi2_min / (N - p) if larger."""
    return max(settings.delta_chi2, min(chis) / max(n_points - n_free, 1))


def _key(values: dict) -> tuple:
    return tuple(sorted(values.items()))


def _write_outputs(out, config_path, base, params, evaluations, chis, n_points, report, estimates,
                   measurements, delta, c_min):
    kinds = list(report["noise"])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    head = ["stage", "point", *[p.key for p in params], "status", "misfit", "chi2"]
    head += [f"rms_{k}_{QUANTITY[k][1]}" for k in kinds] + [f"off_{k}" for k in kinds]
    w.writerow(head + ["results", "message"])
    for e, c in zip(evaluations, chis):
        ok = math.isfinite(c)
        w.writerow([e.stage, e.index, *[repr(e.values[p.key]) for p in params], e.status,
                    repr(c / n_points) if ok else "", repr(c) if ok else "",
                    *[("" if e.rms(k) is None else repr(e.rms(k))) for k in kinds],
                    *[e.off.get(k, "") for k in kinds], e.results, e.message])
    atomic_write_text(out / CALIBRATE_CSV, buf.getvalue())
    atomic_write_text(out / CALIBRATE_JSON, json.dumps(report, indent=2) + "\n")
    # calibrated.toml: the config with the determined values, results beside it
    data = copy.deepcopy(base)
    mandrel = data.get("mandrel", {})
    for key in ("stl", "centerline"):
        if isinstance(mandrel.get(key), str) and mandrel[key] != "auto":
            mandrel[key] = str((config_path.parent / mandrel[key]).resolve())
    lines = [f"# {config_path.name} calibrated by preform calibrate against "
             f"{', '.join(Path(m).name for m in report['measurements'])}"]
    for p in params:
        e = estimates[p.key]
        if e.determined:
            _set(data, p.key, _round(e.value, 6), "calibrated.toml")
            lines.append(f"# {p.key} = {e.value:.6g} +- {e.sigma:.2g} ({e.how})")
        else:
            lines.append(f"# {p.key}: not determined by the measurements; the config's value kept")
    _set(data, "output.dir", str(out / "calibrated"), "calibrated.toml")
    atomic_write_text(out / CALIBRATED_TOML, "\n".join(lines) + "\n\n" + tomli_w.dumps(data))
    plot_misfit(out, params, evaluations, chis, n_points, estimates, delta, c_min)
    best = report["best_run"]
    compare(best, measurements, safe_folder(out, "best"))


def plot_misfit(out, params, evaluations, chis, n_points, estimates, delta, c_min) -> list[Path]:
    """``plots/misfit_<key>.png``: the misfit of every run against the parameter (coarse grid,
    refinement slopes and steps), the level the noise explains and the estimate with its
    interval; left the whole range, right round the best (+-5 standard deviations, or the
    refinement's runs where it is not determined)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    plots = safe_folder(out, "plots")
    written = []
    m = np.array(chis) / n_points
    groups = (("coarse grid", lambda s: s == "coarse", "o", "none", "tab:blue"),
              ("refinement: slopes", lambda s: s.endswith("slopes"), "s", None, "tab:green"),
              ("refinement: steps", lambda s: s.endswith("steps"), "D", None, "tab:orange"))
    level = (c_min + delta) / n_points
    i_best = int(np.argmin(chis))
    for p in params:
        e = estimates[p.key]
        fig = Figure(figsize=(10.0, 4.0), layout="constrained")
        axes = fig.subplots(1, 2)
        if e.determined:
            zoom = (max(p.lo, e.value - 5 * e.sigma), min(p.hi, e.value + 5 * e.sigma))
        else:
            vals = [x.values[p.key] for x in evaluations if x.stage != "coarse"] or [p.lo, p.hi]
            zoom = (min(vals), max(vals)) if max(vals) > min(vals) else (p.lo, p.hi)
        for ax, (x0, x1) in zip(axes, ((p.lo, p.hi), zoom)):
            pad = 0.03 * (x1 - x0)
            for label, test, marker, face, colour in groups:
                runs = [i for i, x in enumerate(evaluations) if test(x.stage) and math.isfinite(chis[i])]
                sel = [i for i in runs if x0 - pad <= evaluations[i].values[p.key] <= x1 + pad]
                if sel:
                    ax.plot([evaluations[i].values[p.key] for i in sel], m[sel], marker, ms=4.5,
                            mfc=face, color=colour, ls="none", label=f"{label} ({len(runs)} runs)")
            ax.plot([evaluations[i_best].values[p.key]], [m[i_best]], "*", ms=11, color="tab:red",
                    label="best run")
            ax.axhline(level, color="tab:red", lw=1.0, ls="--", label="what the noise explains")
            if e.determined:
                xs = np.linspace(max(x0, e.value - 5 * e.sigma), min(x1, e.value + 5 * e.sigma), 200)
                ax.plot(xs, (c_min + delta * ((xs - e.value) / e.sigma) ** 2) / n_points, "-",
                        color="0.35", lw=1.0, label="least-squares profile")
                ax.axvspan(e.low, e.high, color="tab:red", alpha=0.15, label="within the noise")
            if ax is axes[0]:
                ax.set_yscale("log")
            else:   # linear, up to the profile at 5 standard deviations: the interval readable
                ax.set_ylim((c_min - 2 * delta) / n_points, (c_min + 27 * delta) / n_points)
            ax.set_xlim(x0 - pad, x1 + pad)
            ax.set_xlabel(p.key)
            ax.grid(True, which="major", alpha=0.3)
        axes[0].set_ylabel("misfit χ²/N (-)")
        axes[0].set_title("whole range", fontsize=10)
        axes[1].set_title("round the best" + (" (±5 standard deviations)" if e.determined else ""),
                          fontsize=10)
        axes[1].legend(fontsize=8, loc="upper center")
        fig.suptitle(f"{p.key} = {e.value:.4g} ± {e.sigma:.2g}" if e.determined
                     else f"{p.key}: not determined by the measurements", fontsize=12)
        FigureCanvasAgg(fig)
        path = plots / f"misfit_{p.key.replace('.', '_')}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120)
        written.append(path)
    return written


def report_lines(report: dict) -> list[str]:
    """What ``preform calibrate`` prints."""
    lines = [f"calibrate: {report['evaluations']} runs; least misfit {report['misfit_min']:.3g} "
             f"(chi2/N; about 1 where the model reproduces the measurements to their noise)"]
    for kind, n in report["noise"].items():
        unit = n["unit"]
        lines.append(f"noise {kind}: {n['sigma']:.3g} {unit} ({n['source']})")
    for key, p in report["parameters"].items():
        if p["determined"]:
            lines.append(f"{key} = {p['value']:.4g} ± {p['sigma']:.2g} (within the noise: "
                         f"{p['low']:.4g} to {p['high']:.4g}; {p['how']})")
        else:
            lines.append(f"{key}: not determined ({p['how']}; searched {p['range'][0]:g} to "
                         f"{p['range'][1]:g})")
    return lines


