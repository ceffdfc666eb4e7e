"""report.html: one self-contained page of a results folder, checked in a real headless browser."""

from __future__ import annotations

import csv
import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from preform.cli import main
from preform.io.report import REPORT, VERDICT_STYLE, verdict_of, write_sweep_report
from support.simcase import write_cone_case

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian: "
                                    "apt-get install chromium): the page cannot be checked in a browser")


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    """A short kinematic run with its pictures (the 1 m cone, 16 carriers, 0.4 m braided)."""
    folder = tmp_path_factory.mktemp("report")
    cfg = write_cone_case(folder, name="short_cone", braid_length=0.4)
    assert main(["run", str(cfg), "--no-progress"]) == 0
    return folder / "results" / "short_cone"


def test_the_run_writes_its_report_with_every_picture_and_the_inputs(run_folder):
    page = (run_folder / REPORT).read_text()
    summary = json.loads((run_folder / "summary.json").read_text())
    pictures = sorted((run_folder / "plots").glob("*.png"))
    assert len(pictures) >= 5
    assert page.count('<img src="data:image/png;base64,') == len(pictures)
    for p in pictures:
        assert f"plots/{p.name}" in page
    verdict = verdict_of(summary)[0]
    assert f'data-verdict="{verdict}"' in page
    for reason in summary["quality"]["reasons"]:
        assert html.escape(reason, quote=True) in page
    final = summary["braid_angle_deg"]["final"]["warp"]
    assert f"{final:.4g}" in page                        # the key numbers, as the summary has them
    assert "braid_length = 0.4" in page                  # the inputs as run
    # self-contained: nothing is fetched from anywhere (only data: URIs as sources)
    sources = re.findall(r'\b(?:src|href)="([^"]*)"', page)
    assert sources and all(s.startswith("data:") for s in sources)


def test_a_failed_run_is_never_ok():
    verdict, reasons = verdict_of({"status": "failed", "message": "the mandrel's end passed the machine",
                                   "quality": {"verdict": "ok", "reasons": []}})
    assert verdict == "failed" and "mandrel's end" in reasons[0]
    verdict, reasons = verdict_of({"status": "interrupted", "message": "stopped by SIGTERM after step 40",
                                   "quality": {"verdict": "ok", "reasons": []}})
    assert verdict == "interrupted" and "SIGTERM" in reasons[0]


def test_each_layer_has_its_row():
    from preform.io.report import key_numbers

    layers = [{"layer": k, "direction": d, "status": "done", "steps": n, "quality": {"verdict": "ok"},
               "braid_angle_deg": {"final": {"warp": a, "weft": a}}, "fields": {"mean_cover_factor": c}}
              for k, d, n, a, c in ((1, "forward", 1181, 45.75, 0.57), (2, "backward", 1881, 57.07, 0.66))]
    rows = {name: (value, note) for name, value, note in key_numbers({"status": "done", "layers": layers})}
    assert rows["layer 2: final braid angle"][0] == "57.07 / 57.07"
    assert "1,881 steps" in rows["layer 2: final braid angle"][1]
    assert "backward layer" in rows["layer 2: final braid angle"][1]


CHECK = """<script>
window.addEventListener("load", () => {
  const images = [...document.images];
  const out = {images: images.length,
               decoded: images.filter(i => i.complete && i.naturalWidth > 0).length,
               fetched: performance.getEntriesByType("resource").map(e => e.name)
                          .filter(n => !n.startsWith("data:")),
               verdict: (document.getElementById("verdict") || {dataset: {}}).dataset.verdict || null,
               verdictTop: document.getElementById("verdict").getBoundingClientRect().top};
  const pre = document.createElement("pre");
  pre.id = "check-result";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""


def chromium(args, tmp_path, timeout=120):
    """Headless chromium, offline: every host name fails to resolve and no proxy answers."""
    profile = tmp_path / "chromium-profile"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
           "--disable-extensions", "--disable-background-networking", f"--user-data-dir={profile}",
           "--host-resolver-rules=MAP * ~NOTFOUND", "--proxy-server=http://127.0.0.1:9",
           "--hide-scrollbars", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def browser_check(page: Path, tmp_path) -> dict:
    checked = tmp_path / f"check_{page.parent.name}.html"
    checked.write_text(page.read_text().replace("</body>", CHECK + "</body>"))
    done = chromium(["--virtual-time-budget=10000", "--dump-dom", checked.as_uri()], tmp_path)
    found = re.search(r'<pre id="check-result">(.*?)</pre>', done.stdout, re.S)
    assert found, f"chromium gave no check result: {done.stderr[-2000:]}"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


@needs_chromium
def test_the_page_loads_offline_and_every_image_decodes_in_chromium(run_folder, tmp_path):
    result = browser_check(run_folder / REPORT, tmp_path)
    assert result["images"] == len(list((run_folder / "plots").glob("*.png")))
    assert result["decoded"] == result["images"]
    assert result["fetched"] == []                     # nothing but the page itself and data: URIs
    assert result["verdict"] == verdict_of(json.loads((run_folder / "summary.json").read_text()))[0]
    assert result["verdictTop"] < 200                  # the verdict at the top of the page (px)


@needs_chromium
def test_the_verdict_is_visible_in_a_screenshot(run_folder, tmp_path):
    from PIL import Image

    shot = tmp_path / "report_screenshot.png"
    chromium(["--window-size=1280,900", f"--screenshot={shot}", (run_folder / REPORT).as_uri()], tmp_path)
    assert shot.is_file(), "chromium wrote no screenshot"
    print(f"\nreport screenshot for a person to look at: {shot}")
    pixels = np.asarray(Image.open(shot).convert("RGB"))[:300]
    verdict = verdict_of(json.loads((run_folder / "summary.json").read_text()))[0]
    colour = np.array([int(VERDICT_STYLE[verdict][1][k:k + 2], 16) for k in (1, 3, 5)])
    banner = np.all(np.abs(pixels.astype(int) - colour) <= 2, axis=2)
    # the banner: at least a tenth of the first 300 rows of a 1280 px wide page is its colour
    # (it is about 900 x 100 px); 2 levels: the PNG's colour management rounding
    assert banner.mean() > 0.1, f"no verdict banner in the top of {shot}"


@pytest.fixture(scope="module")
def sweep_folder(run_folder, tmp_path_factory):
    """A sweep folder of two points made from the run's folder: sweep.csv and the points."""
    folder = tmp_path_factory.mktemp("sweep") / "friction"
    rows = []
    for k, friction in enumerate((0.0, 0.25)):
        point = folder / f"point_{k}"
        shutil.copytree(run_folder, point)
        rows.append({"point": k, "yarn.friction": friction, "status": "done", "results": str(point)})
    with open(folder / "sweep.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    write_sweep_report(folder)
    return folder


def test_one_sweep_report_over_its_points(sweep_folder):
    page = (sweep_folder / REPORT).read_text()
    assert page.count('href="point_') == 2
    assert page.count('<img src="data:image/png;base64,') == 4      # each point's two histories
    verdict = verdict_of(json.loads((sweep_folder / "point_0" / "summary.json").read_text()))[0]
    assert f'data-verdict="{verdict}"' in page
    assert f"{2 if verdict == 'ok' else 0} of 2 points ok" in page


@needs_chromium
def test_the_sweep_report_loads_offline_in_chromium(sweep_folder, tmp_path):
    result = browser_check(sweep_folder / REPORT, tmp_path)
    assert result["images"] == result["decoded"] == 4
    assert result["fetched"] == []
