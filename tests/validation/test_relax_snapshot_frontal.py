"""A snapshot's frontal iteration without a guide ring by the relaxation
(``RelaxSettings.snapshot_frontal``): its pass and its final solve (``max_iter`` and
``friction_tol`` given) by the relaxation with consistent bounds and the ring preconditioner,
the final one finished by Newton's frontal iteration, land on Newton's fixed point, and the
written snapshot meets balance and the friction law from its own arrays.

A captured step is the problem ``InteractionZone.step`` poses its solver (``tests/validation/test_relax.py``
says how), here of case A with 48 carriers and friction 0.25 after 150 steps.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import preform as pf
from preform.analysis import quality
from preform.interaction import relax as R
from preform.interaction.settings import DEFAULT
from support.simcase import advanced_stepper, capture_step, snapshot_solves

ROOT = Path(__file__).resolve().parents[2]


def _case_a48():
    cfg = pf.load_config(ROOT / "examples" / "case_a.toml")
    return dataclasses.replace(
        cfg, model=dataclasses.replace(cfg.model, kind="interaction", solver="relax"),
        machine=dataclasses.replace(cfg.machine, carriers=48),
        process=dataclasses.replace(cfg.process, braid_length=0.1),
        output=dataclasses.replace(cfg.output, snapshots=2))


@pytest.fixture(scope="module")
def step():
    """(state, boundary with wall planes, friction centres) of case A's 48-carrier step after
    150 steps (copies)."""
    st, bc, _, centres = capture_step(*advanced_stepper(_case_a48(), 150))
    assert not bc.has_ring
    return st, bc, centres[: st.m]


def test_snapshot_solve_without_a_ring_lands_on_newtons(step):
    """The snapshot's final solve through ``solve_zone``: by the relaxation, then Newton's
    frontal iteration from its state, which meets the bounds' tolerance in its first iteration;
    with ``snapshot_frontal`` off Newton iterates from the step's start. Both stop at a bound
    change below the snapshot tolerance (1e-4 of the tensions), so they are the same fixed point
    within what that change moves (measured 1.7e-5 m over 264 crossings; 1e-4 m allowed: at
    ~1000 N/m of geometric stiffness a 1e-4 relative bound change of ~5 N tensions moves a
    crossing by ~5e-7 m, summed over the rows above it along a slipping yarn), with the same
    slip states (measured all 264; 2 % allowed for crossings at the stick/slip edge)."""
    st, bc, s_old = step
    m = st.m
    (relaxed, rep), (newton, ref) = snapshot_solves(st, bc, s_old,
                                                     R.RelaxSettings(snapshot_frontal=False))
    assert rep.iterations == 1 and not rep.lagged
    assert ref.iterations > 1 and not ref.lagged
    assert rep.residual < DEFAULT.frontal.snapshot_tolerance
    assert np.abs(relaxed.pos[:m] - newton.pos[:m]).max() < 1e-4
    assert np.sum(relaxed.slip[:m] != newton.slip[:m]) <= 0.02 * 2 * m


def test_snapshots_of_a_run_balance_from_their_arrays():
    """A short 48-carrier run's snapshots, re-balanced by the relaxation: every crossing in
    balance and inside its friction cone from the snapshot's own arrays (the files' contents)
    to 1e-3 of the largest tension (the requirement; measured at most 1.2e-8 and 1.6e-4)."""
    result = pf.simulate(_case_a48(), progress=False)
    assert len(result.snapshots) >= 2
    for snap in result.snapshots[1:]:          # the first: t = 0, no crossing yet
        # the written state is the run's own: in balance; its friction law holds to the
        # bounds' lag of a step, the re-balanced copy that checks it to 1e-3
        balance, _ = quality.snapshot_checks(snap, 0.25)
        assert balance < 1e-3
        balance, psi = quality.snapshot_checks(snap.rebalanced, 0.25)
        assert balance < 1e-3 and psi < 1e-3
