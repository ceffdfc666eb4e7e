"""A snapshot's final frontal iteration that cycles between stick and slip states is damped
(``FrontalSettings.snapshot_damping``): the bent tube's snapshot after step 170 of its start-up,
re-balanced holding the step's own problem, cycles undamped with crossings outside the friction
cone by 7.0e-3 of their tension after 20 frontal iterations; damped, the same 20 iterations
bring every crossing within the friction law (Psi <= 1e-3: 7.5e-4) and into balance (1e-3: 3e-8),
read from the snapshot's own arrays. Both solves get 20 iterations: the damping starts after 10
(``snapshot_damping_after``). Of the start-up's snapshots every 10 steps from step 100 to 210,
undamped ones above 1e-3 are those after steps 130-170; of those at least 5x above it
(140-170), 170's damped one is furthest inside the law. The written snapshot is the
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
    budget = dataclasses.replace(lifted.frontal, snapshot_iterations=20)
    s, _ = advanced_stepper(cfg, 170, settings=lifted)
    zone = s.zone
    zone.settings = dataclasses.replace(zone.settings, frontal=budget)
    F_machine = s.pose(s.clock.travel).to_machine(s.F)
    mu = float(cfg.yarn.friction)
    imbalance, psi = snapshot_checks(zone.snapshot(s.clock.t, F_machine).rebalanced, mu)
    assert imbalance < 1e-3 and psi < 1e-3
    plain = dataclasses.replace(budget, snapshot_damping=1.0)
    zone.settings = dataclasses.replace(zone.settings, frontal=plain)
    _, psi_plain = snapshot_checks(zone.snapshot(s.clock.t, F_machine).rebalanced, mu)
    # the case this test is about: undamped, this snapshot cycles (measured 7.0e-3)
    assert psi_plain > 1e-3, "the undamped snapshot no longer cycles: pick another case"
