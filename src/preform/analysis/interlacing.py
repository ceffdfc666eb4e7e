"""Whether warp and weft are interlaced: their crossings per unit area against the pattern's.

In a biaxial braid every warp yarn crosses every weft yarn each time their azimuths around the
centerline pass one another. On the unrolled surface, with ``s`` the centerline arc length and
``phi`` the azimuth about the centerline (its frame's normal and binormal), a laid yarn is a
curve ``phi_k(s)``; a warp yarn i and a weft yarn j cross where their azimuth difference
``d_ij(s) = phi_i(s) - phi_j(s)`` passes a multiple of 2 pi. So, over a band of the braid:

* *measured*: the number of times each ``d_ij`` passes a multiple of 2 pi, summed over all
  pairs: the crossings of the laid yarns themselves (curves on the surface cross exactly where
  their azimuths meet, whatever the section's shape);
* *pattern*: the number the interlaced lattice gives for the same yarns, ``sum_ij TV(d_ij) /
  2 pi``, TV the total variation: each pair crosses once per full turn of the one about the other
  when the yarns of a group are spread around the section, as the carriers lay them. On a
  cylinder of perimeter P with n yarns per group at braid angle alpha this is ``2 n^2 tan(alpha)
  / P`` crossings per unit length, ``2 n^2 tan(alpha) / P^2`` per unit area (the lattice of two
  families of lines n per perimeter at +-alpha).

Their ratio is 1 for an interlaced braid, to within one crossing per pair over the band (its
ends), and falls towards 0 where warp and weft lie in separate bands that do not meet (a
model that lets the groups part). The curves are compared on a common grid of ``s``: a yarn is
taken as a function of ``s`` (a yarn laid backwards along the centerline for a moment keeps its
furthest point: the running maximum of its ``s``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class InterlacingSettings:
    """How the laid yarns are compared."""

    #: grid points along the band at most: the pairs' azimuth differences are sampled there
    #: (a crossing and its undoing within one grid interval would be missed; a braid's
    #: differences are monotone, so only the band's ends depend on the grid)
    max_grid: int = 500
    #: points of a laid yarn used at most (every k-th, its last point kept): case A's yarns
    #: have ~4500 points over 7 turns, 1000 of them turn by ~2.5 deg from one to the next
    points_per_yarn: int = 1000
    #: rad, a yarn turning further than this about the centerline between two of the points
    #: used is taken with all its points (the azimuth is unwrapped along the yarn)
    max_turn_step: float = 0.5
    #: the band's grid spacing (m) at least, as a fraction of the median point spacing of the
    #: laid yarns along the centerline: finer adds nothing the polylines hold
    spacing_fraction: float = 1.0


INTERLACING = InterlacingSettings()


@dataclass(frozen=True)
class Interlacing:
    """measured, pattern: crossings in the band (see module docstring); s_start, s_end: the
    band (m of centerline); area_m2: its surface area (perimeter times length); pairs: warp-weft
    pairs compared."""

    measured: int
    pattern: float
    s_start: float
    s_end: float
    area_m2: float
    pairs: int

    @property
    def ratio(self) -> float:
        """measured / pattern (nan where the pattern gives no crossing)."""
        return self.measured / self.pattern if self.pattern > 0 else float("nan")

    @property
    def measured_per_m2(self) -> float:
        return self.measured / self.area_m2 if self.area_m2 > 0 else float("nan")

    @property
    def pattern_per_m2(self) -> float:
        return self.pattern / self.area_m2 if self.area_m2 > 0 else float("nan")


def azimuths(points, centerline):
    """(s (m,) m, phi (m,) rad) of points (m, 3), mandrel frame: the arc length of the closest
    centerline point and the azimuth about the centerline there, ``atan2((p - c).B, (p - c).N)``
    with (N, B) the centerline's frame."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    s, _ = centerline.project(points)
    c, _, N, B = centerline.frames_at(s)
    r = points - c
    return s, np.arctan2(np.einsum("ij,ij->i", r, B), np.einsum("ij,ij->i", r, N))


def yarn_curve(s, phi):
    """(s, phi) of one yarn as a function of s: phi unwrapped along the yarn, the points kept
    where s passes its running maximum (so s increases strictly)."""
    s = np.asarray(s, dtype=float)
    phi = np.unwrap(np.asarray(phi, dtype=float))
    if len(s) == 0:
        return s, phi
    ahead = np.concatenate([[True], s[1:] > np.maximum.accumulate(s)[:-1]])
    return s[ahead], phi[ahead]


def _yarn_curves(points, off, centerline, settings):
    """``yarn_curve`` of every yarn from every k-th of its points (``points_per_yarn``), a yarn
    that turns by more than ``max_turn_step`` between two of them from all its points."""
    picks = []
    for k in range(len(off) - 1):
        n = off[k + 1] - off[k]
        step = max(1, int(np.ceil(n / max(settings.points_per_yarn, 2))))
        idx = np.arange(off[k], off[k + 1], step)
        if n and idx[-1] != off[k + 1] - 1:
            idx = np.append(idx, off[k + 1] - 1)
        picks.append(idx)
    cut = np.cumsum([0] + [len(i) for i in picks])
    s_all, phi_all = azimuths(points[np.concatenate(picks)] if picks else points[:0], centerline)
    curves = []
    for k, idx in enumerate(picks):
        s, phi = s_all[cut[k]:cut[k + 1]], phi_all[cut[k]:cut[k + 1]]
        if len(idx) > 1 and np.max(np.abs(np.diff(np.unwrap(phi)))) > settings.max_turn_step \
                and len(idx) < off[k + 1] - off[k]:
            s, phi = azimuths(points[off[k]:off[k + 1]], centerline)
        curves.append(yarn_curve(s, phi))
    return curves


def count_crossings(warp, weft, grid):
    """(measured crossings, pattern crossings) of warp and weft curves over ``grid`` (g,) m.

    warp, weft : lists of (s, phi) curves (``yarn_curve``), each covering the grid."""
    if len(warp) == 0 or len(weft) == 0 or len(grid) < 2:
        return 0, 0.0
    phi_w = np.array([np.interp(grid, s, p) for s, p in warp])
    phi_o = np.array([np.interp(grid, s, p) for s, p in weft])
    measured, pattern = 0, 0.0
    for row in phi_w:
        d = row[None, :] - phi_o                       # (n_weft, g): d_ij on the grid
        turns = np.floor(d / TWO_PI)
        measured += int(np.abs(np.diff(turns, axis=1)).sum())
        pattern += float(np.abs(np.diff(d, axis=1)).sum()) / TWO_PI
    return measured, pattern


def interlacing(yarns, centerline, s_range=None,
                settings: InterlacingSettings = INTERLACING) -> Interlacing | None:
    """The interlacing of a run's laid yarns (``YarnPaths``, mandrel frame) over the band of
    centerline ``s_range`` (m; default: where every yarn has been laid, from the furthest tie
    point to the least advanced end). None where the band is empty or a group has no yarn."""
    group = np.asarray(yarns.group)
    curves = _yarn_curves(np.asarray(yarns.points, dtype=float), np.asarray(yarns.offsets),
                          centerline, settings)
    curves = [(k, c) for k, c in enumerate(curves) if len(c[0]) >= 2]
    if not curves:
        return None
    lo = max(float(c[0][0]) for _, c in curves)
    hi = min(float(c[0][-1]) for _, c in curves)
    if s_range is not None:
        lo, hi = max(lo, float(s_range[0])), min(hi, float(s_range[1]))
    warp = [c for k, c in curves if group[k] == 0]
    weft = [c for k, c in curves if group[k] == 1]
    if not (hi > lo) or not warp or not weft:
        return None
    spacing = np.median(np.concatenate([np.diff(c[0]) for _, c in curves]))
    n = int(min(settings.max_grid, max(2, np.ceil((hi - lo) / max(
        settings.spacing_fraction * spacing, 1e-12)) + 1)))
    grid = np.linspace(lo, hi, n)
    measured, pattern = count_crossings(warp, weft, grid)
    return Interlacing(measured=measured, pattern=pattern, s_start=lo, s_end=hi,
                       area_m2=band_area(centerline, yarns, lo, hi), pairs=len(warp) * len(weft))


def band_area(centerline, yarns, lo, hi) -> float:
    """m^2 of the surface between centerline arc lengths lo and hi: the centerline's section
    perimeters where it has them, else 2 pi times the laid yarns' mean distance from it."""
    grid = np.linspace(lo, hi, 65)
    if centerline.perimeter is not None:
        per = np.interp(grid, centerline.s, centerline.perimeter)
    else:
        points = np.asarray(yarns.points, dtype=float)
        s, d = centerline.project(points[:: max(1, len(points) // 20000)])   # a mean: a sample
        inside = (s >= lo) & (s <= hi)
        per = np.full_like(grid, TWO_PI * float(np.mean(d[inside] if np.any(inside) else d)))
    return float(np.sum(0.5 * (per[1:] + per[:-1]) * np.diff(grid)))
