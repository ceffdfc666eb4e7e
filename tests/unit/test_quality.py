"""The run verdict and honest steady values, on constructed histories: each reason triggered
by the history built for it, and the steady figures taken over the steady stretch only."""

from __future__ import annotations

import numpy as np
import pytest

from preform.analysis.quality import (QualitySettings, field_reasons, history_reasons, verdict,
                             yarn_reasons)
from preform.result import FLAG_BRIDGE, FLAG_CATCH
from preform.analysis.steady import SteadySettings, steady_state


def du_popper_history(n=400, L_end=1.0, H_inf=0.6, H0=0.2, decay=5.0, alpha_inf=60.0):
    """A clean run: H and the angle approach their steady values exponentially (Du & Popper)."""
    L = np.linspace(0.0, L_end, n)
    H = H_inf + (H0 - H_inf) * np.exp(-decay * L)
    alpha = alpha_inf + 10.0 * np.exp(-decay * L)
    return {"braided_length_m": L, "convergence_length_mean_m": H,
            "convergence_length_min_m": 0.98 * H, "convergence_length_max_m": 1.02 * H,
            "braid_angle_warp_deg": alpha, "braid_angle_weft_deg": alpha + 0.1}


def test_a_clean_run_has_no_reasons():
    assert history_reasons(du_popper_history()) == []
    assert history_reasons(du_popper_history(L_end=5.0, decay=1.0 / 0.6)) == []
    assert verdict([]) == {"verdict": "ok", "reasons": []}


def test_a_collapsing_convergence_length_is_suspect():
    h = du_popper_history()
    h["convergence_length_min_m"][250] = 0.013   # the sliver of a misaligned pose
    (reason,) = history_reasons(h)
    assert "down to 0.013 m" in reason and "median" in reason


def test_a_fell_point_behind_the_supply_plane_is_suspect():
    h = du_popper_history()
    h["convergence_length_min_m"][300] = -0.01
    assert "behind the supply plane" in history_reasons(h)[0]


def test_angle_jumps_between_steps_are_suspect():
    h = du_popper_history()
    h["braid_angle_weft_deg"][200] += 30.0
    reasons = history_reasons(h)
    assert len(reasons) == 1 and "weft braid angle jumps by up to 30" in reasons[0]


def test_the_start_up_transient_is_not_judged():
    h = du_popper_history()
    h["braid_angle_warp_deg"][1] = 0.0      # the tie row's angle is meaningless
    h["convergence_length_min_m"][10] = 0.0
    assert history_reasons(h) == []


def test_a_share_of_bridged_and_caught_points_above_the_threshold_is_suspect():
    flags = np.zeros(1000, dtype=np.uint8)
    flags[:5] = FLAG_BRIDGE                       # 0.5 %: a concave stretch here and there
    assert yarn_reasons(flags) == []
    flags[:300] = FLAG_BRIDGE                     # 30 %
    flags[300:320] = FLAG_CATCH                   # 2 %
    reasons = yarn_reasons(flags)
    assert len(reasons) == 2
    assert reasons[0].startswith("30.0% of the deposited yarn points are bridged")
    assert "2.0%" in reasons[1] and "caught" in reasons[1]
    assert yarn_reasons(flags, QualitySettings(max_flag_share=0.5)) == []


def test_fields_beyond_the_braided_length_and_holes_are_suspect():
    s = np.linspace(0.0, 1.0, 1001)
    covered = s < 0.6
    assert field_reasons(s, covered, braided_end=0.6) == []
    beyond = covered | (s > 0.9)
    assert "beyond the braided length" in field_reasons(s, beyond, braided_end=0.6)[0]
    holed = covered & ~((s > 0.3) & (s < 0.35))
    assert "carry no yarn" in field_reasons(s, holed, braided_end=0.6)[0]


def test_steady_values_only_where_reached():
    # a physical transient: it decays over one convergence length (Du & Popper)
    decay = 1.0 / 0.6
    reached = steady_state(du_popper_history(L_end=5.0, decay=decay))
    assert reached["reached"]
    # against the asymptotes (0.6 m, 60 deg): H decides, |H - 0.6| = 0.4 exp(-L/0.6) <= 1 % of
    # 0.6 (the angle, 10 exp(-L/0.6) <= 0.25, is met earlier); to the grid's 5/399 m
    L_star = np.log(0.4 / (0.01 * 0.6)) / decay
    assert reached["braided_length_m"] == pytest.approx(L_star, abs=5.0 / 399)
    assert reached["braid_angle_deg"]["warp"] == pytest.approx(60.0, abs=1e-3)   # the asymptote
    assert "drift" not in reached
    short = steady_state(du_popper_history(L_end=1.5, decay=decay))
    assert not short["reached"] and "braid_angle_deg" not in short
    # drift: d/dL (60 + 10 exp(-L/0.6)) = -(10/0.6) exp(-L/0.6): -4.8 to -1.4 deg/m over the
    # fit window (the last half, 0.75 to 1.5 m); the least-squares slope lies between
    assert -4.8 < short["drift"]["braid_angle_warp_deg_per_m"] < -1.4
    loose = SteadySettings(angle_deg=50.0, rel_H=1.0)
    assert steady_state(du_popper_history(L_end=1.5, decay=decay), loose)["reached"]


def test_a_run_shorter_than_half_a_convergence_length_is_never_steady():
    # flat to the eye over 4 cm, but the transient decays over H = 0.6 m
    flat = du_popper_history(L_end=0.04, decay=1.0 / 0.6, H0=0.6, alpha_inf=60.0)
    flat["braid_angle_warp_deg"] = flat["braid_angle_weft_deg"] = np.full(400, 60.0)
    assert steady_state(flat) == {"reached": False, "definition": steady_state(flat)["definition"],
                                  "drift": None}
