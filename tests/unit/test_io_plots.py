"""PNG plots are written, are PNGs, and draw what the history holds."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection

from preform.io.plots import braid_angle_figure, convergence_length_figure, plot_history, plot_yarns_3d

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_history_plots_written(small_result, tmp_path):
    paths = plot_history(small_result, tmp_path / "plots")
    assert [p.name for p in paths] == ["braid_angle.png", "convergence_length.png"]
    for p in paths:
        assert p.read_bytes()[:8] == PNG_MAGIC
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == [
        "braid_angle.png", "convergence_length.png"]


def test_braid_angle_figure_draws_history(small_result):
    fig = braid_angle_figure(small_result)
    ax = fig.axes[0]
    h = small_result.history
    warp, weft = ax.get_lines()
    np.testing.assert_array_equal(warp.get_xdata(), h["braided_length_m"])
    np.testing.assert_array_equal(warp.get_ydata(), h["braid_angle_warp_deg"])
    np.testing.assert_array_equal(weft.get_ydata(), h["braid_angle_weft_deg"])
    assert "(m)" in fig.deviation_axes.get_xlabel() and "(deg)" in ax.get_ylabel()


def test_convergence_figure_band_spans_min_max(small_result):
    fig = convergence_length_figure(small_result)
    ax = fig.axes[0]
    h = small_result.history
    (mean,) = ax.get_lines()
    np.testing.assert_array_equal(mean.get_ydata(), h["convergence_length_mean_m"])
    (band,) = [c for c in ax.collections if isinstance(c, PolyCollection)]
    y = band.get_paths()[0].vertices[:, 1]
    lo = np.minimum(h["convergence_length_min_m"], h["convergence_length_max_m"]).min()
    hi = np.maximum(h["convergence_length_min_m"], h["convergence_length_max_m"]).max()
    np.testing.assert_allclose([y.min(), y.max()], [lo, hi], rtol=0, atol=1e-15)
    assert "(m)" in fig.deviation_axes.get_xlabel() and "(m)" in ax.get_ylabel()


def test_yarns_3d_written(small_result, tmp_path):
    path = plot_yarns_3d(small_result, tmp_path / "braided_mandrel.png")
    assert path.read_bytes()[:8] == PNG_MAGIC


def _history_result(small_result, n=200, status="done"):
    """small_result with a Du & Popper-like history: a wind-up at L = 0.008 m, then settling."""
    import dataclasses

    L = np.concatenate([np.full(20, 0.008), np.linspace(0.008, 1.0, n)])
    angle = np.concatenate([np.linspace(0.0, 71.0, 20), 60.0 + 11.0 * np.exp(-8.0 * (L[20:] - 0.008))])
    H = 0.8 - 0.4 * np.exp(-8.0 * L)
    history = dict(small_result.history)
    history.update(braided_length_m=L, braid_angle_warp_deg=angle, braid_angle_weft_deg=angle,
                   braid_angle_min_deg=np.maximum(angle - 1.0, 0.0), braid_angle_max_deg=angle + 1.0,
                   convergence_length_mean_m=H, convergence_length_min_m=H, convergence_length_max_m=H,
                   **{k: np.zeros(len(L)) for k in ("time_s", "contacts", "iterations", "residual")})
    return dataclasses.replace(small_result, history=history, status=status)


def test_history_plot_shows_the_whole_run_and_marks_steady_state(small_result):
    from preform.analysis.steady import steady_state

    result = _history_result(small_result)
    steady = steady_state(result.history)
    assert steady["reached"]
    ax = braid_angle_figure(result, steady=steady).axes[0]
    lo, hi = ax.get_ylim()
    assert lo == 0.0 and 71.0 < hi <= 90.0    # the wind-up from 0 deg and the overshoot to 71
    assert any(line.get_label().startswith("steady from") for line in ax.get_lines())


def test_history_plots_draw_ko_and_h_inf_references(small_result):
    from preform.reference import references

    result = _history_result(small_result)
    s = np.linspace(0.0, 1.0, 11)
    refs = references(result.config, s, np.full_like(s, 0.1))
    ax = braid_angle_figure(result, refs=refs).axes[0]
    (ko,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("Ko")]
    np.testing.assert_allclose(ko.get_ydata(), refs.ko_deg[0])
    ax = convergence_length_figure(result, refs=refs).axes[0]
    assert any(ln.get_label().startswith("H∞") for ln in ax.get_lines())


def test_titles_name_case_model_and_an_unfinished_status(small_result):
    ax = braid_angle_figure(_history_result(small_result, status="interrupted")).axes[0]
    assert "kinematic model" in ax.get_title() and "INTERRUPTED: partial results" in ax.get_title()
    ax = convergence_length_figure(_history_result(small_result)).axes[0]
    assert ax.get_title().endswith("· done")


def test_braided_mandrel_png_shows_the_mandrel_and_the_yarns(small_result, tmp_path):
    """The pyvista render: non-blank, the mandrel grey and both yarn colours present, mode 0644."""
    import dataclasses
    import os
    import stat

    import trimesh

    from preform.geometry import mandrel_from_arrays

    tube = trimesh.creation.cylinder(radius=0.05, height=0.4, sections=64)
    mandrel = mandrel_from_arrays(tube.vertices, tube.faces)
    t = np.linspace(0.0, 1.0, 200)
    paths = [np.column_stack([0.051 * np.cos(sign * 12 * t + k), 0.051 * np.sin(sign * 12 * t + k),
                              -0.2 + 0.4 * t]) for sign in (1, -1) for k in range(4)]
    yarns = dataclasses.replace(
        small_result.yarns, points=np.vstack(paths), offsets=np.arange(9) * 200,
        group=np.repeat(np.array([0, 1], dtype=np.int8), 4))
    result = dataclasses.replace(small_result, mandrel=mandrel, yarns=yarns)
    old = os.umask(0o022)
    try:
        path = plot_yarns_3d(result, tmp_path / "braided_mandrel.png")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    from PIL import Image

    img = np.asarray(Image.open(path).convert("RGB")).reshape(-1, 3).astype(int)
    blue = np.sum((img[:, 2] > img[:, 0] + 60) & (img[:, 2] > 120))
    red = np.sum((img[:, 0] > img[:, 2] + 60) & (img[:, 0] > 120))
    grey = np.sum((np.ptp(img, axis=1) < 12) & (img[:, 0] > 100) & (img[:, 0] < 235))
    assert blue > 500 and red > 500 and grey > 5000


def _marks(fig):
    """The labels of the braid angle plot's lines and its notes."""
    ax = fig.axes[0]
    return [line.get_label() for line in ax.get_lines()] + [t.get_text() for t in ax.texts]


def test_the_history_plots_mark_the_steady_state_they_are_given(small_result):
    """The steady-state mark is the analysis stage's (``Analysed.steady``), drawn as given and
    not read again from the history: a made-up start at 40 % of the run labels the plot with
    that start (a dotted line where the curves are flat from there, a note where not); none
    given, the plot has no steady-state mark."""
    start = 0.4 * float(small_result.history["braided_length_m"][-1])
    marked = _marks(braid_angle_figure(small_result, steady={"reached": True,
                                                             "braided_length_m": start}))
    assert any(f"from {start:.2f} m" in text for text in marked)
    assert not any("steady" in text for text in _marks(braid_angle_figure(small_result)))
