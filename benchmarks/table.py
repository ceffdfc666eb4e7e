"""Run the benchmarks and write their figures as one table in ``benchmarks/README.md``.

``python benchmarks/table.py [--repeat 3] [--quick] [--dry-run]``

Each row runs one benchmark script of this folder (or times one ``preform`` command) in its own
processes, ``--repeat`` times where the script repeats, and takes the median its output prints.
The table states the machine it was measured on (CPU, cores, load, Python, numba, NumPy, SciPy)
and replaces the one between the ``table:start`` / ``table:end`` markers of the README.
``--quick`` leaves out the slow rows (big meshes, the interaction model); ``--dry-run`` prints
the table instead of writing it; ``--log FILE`` keeps every benchmark's printed output.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "benchmarks" / "README.md"
START, END = "<!-- table:start -->", "<!-- table:end -->"


def _run(argv, log, env=None):
    """Run ``argv`` from the repository root; returns (stdout, wall seconds). Fails loudly."""
    t0 = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, **(env or {})})
    wall = time.perf_counter() - t0
    log.append(f"$ {' '.join(argv)}  ({wall:.1f} s, exit {done.returncode})\n{done.stdout}{done.stderr}")
    if done.returncode != 0:
        sys.exit(f"table: {' '.join(argv)} failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return done.stdout, wall


def _find(pattern, text, what):
    m = re.search(pattern, text, re.MULTILINE)
    if m is None:
        sys.exit(f"table: no figure for {what} in the benchmark's output (pattern {pattern!r})")
    return m


def _bench(name):
    return [sys.executable, str(ROOT / "benchmarks" / name)]


def _cli(*args):
    return [sys.executable, "-m", "preform.cli", *args]


def pipeline_rows(repeat, log):
    """``preform run examples/case_a.toml`` (kinematic, 2 m, 35 files): first run and warm."""
    rows = []
    for fresh in (True, False):
        out, _ = _run(_bench("bench_pipeline.py") + ["--command", "--repeat", str(repeat)]
                      + (["--fresh"] if fresh else []), log)
        m = _find(r"^median of \d+(?: fresh)? runs: ([\d.]+) s wall, ([\d.]+) s CPU \(summary [\d.]+ s: (.*)\)$",
                  out, "bench_pipeline")
        what = ("`preform run examples/case_a.toml`, first run (empty numba and preform caches)"
                if fresh else "`preform run examples/case_a.toml`, warm caches")
        rows.append((what, f"{float(m[1]):.1f} s", f"{float(m[2]):.1f} s CPU; stages (s): {m[3].replace('_', ' ')}",
                     f"`bench_pipeline.py --command{' --fresh' if fresh else ''}`, median of {repeat}"))
    return rows


def kinematic_row(repeat, log):
    out, _ = _run(_bench("bench_kinematic.py") + ["--repeat", str(max(repeat, 3))], log)
    m = _find(r"^median wall ([\d.]+) s", out, "bench_kinematic")
    us = statistics.median(float(x) for x in re.findall(r"([\d.]+) us per fell-point update", out))
    return ("kinematic simulation of case A, 144 carriers, 1 m braided (compiled)",
            f"{float(m[1]):.2f} s", f"{us:.2f} us per fell-point update",
            f"`bench_kinematic.py`, median of {max(repeat, 3)}")


def command_rows(repeat, log):
    """Commands a user runs before a run, timed whole (start-up included), warm caches."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = [("`preform check examples/case_a.toml`", _cli("check", "examples/case_a.toml")),
                 ("`preform check examples/case_b.toml`", _cli("check", "examples/case_b.toml")),
                 ("`preform mandrel info mandrels/case_b.stl`",
                  _cli("mandrel", "info", "mandrels/case_b.stl"))]
        for what, argv in cases:
            _run(argv, log)                                     # fills the caches
            walls = [_run(argv, log, env={"TMPDIR": tmp})[1] for _ in range(repeat)]
            rows.append((what, f"{statistics.median(walls):.2f} s", "warm caches, whole command",
                         f"timed by `table.py`, median of {repeat}"))
    return rows


def linalg_row(log):
    out, _ = _run(_bench("bench_linalg.py"), log)
    n = _find(r"^(\d+) unknowns", out, "bench_linalg")
    lines = re.findall(r"^\s+(\S.*?)\s{2,}([\d.]+) ms\s+relative residual", out, re.MULTILINE)
    detail = "; ".join(f"{name.strip()} {ms} ms" for name, ms in lines)
    return (f"one Newton system of a case A zone ({int(n[1]):,} unknowns), factorisation + solve",
            f"{min(float(ms) for _, ms in lines):.0f} ms", detail, "`bench_linalg.py`, median of 7")


def mesh_rows(log):
    out, _ = _run(_bench("bench_meshes.py"), log)
    rows = []
    names = {"well": "well-shaped cylinder", "sliver": "CAD sliver cylinder", "fine": "fine cylinder"}
    for kind, faces, stages in re.findall(r"^(well|sliver|fine)\s+([\d,]+) faces \(medians of \d+\): (.*?) \|",
                                          out, re.MULTILINE):
        figures = dict(re.findall(r"([\w+]+) ([\d.]+)", stages))
        if "total" not in figures:
            sys.exit(f"table: no total for {kind} in bench_meshes' output: {stages}")
        detail = ", ".join(f"{k} {figures[k]}" for k in figures
                           if k not in ("total", "cpu_total", "peak_rss_gb", "angle_deg"))
        detail += f" s; {figures.get('cpu_total', '?')} s CPU, peak memory {figures.get('peak_rss_gb', '?')} GB"
        rows.append((f"{names[kind]}, {faces} faces: 16 carriers, 1 m, STL to files (Python API, no disk cache)",
                     f"{float(figures['total']):.1f} s", detail, "`bench_meshes.py`, one run each"))
    m = _find(r"^mandrel info on ([\d,]+) faces: ([\d.]+) s", out, "bench_meshes mandrel info")
    rows.append((f"`preform mandrel info` on a {m[1]}-face STL", f"{float(m[2]):.1f} s",
                 "whole command", "`bench_meshes.py`"))
    return rows


def interaction_row(log):
    """The interaction model end to end: case B (96 carriers, guide ring, 1.2 m, 20 snapshots)."""
    with tempfile.TemporaryDirectory() as tmp:
        argv = _cli("run", "examples/case_b.toml", "--model", "interaction", "--out",
                    str(Path(tmp) / "b"), "--no-progress", "--force")
        out, wall = _run(argv, log)
        steps = _find(r"(\d+) steps", out, "preform run case B steps")
    return ("`preform run examples/case_b.toml --model interaction` (96 carriers, guide ring, 1.2 m)",
            f"{wall:.0f} s", f"{steps[1]} steps, 20 snapshots, fields and files", "timed by `table.py`, one run")


def machine():
    """CPU model, cores, load, Python and the numerical libraries, as one line."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = []
    for mod in ("numba", "numpy", "scipy"):
        try:
            versions.append(f"{mod} {__import__(mod).__version__}")
        except ImportError:
            versions.append(f"{mod} not installed")
    try:
        import cvxopt  # noqa: F401
        cholmod = "with CHOLMOD (cvxopt)"
    except ImportError:
        cholmod = "without the `cholmod` extra (SciPy's SuperLU)"
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{cpu}, {os.cpu_count()} cores; {platform.system()} {platform.release()}; "
            f"load average {load:.1f} at the start; Python {platform.python_version()}, "
            f"{', '.join(versions)}; {cholmod}")


def table(rows, machine_line, date):
    lines = [START, "",
             f"Measured {date} on: {machine_line}.", "",
             "| what | median | detail | how |", "| --- | --- | --- | --- |"]
    lines += [f"| {what} | {fig} | {detail} | {how} |" for what, fig, detail, how in rows]
    lines += ["", END]
    return "\n".join(lines)


def write(text):
    old = README.read_text(encoding="utf-8") if README.exists() else f"# Benchmarks\n\n{START}\n{END}\n"
    if START not in old or END not in old:
        sys.exit(f"table: {README} has no {START} ... {END} markers to replace")
    head, rest = old.split(START, 1)
    tail = rest.split(END, 1)[1]
    tmp = README.with_name(README.name + ".tmp")
    tmp.write_text(head + text + tail, encoding="utf-8")
    os.replace(tmp, README)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="runs per figure where a benchmark repeats")
    ap.add_argument("--quick", action="store_true", help="leave out big meshes and the interaction model")
    ap.add_argument("--dry-run", action="store_true", help="print the table, do not write the README")
    ap.add_argument("--log", default=None, help="keep every benchmark's output in this file")
    args = ap.parse_args(argv)
    log = []
    machine_line = machine()
    date = datetime.date.today().isoformat()
    rows = []
    try:
        rows += pipeline_rows(args.repeat, log)
        rows.append(kinematic_row(args.repeat, log))
        rows += command_rows(args.repeat, log)
        rows.append(linalg_row(log))
        if not args.quick:
            rows += mesh_rows(log)
            rows.append(interaction_row(log))
    finally:
        if args.log:
            Path(args.log).write_text("\n".join(log), encoding="utf-8")
    load_end = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    text = table(rows, f"{machine_line}; load average {load_end:.1f} at the end", date)
    if args.dry_run:
        print(text)
    else:
        write(text)
        print(f"wrote the table ({len(rows)} rows) to {README.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
