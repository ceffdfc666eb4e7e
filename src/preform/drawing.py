"""The pictures' settings (``preform.Settings.pictures``), in a module of their own: ``io`` draws
with them and must not import the analysis modules the settings tree (``preform.settings``)
holds, and the tree sits below ``io`` (docs/architecture.md §3)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PictureSettings:
    """How the pictures of ``plots/`` are drawn (``preform.io``: the history plots, the unrolled
    map and the 3-D renders): ``preform.Settings.pictures``."""

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
