"""The frontal iteration of the bounds behind a guide ring by the relaxation
(``RelaxSettings.ring_frontal``, ``relax._ring_frontal``): what a snapshot asks ``solve_zone`` for
(its ring passes and its final solve) lands on the fixed point of Newton's frontal iteration
(``frontal.solve_zone_inplace``), and the structure the snapshot's 60 solves of one lattice
share (``preconditioners.BlockStiffness.of``) is the one a new solve builds.

A captured step is the problem ``InteractionZone.step`` poses its solver (``tests/validation/test_relax.py``
says how), here of the case-B-like mandrel (``simcase.case_b_like_config``, 16 carriers).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from preform.interaction import frontal, relax as R
from preform.interaction import preconditioners as PC
from preform.interaction.settings import DEFAULT
from support.simcase import advanced_stepper, capture_step, case_b_like_config, snapshot_solves

# the balance of every solve to 1e-10 of the tensions (``tests/validation/test_relax_ring.py``)
TIGHT = 1e-10


#: the run whose step the tests capture: its time steps iterate only the new crossings' bounds
#: to their converged geometry's (``FrontalSettings.posed_all_bounds`` off), the step these
#: figures were measured on; on the default run's step 150 at mu 0.25 the plain frontal
#: iteration of both solvers contracts more slowly (the relaxation's at 2.4e-7 after 400)
NEW_ONLY = dataclasses.replace(DEFAULT, frontal=dataclasses.replace(DEFAULT.frontal,
                                                                    posed_all_bounds=False))


@pytest.fixture(scope="module")
def ring_step(tmp_path_factory):
    """``ring_step(mu)``: (state, boundary with wall planes, friction centres) of the step
    after 150 steps of the case-B-like run (``NEW_ONLY``), on copies."""
    folder = tmp_path_factory.mktemp("ring_frontal")
    runs = {}

    def get(mu):
        if mu not in runs:
            cfg = case_b_like_config(folder, 0.17)
            cfg = dataclasses.replace(cfg, yarn=dataclasses.replace(cfg.yarn, friction=mu))
            runs[mu] = advanced_stepper(cfg, 150, settings=NEW_ONLY)
        st, bc, _, centres = capture_step(*runs[mu])
        return st, bc, centres[: st.m]

    return get


@pytest.mark.parametrize("mu", [0.25, 0.5])
def test_frontal_iteration_by_the_relaxation_lands_on_newtons_fixed_point(mu, ring_step):
    """The bounds and ring top tensions iterated to 1e-9 of the tensions by the relaxation
    (``_ring_frontal`` without Newton's finish) and by Newton's frontal iteration: the same
    state, positions within 1e-7 m and tensions within 1e-7 of the spool tension. Tolerance:
    the plain bound iteration contracts by about 0.965 an iteration, so a change below 1e-9
    leaves each within ~3e-8 of the fixed point (measured 1.5e-9 m and 5.9e-9 N apart at mu
    0.25). The Newton frontal solve and the relaxation's wall differ by the penalty's
    micrometre at crossings on the mandrel, f / 1e7 N/m: 1e-7 m at these tensions."""
    st, bc, s_old = ring_step(mu)
    m = st.m
    newton = st.copy()
    frontal.solve_zone_inplace(newton, bc, centre=s_old, max_iter=400, friction_tol=1e-9,
                               tol=TIGHT, mode="final")
    relaxed = st.copy()
    rs = R.RelaxSettings(max_iter=300, ring_stall=60)
    rep = R._ring_frontal(relaxed, bc, DEFAULT, rs, "", s_old, TIGHT, 1e-9, 400, finish=False)
    assert rep is not None and not rep.lagged
    assert np.abs(relaxed.pos[:m] - newton.pos[:m]).max() < 1e-7
    assert np.abs(relaxed.tension[:m] - newton.tension[:m]).max() < 1e-7 * bc.f_spool


def test_snapshot_solve_behind_a_ring_is_finished_by_newton(ring_step):
    """A snapshot's final solve (``friction_tol`` given) through ``solve_zone``: the
    relaxation's frontal iteration, then Newton's from its state, which then meets the bounds'
    tolerance in its first frontal iteration; without ``ring_frontal`` Newton takes them from
    the step's start."""
    st, bc, s_old = ring_step(0.25)
    (_, rep), (_, ref) = snapshot_solves(st, bc, s_old, R.RelaxSettings(ring_frontal=False))
    assert rep.iterations == 1 and not rep.lagged
    assert ref.iterations > 1 and not ref.lagged
    assert rep.residual < DEFAULT.frontal.snapshot_tolerance


def test_structure_is_shared_only_by_the_same_lattice(ring_step):
    """``BlockStiffness.of`` gives the last structure again for the same lattice and order
    (METIS's), a new one for another lattice or the band order; a step solved twice, the
    second time through the shared structure, gives the same result bit for bit."""
    st, bc, s_old = ring_step(0.25)
    m = st.m
    lat = R.lattice_of(st)
    a = PC.BlockStiffness.of(lat, st.pos[:m], 5, "metis")
    assert PC.BlockStiffness.of(R.lattice_of(st.copy()), st.pos[:m], 5, "metis") is a
    assert PC.BlockStiffness.of(lat, st.pos[:m], 3, "metis") is not a
    assert PC.BlockStiffness.of(lat, st.pos[:m], 5, "band") is not a
    other = lat._replace(low=lat.low.copy())
    c = int(np.nonzero(other.low[:, 0] >= 0)[0][-1])
    other.low[c, 0] = -1
    assert PC.BlockStiffness.of(other, st.pos[:m], 5, "metis") is not a
    b0, f0 = R.start_bounds(st, bc)
    full = R.RelaxSettings(preconditioner="full")
    args = (lat, st.pos[:m], st.material[:m], st.material_fell, s_old, bc.fell, bc.top, f0, b0)
    kw = dict(f_spool=bc.f_spool, mu=bc.mu, h=bc.h, width=bc.width, plane=bc.plane)
    PC.BlockStiffness._last = None
    first = R.relax(*args, settings=full, **kw)
    assert PC.BlockStiffness._last is not None
    again = R.relax(*args, settings=full, **kw)
    assert first.converged and np.array_equal(first.pos, again.pos)
    assert np.array_equal(first.tension, again.tension)
