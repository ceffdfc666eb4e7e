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
class PictureSettings:
    """How the pictures of ``plots/`` are drawn (``preform.io``: the history plots, the unrolled
    map and the 3-D renders). Defined here rather than in ``io``, which sits above this tree's
    layer (docs/architecture.md §3)."""

    #: inches of a history figure: two panels, the legend and a two-line title at history_dpi
    history_size_in: tuple = (7.2, 6.0)
    #: dots per inch of the history figures (1080 x 900 px: thin lines stay one pixel apart)
    history_dpi: int = 150
    #: a steady-state marker only where every curve after it moves by at most this many pixels
    #: (flat to the eye; elsewhere the plot says where the tolerances put it)
    flat_pixels: float = 2.0
    #: the wind-up at the start of a history ends where the braided length has grown by this
    #: share of the run (the fell points stay put while the yarns wind to tangency)
    start_fraction: float = 1e-3
    #: dots per inch of the unrolled map (10 in wide: 1300 px, a face of 5 mm a few pixels on 3 m)
    map_dpi: int = 130
    #: ticks a colour bar's rounded range aims for (1-2-5 steps: 4 to 6 labels that do not crowd)
    bar_ticks: int = 5
    #: pixels across a surface picture, least and most: a 3 m part at 2 mm a pixel (its faces
    #: visible); narrower only where a short thick part would not fill the width of the tallest
    #: view, down to what the titles need
    surface_width_px: tuple = (700, 1400)
    #: least and largest height of a surface picture's view, pixels: a long part is a band no
    #: lower than the ruler and title need, a short thick one a view up to about as tall as wide
    surface_view_height_px: tuple = (240, 900)
    #: pixels of a surface picture's colour-bar row (the bar, its ticks and its title)
    surface_bar_height_px: int = 110
    #: pixels of a view above the part (its title) and below it (the ruler, its ticks and labels)
    surface_view_room_px: tuple = (40, 90)
    #: share of a view's width the part spans (the rest a margin on either side)
    fill_width: float = 0.96
    #: pixels of braided_mandrel.png (width, height): the whole part on top, two close-ups below
    mandrel_window_px: tuple = (1600, 1000)
    #: points drawn per yarn in braided_mandrel.png at most (every k-th beyond): case A's 4 m
    #: yarns get 4 mm segments, whose chord sag on 75 mm (20 um) is a thirtieth of a pixel
    mandrel_points_per_yarn: int = 1000
    #: the same for the matplotlib picture drawn where off-screen rendering fails
    fallback_points_per_yarn: int = 2000
    #: a braided_mandrel.png view's half extents are its content's times this (a margin)
    view_margin: float = 1.08
    #: least pixels between neighbouring yarns of a family in the whole part's view: closer
    #: lines alias into a moire, so every k-th yarn is drawn
    min_yarn_spacing_px: float = 5.0
    #: multisampling of the 3-D render windows: none (Mesa's llvmpipe, the usual off-screen
    #: EGL, took 0.19 s a frame with 2-4 samples against 0.02 s without)
    multi_samples: int = 0
    #: seconds the run waits for the picture worker after its own work before stopping it
    worker_timeout_s: float = 600.0


#: the pictures' defaults
PICTURES = PictureSettings()


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
