"""A finished run against measurements of the real braid (``preform compare``).

Three kinds of measurement are read from CSV files, each recognised by its header:

``angle``
    braid angles on the braided part: ``arc_length_m, azimuth_deg, braid_angle_deg`` and an
    optional ``group`` (``warp`` / ``weft``, or 0 / 1). ``arc_length_m`` is the centerline arc
    length from the mandrel's tip, ``azimuth_deg`` the angle round the centerline in its own
    frame ``(N, B)`` at that section (``atan2(r.B, r.N)``, -180..180), as the unrolled map
    ``plots/surface_map.png`` draws them. The simulated value is the field of the face of the
    run's field mesh (``surface.vtu``) that holds the point in the unrolled ``(s, azimuth)``
    plane (:func:`preform.io.maps.unrolled_coordinates`): ``braid_angle_deg`` (the mean of the
    groups present), or ``braid_angle_warp_deg`` / ``braid_angle_weft_deg`` when ``group`` is
    given. The field is constant on a face (the mean over the yarn pieces in it), so the sample
    is the value written in the file, not a value interpolated between faces. On a run of
    several ``[[layer]]`` s an optional ``layer`` column (from 1, the layer on the mandrel)
    names the layer measured; without it the outermost, the one a picture of the part sees.
``convergence``
    convergence lengths during the run: ``braided_length_m, convergence_length_m``. The
    simulated value is ``history.csv``'s ``convergence_length_mean_m`` (the mean over the yarns
    of the fell point's axial distance to the supply plane) interpolated linearly in
    ``braided_length_m``; of rows with the same braided length (the start, before the mandrel
    moves the braid on) the last is used; within one time step's braided length beyond the
    run's first or last row, that row's value. An optional ``layer`` column takes
    ``layer<k>/history.csv`` of a run of several layers (without it the first layer's).
``yarn``
    yarn coordinates in the convergence zone: ``x_m, y_m, z_m`` in the machine frame and an
    optional ``time_s``. The deviation is the distance from the point to the nearest segment
    of the free yarns (fell point to supply point, through the crossings and the ring point) of
    the snapshot (``convergence/step_NNNN.vtp``) nearest in time, the last one without
    ``time_s``: the paper's "average deviation" of photogrammetry against the model.

Differences are simulated minus measured (the yarn deviation is a distance, never negative).
A point the run cannot be sampled at (off the field mesh, on a face no yarn reached, outside
the run's braided length or snapshot times) is kept in ``compare.csv`` with its reason in
``status``, counted as ``off`` in ``compare.json`` and left out of the statistics; it is never
dropped silently.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import MandrelConfig
from ..errors import PreformError
from ..io.atomic import atomic_path, atomic_write_text, safe_folder

COMPARE_CSV = "compare.csv"
COMPARE_JSON = "compare.json"
COMPARE_PNG = "compare.png"

ANGLE, CONVERGENCE, YARN = "angle", "convergence", "yarn"
KINDS = (ANGLE, CONVERGENCE, YARN)
#: required columns of each kind
COLUMNS = {ANGLE: ("arc_length_m", "azimuth_deg", "braid_angle_deg"),
           CONVERGENCE: ("braided_length_m", "convergence_length_m"),
           YARN: ("x_m", "y_m", "z_m")}
#: optional columns of each kind
OPTIONAL = {ANGLE: ("group", "layer"), CONVERGENCE: ("layer",), YARN: ("time_s",)}
#: what each kind's difference is, and its unit, for messages and the JSON
QUANTITY = {ANGLE: ("braid angle", "deg"), CONVERGENCE: ("convergence length", "m"),
            YARN: ("yarn deviation", "m")}
GROUPS = {"warp": 0, "weft": 1, "0": 0, "1": 1}
OK = "ok"


class MeasurementError(PreformError):
    """A measurement file cannot be read or does not fit the run (exit code 2)."""


@dataclass(frozen=True)
class CompareSettings:
    """How points are located on the run."""

    #: a point inside a face's unrolled triangle up to this barycentric margin still counts as
    #: in it: a point on an edge between two faces falls in one of them despite round-off
    inside_tolerance: float = 1e-9
    #: a value this many times the run's own scale while a thousandth of it fits: mm taken for m
    mm_factor: float = 20.0
    #: a measurement time further than this fraction of the snapshots' spacing outside their span
    #: has no snapshot near it
    time_margin: float = 0.5


SETTINGS = CompareSettings()


# ------------------------------------------------------------------------------ measurements

@dataclass(frozen=True)
class Measurements:
    """One file's points: kind, the columns (name -> float array), the file's line of each
    point (for messages), ``group`` (-1: not given, 0 warp, 1 weft) for angles and ``layer``
    (0: not given, else the layer from 1) for angles and convergence lengths."""

    kind: str
    path: Path
    values: dict
    lines: np.ndarray
    group: np.ndarray | None = None
    layer: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.lines)


def _kind_of(path: Path, header: list[str]) -> str:
    names = set(header)
    for kind in KINDS:
        if set(COLUMNS[kind]) <= names:
            return kind
    best = max(KINDS, key=lambda k: len(set(COLUMNS[k]) & names))
    have = set(COLUMNS[best]) & names
    expected = "; ".join(f"{k}: {', '.join(COLUMNS[k] + OPTIONAL[k])}" for k in KINDS)
    if have:
        missing = [c for c in COLUMNS[best] if c not in names]
        raise MeasurementError(f"{path}: column(s) {', '.join(missing)} missing: a file of "
                               f"{QUANTITY[best][0]}s needs {', '.join(COLUMNS[best])} (it has "
                               f"{', '.join(header)})")
    mm = [c for c in header if c.endswith("_mm")]
    hint = (f" (column(s) {', '.join(mm)} are in mm: give metres, named *_m)" if mm else "")
    raise MeasurementError(f"{path}: the header {', '.join(header) or '(empty)'} names no kind of "
                           f"measurement{hint}; expected the columns of one of: {expected} "
                           "(optional columns last)")


def read_measurements(path) -> Measurements:
    """Read one measurement CSV (see the module docstring); lines starting with ``#`` and blank
    lines are skipped. Raises MeasurementError naming the file, line and column of a bad value."""
    path = Path(path).expanduser()
    if path.is_dir():
        raise MeasurementError(f"measurement file {path} is a folder: give a .csv file")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except FileNotFoundError:
        raise MeasurementError(f"measurement file {path} not found") from None
    except OSError as err:
        raise MeasurementError(f"measurement file {path} cannot be read: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise MeasurementError(f"measurement file {path}: not UTF-8 text; save it as UTF-8 CSV") from None
    rows = [(n, row) for n, row in enumerate(csv.reader(io.StringIO(text)), start=1)
            if row and any(c.strip() for c in row) and not row[0].lstrip().startswith("#")]
    if not rows:
        raise MeasurementError(f"measurement file {path} is empty: expected a header line and rows")
    header = [c.strip().lower() for c in rows[0][1]]
    kind = _kind_of(path, header)
    wanted = COLUMNS[kind] + tuple(c for c in OPTIONAL[kind] if c in header)
    index = {c: header.index(c) for c in wanted}
    data = {c: [] for c in wanted}
    lines = []
    for n, row in rows[1:]:
        if len(row) < len(header):
            raise MeasurementError(f"{path} line {n}: {len(row)} values, the header has {len(header)}")
        for c in wanted:
            cell = row[index[c]].strip()
            if c == "group":
                if cell.lower() not in GROUPS:
                    raise MeasurementError(f"{path} line {n}: group = {cell!r}: expected warp or "
                                           "weft (or 0, 1)")
                data[c].append(GROUPS[cell.lower()])
                continue
            if c == "layer":   # a whole number, as a spreadsheet may write it (2.0)
                try:
                    k = float(cell)
                except ValueError:
                    k = 0.0
                if not (math.isfinite(k) and k.is_integer() and k >= 1):
                    raise MeasurementError(f"{path} line {n}: layer = {cell!r}: expected the "
                                           "layer's number, 1 for the one on the mandrel")
                data[c].append(int(k))
                continue
            try:
                value = float(cell)
            except ValueError:
                raise MeasurementError(f"{path} line {n}: {c} = {cell!r}: expected a number") from None
            if not math.isfinite(value):
                raise MeasurementError(f"{path} line {n}: {c} = {cell}: expected a finite number")
            data[c].append(value)
        lines.append(n)
    if not lines:
        raise MeasurementError(f"measurement file {path} has a header and no rows")
    group = np.asarray(data.pop("group"), dtype=np.int64) if "group" in data else None
    if kind == ANGLE and group is None:
        group = np.full(len(lines), -1, dtype=np.int64)
    layer = np.asarray(data.pop("layer"), dtype=np.int64) if "layer" in data else None
    if kind in (ANGLE, CONVERGENCE) and layer is None:
        layer = np.zeros(len(lines), dtype=np.int64)
    values = {c: np.asarray(v, dtype=np.float64) for c, v in data.items()}
    _check_values(path, kind, values, np.asarray(lines))
    return Measurements(kind=kind, path=path, values=values, lines=np.asarray(lines), group=group,
                        layer=layer)


def _check_values(path, kind, values, lines) -> None:
    """Refuse values no measurement of this kind can have (the run-dependent unit checks are
    in :func:`check_units`)."""
    def bad(column, mask, expected):
        k = int(np.flatnonzero(mask)[0])
        raise MeasurementError(f"{path} line {lines[k]}: {column} = {values[column][k]:g}: {expected}")

    if kind == ANGLE:
        a = values["braid_angle_deg"]
        if np.any((a <= 0) | (a >= 90)):
            bad("braid_angle_deg", (a <= 0) | (a >= 90), "expected a braid angle between 0 and 90 deg")
        if len(a) >= 3 and a.max() <= 0.5 * math.pi:
            raise MeasurementError(f"{path}: braid_angle_deg at most {a.max():g}: the angles look "
                                   "like radians; give degrees")
        phi = values["azimuth_deg"]
        if np.any(np.abs(phi) > 360):
            bad("azimuth_deg", np.abs(phi) > 360, "expected degrees, -180..180 (or 0..360)")
    if kind == CONVERGENCE:
        for c in COLUMNS[CONVERGENCE]:
            if np.any(values[c] < 0):
                bad(c, values[c] < 0, "expected a length >= 0 m")
    if kind == YARN and "time_s" in values and np.any(values["time_s"] < 0):
        bad("time_s", values["time_s"] < 0, "expected a time >= 0 s from the run's start")


def _looks_like_mm(values, scale, settings) -> bool:
    top = float(np.max(np.abs(values))) if len(values) else 0.0
    return scale > 0 and top > settings.mm_factor * scale and top / 1000.0 <= 2.0 * scale


def check_units(meas: Measurements, run: "RunData", settings: CompareSettings = SETTINGS) -> None:
    """Refuse lengths that look like mm against the run's own sizes (the part's length, the
    run's braided and convergence lengths, the zone's extent)."""
    if meas.kind == ANGLE:
        checks = [("arc_length_m", run.centerline_length, "the part's centerline is")]
    elif meas.kind == CONVERGENCE:
        checks = [("braided_length_m", run.braided_length, "the run braided"),
                  ("convergence_length_m", run.convergence_scale, "the run's convergence length reaches")]
    else:
        checks = [(c, run.zone_extent, "the run's convergence zone spans") for c in COLUMNS[YARN]]
    for column, scale, what in checks:
        if _looks_like_mm(meas.values[column], scale, settings):
            top = float(np.max(np.abs(meas.values[column])))
            raise MeasurementError(f"{meas.path}: {column} up to {top:g} while {what} {scale:.3g} m: "
                                   "the values look like mm; give metres (divide by 1000)")


# ------------------------------------------------------------------------------ the run

@dataclass
class RunData:
    """What a results folder offers to sample (read by :func:`load_run`)."""

    folder: Path
    summary: dict
    centerline: object = None
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    cell_data: dict = field(default_factory=dict)
    history: dict = field(default_factory=dict)
    #: layer (from 2) -> its history (``layer<k>/history.csv``); ``history`` is the first's
    layer_histories: dict = field(default_factory=dict)
    snapshot_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    snapshot_files: list = field(default_factory=list)
    _polys: np.ndarray | None = None
    _snapshots: dict = field(default_factory=dict)

    @property
    def n_layers(self) -> int:
        """The layers braided: 1, or the count of ``layer<k>_braid_angle_deg`` fields."""
        k = 1
        while f"layer{k + 1}_braid_angle_deg" in self.cell_data or (k + 1) in self.layer_histories:
            k += 1
        return k

    def history_of(self, layer: int) -> dict:
        return self.history if layer <= 1 else self.layer_histories.get(layer, {})

    @property
    def centerline_length(self) -> float:
        return float(self.centerline.length) if self.centerline is not None else 0.0

    @property
    def braided_length(self) -> float:
        L = self.history.get("braided_length_m")
        return float(np.max(L)) if L is not None and len(L) else 0.0

    @property
    def convergence_scale(self) -> float:
        H = self.history.get("convergence_length_mean_m")
        return float(np.max(H)) if H is not None and len(H) else 0.0

    @property
    def zone_extent(self) -> float:
        if not self.snapshot_files:
            return 0.0
        pts = self.snapshot(len(self.snapshot_files) - 1)[0]
        return float(np.linalg.norm(np.ptp(pts, axis=0))) if len(pts) else 0.0

    def unrolled(self) -> np.ndarray:
        """(nf, 3, 2) the field faces' corners in the unrolled (s, azimuth) plane."""
        if self._polys is None:
            from ..io.maps import unrolled_coordinates

            self._polys = unrolled_coordinates(self.vertices, self.faces, self.centerline)
        return self._polys

    def snapshot(self, k: int):
        """(points (m, 3), segments (n, 2) point ids) of snapshot k, machine frame."""
        if k not in self._snapshots:
            self._snapshots[k] = _read_segments(self.snapshot_files[k])
        return self._snapshots[k]


def _need(path: Path, what: str, kind: str) -> Path:
    if not path.is_file():
        raise MeasurementError(f"{path.parent}: no {path.name}, which {what}: the {kind} measurements "
                               "cannot be compared (is this a complete results folder of preform run?)")
    return path


def _run_centerline(folder: Path, summary: dict):
    """The centerline of the run (the mandrel's, as the fields were mapped on), rebuilt from the
    inputs echoed in summary.json."""
    m = (summary.get("inputs") or {}).get("mandrel") or {}
    if not m.get("stl"):
        raise MeasurementError(f"{folder / 'summary.json'}: no mandrel in its inputs: cannot place "
                               "arc lengths and azimuths on the part")
    centerline = m.get("centerline") or "auto"
    roll = m.get("roll_reference")
    unit = m.get("stl_unit") or "m"
    try:
        if centerline != "auto":
            from ..geometry import read_centerline_csv

            return read_centerline_csv(Path(centerline), unit=unit,
                                       roll_reference=None if roll is None else tuple(roll))
        from ..pipeline import load_geometry

        config = type("MandrelOnly", (), {"mandrel": MandrelConfig(
            stl=Path(m["stl"]), stl_unit=unit, centerline="auto",
            roll_reference=None if roll is None else tuple(roll), body=m.get("body"))})()
        return load_geometry(config)[1]
    except PreformError as err:
        raise MeasurementError(f"{folder}: the run's mandrel is needed to place arc lengths and "
                               f"azimuths on the part, and it cannot be read: {err}") from None


def load_run(folder, kinds=KINDS) -> RunData:
    """Read what ``kinds`` need from a results folder of ``preform run``."""
    folder = Path(folder).expanduser().resolve()
    if not folder.is_dir():
        raise MeasurementError(f"results folder {folder} not found")
    summary_path = folder / "summary.json"
    if not summary_path.is_file():
        raise MeasurementError(f"{folder}: no summary.json: not a complete results folder of "
                               "preform run (an interrupted run writes it once finished with --resume)")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise MeasurementError(f"{summary_path} cannot be read: {err}") from None
    run = RunData(folder=folder, summary=summary)
    if ANGLE in kinds:
        import meshio

        vtu = _need(folder / "surface.vtu", "holds the surface fields", "braid angle")
        mesh = meshio.read(vtu)
        run.vertices = np.asarray(mesh.points, dtype=np.float64)
        run.faces = np.asarray(mesh.cells_dict["triangle"], dtype=np.int64)
        run.cell_data = {name: np.asarray(values[0]) for name, values in mesh.cell_data.items()}
        missing = [k for k in ("braid_angle_deg", "braid_angle_warp_deg", "braid_angle_weft_deg",
                               "reached_warp", "reached_weft") if k not in run.cell_data]
        if missing:
            raise MeasurementError(f"{vtu}: no cell array {', '.join(missing)}: not the surface "
                                   "fields of a preform run")
        run.centerline = _run_centerline(folder, summary)
    if CONVERGENCE in kinds:
        hist = _need(folder / "history.csv", "holds the convergence lengths", "convergence length")
        run.history = _read_history(hist)
        k = 2
        while (folder / f"layer{k}" / "history.csv").is_file():
            run.layer_histories[k] = _read_history(folder / f"layer{k}" / "history.csv")
            k += 1
    if YARN in kinds:
        pvd = _need(folder / "convergence.pvd", "lists the convergence-zone snapshots", "yarn")
        times, files = _read_pvd(pvd)
        if not files:
            raise MeasurementError(f"{pvd}: the run wrote no snapshots ([output] snapshots = 0): "
                                   "yarn coordinates cannot be compared; run with snapshots")
        run.snapshot_times, run.snapshot_files = times, files
    return run


def _read_history(path: Path) -> dict:
    try:
        table = np.atleast_1d(np.genfromtxt(path, delimiter=",", names=True))
        return {name: np.asarray(table[name], dtype=np.float64) for name in table.dtype.names}
    except (OSError, ValueError, TypeError) as err:
        raise MeasurementError(f"{path} cannot be read as a history table: {err}") from None


def _read_pvd(path: Path):
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(path.read_text(encoding="utf-8"))
    except (OSError, ET.ParseError) as err:
        raise MeasurementError(f"{path} cannot be read: {err}") from None
    entries = []
    for ds in root.iter("DataSet"):
        f = (path.parent / ds.get("file", "")).resolve()
        if not f.is_relative_to(path.parent.resolve()):
            raise MeasurementError(f"{path}: a snapshot file {ds.get('file')} outside the results folder")
        entries.append((float(ds.get("timestep", "nan")), f))
    entries.sort(key=lambda e: e[0])
    return np.array([t for t, _ in entries]), [f for _, f in entries]


def _read_segments(path: Path):
    """(points, segments) of a snapshot .vtp: its points and its line cells as point-id pairs."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    if not Path(path).is_file():
        raise MeasurementError(f"snapshot {path} listed in convergence.pvd is missing")
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    poly = reader.GetOutput()
    if poly is None or poly.GetPoints() is None:
        return np.zeros((0, 3)), np.zeros((0, 2), dtype=np.int64)
    points = vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    lines = poly.GetLines()
    conn = vtk_to_numpy(lines.GetConnectivityArray()).astype(np.int64)
    offs = vtk_to_numpy(lines.GetOffsetsArray()).astype(np.int64)
    segs = [conn[a:b] for a, b in zip(offs[:-1], offs[1:])]
    pairs = [np.column_stack([c[:-1], c[1:]]) for c in segs if len(c) >= 2]
    return points, (np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64))


# ------------------------------------------------------------------------------ sampling

def locate_faces(polys, s, phi, tolerance=SETTINGS.inside_tolerance) -> np.ndarray:
    """Per point (s m, phi deg), the face whose unrolled triangle holds it, -1 where none does.

    polys: (nf, 3, 2) from :func:`preform.io.maps.unrolled_coordinates`. The point's azimuth is
    taken within 180 deg of each candidate face's (the faces on the seam keep their shape there);
    of faces sharing the point (an edge, a vertex) the one it lies deepest in is taken.
    """
    s, phi = np.asarray(s, dtype=float), np.asarray(phi, dtype=float)
    out = np.full(len(s), -1, dtype=np.int64)
    if len(polys) == 0:
        return out
    smin, smax = polys[..., 0].min(axis=1), polys[..., 0].max(axis=1)
    centre = polys[..., 1].mean(axis=1)
    a, b, c = polys[:, 0], polys[:, 1], polys[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    live = np.abs(det) > 0
    for i in range(len(s)):
        f = np.flatnonzero(live & (smin <= s[i]) & (smax >= s[i]))
        if not len(f):
            continue
        p = centre[f] + (phi[i] - centre[f] + 180.0) % 360.0 - 180.0
        dx, dy = s[i] - a[f, 0], p - a[f, 1]
        l1 = (dx * (c[f, 1] - a[f, 1]) - (c[f, 0] - a[f, 0]) * dy) / det[f]
        l2 = ((b[f, 0] - a[f, 0]) * dy - dx * (b[f, 1] - a[f, 1])) / det[f]
        depth = np.minimum(np.minimum(l1, l2), 1.0 - l1 - l2)
        k = int(np.argmax(depth))
        if depth[k] >= -tolerance:
            out[i] = f[k]
    return out


@dataclass
class Comparison:
    """One measurement file against the run: per point the simulated value, the difference
    (NaN where ``status`` is not "ok") and the status."""

    meas: Measurements
    simulated: np.ndarray
    difference: np.ndarray
    status: list
    extra: dict = field(default_factory=dict)   # column -> per point values for compare.csv

    @property
    def ok(self) -> np.ndarray:
        return np.array([s == OK for s in self.status], dtype=bool)


def compare_angles(meas: Measurements, run: RunData) -> Comparison:
    s, phi = meas.values["arc_length_m"], meas.values["azimuth_deg"]
    phi = (phi + 180.0) % 360.0 - 180.0
    face = locate_faces(run.unrolled(), s, phi)
    data = run.cell_data
    n = len(meas)
    n_layers = run.n_layers
    layers = np.where(meas.layer > 0, meas.layer, n_layers)   # unsaid: the outermost, as seen
    _check_layers(meas, n_layers)
    sim = np.full(n, np.nan)
    status = []
    for i in range(n):
        f, g = int(face[i]), int(meas.group[i])
        prefix = f"layer{layers[i]}_" if n_layers > 1 else ""
        if f < 0:
            status.append("off the part (no face of the field mesh at this arc length and azimuth)")
            continue
        if g < 0:
            reached = any(data[prefix + k][f] > 0 for k in ("reached_warp", "reached_weft"))
            value = float(data[prefix + "braid_angle_deg"][f])
        else:
            name = ("warp", "weft")[g]
            reached = data[f"{prefix}reached_{name}"][f] > 0
            value = float(data[f"{prefix}braid_angle_{name}_deg"][f])
        if not reached or value <= 0:
            status.append("off the braid (no yarn reached this face" + ("" if g < 0 else f" in the {name} group") + ")")
            continue
        sim[i] = value
        status.append(OK)
    return Comparison(meas, sim, sim - meas.values["braid_angle_deg"], status,
                      extra={"face": face, "layer": layers if n_layers > 1 else None})


def _check_layers(meas: Measurements, n_layers: int) -> None:
    bad = np.flatnonzero(meas.layer > n_layers)
    if len(bad):
        i = int(bad[0])
        raise MeasurementError(f"{meas.path} line {meas.lines[i]}: layer = {meas.layer[i]}: the run "
                               f"braided {n_layers} layer{'s' if n_layers > 1 else ''}")


def history_curve(run: RunData, layer: int = 1):
    """(braided length, convergence length) of ``history.csv`` (layer k's
    ``layer<k>/history.csv``) as the curve sampled: rows whose braided length repeats the one
    before are replaced by the last of them."""
    history = run.history_of(layer)
    L = history["braided_length_m"]
    H = history["convergence_length_mean_m"]
    keep = np.ones(len(L), dtype=bool)
    keep[:-1] = L[1:] > L[:-1]
    return L[keep], H[keep]


def compare_convergence(meas: Measurements, run: RunData) -> Comparison:
    _check_layers(meas, run.n_layers)
    x = meas.values["braided_length_m"]
    layers = np.maximum(meas.layer, 1)                        # unsaid: the first layer
    sim = np.full(len(x), np.nan)
    status = [OK] * len(x)
    for k in np.unique(layers):
        rows = np.flatnonzero(layers == k)
        L, H = history_curve(run, int(k))
        if len(L):
            sim[rows] = np.interp(x[rows], L, H)
        # a run ends on the step that passes braid_length, one run a little before another:
        # within one step of its ends the end value stands
        step = float(np.mean(np.diff(L))) if len(L) > 1 else 0.0
        for i in rows:
            if not len(L) or x[i] < L[0] - step or x[i] > L[-1] + step:
                span = f"{L[0]:.4g}-{L[-1]:.4g} m" if len(L) else "none"
                status[i] = f"off the run (braided length outside the run's {span})"
                sim[i] = np.nan
    return Comparison(meas, sim, sim - meas.values["convergence_length_m"], status,
                      extra={"layer": layers if run.n_layers > 1 else None})


def point_segment_distance(points, a, b) -> tuple[np.ndarray, np.ndarray]:
    """(distance (n,), nearest segment index (n,)) of each point to segments a[k]-b[k]."""
    points = np.asarray(points, dtype=float)
    d = b - a
    dd = np.einsum("kj,kj->k", d, d)
    out = np.full(len(points), np.inf)
    idx = np.full(len(points), -1, dtype=np.int64)
    for i, p in enumerate(points):
        t = np.where(dd > 0, np.einsum("kj,kj->k", p - a, d) / np.where(dd > 0, dd, 1.0), 0.0)
        t = np.clip(t, 0.0, 1.0)
        r = np.linalg.norm(a + t[:, None] * d - p, axis=1)
        if len(r):
            k = int(np.argmin(r))
            out[i], idx[i] = r[k], k
    return out, idx


def compare_yarns(meas: Measurements, run: RunData, settings: CompareSettings = SETTINGS) -> Comparison:
    P = np.column_stack([meas.values[c] for c in COLUMNS[YARN]])
    times = run.snapshot_times
    n = len(meas)
    if "time_s" in meas.values:
        t = meas.values["time_s"]
        which = np.argmin(np.abs(t[:, None] - times[None, :]), axis=1)
        spacing = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
        margin = settings.time_margin * spacing
        far = (t < times[0] - margin) | (t > times[-1] + margin)
    else:
        which = np.full(n, len(times) - 1)
        far = np.zeros(n, dtype=bool)
    dist = np.full(n, np.nan)
    status = [OK] * n
    for k in np.unique(which):
        rows = np.flatnonzero(which == k)
        pts, segs = run.snapshot(int(k))
        if not len(segs):
            for i in rows:
                status[i] = "off the run (the snapshot has no free yarns)"
            continue
        dist[rows] = point_segment_distance(P[rows], pts[segs[:, 0]], pts[segs[:, 1]])[0]
    for i in np.flatnonzero(far):
        status[i] = (f"off the run (time {meas.values['time_s'][i]:g} s, snapshots from "
                     f"{times[0]:g} to {times[-1]:g} s)")
        dist[i] = np.nan
    return Comparison(meas, dist, dist, status,
                      extra={"snapshot_time_s": times[which]})


def compare_one(meas: Measurements, run: RunData, settings: CompareSettings = SETTINGS) -> Comparison:
    check_units(meas, run, settings)
    if meas.kind == ANGLE:
        return compare_angles(meas, run)
    if meas.kind == CONVERGENCE:
        return compare_convergence(meas, run)
    return compare_yarns(meas, run, settings)


def compare_run(results, measurements, settings: CompareSettings = SETTINGS) -> list[Comparison]:
    """Every measurement file (paths or :class:`Measurements`) against the results folder."""
    meas = [m if isinstance(m, Measurements) else read_measurements(m) for m in measurements]
    if not meas:
        raise MeasurementError("no measurement files given")
    run = results if isinstance(results, RunData) else load_run(results, {m.kind for m in meas})
    return [compare_one(m, run, settings) for m in meas]


# ------------------------------------------------------------------------------ figures, files

def statistics(comparisons) -> dict:
    """Per kind: count (points compared), off (points that could not be), mean, rms and max
    (largest magnitude) of the difference, in the kind's unit; None where nothing was compared."""
    out = {}
    for kind in KINDS:
        these = [c for c in comparisons if c.meas.kind == kind]
        if not these:
            continue
        d = np.concatenate([c.difference[c.ok] for c in these])
        off = int(sum((~c.ok).sum() for c in these))
        name, unit = QUANTITY[kind]
        entry = {"quantity": name, "unit": unit, "count": int(len(d)), "off": off,
                 "files": [str(c.meas.path) for c in these]}
        if len(d):
            entry.update(mean=float(d.mean()), rms=float(np.sqrt(np.mean(d * d))),
                         max=float(np.abs(d).max()))
        else:
            entry.update(mean=None, rms=None, max=None)
        out[kind] = entry
    return out


def _fmt(kind, value) -> str:
    if value is None:
        return "n/a"
    return f"{value:.3g} deg" if kind == ANGLE else f"{value * 1e3:.3g} mm"


def summary_lines(comparisons) -> list[str]:
    """What ``preform compare`` prints: a line per kind, then the points that were off."""
    lines = []
    for kind, e in statistics(comparisons).items():
        sign = "" if kind == YARN else "signed "
        text = (f"{e['quantity']}: {e['count']} points, {sign}mean {_fmt(kind, e['mean'])}, "
                f"RMS {_fmt(kind, e['rms'])}, max {_fmt(kind, e['max'])}")
        if e["off"]:
            text += f"; {e['off']} off the run (see compare.csv)"
        lines.append(text)
    return lines


def off_lines(comparisons, limit: int = 5) -> list[str]:
    out = []
    for c in comparisons:
        bad = np.flatnonzero(~c.ok)
        for i in bad[:limit]:
            out.append(f"{c.meas.path} line {c.meas.lines[i]}: {c.status[i]}")
        if len(bad) > limit:
            out.append(f"{c.meas.path}: {len(bad) - limit} more point(s) off the run")
    return out


CSV_COLUMNS = ("kind", "file", "line", "layer", "arc_length_m", "azimuth_deg", "group", "braided_length_m",
               "x_m", "y_m", "z_m", "time_s", "measured", "simulated", "difference", "unit", "status")


def _cell(v):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return repr(float(v)) if isinstance(v, (float, np.floating)) else v


def comparison_rows(comparisons):
    for c in comparisons:
        m, kind = c.meas, c.meas.kind
        measured = {ANGLE: "braid_angle_deg", CONVERGENCE: "convergence_length_m"}.get(kind)
        for i in range(len(m)):
            row = {"kind": kind, "file": str(m.path), "line": int(m.lines[i]),
                   "measured": m.values[measured][i] if measured else 0.0,
                   "simulated": c.simulated[i], "difference": c.difference[i],
                   "unit": QUANTITY[kind][1], "status": c.status[i]}
            for col in ("arc_length_m", "azimuth_deg", "braided_length_m", "x_m", "y_m", "z_m", "time_s"):
                if col in m.values:
                    row[col] = m.values[col][i]
            if kind == ANGLE and m.group[i] >= 0:
                row["group"] = ("warp", "weft")[m.group[i]]
            if c.extra.get("layer") is not None:
                row["layer"] = int(c.extra["layer"][i])
            if kind == YARN:
                row["time_s"] = c.extra["snapshot_time_s"][i] if "time_s" not in m.values else m.values["time_s"][i]
            yield row


def write_compare(comparisons, out_dir, title: str = "", plot: bool = True) -> list[Path]:
    """compare.csv, compare.json and (``plot``) compare.png into ``out_dir``; their paths."""
    out_dir = safe_folder(out_dir)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for row in comparison_rows(comparisons):
        w.writerow([_cell(row.get(c)) for c in CSV_COLUMNS])
    written = [atomic_write_text(out_dir / COMPARE_CSV, buf.getvalue())]
    written.append(atomic_write_text(out_dir / COMPARE_JSON,
                                     json.dumps(statistics(comparisons), indent=2) + "\n"))
    if plot:
        written.append(plot_compare(comparisons, out_dir / COMPARE_PNG, title))
    return written


def _sides(phi: np.ndarray):
    """Label per point of the side it was measured on: its azimuth when at most eight distinct
    ones (to 1 deg) were measured, else the quarter of the circumference round it."""
    rounded = np.round(phi).astype(int)
    values = np.unique(rounded)
    if len(values) <= 8:
        return [f"azimuth {v:d} deg" for v in rounded]
    quarter = ((np.round(phi / 90.0).astype(int) + 2) % 4) - 2
    return [f"azimuth {90 * q:d} ± 45 deg" for q in quarter]


def plot_compare(comparisons, path, title: str = "", run: RunData | None = None) -> Path:
    """compare.png: a panel per kind given: braid angles measured (circles) and simulated (dots,
    joined by a line) against the arc length, one colour per side, the points off the run grey; H measured against the run's curve
    against the braided length; the yarn deviations against the axial position."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    kinds = [k for k in KINDS if any(c.meas.kind == k for c in comparisons)]
    fig = Figure(figsize=(8.0, 3.2 * len(kinds) + 0.6), layout="constrained")
    axes = fig.subplots(len(kinds), 1, squeeze=False)[:, 0]
    colours = __import__("matplotlib").colormaps["tab10"]
    stats = statistics(comparisons)
    for ax, kind in zip(axes, kinds):
        these = [c for c in comparisons if c.meas.kind == kind]
        e = stats[kind]
        rms = f"RMS {_fmt(kind, e['rms'])}, {e['count']} points" + (f", {e['off']} off" if e["off"] else "")
        if kind == ANGLE:
            s = np.concatenate([c.meas.values["arc_length_m"] for c in these])
            phi = np.concatenate([(c.meas.values["azimuth_deg"] + 180) % 360 - 180 for c in these])
            g = np.concatenate([c.meas.group for c in these])
            a = np.concatenate([c.meas.values["braid_angle_deg"] for c in these])
            sim = np.concatenate([c.simulated for c in these])
            labels = [side + ("" if gi < 0 else f", {('warp', 'weft')[gi]}") for side, gi in zip(_sides(phi), g)]
            for k, label in enumerate(dict.fromkeys(labels)):
                sel = np.array([lab == label for lab in labels]) & np.isfinite(sim)
                col = colours(k % 10)
                ax.plot(s[sel], a[sel], "o", ms=5, color=col, mfc="none", label=f"{label}: measured")
                ax.plot(s[sel], sim[sel], ".", ms=5, color=col, label="simulated")
                ax.vlines(s[sel], a[sel], sim[sel], color=col, lw=0.6)
            off = ~np.isfinite(sim)
            if off.any():
                ax.plot(s[off], a[off], "x", ms=5, color="0.45", label="measured, off the run")
            ax.set_xlabel("centerline arc length from the tip s (m)")
            ax.set_ylabel("braid angle (deg)")
            ax.set_title(f"Braid angle on the part ({rms})", fontsize=10)
        elif kind == CONVERGENCE:
            L = np.concatenate([c.meas.values["braided_length_m"] for c in these])
            H = np.concatenate([c.meas.values["convergence_length_m"] for c in these])
            sim = np.concatenate([c.simulated for c in these])
            if run is not None and run.history:
                Lr, Hr = history_curve(run)
                ax.plot(Lr, Hr * 1e3, "-", color="0.5", lw=1.0, label="simulated (history.csv)")
            order = np.argsort(L)
            ax.plot(L[order], sim[order] * 1e3, "-", color=colours(0), lw=1.4, label="simulated at the measured L")
            ax.plot(L, H * 1e3, "o", ms=4, mfc="none", color=colours(1), label="measured")
            ax.set_xlabel("braided length L (m)")
            ax.set_ylabel("convergence length H (mm)")
            ax.set_title(f"Convergence length during the run ({rms})", fontsize=10)
        else:
            z = np.concatenate([c.meas.values["z_m"] for c in these])
            d = np.concatenate([c.difference for c in these])
            ok = np.isfinite(d)
            ax.plot(z[ok], d[ok] * 1e3, "o", ms=4, color=colours(2), label="deviation")
            if e["mean"] is not None:
                ax.axhline(e["mean"] * 1e3, color="0.4", lw=1.0, ls="--",
                           label=f"mean {_fmt(kind, e['mean'])}")
            ax.set_xlabel("axial position z (m, machine frame)")
            ax.set_ylabel("distance to the nearest\nsimulated yarn (mm)")
            ax.set_ylim(bottom=0)
            ax.set_title(f"Yarn coordinates in the zone ({rms})", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.suptitle(title or "Measured against simulated", fontsize=11)
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return Path(path)


def run_title(run: RunData) -> str:
    inputs = run.summary.get("inputs") or {}
    source = inputs.get("source")
    name = Path(source).stem if source else run.folder.name
    model = (inputs.get("model") or {}).get("kind", "")
    mu = (inputs.get("yarn") or {}).get("friction")
    return f"{name} · {model} model" + (f" · friction {mu:.3g}" if isinstance(mu, (int, float)) else "")


def compare(results, measurements, out_dir=None, *, plot=True,
            settings: CompareSettings = SETTINGS):
    """``preform compare``: (comparisons, paths written). out_dir: default the results folder."""
    meas = [m if isinstance(m, Measurements) else read_measurements(m) for m in measurements]
    if not meas:
        raise MeasurementError("no measurement files given")
    run = results if isinstance(results, RunData) else load_run(results, {m.kind for m in meas})
    comparisons = [compare_one(m, run, settings) for m in meas]
    out = Path(out_dir).expanduser().resolve() if out_dir is not None else run.folder
    written = write_compare(comparisons, out, plot=False)
    if plot:
        written.append(plot_compare(comparisons, out / COMPARE_PNG, run_title(run), run=run))
    return comparisons, written

