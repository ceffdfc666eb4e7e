"""A held-out-style curved mandrel: an elliptic section swept along a 70 deg arc,
in millimetres, rotated into an arbitrary frame. With the pose lead at the convergence length
the run is nonsense and the verdict says so; with the
automatic pose lead the run is sane."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

import preform as pf
from preform.geometry import centerline_from_points, shapes
from preform.analysis.quality import assess

TOML = """
[mandrel]
stl = "ellbend.stl"
stl_unit = "mm"
centerline = "auto"
[machine]
carriers = 24
spool_radius = 0.85
angular_speed = 18.0
pattern = "regular"
guide_ring = {{ radius = 0.17, offset = 0.0 }}
[yarn]
width = 4e-3
thickness = 2.5e-4
tension = 4.7
friction = 0.25
[process]
take_up_speed = 0.0263
initial_position = 0.2
braid_length = 0.45
{lead}
[model]
kind = "kinematic"
"""


def elliptic_bend(path):
    """80 x 50 mm ellipse swept along 0.15 m straight, a 70 deg arc of radius 0.45 m, 0.3 m
    straight; rotated by arbitrary Euler angles, shifted, and written in mm."""
    phi = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    ellipse = np.column_stack([0.040 * np.cos(phi), 0.025 * np.sin(phi)])
    bend, angle = 0.45, np.radians(70.0)
    t = np.linspace(0.0, angle, 40)
    arc = np.column_stack([bend * (1 - np.cos(t)), np.zeros_like(t), 0.15 + bend * np.sin(t)])
    end = arc[-1] + 0.3 * np.array([np.sin(angle), 0.0, np.cos(angle)])
    line = np.vstack([[0.0, 0.0, 0.0], arc, end])
    length = centerline_from_points(line).length
    V, F = shapes.sweep(line, lambda s: ellipse, 64, s_values=np.append(np.arange(0.0, length, 0.012), length))
    R = Rotation.from_euler("xyz", [23.0, -41.0, 67.0], degrees=True).as_matrix()
    trimesh.Trimesh((V @ R.T + [0.3, -0.2, 0.5]) * 1000.0, F).export(path)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("curved")
    elliptic_bend(folder / "ellbend.stl")
    out = {}
    # H_inf here is about 0.42 m; "pose_lead near the expected convergence length" was the advice
    for name, lead in (("bad", "pose_lead = 0.42"), ("auto", "")):
        cfg = folder / f"{name}.toml"
        cfg.write_text(TOML.format(lead=lead))
        out[name] = pf.simulate(pf.load_config(cfg), progress=False)
    return out


def test_a_badly_posed_curved_mandrel_is_called_suspect(runs):
    q = assess(runs["bad"])
    assert q["verdict"] == "suspect"
    text = " ".join(q["reasons"])
    # 2.5 % of the points are caught; the walk's 9.9 % "concave" jumps here run along flat facets
    # (stand-off 1e-10 m), which are not bridges (Tolerances.bridge_depth_thickness)
    assert "caught" in text and "check the pose" in text
    assert "behind the supply plane" in text


def test_the_automatic_pose_lead_makes_the_run_sane(runs):
    """No reason of the pose is left with the automatic pose lead; what the verdict still says
    is the part's own: on the 70 deg bend 57 % of the laid points have a slip tendency (the
    models keep the yarn where it was laid), and a yarn on the bend's inside jumps along it
    now and then (measured: 118 mm in one step, 13 mm of the mean fell front, 15.8x the take-up
    advance, 11 times)."""
    result = runs["auto"]
    assert 0.15 < result.config.process.pose_lead < 0.25      # H_inf / 2
    q = assess(result)
    text = " ".join(q["reasons"])
    for pose in ("caught", "bridged", "behind the supply plane", "convergence length down",
                 "braid angle jumps", "separate", "residual"):
        assert pose not in text, pose
    assert "slip tendency" in text and "where it was laid" in text
    flags = np.asarray(result.yarns.flags)
    assert np.count_nonzero(flags & 3) < 0.01 * len(flags)      # bridged or caught
    h = result.history
    settled = h["braided_length_m"] > 0.1 * h["braided_length_m"][-1]
    assert np.min(h["convergence_length_min_m"][settled]) > 0.5 * np.median(h["convergence_length_mean_m"][settled])
