"""The ``preform`` command (docs/guide/commands.md): thin argparse subcommands over the Python API.

``main(argv=None) -> int`` so tests call it in-process (meshio style). Exit codes: 0 done,
1 failed (simulation or writing), 2 bad input, 130 interrupted. A :class:`PreformError` prints
``error: <message>`` on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ._version import __version__
from .checkpoint import CHECKPOINT  # noqa: F401 - the checkpoint's name in a results folder
from .errors import ConfigError, MandrelError, PreformError

EXIT_DONE, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
#: ``time.perf_counter()`` when this module was imported (the fallback of :func:`process_started`)
_IMPORTED = time.perf_counter()


def process_started() -> float:
    """``time.perf_counter()`` at the start of this process, so that a summary's wall time is the
    command's, the interpreter's start and the imports included: on Linux from ``/proc`` (the
    process's start in clock ticks since boot against the time since boot), elsewhere, or where
    ``/proc`` cannot be read, when this module was imported."""
    import os

    try:
        with open("/proc/self/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        start_ticks = int(fields[19])          # field 22 of stat(5), counted after "pid (comm)"
        with open("/proc/uptime", encoding="ascii") as fh:
            uptime = float(fh.read().split()[0])
        age = uptime - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return _IMPORTED
    now = time.perf_counter()
    return now - age if 0.0 <= age <= now - _IMPORTED + 60.0 else _IMPORTED


# ---------------------------------------------------------------- preform run

def _out_dir(config, out):
    if out is not None:
        return Path(out).expanduser().resolve()
    if config.output is not None:
        return Path(config.output.dir)
    source = Path(config.source) if config.source else Path("config.toml")
    return source.parent / "results" / source.stem


def _fmt(value, spec=".3f"):
    return "n/a" if value is None else f"{value:{spec}}"


def written_summary(out_dir) -> dict | None:
    """The summary.json a run wrote in ``out_dir``, or None where there is none to read."""
    import json

    try:
        return json.loads((Path(out_dir) / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def summary_lines(result, out_dir, n_files, summary=None) -> list[str]:
    """The three lines ``preform run`` prints at the end, from the written ``summary`` (whose wall
    time is the command's, with its stages), else from the result; then one line per layer of a
    run with [[layer]] tables."""
    from .analysis.derived import summary_dict

    s = summary if summary is not None else summary_dict(result)
    stages = s.get("stages_s") or {}
    stage_text = (" (" + ", ".join(f"{k.replace('_', ' ')} {v:.1f}" for k, v in stages.items()) + ")"
                  if stages else "")
    angle = s["braid_angle_deg"]["final"]
    conv = s["convergence_length_m"]["final"]
    steady = s.get("steady_state") or {}
    if steady.get("reached"):
        steady_line = f"steady state from {steady['braided_length_m']:.3f} m braided on"
    else:
        steady_line = "steady state not reached in this run"
    status = s["status"] + (f" ({s['message']})" if s["message"] else "")
    layers = [_layer_line(e) for e in s.get("layers") or []]
    return [
        f"results: {out_dir} ({n_files} files)",
        f"status: {status}; {s['steps']} steps, {s['wall_time_s']:.1f} s wall{stage_text}, "
        f"braided length {_fmt(s['braided_length_m'])} m",
        f"final braid angle: warp {_fmt(angle['warp'], '.2f')} deg, weft {_fmt(angle['weft'], '.2f')} deg; "
        f"convergence length {_fmt(conv['mean'])} m (min {_fmt(conv['min'])}, max {_fmt(conv['max'])}); "
        + steady_line,
        *layers,
    ]


def _layer_line(entry) -> str:
    """One console line of a layer of a run with [[layer]] tables (summary.json's entry)."""
    angle = (entry.get("braid_angle_deg") or {}).get("final") or {}
    quality = (entry.get("quality") or {}).get("verdict") or "not judged"
    status = entry.get("status") or "not run"
    return (f"layer {entry.get('layer')} ({entry.get('direction')}): {status}; {entry.get('steps')} steps, "
            f"braided length {_fmt(entry.get('braided_length_m'))} m, final braid angle warp "
            f"{_fmt(angle.get('warp'), '.2f')} deg, weft {_fmt(angle.get('weft'), '.2f')} deg; "
            f"quality {quality}")


#: the exit code of a run stopped by a signal: 128 + the signal number, as shells report it
SIGNAL_EXIT = {"SIGINT": EXIT_INTERRUPTED, "SIGTERM": 143, "SIGHUP": 129}


def _with_model(config, model):
    if not model:
        return config
    import dataclasses

    return dataclasses.replace(config, model=dataclasses.replace(config.model, kind=model))


#: said once when numba compiles a kernel (not when it loads one from its cache)
COMPILING = ("note: compiling the numba kernels (a first run in this environment, some seconds; "
             "later runs load them from the cache)")


def _compile_note_marker():
    """The file whose presence says :data:`COMPILING` was printed in this environment (the
    interpreter's prefix and the versions of preform and numba, hashed), in the preform cache
    folder (``io.cache.cache_dir``); None with the cache off."""
    import hashlib

    from ._version import __version__
    from .io.cache import cache_dir

    folder = cache_dir()
    if folder is None:
        return None
    try:
        import numba

        numba_version = numba.__version__
    except ImportError:   # pragma: no cover - numba is a dependency
        numba_version = ""
    key = hashlib.sha256("\0".join((sys.prefix, __version__, numba_version)).encode()).hexdigest()[:16]
    return folder / f"compile-note-{key}"


class _CompileNote:
    """Prints :data:`COMPILING` on stderr at numba's first compilation while registered (numba's
    ``numba:compile`` event, raised for a compilation, not for a cache load), once per
    environment: a run that compiles kernels for a new config in an environment that already
    compiled some says nothing (:func:`_compile_note_marker`)."""

    def __enter__(self):
        self.listener = None
        try:
            from numba.core import event
        except ImportError:   # pragma: no cover - numba is a dependency
            return self

        class Note(event.Listener):
            said = False

            def on_start(self, ev):
                self.say()

            def say(self):
                if self.said:
                    return
                self.said = True
                marker = _compile_note_marker()
                if marker is not None and marker.exists():
                    return
                print(COMPILING, file=sys.stderr, flush=True)
                if marker is not None:
                    try:
                        from .io.atomic import atomic_write_text

                        marker.parent.mkdir(parents=True, exist_ok=True)
                        atomic_write_text(marker, "the numba compile note was printed\n")
                    except OSError:   # a cache that cannot be written: the note comes again
                        pass

            def on_end(self, ev):
                pass

        self.event, self.listener = event, Note()
        event.register("numba:compile", self.listener)
        return self

    def say(self):
        """Print the note now (once), e.g. when another process compiles for this one."""
        if self.listener is not None:
            self.listener.say()

    def __exit__(self, *exc):
        if self.listener is not None:
            self.event.unregister("numba:compile", self.listener)
        return False


def cmd_run(args) -> int:
    with _CompileNote():
        return _cmd_run(args)


def _cmd_run(args) -> int:
    from .config import load_config

    started = time.perf_counter()
    # the interpreter's start and the imports count when this process is the command itself
    # (``main()`` from the entry point); a caller's ``main(argv)`` (tests) times from here
    startup = max(0.0, started - process_started()) if args.whole_process else None
    config = _with_model(load_config(args.config), args.model)  # bad input fails here, before the heavy imports
    out_dir = _out_dir(config, args.out)
    from ._jit import Warmup
    from .pipeline import load, run_case   # the stages' imports (numba, SciPy): after the config

    # a first run: from the first compilation on, a worker compiles the run's later kernels
    with Warmup(config, args.config, args.model or ""):
        loaded = load(config)  # the load stage: impossible set-ups fail here, before simulating
        _print_notes(loaded.notes)
        outcome = run_case(config, out_dir, progress=not args.no_progress, resume=args.resume,
                           force=args.force, geometry=(loaded.mandrel, loaded.centerline, []),
                           started=started, background_pictures=True, startup_s=startup,
                           say=lambda note: print(note, file=sys.stderr, flush=True))
    result = outcome.result
    summary = written_summary(out_dir)
    for line in summary_lines(result, out_dir, len(outcome.written), summary):
        print(line)
    quality = _quality_line(summary)
    if quality:
        print(quality)
    if result.status == "interrupted":
        print(f"interrupted: partial results in {out_dir}; the state is kept in "
              f"{out_dir / CHECKPOINT}: --resume goes on from it", file=sys.stderr)
        return SIGNAL_EXIT.get(result.stop_signal, EXIT_INTERRUPTED)
    if result.status != "done":
        print(f"error: simulation {result.status}: {result.message}", file=sys.stderr)
        return EXIT_FAILED
    if args.strict and quality.startswith("quality: suspect"):
        print("error: --strict: the run is suspect (see the reasons above)", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_DONE


def _print_notes(notes):
    for note in notes:
        print(note, file=sys.stderr)


def _quality_line(summary) -> str:
    """``quality: ok`` or ``quality: suspect: reason; reason`` from the written summary."""
    quality = (summary or {}).get("quality")
    if not quality:
        return ""
    if quality["verdict"] == "ok":
        return "quality: ok"
    return "quality: suspect: " + "; ".join(quality["reasons"])


# ---------------------------------------------------------------- preform check

def cmd_check(args) -> int:
    with _CompileNote():
        return _cmd_check(args)


def _cmd_check(args) -> int:
    from .config import load_config

    config = _with_model(load_config(args.config), getattr(args, "model", None))
    from .pipeline import check, load   # the stages' imports (numba, SciPy): after the config
    # the run's load and check stages, without a results folder: every layer's checks and estimate
    _print_notes(check(load(config), None, force=args.force).notes)
    from .checks import setting_ranges

    for line in setting_ranges(config):
        print(f"process: {line}")
    print(f"OK: {config.source or args.config}")
    return EXIT_DONE


# ---------------------------------------------------------------- preform mandrel info

def _existing_file(path, what) -> Path:
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise MandrelError(f"{what} {path} not found")
    return path


def cmd_mandrel_info(args) -> int:
    """Measure an STL; print in metres (``format_mandrel_info``), warnings on stderr; write the
    centerline CSV (in the STL's unit, as ``[mandrel] centerline`` reads it) only to ``--csv``."""
    stl = _existing_file(args.file, "mandrel STL")
    centerline = "auto" if args.centerline == "auto" else _existing_file(args.centerline, "centerline CSV")
    csv = Path(args.csv).expanduser().absolute() if args.csv else None
    if csv is not None and not csv.parent.is_dir():
        raise MandrelError(f"--csv {args.csv}: the folder {csv.parent} does not exist")
    from .io.centerline_csv import write_centerline_csv
    from .geometry.info import format_mandrel_info, mandrel_info

    info = mandrel_info(stl, unit=args.unit, centerline=centerline)
    print(format_mandrel_info(info))
    for text in getattr(info, "warnings", ()):
        print(f"warning: {text}", file=sys.stderr)
    if csv is not None:
        try:
            write_centerline_csv(info.centerline, csv, unit=args.unit)
        except OSError as err:
            raise MandrelError(f"--csv {csv}: cannot write the centerline there "
                               f"({err.strerror or err})") from None
        print(f"centerline written to {csv} (in {args.unit}, the STL's unit)")
    return EXIT_DONE


# ---------------------------------------------------------------- preform sweep

def cmd_sweep(args) -> int:
    from .studies.sweeps import SWEEP_CSV, load_sweep, sweep

    spec = load_sweep(args.sweep)   # bad input fails here, before a cluster starts
    rows = sweep(args.sweep, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                 progress=not args.no_progress)
    failed = [r for r in rows if r.get("status") != "done"]
    print(f"sweep: {len(rows) - len(failed)} of {len(rows)} points done; table: {spec.out_dir / SWEEP_CSV}")
    for r in failed:
        print(f"error: point {r['point']} ({r['results']}): {r.get('status')}: {r.get('message', '')}",
              file=sys.stderr)
    return EXIT_FAILED if failed else EXIT_DONE


# ---------------------------------------------------------------- preform design

def cmd_design(args) -> int:
    import dataclasses

    from .config import load_config
    from .studies.design import (DESIGN, design_speed, plot_design, read_target_table, shortfall,
                                 write_design_config, write_design_process, write_design_runs,
                                 write_design_table)

    config = load_config(args.config)
    if args.model:
        config = dataclasses.replace(config, model=dataclasses.replace(config.model, kind=args.model))
    settings = DESIGN
    if args.tolerance is not None:
        if not 0.0 < args.tolerance < 90.0:
            raise ConfigError(f"--tolerance {args.tolerance:g}: expected a braid angle error in (0, 90) deg")
        settings = dataclasses.replace(DESIGN, tolerance_deg=args.tolerance)
    target = args.target_angle if args.target_table is None else read_target_table(args.target_table)
    source = Path(config.source) if config.source else Path.cwd() / "case.toml"
    out = Path(args.out).expanduser() if args.out else source.with_name(f"{source.stem}_designed.toml")
    out = out.resolve()
    if out.suffix != ".toml":
        raise ConfigError(f"--out {args.out}: expected a .toml file for the designed config")
    if config.source and out == Path(config.source).resolve():
        raise ConfigError(f"--out {args.out}: is the source config; give another file")
    from .pipeline import checked_geometry

    mandrel, centerline, notes = checked_geometry(config)
    _print_notes(notes)
    design = design_speed(config, target, mandrel=mandrel, centerline=centerline, settings=settings,
                          progress=lambda k, e: print(f"design: forward run {k}: largest error "
                                                      f"{e:.2f} deg beyond the start-up transient",
                                                      file=sys.stderr, flush=True))
    toml = write_design_config(config, design, out)
    csv = write_design_table(design, out.with_name(f"{out.stem}_design.csv"))
    runs = write_design_runs(design, out.with_name(f"{out.stem}_design_runs.csv"))
    process = write_design_process(design, out.with_name(f"{out.stem}_process.csv"))
    title = f"Designed take-up speed: {source.stem} · {config.model.kind} model"
    png = plot_design(design, out.with_name(f"{out.stem}_design.png"), title)
    v = design.speed * 1e3
    print(f"design: {design.passes} forward runs ({config.model.kind} model), the best is run "
          f"{design.best_pass}: largest error {design.max_error_deg():.2f} deg beyond "
          f"{design.judged_from:.2f} m of braid (tolerance {settings.tolerance_deg:g} deg); "
          f"take-up speed {v.min():.2f}-{v.max():.2f} mm/s in {len(v)} rows")
    print(f"design: config {toml} (results to {toml.parent / 'results' / toml.stem})")
    print(f"design: every row in {csv}; each forward run in {runs}; plot {png}")
    print(f"design: the process (speeds and the mandrel's pose per step, a robot program) in {process}")
    if not design.met:
        print(f"error: design: the achieved braid angle is {design.max_error_deg():.2f} deg from the "
              f"target, above the tolerance {settings.tolerance_deg:g} deg, {shortfall(design)}; the "
              "best speed table is written all the same", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_DONE


# ---------------------------------------------------------------- preform compare

def cmd_compare(args) -> int:
    from .studies.compare import compare, off_lines, summary_lines

    comparisons, written = compare(args.results, args.measured, args.out, plot=not args.no_plot)
    for line in summary_lines(comparisons):
        print(line)
    for line in off_lines(comparisons):
        print(f"warning: {line}", file=sys.stderr)
    print(f"compare: {', '.join(str(p) for p in written)}")
    return EXIT_DONE


def add_compare_parser(sub) -> None:
    cmp = sub.add_parser("compare", help="compare a run's results with measurements of the braid")
    cmp.add_argument("results", metavar="RESULTS", help="results folder of preform run")
    cmp.add_argument("measured", metavar="MEASURED", nargs="+",
                     help="CSV files of braid angles (arc_length_m,azimuth_deg,braid_angle_deg[,group]), "
                          "convergence lengths (braided_length_m,convergence_length_m) or yarn "
                          "coordinates (x_m,y_m,z_m[,time_s]); see docs/calibration.md")
    cmp.add_argument("--out", metavar="DIR", help="where compare.csv/.json/.png go (default: RESULTS)")
    cmp.add_argument("--no-plot", action="store_true", help="no compare.png")
    cmp.set_defaults(func=cmd_compare)


# ---------------------------------------------------------------- preform calibrate

def cmd_calibrate(args) -> int:
    from .studies.calibrate import (CALIBRATE_CSV, CALIBRATED_TOML, calibrate, parse_noise, parse_param,
                            report_lines)

    params = [parse_param(p) for p in args.param]   # bad input fails here, before a cluster starts
    noise = parse_noise(args.noise)
    report = calibrate(args.config, args.measured, params, out_dir=args.out, noise=noise,
                       scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                       progress=not args.no_progress)
    for line in report_lines(report):
        print(line)
    out = Path(report["out"])
    print(f"calibrate: table {out / CALIBRATE_CSV}; runnable config {out / CALIBRATED_TOML}; "
          f"misfit plots {out / 'plots'}; the best run against the measurements {out / 'best'}")
    return EXIT_DONE


def add_calibrate_parser(sub) -> None:
    cal = sub.add_parser("calibrate", help="fit model parameters (friction, initial position, ...) "
                                           "to measurements of the braid")
    cal.add_argument("config", metavar="CONFIG", help="case file (TOML), normally of the interaction model")
    cal.add_argument("measured", metavar="MEASURED", nargs="+",
                     help="measurement CSV files, as preform compare reads them")
    cal.add_argument("--param", action="append", required=True, metavar="KEY=LO:HI[:N]",
                     help="a parameter and its range, e.g. yarn.friction=0:0.5 (N: coarse grid points, "
                          "default 5); repeat for more")
    cal.add_argument("--noise", action="append", metavar="KIND=SIGMA",
                     help="standard deviation of one measurement: angle=DEG, convergence=M, yarn=M "
                          "(default: per kind the least RMS residual over the runs)")
    cal.add_argument("--out", metavar="DIR", help="output folder (default: results/<config>_calibration)")
    where = cal.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N", help="worker processes of the LocalCluster")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, tcp://host:port")
    cal.add_argument("--resume", action="store_true", help="skip the runs already finished")
    cal.add_argument("--no-progress", action="store_true", help="no progress lines")
    cal.set_defaults(func=cmd_calibrate)


# ---------------------------------------------------------------- parser and main

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="preform", description="Biaxial overbraiding on CAD mandrels: simulate, map, export.")
    parser.add_argument("--version", action="version", version=f"preform {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser("run", help="simulate a TOML case and write its result files")
    run.add_argument("config", metavar="CONFIG", help="case file (TOML)")
    run.add_argument("--out", metavar="DIR", help="result folder (default: [output] dir of the config)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument("--model", choices=("kinematic", "interaction"),
                     help="the model to run, in place of the config's [model] kind")
    run.add_argument("--resume", action="store_true",
                     help="continue an interrupted run from its checkpoint (<out>/checkpoint.npz), or "
                          "write the results of a finished one whose writing failed")
    run.add_argument("--force", action="store_true",
                     help="run even beyond the work limits (field faces, time steps)")
    run.add_argument("--strict", action="store_true",
                     help="exit 1 when the run's quality verdict is suspect")
    run.set_defaults(func=cmd_run)

    check = sub.add_parser("check", help="validate a case and its mandrel without simulating")
    check.add_argument("config", metavar="CONFIG", help="case file (TOML)")
    check.add_argument("--force", action="store_true", help="do not refuse work beyond the limits")
    check.set_defaults(func=cmd_check)

    sw = sub.add_parser("sweep", help="run a parameter sweep on Dask (a LocalCluster or --scheduler)")
    sw.add_argument("sweep", metavar="SWEEP.toml", help="sweep file: base config, [grid] and/or [[points]]")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="an existing Dask scheduler, tcp://host:port (default: a LocalCluster here)")
    sw.add_argument("--workers", type=int, metavar="N",
                    help="worker processes of the LocalCluster (default: one per core)")
    sw.add_argument("--resume", action="store_true", help="skip the points already finished")
    sw.add_argument("--no-progress", action="store_true", help="no progress lines")
    sw.set_defaults(func=cmd_sweep)

    des = sub.add_parser("design", help="take-up speed table for a target braid angle")
    des.add_argument("config", metavar="CONFIG", help="case file (TOML)")
    target = des.add_mutually_exclusive_group(required=True)
    target.add_argument("--target-angle", type=float, metavar="DEG", help="constant target braid angle")
    target.add_argument("--target-table", metavar="CSV",
                        help="target braid angle against centerline arc length: rows s_m,angle_deg")
    des.add_argument("--model", choices=("kinematic", "interaction"),
                     help="the forward model, in place of the config's [model] kind")
    des.add_argument("--out", metavar="FILE.toml",
                     help="the designed config (default CONFIG's folder, <name>_designed.toml), with "
                          "the table <name>_design.csv and the plot <name>_design.png beside it")
    des.add_argument("--tolerance", type=float, metavar="DEG",
                     help="largest error of the achieved braid angle beyond the start-up transient "
                          "(default 0.2 deg); exit code 1 when it is not met")
    des.set_defaults(func=cmd_design)

    mandrel = sub.add_parser("mandrel", help="mandrel tools")
    msub = mandrel.add_subparsers(dest="mandrel_command", metavar="COMMAND", required=True)
    info = msub.add_parser("info", help="watertightness, centerline, perimeter along the length")
    info.add_argument("file", metavar="FILE.stl", help="mandrel STL")
    info.add_argument("--unit", choices=("m", "mm"), default="m", help="the STL's length unit (default m)")
    info.add_argument("--centerline", default="auto", metavar="auto|CSV",
                      help="derive the centerline (auto, default) or read it from a CSV")
    info.add_argument("--csv", metavar="OUT",
                      help="also write the centerline (x,y,z,s,perimeter in the STL's unit, readable "
                           "as [mandrel] centerline) to this file; nothing is written without it")
    info.set_defaults(func=cmd_mandrel_info)
    add_compare_parser(sub)
    add_calibrate_parser(sub)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as ``warning:`` lines for people, never a raw ``file:line: Category`` dump."""
    text = str(message)
    if issubclass(category, RuntimeWarning) and "preform" not in filename:
        text = f"numerical warning from {Path(filename).parent.name}: {text} (results are checked for it)"
    print(f"warning: {text}", file=sys.stderr)


#: the commands after which the process leaves at once (see :func:`main`): every file they
#: write is complete (written atomically) before they return; ``sweep`` shuts its cluster down
#: at exit and so leaves the usual way
QUICK_EXIT = ("run", "check", "mandrel", "design", "compare")


def main(argv=None) -> int:
    """Entry point of the ``preform`` command; returns the exit code.

    Called as the command itself (``argv`` None) for one of ``QUICK_EXIT``, the process leaves
    with ``os._exit`` once the output is flushed: the interpreter's clean-up of the modules a run
    loads (numba, VTK, matplotlib, scipy) takes 0.5-1.7 s and frees nothing the system would not.
    """
    import warnings

    previous, warnings.showwarning = warnings.showwarning, _show_warning
    try:
        code = _main(argv)
    finally:
        warnings.showwarning = previous
    if argv is None and len(sys.argv) > 1 and sys.argv[1] in QUICK_EXIT:
        import os

        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code if isinstance(code, int) else EXIT_FAILED)
    return code


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP outside the time stepping (while mapping or writing): stop like Ctrl-C."""

    def __init__(self, name):
        super().__init__(name)
        self.name = name


def _stop_on_signals():
    """SIGTERM (batch schedulers, docker stop) and SIGHUP stop the command as Ctrl-C does; the
    simulation installs its own graceful handler while it steps."""
    import signal

    def handler(signum, frame):
        raise Stopped(signal.Signals(signum).name)

    previous = {}
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            try:
                previous[name] = signal.signal(getattr(signal, name), handler)
            except ValueError:   # not the main thread (a test runner's worker): leave it
                pass
    return previous


def _restore_signals(previous):
    import signal

    for name, old in previous.items():
        signal.signal(getattr(signal, name), old)


def _main(argv):
    previous = _stop_on_signals()
    try:
        return _run_command(argv)
    finally:
        _restore_signals(previous)


def _run_command(argv):
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help, --version, usage errors (argparse exits 2)
        return stop.code if isinstance(stop.code, int) else EXIT_BAD_INPUT
    args.whole_process = argv is None   # the command line of this process (the entry point)
    try:
        return args.func(args)
    except PreformError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt as stop:
        name = stop.name if isinstance(stop, Stopped) else "SIGINT"
        print(f"interrupted ({name}); a results folder keeps its checkpoint: --resume finishes it",
              file=sys.stderr)
        return SIGNAL_EXIT.get(name, EXIT_INTERRUPTED)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
