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
    ax = braid_angle_figure(small_result).axes[0]
    h = small_result.history
    warp, weft = ax.get_lines()
    np.testing.assert_array_equal(warp.get_xdata(), h["braided_length_m"])
    np.testing.assert_array_equal(warp.get_ydata(), h["braid_angle_warp_deg"])
    np.testing.assert_array_equal(weft.get_ydata(), h["braid_angle_weft_deg"])
    assert "(m)" in ax.get_xlabel() and "(deg)" in ax.get_ylabel()


def test_convergence_figure_band_spans_min_max(small_result):
    ax = convergence_length_figure(small_result).axes[0]
    h = small_result.history
    (mean,) = ax.get_lines()
    np.testing.assert_array_equal(mean.get_ydata(), h["convergence_length_mean_m"])
    (band,) = [c for c in ax.collections if isinstance(c, PolyCollection)]
    y = band.get_paths()[0].vertices[:, 1]
    lo = np.minimum(h["convergence_length_min_m"], h["convergence_length_max_m"]).min()
    hi = np.maximum(h["convergence_length_min_m"], h["convergence_length_max_m"]).max()
    np.testing.assert_allclose([y.min(), y.max()], [lo, hi], rtol=0, atol=1e-15)
    assert "(m)" in ax.get_xlabel() and "(m)" in ax.get_ylabel()


def test_yarns_3d_written(small_result, tmp_path):
    path = plot_yarns_3d(small_result, tmp_path / "braided_mandrel.png")
    assert path.read_bytes()[:8] == PNG_MAGIC
