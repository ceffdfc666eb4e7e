"""A snapshot's final frontal iteration that cycles between stick and slip states is damped
(``FrontalSettings.snapshot_damping``): the bent tube's snapshot at t = 5.634 s (step 177 of its
start-up, the third of its 20 snapshots) cycles undamped at a bound change of 2-3e-3 for 100
iterations, with crossings outside the friction cone by 4.7e-3 of their tension; damped, it
converges and every crossing meets the friction law (Psi <= 1e-3) and
balances (1e-3), read from the snapshot's own arrays. The written snapshot is the
run's own state; the re-balanced copy that checks it is what is damped (``rebalanced``). The
start-up's steps exceed ``ZoneSettings.max_step_residual`` (1.31 at step 119), which would stop
the run: lifted here, this test is about the re-balance."""

import dataclasses
from pathlib import Path

import numpy as np

import preform as pf
from preform.interaction.settings import DEFAULT
from preform.analysis.quality import snapshot_checks
from support.simcase import advanced_stepper

ROOT = Path(__file__).resolve().parents[2]


def test_the_bent_tubes_cycling_snapshot_converges_when_damped():
    cfg = pf.load_config(ROOT / "examples" / "bent_tube.toml")
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, kind="interaction"),
                              output=dataclasses.replace(cfg.output, snapshots=0))
    # the start-up as solved once a step at its posed Capstan tensions (posed_iterations = 1):
    # the trajectory on which this snapshot cycles
    lifted = dataclasses.replace(
        DEFAULT, zone=dataclasses.replace(DEFAULT.zone, max_step_residual=np.inf),
        frontal=dataclasses.replace(DEFAULT.frontal, posed_iterations=1))
    s, _ = advanced_stepper(cfg, 177, settings=lifted)
    zone = s.zone
    F_machine = s.pose(s.clock.travel).to_machine(s.F)
    mu = float(cfg.yarn.friction)
    imbalance, psi = snapshot_checks(zone.snapshot(s.clock.t, F_machine).rebalanced, mu)
    assert imbalance < 1e-3 and psi < 1e-3
    plain = dataclasses.replace(zone.settings.frontal, snapshot_damping=1.0)
    zone.settings = dataclasses.replace(zone.settings, frontal=plain)
    _, psi_plain = snapshot_checks(zone.snapshot(s.clock.t, F_machine).rebalanced, mu)
    # the case this test is about: undamped, this snapshot cycles (measured 4.7e-3)
    assert psi_plain > 1e-3, "the undamped snapshot no longer cycles: pick another case"
