"""preform calibrate: it recovers the friction and the initial position that made synthetic
noisy measurements, within the uncertainty it reports, and says when a parameter is not
determined; on a 16-carrier interaction cylinder without a ring (seconds a run)."""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest

from preform.studies.calibrate import CalibrationSettings, calibrate, parse_noise, parse_param
from preform.cli import main
from preform.errors import ConfigError
from support.simcase import write_cylinder_case

TRUTH = {"yarn.friction": 0.22, "process.initial_position": 0.085}
#: the measurement noise of the synthetic measurements: small against what the friction
#: changes on this set-up (friction 0.2 to 0.3 moves the angles by 0.03 deg RMS, H by 0.2 mm)
NOISE = {"angle": 0.02, "convergence": 5e-5, "yarn": 2e-5}


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """(base config, measurement files): the base case (friction 0, initial position 0.08 m,
    pictures), and measurements of the truth's run with Gaussian noise of NOISE (seeded)."""
    d = tmp_path_factory.mktemp("cal")
    base = write_cylinder_case(d, name="base", kind="interaction", carriers=16, braid=0.12,
                               friction=0.0, snapshots=2)
    truth = write_cylinder_case(d, name="truth", kind="interaction", carriers=16, braid=0.12,
                                friction=TRUTH["yarn.friction"], snapshots=2, out=d / "truth",
                                output_extra="pictures = false")
    truth.write_text(truth.read_text().replace("initial_position = 0.08",
                                               f"initial_position = {TRUTH['process.initial_position']}"))
    assert main(["run", str(truth), "--no-progress"]) == 0
    return base, _measurements(d / "truth", d)


def _measurements(run, d):
    from preform.studies.compare import history_curve, load_run
    from preform.analysis.interlacing import azimuths

    rng = np.random.default_rng(7)
    r = load_run(run)
    s, phi = azimuths(r.vertices[r.faces].mean(axis=1), r.centerline)
    phi = np.degrees(phi)
    a = r.cell_data["braid_angle_deg"]
    faces = rng.choice(np.flatnonzero(a > 0), 60, replace=False)
    files = [d / "angles.csv", d / "H.csv", d / "yarns.csv"]
    np.savetxt(files[0], np.column_stack([s[faces], phi[faces], a[faces] + rng.normal(0, NOISE["angle"], 60)]),
               delimiter=",", header="arc_length_m,azimuth_deg,braid_angle_deg", comments="")
    L, H = history_curve(r)
    np.savetxt(files[1], np.column_stack([L[1::2], H[1::2] + rng.normal(0, NOISE["convergence"], len(L[1::2]))]),
               delimiter=",", header="braided_length_m,convergence_length_m", comments="")
    pts = r.snapshot(len(r.snapshot_files) - 1)[0][::2]
    np.savetxt(files[2], pts + rng.normal(0, NOISE["yarn"], pts.shape), delimiter=",",
               header="x_m,y_m,z_m", comments="")
    return files


@pytest.fixture(scope="module")
def calibrated(case, tmp_path_factory):
    base, files = case
    out = tmp_path_factory.mktemp("out")
    params = [parse_param("yarn.friction=0:0.5:3"), parse_param("process.initial_position=0.06:0.12:4")]
    report = calibrate(base, files, params, out_dir=out, workers=2, progress=False)
    return report, out


def test_friction_and_initial_position_recovered_within_the_reported_uncertainty(calibrated):
    report, _ = calibrated
    for key, truth in TRUTH.items():
        p = report["parameters"][key]
        assert p["determined"], p
        # within two of the reported standard deviations (a 95 % interval of one parameter)
        assert abs(p["value"] - truth) <= 2.0 * p["sigma"], (key, p)
    # the uncertainty resolves something: the friction to better than a tenth of its range
    assert report["parameters"]["yarn.friction"]["sigma"] < 0.05
    # the model reproduces its own measurements: the least misfit is what the noise explains
    assert report["misfit_min"] < 2.0


def test_the_files_and_the_calibrated_config_runs(calibrated, capsys):
    report, out = calibrated
    rows = (out / "calibrate.csv").read_text().splitlines()
    assert rows[0].startswith("stage,point,yarn.friction,process.initial_position,status,misfit")
    assert len(rows) - 1 == report["evaluations"] >= 12
    data = tomllib.loads((out / "calibrated.toml").read_text())
    for key, truth in TRUTH.items():
        section, name = key.split(".")
        assert data[section][name] == pytest.approx(report["parameters"][key]["value"], rel=1e-5)
    assert "pictures" not in data["output"]     # the base config's: the search's runs alone go without
    for key in TRUTH:
        png = out / "plots" / f"misfit_{key.replace('.', '_')}.png"
        assert png.stat().st_size > 10_000
    assert json.loads((out / "best" / "compare.json").read_text())["angle"]["count"] == 60
    # the runs of the search draw no pictures ([output] pictures = false)
    assert not list((out / "coarse").glob("*/plots/*.png"))
    assert main(["check", str(out / "calibrated.toml")]) == 0


def test_resume_reruns_nothing(case, calibrated, capsys):
    report, out = calibrated
    base, files = case
    params = [parse_param("yarn.friction=0:0.5:3"), parse_param("process.initial_position=0.06:0.12:4")]
    again = calibrate(base, files, params, out_dir=out, workers=2, resume=True, progress=True)
    assert again["parameters"] == report["parameters"]
    assert "running" not in capsys.readouterr().err.replace("0 running", "")


def test_a_parameter_the_measurements_do_not_constrain_is_said_so(case, tmp_path):
    """Without a guide ring the yarn-ring friction does nothing: its misfit is flat."""
    base, files = case
    code = main(["calibrate", str(base), *map(str, files), "--param", "yarn.ring_friction=0:0.5:3",
                 "--out", str(tmp_path), "--workers", "2", "--no-progress"])
    assert code == 0
    report = json.loads((tmp_path / "calibrate.json").read_text())
    p = report["parameters"]["yarn.ring_friction"]
    assert not p["determined"] and p["value"] is None and "flat" in p["how"]
    text = (tmp_path / "calibrated.toml").read_text()
    assert "yarn.ring_friction: not determined" in text
    assert "ring_friction" not in tomllib.loads(text)["yarn"]   # the base config's (absent) kept


@pytest.mark.parametrize("text, says", [
    ("friction=0:1", "KEY=LO:HI"), ("yarn.friction=0.5:0.1", "LO < HI"),
    ("yarn.friction=a:b", "must be numbers"), ("yarn.friction=0:1:1", "at least 2"),
])
def test_bad_params_are_refused(text, says):
    with pytest.raises(ConfigError, match=says):
        parse_param(text)


def test_bad_noise_is_refused():
    with pytest.raises(ConfigError, match="one of angle, convergence, yarn"):
        parse_noise(["H=0.1"])
    with pytest.raises(ConfigError, match="positive"):
        parse_noise(["angle=-1"])
    assert parse_noise(["angle=0.5"]) == {"angle": 0.5}


def test_a_key_that_is_no_config_value_is_refused_before_any_run(case, tmp_path, capsys):
    base, files = case
    code = main(["calibrate", str(base), str(files[0]), "--param", "yarn.friction.x=0:1",
                 "--out", str(tmp_path)])
    assert code == 2 and "yarn.friction.x" in capsys.readouterr().err
    assert not (tmp_path / "coarse").exists()


def test_with_noise_given_too_small_the_intervals_widen_by_birges_ratio():
    """calibrate's Delta chi2: 1 where the noise explains the best fit, chi2_min / (N - p)
    where it does not."""
    from preform.studies.calibrate import SETTINGS, Evaluation, _delta, chi2

    e = Evaluation("coarse", 0, {}, "done", "", n={"angle": 10}, ss={"angle": 10 * 0.5 ** 2},
                   off={"angle": 2}, residuals={"angle": np.zeros(12)})
    # 10 residuals of 0.5 deg at a noise of 0.5 deg, 2 points off at 3 sigmas: 10 + 2 * 9
    assert chi2(e, {"angle": 0.5}) == pytest.approx(28.0)
    assert _delta([28.0], 12, 1, SETTINGS) == pytest.approx(28.0 / 11)
    assert _delta([5.0], 12, 1, SETTINGS) == 1.0

