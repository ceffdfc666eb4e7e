"""``braided_mandrel.png``: the mandrel with its deposited yarns, from two opposite sides.

An off-screen pyvista render (EGL, no display needed): the mandrel surface in grey under the
yarn centerlines (warp blue, weft red), seen across the braided part's long axis from two
opposite oblique directions, each 45 deg between two faces of a four-sided section, so that all
four sides of a square mandrel are in one picture; the view is framed on the braided part (the
unbraided rest of a long mandrel would make it a thin stick). If rendering fails (no OpenGL) the
caller falls back to a matplotlib picture.
"""

from __future__ import annotations

import os

import numpy as np

from ..drawing import PICTURES as PICTURE_SETTINGS

COLOURS = {0: "#1f77b4", 1: "#d62728"}   # warp, weft: matplotlib's tab:blue, tab:red
MANDREL_COLOUR = "#c8c8c8"


def view_axes(points):
    """(centre (3,), long axis (3,), two unit vectors across it) of a point cloud, by PCA."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    return centre, vt[0], vt[1], vt[2]


def part_axes(points, centerline=None):
    """(centre, long axis, across, third) of the part ``points`` (n, 3) show, for the views.

    With a centerline, its stretch under the points gives the long axis (a short braid on a thick
    part is wider than long, and a principal-component axis would then look at its end); on a
    curved stretch ``third`` is the normal of its plane (the bend faces the viewer), on a
    straight one the section's direction of least spread. Without one: :func:`view_axes`."""
    centre, axis, across, third = view_axes(points)
    if centerline is None or len(points) < 3:
        return centre, axis, across, third
    s = centerline.project(points)[0]
    lo, hi = float(np.min(s)), float(np.max(s))
    if not hi > lo:
        return centre, axis, across, third
    path = np.asarray(centerline.frames_at(np.linspace(lo, hi, 64))[0])
    _, sv, vt = np.linalg.svd(path - path.mean(axis=0), full_matrices=False)
    axis = vt[0]
    if sv[1] > 1e-3 * sv[0]:              # curved: the plane of the bend faces the viewer
        third = vt[2] - np.dot(vt[2], axis) * axis
    else:                                 # straight: the section's least spread
        rel = points - centre
        rel = rel - np.outer(rel @ axis, axis)
        third = np.linalg.svd(rel, full_matrices=False)[2][1]   # [2]: the axis, no spread left
        third = third - np.dot(third, axis) * axis
    third /= np.linalg.norm(third)
    return centre, axis, np.cross(third, axis), third


def _yarn_polylines(yarns, group, max_points):
    """The yarns of ``group`` as point blocks (each (k, 3), every ``stride``-th point and the
    last, at most ``max_points``), one per yarn with two points or more."""
    blocks = []
    for k in np.flatnonzero(np.asarray(yarns.group) == group):
        yarn = yarns.yarn(k)
        if len(yarn) < 2:
            continue
        stride = max(1, int(np.ceil(len(yarn) / max_points)))
        blocks.append(np.vstack([yarn[::stride], yarn[-1:]]))
    return blocks


def _lines(blocks):
    """One PolyData of polylines (each block a polyline), or None for no block."""
    import pyvista as pv

    if not blocks:
        return None
    points = np.vstack(blocks)
    sizes = [len(b) for b in blocks]
    starts = np.cumsum([0, *sizes[:-1]])
    lines = np.concatenate([np.concatenate([[n], np.arange(s, s + n)]) for s, n in zip(starts, sizes)])
    return pv.PolyData(points, lines=lines)


def _clipped(blocks, centre, right, up, half_right, half_up):
    """The blocks cut to the runs of points inside the box ``|(p - centre) . right| <= half_right,
    |(p - centre) . up| <= half_up`` widened on each side by the longest segment: a segment that
    crosses the box then has both end points in the widened box, so every segment a view of that
    box shows is kept whole, and the segments it cannot show are not drawn."""
    out = []
    for b in blocks:
        rel = b - centre
        reach = float(np.max(np.linalg.norm(np.diff(b, axis=0), axis=1)))
        keep = (np.abs(rel @ right) <= half_right + reach) & (np.abs(rel @ up) <= half_up + reach)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], keep.astype(np.int8), [0]])))
        for a, z in zip(edges[::2], edges[1::2]):
            if z - a >= 2:
                out.append(b[a:z])
    return out


def _close_up(result, laid, centre, axis, across, third):
    """(centre, tangent, up, front, section radius) of a close-up at the middle of the braid.

    On the centerline at half the braided length, looking across its tangent from 27 deg off its
    principal normal (two faces of a square section in view); the radius is that of the laid yarn
    within 1 cm of that section.
    """
    braided = np.asarray(result.history["braided_length_m"], dtype=float) if result.steps else []
    if result.centerline is None or not len(braided) or len(laid) < 3:
        return centre, axis, (third - across) / np.sqrt(2.0), (across + third) / np.sqrt(2.0), \
            float(np.max(np.linalg.norm(laid - centre, axis=1), initial=1e-3))
    p, T, N, B = (np.asarray(a)[0] for a in result.centerline.frames_at(np.array([0.5 * braided[-1]])))
    rel = laid - p
    near = np.abs(rel @ T) < 0.01
    radius = float(np.max(np.linalg.norm(rel[near], axis=1))) if np.any(near) else \
        float(np.min(np.linalg.norm(rel, axis=1)))
    # mostly along the principal normal: a bend then runs towards the viewer, not off the view
    front = (N + 0.5 * B) / np.sqrt(1.25)
    up = (B - 0.5 * N) / np.sqrt(1.25)
    return p, T, up, front, max(radius, 1e-4)


def _sunk(mandrel, result):
    """The mandrel's vertices moved inwards by half a yarn thickness along their mean face normal,
    as the yarn centerlines lie above the surface: a yarn's straight segments between points on
    the facets dip below the drawn surface on a convex part (chord sag), and where they did, the
    surface hid one yarn family along half the part."""
    V = np.asarray(mandrel.vertices, dtype=np.float64)
    F = np.asarray(mandrel.faces, dtype=np.int64)
    config = getattr(result, "config", None)
    depth = 0.5 * float(config.yarn.thickness) if config is not None else 0.0
    if not depth > 0:
        return V
    normals = np.zeros_like(V)
    for k in range(3):
        np.add.at(normals, F[:, k], np.asarray(mandrel.face_normals, dtype=np.float64))
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    return V - depth * np.divide(normals, norm, out=np.zeros_like(V), where=norm > 0)


def _camera(plotter, centre, view, up, half_width, half_height, aspect, margin):
    """Parallel projection looking at ``centre`` along ``-view``, fitting the given half extents
    times ``margin``."""
    plotter.camera_position = [tuple(centre + 10.0 * max(half_width, half_height) * view),
                               tuple(centre), tuple(up)]
    plotter.enable_parallel_projection()
    plotter.camera.parallel_scale = margin * max(half_height, half_width / aspect)
    plotter.reset_camera_clipping_range()


def render_braided_mandrel(result, path, title: str, pictures=PICTURE_SETTINGS, frame=None) -> None:
    """Render ``result`` (mandrel + yarns, mandrel frame) into the PNG ``path``; ``pictures``:
    ``preform.settings.PictureSettings``; ``frame``: the centerline the views put the tip of on
    the left and measure the ruler along (the mandrel's: a layer braided backward has its own
    from the far end), None for the result's.

    Top: the whole braided part from the front (where the braid lies on the mandrel), tip on the
    left, with a ruler of arc length from the tip, drawing every k-th yarn where the pixels
    cannot show them all (:func:`whole_stride`); bottom: close-ups of the middle of the braid
    from the front and from the back (the yarn pattern); the three panels framed apart.
    """
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    yarns = result.yarns
    laid = np.asarray(yarns.points, dtype=np.float64).reshape(-1, 3)
    mandrel = result.mandrel
    faces = np.asarray(mandrel.faces, dtype=np.int64)
    cells = np.column_stack([np.full(len(faces), 3), faces]).ravel()
    surface = pv.PolyData(_sunk(mandrel, result), cells)
    focus = laid if len(laid) >= 3 else np.asarray(mandrel.vertices, dtype=np.float64)
    centre, axis, across, third = part_axes(focus, result.centerline)
    along = (focus - centre) @ axis
    lo, hi = float(along.min()), float(along.max())
    spread = float(np.max(np.abs((focus - centre) @ across)))
    depth = float(np.max(np.abs((focus - centre) @ third)))
    # whole part: mostly across its least spread (a bent part's bend plane faces the viewer)
    whole_view = (0.8 * third + 0.6 * across)
    whole_up = np.cross(whole_view, axis)
    whole_centre = centre + 0.5 * (lo + hi) * axis
    mid, tangent, up, front, radius = _close_up(result, laid, centre, axis, across, third)
    cl = result.centerline if frame is None else frame
    tip = np.asarray(cl.frames_at(np.array([0.0]))[0])[0] if cl is not None else None
    # the tip on the left in every view, as in the other pictures and the unrolled map
    whole_up = tip_left(whole_centre, whole_view, whole_up, tip)
    up = tip_left(mid, front, up, tip)
    w, h = pictures.mandrel_window_px
    margin = pictures.view_margin
    plotter = pv.Plotter(off_screen=True, window_size=(w, h), shape=(2, 2),
                         groups=[(0, np.s_[:])], border=True, border_color="black", border_width=2)
    plotter.render_window.SetMultiSamples(pictures.multi_samples)
    blocks = [_yarn_polylines(yarns, group, pictures.mandrel_points_per_yarn) for group in (0, 1)]
    whole_half_w = 0.5 * (hi - lo) + 0.1 * spread
    whole_half_h = max(spread, depth)
    stride = whole_stride(result, radius, whole_half_w, w, pictures)
    # the close-ups show a box 3 section radii wide around the middle: their lines are cut to it
    # (llvmpipe draws every line sent, visible or not)
    scale = margin * max(1.5 * radius, 3.0 * radius / (w / h))
    close_stride = whole_stride(result, radius, 3.0 * radius, w // 2, pictures)
    cut = [_clipped(b[::close_stride], mid, np.cross(front, up), up, scale * w / h, scale) for b in blocks]
    whole = [_lines(b[::stride]) for b in blocks]
    close = [_lines(b) for b in cut]
    drawn = "" if stride == 1 else f" (every {_ordinal(stride)} yarn drawn: the pixels cannot show them all)"
    # the back close-up is the part turned over about its axis: view and up reversed, the
    # screen's right (up x view) kept, so the tip stays on the left (a rotation, not a mirror)
    views = [((0, 0), whole_view, whole_up, whole_centre - 0.2 * whole_half_h * whole_up, whole_half_w,
              1.4 * whole_half_h, 2.0 * w / h, f"{title}: braided part{drawn}"),
             ((1, 0), front, up, mid, 3.0 * radius, 1.5 * radius, w / h,
              "middle of the braid, front" + ("" if close_stride == 1 else f" (every {_ordinal(close_stride)} yarn)")),
             ((1, 1), -front, -up, mid, 3.0 * radius, 1.5 * radius, w / h,
              "middle of the braid, back (turned over about its axis)")]
    try:
        for (row, col), view, view_up, look_at, half_w, half_h, aspect, label in views:
            plotter.subplot(row, col)
            plotter.set_background("white")
            plotter.add_mesh(surface, color=MANDREL_COLOUR, smooth_shading=True, ambient=0.35, diffuse=0.7)
            for group, poly in enumerate(close if row else whole):
                if poly is not None:
                    plotter.add_mesh(poly, color=COLOURS[group], line_width=1.5 if row else 1.0)
            plotter.add_text(label, font_size=10 if row else 11, color="black", position="upper_left")
            if row == 0 and cl is not None:
                add_ruler(plotter, cl, whole_centre, view, view_up, whole_half_w, whole_half_h,
                          margin=margin)
            _camera(plotter, look_at, view, view_up, half_w, half_h, aspect, margin)
        plotter.screenshot(str(path))
    finally:
        plotter.close()


def whole_stride(result, radius, half_w, width_px, pictures=PICTURE_SETTINGS) -> int:
    """k: draw every k-th yarn of a family in the whole part's view, so that neighbouring lines
    stay ``pictures.min_yarn_spacing_px`` apart (closer ones alias into a moire). Neighbouring
    yarns of a family lie ``2 pi r cos(alpha) / n`` apart on a section of radius r (n yarns a
    family, alpha the braid angle at the end of the run)."""
    n = max(1, int(result.yarns.n_yarns) // 2)
    alpha = 0.0
    if result.steps:
        alpha = np.radians(float(np.nanmean([result.history["braid_angle_warp_deg"][-1],
                                             result.history["braid_angle_weft_deg"][-1]])))
    spacing = 2.0 * np.pi * radius * max(np.cos(alpha), 0.05) / n
    px = spacing * width_px / (2.0 * pictures.view_margin * max(half_w, 1e-9))
    return max(1, int(np.ceil(pictures.min_yarn_spacing_px / max(px, 1e-9))))


def _ordinal(k: int) -> str:
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


#: the colour of the tip's label in every 3-D view (none of viridis' colours, so a test can find it)
TIP_COLOUR = "#ff7f0e"


def nice_length(span: float, ticks: int = 6) -> float:
    """A round step (1, 2 or 5 times a power of ten) giving about ``ticks`` steps over ``span``."""
    if not span > 0:
        return 1.0
    raw = span / ticks
    power = 10.0 ** np.floor(np.log10(raw))
    return float(next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= raw * (1 - 1e-9)))


def tip_left(centre, view, up, tip):
    """``up`` (or its opposite) such that the tip lies on the left of a camera looking along
    ``-view``: screen right is ``up x view``. Turning ``up`` over turns the part about the
    viewing direction (a rotation, never a mirror image)."""
    if tip is not None and float(np.dot(np.asarray(tip) - centre, np.cross(up, view))) > 0:
        return -up
    return up


#: pixels from the part's lowest point down to the ruler, and the ruler's ticks' height, where
#: the view gives its scale (``add_ruler``'s ``pixel``)
RULER_GAP_PX, RULER_TICK_PX = 14, 12


def add_ruler(plotter, centerline, centre, view, up, half_w, half_h, s_range=None, pixel=None,
              margin=1.08):
    """Arc-length marks under the part: a ruler along the screen's horizontal below the part,
    a tick and a label ``s (m)`` where the centerline reaches each round arc length, and the tip
    labelled (in TIP_COLOUR). ``half_w``, ``half_h``: the part's half extents across the screen;
    ``pixel``: metres a pixel of the view (the ruler then sits RULER_GAP_PX under the part), or
    None (a share of ``half_h`` under it); ``margin``: the view's half width over ``half_w``."""
    import pyvista as pv

    right = np.cross(up, view)
    length = float(centerline.length)
    lo, hi = (0.0, length) if s_range is None else s_range
    step = nice_length(2.0 * half_w, 5)     # round marks over what the view shows
    s = np.arange(np.ceil(lo / step - 1e-9) * step, hi + 1e-9, step)
    points = np.asarray(centerline.frames_at(s)[0]) if len(s) else np.zeros((0, 3))
    x = (points - centre) @ right
    keep = np.abs(x) <= margin * half_w   # what the view shows
    s, x = s[keep], x[keep]
    gap, tick, drop = ((0.15 * half_h, 0.18 * half_h, 0.12 * half_h) if pixel is None else
                       (RULER_GAP_PX * pixel, RULER_TICK_PX * pixel, 0.8 * RULER_TICK_PX * pixel))
    base = centre - (half_h + gap) * up
    if len(s) >= 2:
        ends = [base + x.min() * right, base + x.max() * right]
        ticks = [p for xi in x for p in (base + xi * right, base + xi * right + tick * up)]
        pts = np.array(ends + ticks)
        n = len(pts)
        lines = np.concatenate([[2, 0, 1], *([2, k, k + 1] for k in range(2, n, 2))])
        plotter.add_mesh(pv.PolyData(pts, lines=lines), color="black", line_width=2)
        digits = max(0, -int(np.floor(np.log10(step))))
        labels = [f"{abs(v) if abs(v) < 0.5 * step else v:.{digits}f} m" for v in s]
        plotter.add_point_labels(base[None, :] + x[:, None] * right[None, :] - drop * up,
                                 labels, font_size=14, text_color="black", shape=None,
                                 show_points=False, always_visible=True, justification_horizontal="center",
                                 justification_vertical="top")
    tip = np.asarray(centerline.frames_at(np.array([0.0]))[0])[0]
    if abs(float((tip - centre) @ right)) <= 1.05 * half_w:
        plotter.add_point_labels(tip[None, :], ["tip"], font_size=14, text_color="white",
                                 shape="rounded_rect", shape_color=TIP_COLOUR, shape_opacity=1.0,
                                 show_points=False, always_visible=True)
