"""The run's verdict reads the written convergence-zone snapshots (``quality.snapshot_reasons``):
a crossing out of balance or outside the friction cone makes the run "suspect", with the time
and the figure; balanced crossings inside the cone and the kinematic zone's snapshots do not."""

import numpy as np

from preform.analysis.quality import QUALITY, snapshot_checks, snapshot_reasons
from preform.result import Snapshot


def _crossing(f_a=(1.0, 1.0), f_b=(1.0, 1.0), ext_a=(0.0, 0.0, 0.0), bend=0.3):
    """Two yarns crossing at one contact (id 7): yarn a from (-1, 0, -1) over (0, 0, 0) to
    (1, 0, 1) bent by ``bend`` in y at the crossing, yarn b mirrored in x; segment tensions
    f_a, f_b (below, above); ``ext_a`` the external force at a's crossing point."""
    a = np.array([[-1.0, -bend, -1.0], [0.0, 0.0, 0.0], [1.0, -bend, 1.0]])
    b = np.array([[1.0, bend, -1.0], [0.0, 0.0, 0.0], [-1.0, bend, 1.0]])
    ext = np.zeros((6, 3))
    ext[1] = ext_a
    return Snapshot(time_s=2.5, points=np.vstack([a, b]), offsets=np.array([0, 3, 6]),
                    tension_N=np.array([*f_a, *f_b]), contact_id=np.array([-1, 7, -1, -1, 7, -1]),
                    slip=np.zeros(6, dtype=np.int8), group=np.array([0, 1], dtype=np.int8),
                    external_force_N=ext)


def _pull(f, bend):
    """The net pull of a yarn with equal tensions f at the crossing of ``_crossing``."""
    u = np.array([[-1.0, -bend, -1.0], [1.0, -bend, 1.0]])
    return f * (u / np.linalg.norm(u, axis=1)[:, None]).sum(axis=0)


def test_a_balanced_crossing_inside_the_cone_gives_no_reason():
    snap = _crossing(ext_a=(0.0, 0.0, 0.0))
    imbalance, psi = snapshot_checks(snap, 0.25)
    assert imbalance < 1e-12          # the two yarns' pulls cancel (mirror images)
    assert psi < 0.0                  # equal tensions: inside the cone for any mu > 0
    assert snapshot_reasons([snap], 0.25) == []


def test_a_tension_jump_the_friction_cannot_hold_is_reported():
    # 1.0 below, 1.2 above: |df| sin(beta/2) = 0.2 * 0.99 against mu (f_lo + f_hi) cos(beta/2)
    # = 0.25 * 2.2 * 0.15: outside the cone; the jump's net force is carried by ext, so the
    # crossing still balances and only the friction law is broken
    f_lo, f_hi, bend = 1.0, 1.2, 0.3
    u = np.array([[-1.0, -bend, -1.0], [1.0, -bend, 1.0]])
    u /= np.linalg.norm(u, axis=1)[:, None]
    ext = -(f_lo * u[0] + f_hi * u[1]) + _pull(1.0, bend)
    snap = _crossing(f_a=(f_lo, f_hi), ext_a=tuple(ext), bend=bend)
    imbalance, psi = snapshot_checks(snap, 0.25)
    assert imbalance < 1e-12
    cb = u[0] @ u[1]
    expected = (0.2 * np.sqrt((1 - cb) / 2) - 0.25 * 2.2 * np.sqrt((1 + cb) / 2)) / 1.2
    assert np.isclose(psi, expected, rtol=1e-12) and psi > QUALITY.max_snapshot_psi
    (reason,) = snapshot_reasons([snap], 0.25)
    assert "t = 2.5 s" in reason and "friction cone" in reason and f"{psi:.2g}" in reason
    assert snapshot_reasons([snap], 5.0) == []     # a friction that holds the jump


def test_mixed_yarns_check_each_crossing_at_its_pairs_friction():
    """With every yarn's type (``kinds``) and the table of pairs, a crossing is checked at its
    pair's coefficient: the jump above breaks 0.25 (pair 0-1) and holds at 5.0."""
    f_lo, f_hi, bend = 1.0, 1.2, 0.3
    u = np.array([[-1.0, -bend, -1.0], [1.0, -bend, 1.0]])
    u /= np.linalg.norm(u, axis=1)[:, None]
    ext = -(f_lo * u[0] + f_hi * u[1]) + _pull(1.0, bend)
    snap = _crossing(f_a=(f_lo, f_hi), ext_a=tuple(ext), bend=bend)
    kinds = np.array([0, 1])                        # yarn a of type 0, yarn b of type 1
    weak = np.array([[5.0, 0.25], [0.25, 5.0]])      # the types hold it alone, not together
    assert snapshot_checks(snap, weak, kinds) == snapshot_checks(snap, 0.25)
    strong = np.array([[0.0, 5.0], [5.0, 0.0]])
    assert snapshot_checks(snap, strong, kinds) == snapshot_checks(snap, 5.0)
    assert snapshot_reasons([snap], strong, kinds=kinds) == []
    assert len(snapshot_reasons([snap], weak, kinds=kinds)) == 1


def test_a_crossing_out_of_balance_is_reported():
    snap = _crossing(ext_a=(0.0, 0.0, 0.01))       # 1 % of the largest tension, not balanced
    imbalance, _ = snapshot_checks(snap, 0.25)
    assert np.isclose(imbalance, 0.01, rtol=1e-9)
    (reason,) = snapshot_reasons([snap], 0.25)
    assert "out of balance, by up to 0.01" in reason


def test_kinematic_snapshots_have_no_crossings_to_check():
    snap = Snapshot(time_s=1.0, points=np.zeros((4, 3)) + [[0, 0, 0], [0, 0, 1], [1, 0, 0], [1, 0, 1]],
                    offsets=np.array([0, 2, 4]), tension_N=np.array([1.0, 1.0]),
                    contact_id=np.full(4, -1), slip=np.zeros(4, dtype=np.int8),
                    group=np.array([0, 1], dtype=np.int8))
    assert snapshot_checks(snap, 0.25) == (0.0, 0.0)
    assert snapshot_reasons([snap], 0.25) == []
