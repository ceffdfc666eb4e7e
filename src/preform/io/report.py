"""``report.html``: one self-contained page of a finished results folder, to share.

It reads only the folder's files: ``summary.json``, the pictures in ``plots/`` (embedded as
``data:`` URIs, so the page needs nothing else and loads offline) and, where there is one, the
config copy ``config.toml`` (a sweep point's); otherwise the inputs as the summary echoes them.
The page: the verdict and its reasons at the top, the key numbers in a table, the pictures, the
inputs. For a sweep, :func:`write_sweep_report` makes one page over its points from
``sweep.csv`` and the points' folders.

Nothing here computes a result: a number missing from the summary is missing from the page.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import warnings
from pathlib import Path

from .atomic import atomic_write_text

REPORT = "report.html"
SUMMARY = "summary.json"
PLOTS = "plots"

#: what each picture shows, by file name; other PNGs get their name as caption
CAPTIONS = {
    "braid_angle.png": "Braid angle against braided length: the start-up transient and steady state",
    "convergence_length.png": "Convergence length H against braided length",
    "surface_map.png": "Braid angle, cover factor and thickness on the part, unrolled",
    "surface_braid_angle.png": "Braid angle on the part",
    "surface_cover_factor.png": "Cover factor on the part",
    "surface_thickness.png": "Thickness on the part",
    "braided_mandrel.png": "The braided mandrel",
    "rtm_map.png": "Fibre volume fraction, K1 and porosity, unrolled",
}

#: the verdict's words and colours (text on background): ok, suspect, failed or interrupted
VERDICT_STYLE = {"ok": ("OK", "#1e7b34"), "suspect": ("SUSPECT", "#a85d00"),
                 "failed": ("FAILED", "#b3261e"), "interrupted": ("INTERRUPTED", "#5f3dc4")}

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1c1c1c;background:#f6f6f4}
main{max-width:1100px;margin:0 auto;padding:24px}
h1{font-size:1.5rem;margin:0 0 4px} h2{font-size:1.15rem;margin:28px 0 8px;border-bottom:1px solid #ccc;padding-bottom:4px}
.sub{color:#555;margin:0 0 16px}
.verdict{color:#fff;border-radius:8px;padding:16px 20px;margin:8px 0 16px}
.verdict .word{font-size:2rem;font-weight:700;letter-spacing:.05em}
.verdict ul{margin:8px 0 0 20px;padding:0} .verdict p{margin:6px 0 0}
table{border-collapse:collapse;background:#fff;width:100%}
th,td{text-align:left;padding:5px 10px;border-bottom:1px solid #e4e4e4;vertical-align:top}
th{background:#ecece8;font-weight:600} td:first-child{white-space:nowrap} td.num{font-variant-numeric:tabular-nums;white-space:nowrap}
figure{background:#fff;margin:0 0 18px;padding:10px;border:1px solid #e0e0e0;border-radius:6px}
figure img{max-width:100%;height:auto;display:block;margin:0 auto}
figcaption{color:#444;font-size:.9rem;margin-top:6px}
pre{background:#fff;border:1px solid #e0e0e0;padding:10px;overflow:auto;font-size:.85rem}
details summary{cursor:pointer;color:#333}
a{color:#0b57d0} .wide{overflow-x:auto}
"""


def _read_summary(folder: Path) -> dict:
    return json.loads((folder / SUMMARY).read_text(encoding="utf-8"))


def _e(value) -> str:
    return html.escape(str(value), quote=True)


def _num(value, digits=4) -> str:
    if isinstance(value, bool) or value is None:
        return "" if value is None else str(value)
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        return f"{value:.{digits}g}"
    return str(value)


def _get(data, *path):
    for key in path:
        if not isinstance(data, dict) or key not in data:
            return None
        data = data[key]
    return data


def verdict_of(summary: dict) -> tuple[str, list[str]]:
    """("ok" | "suspect" | "failed" | "interrupted", reasons): a run that did not finish is failed
    (or interrupted, when stopped) whatever its quality says; else the quality verdict."""
    status = summary.get("status", "unknown")
    reasons = list(_get(summary, "quality", "reasons") or [])
    if status != "done":
        message = summary.get("message") or ""
        return ("interrupted" if status == "interrupted" else "failed"), \
            [f"status {status}" + (f": {message}" if message else ""), *reasons]
    return ("ok" if _get(summary, "quality", "verdict") == "ok" else "suspect"), reasons


def key_numbers(summary: dict) -> list[tuple[str, str, str]]:
    """(quantity, value, note) rows of the numbers a reader looks for first, as the summary has
    them."""
    rows = []

    def add(name, value, note="", digits=4):
        if value is not None:
            rows.append((name, _num(value, digits), note))

    add("status", summary.get("status"))
    add("model", summary.get("model"))
    add("braided length", _get(summary, "braided_length_m"), "m")
    add("steps", summary.get("steps"))
    add("wall time", _get(summary, "wall_time_s"), "s", 3)
    for key in ("ko_braid_angle_deg", "ko_deg"):
        add("Ko's braid angle", _flat(_get(summary, key)), "deg, quasi-static")
    for key in ("h_inf_m", "steady_convergence_length_m"):
        add("H_inf", _flat(_get(summary, key)), "m, kinematic steady convergence length")
    ref = summary.get("reference") or summary.get("references")
    if isinstance(ref, dict):
        for k, v in ref.items():
            add(f"reference: {k}", _flat(v))
    fa = _get(summary, "braid_angle_deg", "final")
    if isinstance(fa, dict):
        add("final braid angle", " / ".join(_num(fa[g]) for g in ("warp", "weft") if g in fa),
            "deg, warp / weft")
    fh = _get(summary, "convergence_length_m", "final")
    if isinstance(fh, dict):
        add("final convergence length", _num(fh.get("mean")),
            f"m (min {_num(fh.get('min'))}, max {_num(fh.get('max'))})")
    st = summary.get("steady_state") or {}
    if st.get("reached"):
        add("steady state from", st.get("braided_length_m"), "m braided")
        sa = st.get("braid_angle_deg") or {}
        if sa:
            add("steady braid angle", " / ".join(_num(sa[g]) for g in ("warp", "weft") if g in sa),
                "deg, warp / weft")
        add("steady convergence length", st.get("convergence_length_m"), "m")
    elif st:
        drift = st.get("drift")
        add("steady state", "not reached", "drift per metre braided: " + _flat(drift) if isinstance(drift, dict) else "")
    for k, layer in enumerate(summary.get("layers") or [], start=1):
        if not isinstance(layer, dict):
            continue
        la = _get(layer, "braid_angle_deg", "final")
        notes = [f"{layer.get('direction', '')} layer", f"{_num(layer.get('steps'))} steps",
                 f"status {layer.get('status', '')}", f"quality {_get(layer, 'quality', 'verdict') or ''}"]
        notes += [f"{name.replace('_', ' ')} {_num(v)}" for name, v in (layer.get("fields") or {}).items()
                  if isinstance(v, (int, float))]
        if isinstance(la, dict):
            add(f"layer {layer.get('layer', k)}: final braid angle",
                " / ".join(_num(la[g]) for g in ("warp", "weft") if g in la), "deg, warp / weft; " + "; ".join(notes))
    yarns = summary.get("yarns") or {}
    if yarns.get("flags"):
        add("yarn flags", ", ".join(f"{k} {v}" for k, v in yarns["flags"].items()), "points")
    rtm = summary.get("rtm") or {}
    if rtm.get("written"):
        vf = rtm.get("fibre_volume_fraction") or {}
        if vf:
            add("fibre volume fraction", vf.get("mean"), f"area mean (min {_num(vf.get('min'))}, "
                f"max {_num(vf.get('max'))})")
        add("compression", rtm.get("compression"), "braid thickness / cavity")
        kb = rtm.get("k1_binning") or {}
        if kb:
            add("RTM sets: K1 binning error", f"x{kb.get('rms_factor', float('nan')):.3g}",
                f"typical factor; at most x{kb.get('max_factor', float('nan')):.3g}")
    return rows


def _flat(value):
    """A number, or a short text of a list or dict of numbers."""
    if isinstance(value, (list, tuple)):
        return " - ".join(_num(v) for v in value)
    if isinstance(value, dict):
        return ", ".join(f"{k} {_num(v)}" for k, v in value.items() if not isinstance(v, (dict, list)))
    return value


def field_statistics(summary: dict) -> list[tuple[str, dict]]:
    """(name, {mean, min, max, ...}) of the fields' statistics where the summary has them."""
    found = []
    for key in ("fields", "field_statistics", "surface_fields"):
        block = summary.get(key)
        if isinstance(block, dict):
            for name, stats in block.items():
                if isinstance(stats, dict) and any(k in stats for k in ("mean", "min", "max")):
                    found.append((name, stats))
    return found


def _all_numbers(data, prefix="") -> list[tuple[str, str]]:
    out = []
    if isinstance(data, dict):
        for k, v in data.items():
            if prefix == "" and k in ("inputs", "files"):
                continue
            out += _all_numbers(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(data, list) and data and all(isinstance(v, (int, float)) for v in data) and len(data) <= 12:
        out.append((prefix, ", ".join(_num(v) for v in data)))
    elif isinstance(data, list):
        for k, v in enumerate(data):
            out += _all_numbers(v, f"{prefix}[{k}]")
    elif data is not None and data != "":
        out.append((prefix, _num(data)))
    return out


def _png_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _pictures(folder: Path) -> list[Path]:
    plots = folder / PLOTS
    if not plots.is_dir():
        return []
    found = [p for p in sorted(plots.glob("*.png")) if p.is_file() and not p.is_symlink()]
    order = list(CAPTIONS)

    def rank(p):
        base = _layer_picture(p.name)[0]
        return order.index(base) if base in order else len(order), p.name
    return sorted(found, key=rank)


def _layer_picture(name: str) -> tuple[str, int | None]:
    """(the picture's name without a stack's ``_layer<k>``, k or None)."""
    stem, dot, ext = name.rpartition(".")
    head, sep, k = stem.rpartition("_layer")
    if sep and k.isdigit():
        return f"{head}{dot}{ext}", int(k)
    return name, None


def caption(name: str) -> str:
    """What a picture shows (CAPTIONS; a stack's ``<name>_layer<k>.png``: of layer k)."""
    base, k = _layer_picture(name)
    if base in CAPTIONS:
        return CAPTIONS[base] + ("" if k is None else f", layer {k}")
    return Path(name).stem.replace("_", " ")


def _inputs_text(folder: Path, summary: dict) -> tuple[str, str]:
    """(heading, text) of the config as run: the folder's config.toml, else the summary's echo."""
    copy = folder / "config.toml"
    if copy.is_file() and not copy.is_symlink():
        return "config.toml (the config as run)", copy.read_text(encoding="utf-8")
    inputs = summary.get("inputs")
    if not isinstance(inputs, dict):
        return "inputs", "(not in the summary)"
    try:
        import tomli_w

        def clean(value):
            if isinstance(value, dict):
                return {k: clean(v) for k, v in value.items() if v is not None}
            if isinstance(value, list):
                return [clean(v) for v in value if v is not None]
            return value

        return "the inputs as read (summary.json)", tomli_w.dumps(clean(inputs))
    except Exception:   # noqa: BLE001 - an echo tomli-w cannot lay out is shown as JSON
        return "the inputs as read (summary.json)", json.dumps(inputs, indent=2)


def _verdict_block(verdict: str, reasons: list[str], detail: str = "",
                   empty: str = "no reasons to doubt the run") -> str:
    word, colour = VERDICT_STYLE[verdict]
    items = "".join(f"<li>{_e(r)}</li>" for r in reasons)
    lines = [f'<section class="verdict" id="verdict" data-verdict="{verdict}" style="background:{colour}">',
             f'<div class="word">{word}</div>']
    if detail:
        lines.append(f"<p>{_e(detail)}</p>")
    lines.append(f"<ul>{items}</ul>" if items else f"<p>{_e(empty)}</p>")
    lines.append("</section>")
    return "\n".join(lines)


def _table(header, rows, numeric=()) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f'<td class="num">{_e(c)}</td>' if k in numeric else f"<td>{_e(c)}</td>"
                                    for k, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _page(title, subtitle, body) -> str:
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{_e(title)}</title><style>{CSS}</style></head><body><main>\n"
            f"<h1>{_e(title)}</h1><p class=\"sub\">{_e(subtitle)}</p>\n{body}\n</main></body></html>\n")


def report_html(folder) -> str:
    """The page of the results folder ``folder`` (see module docstring)."""
    folder = Path(folder)
    summary = _read_summary(folder)
    verdict, reasons = verdict_of(summary)
    model = summary.get("model", "")
    case = Path(str(_get(summary, "inputs", "source") or folder.name)).stem
    title = f"{case}: {model} model" if model else case
    parts = [_verdict_block(verdict, reasons, f"status {summary.get('status', 'unknown')}, quality "
                            f"{_get(summary, 'quality', 'verdict') or 'not judged'}")]
    parts.append("<h2>Key numbers</h2>" + _table(("quantity", "value", "unit, note"), key_numbers(summary),
                                                 numeric=(1,)))
    stats = field_statistics(summary)
    if stats:
        cols = ("mean", "min", "max")
        parts.append("<h2>Field statistics (area-weighted)</h2>" + _table(
            ("field", *cols), [(name, *(_num(s.get(c)) for c in cols)) for name, s in stats], numeric=(1, 2, 3)))
    pictures = _pictures(folder)
    parts.append("<h2>Pictures</h2>")
    if not pictures:
        parts.append("<p>no pictures in plots/</p>")
    for p in pictures:
        said = caption(p.name)
        parts.append(f'<figure><img src="{_png_uri(p)}" alt="{_e(said)}">'
                     f"<figcaption>{_e(said)} (<code>plots/{_e(p.name)}</code>)</figcaption></figure>")
    heading, text = _inputs_text(folder, summary)
    parts.append(f"<h2>Inputs</h2><p>{_e(heading)}</p><pre>{_e(text)}</pre>")
    parts.append("<h2>Every number of the summary</h2><details><summary>show</summary>"
                 + _table(("key", "value"), _all_numbers(summary), numeric=(1,)) + "</details>")
    files = summary.get("files") or []
    if files:
        parts.append("<h2>Files</h2><p>" + ", ".join(f"<code>{_e(f)}</code>" for f in files) + "</p>")
    sub = f"preform {summary.get('preform_version', '')} · results folder {folder}"
    return _page(title, sub, "\n".join(parts))


def write_report(folder) -> Path:
    """Write ``<folder>/report.html`` atomically from the finished folder's files."""
    folder = Path(folder)
    return atomic_write_text(folder / REPORT, report_html(folder))


def sweep_report_html(folder) -> str:
    """One page over a sweep's points: a table of their parameters, status, verdict and final
    values with links to each point's own report, the sweep's pictures, and each point's
    braid angle and convergence length pictures."""
    folder = Path(folder)
    with open(folder / "sweep.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    #: sweep.csv's columns the page leaves out: the verdict is its own (from the point's summary),
    #: the folder is the link, the message is in the reasons
    left_out = {"verdict", "results", "message"}
    header = [k for k in (rows[0] if rows else []) if k not in left_out]
    points = []
    worst = "ok"
    rank = {"ok": 0, "suspect": 1, "interrupted": 2, "failed": 3}
    table_rows = []
    for row in rows:
        results = Path(row.get("results") or "")
        point = results if results.is_absolute() else folder / results
        summary = _read_summary(point) if (point / SUMMARY).is_file() else None
        verdict, reasons = verdict_of(summary) if summary else ("failed", [row.get("message") or "no summary.json"])
        worst = max(worst, verdict, key=rank.__getitem__)
        points.append((row, point, summary, verdict, reasons))
        target = point.relative_to(folder).as_posix() if point.is_relative_to(folder) else point.as_uri()
        link = f'<a href="{_e(target)}/{REPORT}">{_e(row.get("point", ""))}</a>'
        cells = [link if k == "point" else _e(_num(_maybe_float(row[k]))) for k in header]
        word, colour = VERDICT_STYLE[verdict]
        table_rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells)
                          + f'<td style="color:{colour};font-weight:700">{word}</td>'
                          + f"<td>{_e('; '.join(reasons))}</td></tr>")
    n_bad = sum(v != "ok" for *_, v, _ in points)
    reasons = [f"point {r.get('point')}: {verdict_word}: {'; '.join(why)}"
               for r, _, _, verdict_word, why in points if verdict_word != "ok"]
    parts = [_verdict_block(worst, reasons, f"{len(points) - n_bad} of {len(points)} points ok",
                            empty="no reasons to doubt any point")]
    names = {"braid_angle_final_deg": "final angle (deg)", "braid_angle_steady_deg": "steady angle (deg)",
             "convergence_length_final_m": "final H (m)", "wall_time_s": "wall (s)"}
    head = "".join(f"<th>{_e(names.get(h, h))}</th>" for h in header) + "<th>verdict</th><th>reasons</th>"
    parts.append(f"<h2>Points</h2><p>each point's number links to its own report</p><div class=\"wide\"><table><thead>"
                 f"<tr>{head}</tr></thead><tbody>{''.join(table_rows)}</tbody></table></div>")
    own = [p for p in sorted([*folder.glob("*.png"), *(folder / PLOTS).glob("*.png")])
           if p.is_file() and not p.is_symlink()]
    if own:
        parts.append("<h2>The sweep</h2>")
        parts += [f'<figure><img src="{_png_uri(p)}" alt="{_e(p.stem)}"><figcaption>{_e(p.name)}'
                  "</figcaption></figure>" for p in own]
    parts.append("<h2>Each point</h2>")
    for row, point, summary, verdict, _ in points:
        for name in ("braid_angle.png", "convergence_length.png"):
            pic = point / PLOTS / name
            if pic.is_file() and not pic.is_symlink():
                caption = f"point {row.get('point')}: {CAPTIONS[name]}"
                parts.append(f'<figure><img src="{_png_uri(pic)}" alt="{_e(caption)}">'
                             f"<figcaption>{_e(caption)}</figcaption></figure>")
    varied = ", ".join(k for k in header if k not in ("point", *SWEEP_RESULT_COLUMNS))
    return _page(f"{folder.name}: sweep of {len(points)} points" + (f" over {varied}" if varied else ""),
                 f"results folder {folder}", "\n".join(parts))


#: sweep.csv's result columns (the others are the varied keys)
SWEEP_RESULT_COLUMNS = ("status", "braid_angle_final_deg", "braid_angle_steady_deg", "convergence_length_final_m",
                        "wall_time_s")


def _maybe_float(text):
    try:
        return float(text) if text not in ("", None) and not str(text).isdigit() else text
    except ValueError:
        return text


def write_sweep_report(folder) -> Path:
    """Write ``<folder>/report.html`` of a finished sweep, atomically."""
    folder = Path(folder)
    return atomic_write_text(folder / REPORT, sweep_report_html(folder))


def report_hook(folder, sweep: bool = False) -> list[Path]:
    """The report of a finished folder, for the end of a run's or a sweep's writing: the paths
    written, or none with a warning where the page cannot be made (the results stand without it)."""
    try:
        return [write_sweep_report(folder) if sweep else write_report(folder)]
    except (OSError, ValueError, KeyError, TypeError) as err:
        warnings.warn(f"report.html not written: {type(err).__name__}: {err}; the results are written",
                      RuntimeWarning, stacklevel=2)
        return []
