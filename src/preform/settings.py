"""The numerical settings of a run, as one tree (docs/architecture.md §6).

A user's inputs are the config (``preform.config``); the numerical settings a user normally
leaves alone are :class:`Settings`: frozen, one branch per stage, each branch the frozen
dataclass of the module that uses it (every field there with the reason for its value). The
tree is passed down from ``simulate`` and ``pipeline.run_case`` (``preform run``) to every stage,
which takes its own branch; a test or a study varies a knob by passing another tree::

    s = Settings()
    s = dataclasses.replace(s, quality=dataclasses.replace(s.quality, residual_max=0.05))

``Settings()`` is the defaults every stage uses when it is given none. The studies' own
settings (``design.DesignSettings``, ``sweeps.ClusterSettings``, ``compare.CompareSettings``,
``calibrate.CalibrationSettings``) are inputs of a study, not of a run, and stay with it; so, for
now, does ``geometry.repair.IntakeSettings``, the mesh intake's thresholds, which ``repair_mesh``
takes when a mandrel is loaded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .budget import WorkLimits
from .drawing import PICTURES, PictureSettings  # noqa: F401 - a branch of the tree
from .geometry.offset import OffsetSettings
from .geometry.remesh import RemeshSettings
from .interaction.settings import InteractionSettings
from .analysis.interlacing import InterlacingSettings
from .analysis.quality import QualitySettings
from .analysis.rtm import BinningSettings
from .analysis.steady import SteadySettings
from .structural.layup import BinSettings
from .tolerances import Tolerances


@dataclass(frozen=True)
class Settings:
    """Every numerical setting of a run, by the stage that uses it."""

    #: the stepper and the kinematic model: step control, the walk, catch and bridge tests,
    #: slip curvature (``simulation.simulate`` -> ``stepping.Stepper``)
    tolerances: Tolerances = field(default_factory=Tolerances)
    #: the interaction model: energy, Newton, frontal iteration, zone, ring, relaxation and the
    #: mandrel look-ups (``InteractionZone.for_run``)
    interaction: InteractionSettings = field(default_factory=InteractionSettings)
    #: the field mesh the laid yarns are mapped onto (``fields.map_to_surface``)
    remesh: RemeshSettings = field(default_factory=RemeshSettings)
    #: the offset surface each ``[[layer]]`` above the first is braided on (``pipeline``)
    offset: OffsetSettings = field(default_factory=OffsetSettings)
    #: the warp-weft crossing count the verdict judges (``quality.run_interlacing``)
    interlacing: InterlacingSettings = field(default_factory=InterlacingSettings)
    #: the steady-state reading of history.csv (``steady.steady_state``)
    steady: SteadySettings = field(default_factory=SteadySettings)
    #: the verdict's thresholds (``quality.assess``, ``quality.surface_reasons``)
    quality: QualitySettings = field(default_factory=QualitySettings)
    #: the work estimate's limits, refused beyond unless ``--force`` (``budget.check_work``)
    limits: WorkLimits = field(default_factory=WorkLimits)
    #: how the RTM solver files group the faces' K1 into property sets
    #: (``analysis.rtm.solver_properties``)
    rtm: BinningSettings = field(default_factory=BinningSettings)
    #: how finely the shell deck's plies are binned into element groups
    #: (``structural.layup.structural_layup``)
    binning: BinSettings = field(default_factory=BinSettings)
    #: how the pictures are drawn: sizes, the steady marker's flatness, the yarns' thinning
    #: (``io.draw_pictures`` and the picture worker)
    pictures: PictureSettings = field(default_factory=PictureSettings)


#: the defaults of every stage
DEFAULT = Settings()


def resolved(settings: Settings | None) -> Settings:
    """``settings``, or the defaults where None; TypeError naming what was given if it is not a
    :class:`Settings` (a branch passed instead of the tree, say)."""
    if settings is None:
        return DEFAULT
    if not isinstance(settings, Settings):
        raise TypeError(f"settings = {type(settings).__name__}(...): expected a preform.Settings, "
                        "the tree of every numerical setting; give a branch as "
                        "preform.Settings(interaction=...), preform.Settings(quality=...), ...")
    return settings
