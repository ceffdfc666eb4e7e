"""summary.json and history.csv: contract header, exact round trip, NaN refused."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

import preform
from preform.errors import SimulationError
from preform.analysis.derived import summary_dict
from preform.io.tables import write_history, write_summary
from preform.result import HISTORY_COLUMNS


def test_history_header_and_exact_round_trip(small_result, tmp_path):
    path = write_history(small_result, tmp_path / "history.csv")
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == HISTORY_COLUMNS
    assert len(rows) == 1 + small_result.steps
    table = np.array(rows[1:], dtype=np.float64)
    for j, name in enumerate(HISTORY_COLUMNS):
        # repr() floats read back bit for bit: atol = 0
        np.testing.assert_allclose(table[:, j], small_result.history[name], rtol=0, atol=0,
                                   err_msg=name)
    assert rows[2][HISTORY_COLUMNS.index("contacts")] == "3"  # counts are written as integers


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_history_refuses_non_finite(small_result, tmp_path, bad):
    history = dict(small_result.history)
    column = np.array(history["convergence_length_min_m"])
    column[4] = bad
    history["convergence_length_min_m"] = column
    broken = dataclasses.replace(small_result, history=history)
    with pytest.raises(SimulationError, match=r"convergence_length_min_m.*row 4"):
        write_history(broken, tmp_path / "history.csv")
    assert not (tmp_path / "history.csv").exists()


def test_history_refuses_missing_column(small_result, tmp_path):
    history = {k: v for k, v in small_result.history.items() if k != "residual"}
    with pytest.raises(SimulationError, match="residual"):
        write_history(dataclasses.replace(small_result, history=history), tmp_path / "h.csv")


def test_summary_content(small_result, tmp_path):
    path = write_summary(summary_dict(small_result, {"files": ["a", "b"]}), tmp_path / "summary.json")
    summary = json.loads(path.read_text())
    h = small_result.history
    assert summary["preform_version"] == preform.__version__
    assert summary["model"] == "kinematic"
    assert summary["status"] == "done"
    assert summary["steps"] == small_result.steps == 6
    assert summary["wall_time_s"] == 1.25
    assert summary["files"] == ["a", "b"]
    assert summary["braided_length_m"] == h["braided_length_m"][-1]
    final = summary["braid_angle_deg"]["final"]
    assert final == {"warp": h["braid_angle_warp_deg"][-1], "weft": h["braid_angle_weft_deg"][-1]}
    # six steps are too few to call anything steady: no steady values
    assert summary["braid_angle_deg"]["steady"] is None
    assert summary["convergence_length_m"]["steady"] is None
    assert summary["steady_state"]["reached"] is False
    assert summary["quality"]["verdict"] in ("ok", "suspect")
    conv = summary["convergence_length_m"]["final"]
    assert conv["mean"] == h["convergence_length_mean_m"][-1]
    assert conv["min"] == h["convergence_length_min_m"][-1]
    assert conv["max"] == h["convergence_length_max_m"][-1]
    # conftest sets FLAG_BRIDGE at points 3, 7 and FLAG_CATCH | FLAG_SLIP at point 8
    assert summary["yarns"]["flags"] == {"bridge": 2, "catch": 1, "slip": 1}
    assert summary["yarns"]["count"] == 4
    inputs = summary["inputs"]
    assert inputs["machine"]["carriers"] == 4
    assert inputs["mandrel"]["stl"].endswith("mandrel.stl")


def test_summary_of_run_without_steps_is_valid_json(small_result, tmp_path):
    empty = dataclasses.replace(small_result, history={c: np.empty(0) for c in HISTORY_COLUMNS},
                                status="failed", message="diverged at step 0")
    summary = json.loads(write_summary(summary_dict(empty), tmp_path / "summary.json").read_text())
    assert summary["steps"] == 0
    assert summary["braid_angle_deg"]["final"]["warp"] is None
    assert summary["message"] == "diverged at step 0"
