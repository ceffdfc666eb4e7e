"""``fe/preform.inp`` (CalculiX ``ccx`` and Abaqus keyword deck) and ``fe/layup.csv``.

The deck holds, in SI units and the mandrel frame:

* ``*NODE``: the corners of the preform faces and one node at the middle of each of their
  edges, on the surface's curve (:func:`quadratic_mesh`); ``*ELEMENT, TYPE=S6``: 6-node triangular shells (corners, then the mid-edge nodes of
  edges 1-2, 2-3, 3-1), numbered 1.. in the order of ``layup.csv``, normals outward;
* element sets ``BRAIDED`` (all) and ``G1``, ``G2``, ... (the groups of :func:`layup.bin_plies`);
  node sets ``BRAIDED`` (all), ``TIP`` and ``END``: the nodes on the braided region's boundary
  loop nearest the centerline's tip, and on the loop nearest its far end;
* one ``*MATERIAL`` per fibre volume fraction of the groups (``VF0550`` at 0.550), elastic
  ``ENGINEERING CONSTANTS`` from Chamis's micromechanics (``micromechanics.chamis``);
* per element and ply an ``*ORIENTATION`` whose 1-axis is the ply's fibre direction: the
  group's ply angle turned from the element's local 1-axis (the mandrel's axis on the surface)
  about its normal, and one ``*SHELL SECTION, COMPOSITE`` with the group's plies (thickness,
  material, that orientation), from the mandrel outwards, ``OFFSET=-0.5`` so that the shell lies
  on the mandrel's surface, outside it. CalculiX names a ply's direction only by an orientation
  and takes element-wise orientations (``*DISTRIBUTION``) only in solid sections, so a group's
  section is written once per element; the plies are the group's.
* no step, but a commented template of an axial tension step.

Abaqus reads the same deck once ``TYPE=S6`` reads ``TYPE=STRI65`` (its 6-node triangular shell
of the same node order), see ``docs/structural.md``.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..materials import FibreMatrix
from ..structural.micromechanics import chamis
from .atomic import atomic_write_text, safe_folder

if TYPE_CHECKING:   # the types of the plies only: the writer imports no analysis
    from ..structural.layup import Groups, Plies

ELEMENT_TYPE = "S6"
#: Simpson integration points through each ply (Abaqus reads it; CalculiX ignores the field)
PLY_POINTS = 3


#: an edge whose end normals differ by more than this is a crease: its mid-edge node stays on the chord
CREASE_DEG = 30.0


def vertex_normals(vertices, faces) -> np.ndarray:
    """(nv, 3) unit normals at the vertices: the area-weighted mean of their faces' normals."""
    V, F = np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)
    weighted = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])   # normal x 2 area
    n = np.zeros_like(V)
    for j in range(3):
        np.add.at(n, F[:, j], weighted)
    norm = np.linalg.norm(n, axis=1)
    return np.divide(n, norm[:, None], out=np.zeros_like(n), where=norm[:, None] > 0)


def curved_midpoint(p0, p1, n0, n1):
    """Mid-edge points (n, 3) of the cubic Hermite curve from p0 to p1 tangent to the planes of
    the unit normals n0, n1 at its ends: ``(p0 + p1) / 2 + (T0 - T1) / 8`` with ``T = d - (d . n) n``
    the chord ``d = p1 - p0`` projected on each end's plane. On a circle of radius r through
    both ends this lies within ``O(h^4 / r^3)`` of the arc, where the chord's middle is
    ``h^2 / (8 r)`` inside it; on a crease (normals apart by more than CREASE_DEG) the chord's
    middle is kept."""
    d = p1 - p0
    t0 = d - np.einsum("ij,ij->i", d, n0)[:, None] * n0
    t1 = d - np.einsum("ij,ij->i", d, n1)[:, None] * n1
    mid = 0.5 * (p0 + p1) + (t0 - t1) / 8.0
    crease = np.einsum("ij,ij->i", n0, n1) < np.cos(np.radians(CREASE_DEG))
    return np.where(crease[:, None], 0.5 * (p0 + p1), mid)


def quadratic_mesh(vertices, faces):
    """(nodes (n, 3), connectivity (ne, 6) 0-based, corner vertex ids (nc,)) of 6-node triangles
    on the triangles ``faces`` of ``vertices``: the used corners first, in the order of their
    vertex ids, then the mid-edge nodes, on the curve through the corners that follows the
    surface's normals there (:func:`curved_midpoint`): flat 6-node facets on a curved part
    meet at kinks that bend under load, curved ones at slopes that differ by ``O((h / r)^2)``."""
    V, F = np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)
    used, corner = np.unique(F, return_inverse=True)
    corner = corner.reshape(F.shape)
    edges = np.sort(corner[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, mid = np.unique(edges, axis=0, return_inverse=True)
    P = V[used]
    n = vertex_normals(P, corner)
    midpoints = curved_midpoint(P[unique[:, 0]], P[unique[:, 1]], n[unique[:, 0]], n[unique[:, 1]])
    nodes = np.vstack([P, midpoints])
    connectivity = np.column_stack([corner, len(used) + mid.reshape(-1, 3)])
    return nodes, connectivity, used


def boundary_loops(connectivity) -> list[np.ndarray]:
    """The node ids (0-based, corners and mid-edge nodes) of each closed loop of boundary edges
    (edges of one element only) of the 6-node mesh."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    C = np.asarray(connectivity)
    edges = np.concatenate([C[:, [0, 1, 3]], C[:, [1, 2, 4]], C[:, [2, 0, 5]]])
    key = np.sort(edges[:, :2], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    free = edges[counts[inverse.ravel()] == 1]
    if len(free) == 0:
        return []
    n = int(C.max()) + 1
    pairs = np.concatenate([free[:, [0, 2]], free[:, [2, 1]]])
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    on = np.unique(free)
    return [on[label[on] == c] for c in np.unique(label[on])]


def material_name(vf: float) -> str:
    return f"VF{int(round(vf * 1000)):04d}"


def ply_name(layer: int, family: str) -> str:
    return f"L{layer}{family.upper()}"


def _fmt(x: float) -> str:
    return f"{x:.9e}"


def _ply_directions(plies: Plies, groups: Groups):
    """(a, b) (ne, P, 3): each element's plies' fibre directions at the group's angle, and the
    in-plane directions across them (local 1 and 2 axes of the ply)."""
    e1, n = plies.axis, plies.normal
    e2 = np.cross(n, e1)
    theta = np.radians(groups.angle_deg[groups.index])[:, :, None]
    a = np.cos(theta) * e1[:, None, :] + np.sin(theta) * e2[:, None, :]
    b = -np.sin(theta) * e1[:, None, :] + np.cos(theta) * e2[:, None, :]
    return a, b


def deck_text(nodes, connectivity, plies: Plies, groups: Groups, fm: FibreMatrix, tip, end,
              end_axis, title: str = "preform") -> str:
    """The keyword deck (see module docstring). ``tip``, ``end``: 0-based node ids of the two
    boundary loops (may be empty); ``end_axis``: unit axis direction at the end (for the
    template step)."""
    out = io.StringIO()
    w = out.write
    w("** preform: the braided part as composite shells, for CalculiX (ccx) and Abaqus\n"
      "** SI units (m, N, Pa), mandrel frame. Elements = the preform faces of surface.vtu\n"
      "** (layup.csv: element -> face, centroid and plies). Plies from the mandrel outwards,\n"
      "** one per yarn family and layer; a ply's orientation O<element>_<ply> has its 1-axis\n"
      "** along the fibres. Abaqus: read TYPE=STRI65 for TYPE=S6 below (same node order).\n")
    w(f"*HEADING\n{title}\n")
    w("*NODE, NSET=BRAIDED\n")
    w("".join(f"{i},{_fmt(x)},{_fmt(y)},{_fmt(z)}\n" for i, (x, y, z) in enumerate(nodes, start=1)))
    w(f"*ELEMENT, TYPE={ELEMENT_TYPE}, ELSET=BRAIDED\n")
    w("".join(f"{e}," + ",".join(str(int(v) + 1) for v in row) + "\n"
              for e, row in enumerate(connectivity, start=1)))
    for g in range(len(groups.angle_deg)):
        _id_lines(w, f"*ELSET, ELSET=G{g + 1}", np.nonzero(groups.index == g)[0] + 1)
    for name, ids in (("TIP", tip), ("END", end)):
        if len(ids):
            _id_lines(w, f"*NSET, NSET={name}", np.asarray(ids) + 1)
    present_vf = np.unique(groups.vf[groups.thickness_m > 0])
    constants = chamis(fm, present_vf)
    for i, vf in enumerate(present_vf):
        E1, E2, G12, nu12 = (float(getattr(constants, k)[i]) for k in ("E1", "E2", "G12", "nu12"))
        G23, nu23 = float(constants.G23[i]), float(constants.nu23[i])
        w(f"*MATERIAL, NAME={material_name(vf)}\n*ELASTIC, TYPE=ENGINEERING CONSTANTS\n")
        w(",".join(_fmt(v) for v in (E1, E2, E2, nu12, nu12, nu23, G12, G12)) + f"\n{_fmt(G23)}\n")
    a, b = _ply_directions(plies, groups)
    names = [ply_name(layer, family) for layer, family in plies.names]
    for e in range(len(connectivity)):
        g = groups.index[e]
        here = np.nonzero(groups.thickness_m[g] > 0)[0]
        for p in here:
            w(f"*ORIENTATION, NAME=O{e + 1}_{p + 1}\n" + ",".join(_fmt(v) for v in (*a[e, p], *b[e, p])) + "\n")
        w(f"*ELSET, ELSET=E{e + 1}\n{e + 1}\n*SHELL SECTION, ELSET=E{e + 1}, COMPOSITE, OFFSET=-0.5\n")
        for p in here:
            w(f"{_fmt(groups.thickness_m[g, p])},{PLY_POINTS},{material_name(groups.vf[g, p])},"
              f"O{e + 1}_{p + 1},{names[p]}\n")
    axis = np.asarray(end_axis, dtype=float)
    w(_template(end, end_weights(nodes, connectivity, end, axis), axis))
    return out.getvalue()


def _id_lines(w, card, ids, per_line=16):
    w(card + "\n")
    ids = [str(int(i)) for i in ids]
    for k in range(0, len(ids), per_line):
        w(",".join(ids[k:k + per_line]) + "\n")


def end_weights(nodes, connectivity, end, axis) -> np.ndarray:
    """(len(end),) shares (sum 1) of a uniform traction round the END loop: each boundary edge's
    share in proportion to its length round the axis, signed (its component along the hoop
    direction ``axis x normal`` of its element, in the element's winding), spread over its
    corner, middle and corner nodes as 1/6, 4/6, 1/6 (a quadratic edge's consistent loads). The
    loop is ragged (its edges zig-zag along the axis and back round it): equal nodal forces, or
    shares by unsigned length, would load it unevenly round and bend the part."""
    C = np.asarray(connectivity)
    P = np.asarray(nodes, dtype=float)
    owner = np.tile(np.arange(len(C)), 3)
    edges = np.concatenate([C[:, [0, 1, 3]], C[:, [1, 2, 4]], C[:, [2, 0, 5]]])
    key = np.sort(edges[:, :2], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    free = counts[inverse.ravel()] == 1
    on_end = np.zeros(len(P), dtype=bool)
    on_end[np.asarray(end, dtype=np.int64)] = True
    free &= on_end[edges].all(axis=1)
    edges, owner = edges[free], owner[free]
    normal = np.cross(P[C[owner, 1]] - P[C[owner, 0]], P[C[owner, 2]] - P[C[owner, 0]])
    hoop = np.cross(axis, normal)
    hoop /= np.maximum(np.linalg.norm(hoop, axis=1), 1e-300)[:, None]
    around = np.einsum("ij,ij->i", P[edges[:, 1]] - P[edges[:, 0]], hoop)
    weight = np.zeros(len(P))
    for column, share in ((0, 1 / 6), (1, 1 / 6), (2, 4 / 6)):
        np.add.at(weight, edges[:, column], share * around)
    w = weight[np.asarray(end, dtype=np.int64)]
    total = w.sum()
    return w / total if abs(total) > 0 else np.full(len(w), 1.0 / max(len(w), 1))


def _template(end, weights, axis, force=1000.0) -> str:
    """A commented axial tension step: TIP held, ``force`` N along the axis at END as a uniform
    traction round it (:func:`end_weights`)."""
    lines = ["", "---- template: axial tension (remove the leading '** ' of the lines below the next",
             f"---- one to use it). TIP held in translation; {force:g} N along the mandrel's axis at END,",
             "---- spread evenly round it; results to <job>.frd and <job>.dat",
             "----", "*STEP", "*STATIC", "*BOUNDARY", "TIP, 1, 3", "*CLOAD"]
    for node, w in zip(np.asarray(end, dtype=np.int64) + 1, weights):
        lines += [f"{node}, {k + 1}, {force * w * float(axis[k]):.9e}" for k in range(3) if abs(axis[k]) > 1e-12]
    lines += ["*NODE FILE", "U", "*EL FILE", "S, E", "*NODE PRINT, NSET=END", "U", "*END STEP"]
    return "".join(f"** {line}\n" if line else "**\n" for line in lines)


def layup_rows(plies: Plies, groups: Groups, fm: FibreMatrix, centroids) -> str:
    """``layup.csv``: one row per element (the deck's values: the groups')."""
    names = plies.names
    head = ["element", "face", "group", "x_m", "y_m", "z_m"]
    for k in range(1, len(names) + 1):
        head += [f"ply{k}_{c}" for c in ("angle_deg", "thickness_m", "E1_Pa", "E2_Pa", "G12_Pa", "nu12",
                                         "family", "layer")]
    g = groups.index
    vf = groups.vf[g]
    present = groups.thickness_m[g] > 0
    constants = chamis(fm, np.where(present, vf, 0.0))
    lines = [",".join(head)]
    for e in range(len(g)):
        row = [str(e + 1), str(int(plies.faces[e])), str(int(g[e]) + 1), *(repr(float(c)) for c in centroids[e])]
        for p, (layer, family) in enumerate(names):
            if not present[e, p]:
                row += [""] * 8
                continue
            row += [repr(float(groups.angle_deg[g[e], p])), repr(float(groups.thickness_m[g[e], p])),
                    *(repr(float(getattr(constants, k)[e, p])) for k in ("E1", "E2", "G12", "nu12")),
                    family, str(layer)]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"


def write_deck(folder, fields, plies: Plies, groups: Groups, fm: FibreMatrix, arc_length, axis_at,
               title="preform") -> tuple[list[Path], dict]:
    """Write ``preform.inp`` and ``layup.csv`` into ``folder``; (paths, what the summary says).

    arc_length : points (n, 3) -> centerline arc length (n,), to tell the tip's loop from the end's
    axis_at : arc length -> unit centerline tangent (3,), the axial direction of the template
    """
    F = np.asarray(fields.faces)[plies.faces]
    nodes, connectivity, _ = quadratic_mesh(fields.vertices, F)
    loops = boundary_loops(connectivity)
    tip = end = np.zeros(0, dtype=np.int64)
    s_end = float(np.max(arc_length(nodes)))
    if loops:
        s = [float(np.mean(arc_length(nodes[loop]))) for loop in loops]
        tip, end = loops[int(np.argmin(s))], loops[int(np.argmax(s))]
        s_end = max(s)
        if len(loops) == 1:   # one loop (a closed end): it is the end nearer to it
            tip = np.zeros(0, dtype=np.int64)
    text = deck_text(nodes, connectivity, plies, groups, fm, tip, end, axis_at(s_end), title)
    deck = atomic_write_text(Path(folder) / "preform.inp", text)
    V = np.asarray(fields.vertices)
    centroids = V[F].mean(axis=1)
    layup = atomic_write_text(Path(folder) / "layup.csv", layup_rows(plies, groups, fm, centroids))
    said = {"written": True, "elements": int(len(F)), "nodes": int(len(nodes)), "element_type": ELEMENT_TYPE,
            "groups": int(len(groups.angle_deg)),
            "materials": int(len(np.unique(groups.vf[groups.thickness_m > 0]))),
            "plies": [ply_name(layer, family) for layer, family in plies.names],
            "binning_error": groups.errors, "tip_nodes": int(len(tip)), "end_nodes": int(len(end)),
            "boundary_loops": len(loops)}
    return [deck, layup], said


FE_DIR = "fe"


def write_structural(layup, out_dir) -> tuple[list[Path], dict]:
    """``<out_dir>/fe/preform.inp`` and ``layup.csv`` of ``layup``
    (``preform.structural.layup.StructuralLayup``); (paths, what the summary says). With no
    layup (None) an earlier run's deck in this folder, which is not this run's, is removed."""
    if layup is None:
        _remove_earlier(out_dir)
        return [], {}
    centerline = layup.centerline

    def arc_length(points):
        return np.asarray(centerline.project(np.asarray(points, dtype=float))[0], dtype=float)

    def axis_at(s):
        return np.asarray(centerline.frames_at(np.array([float(s)]))[1], dtype=float)[0]

    folder = safe_folder(out_dir, FE_DIR)
    paths, said = write_deck(folder, layup.fields, layup.plies, layup.groups, layup.constituents,
                             arc_length, axis_at, title=layup.title)
    said["left_out_faces"] = layup.left_out_faces
    said["left_out"] = ("faces that are no preform (no yarn, or a fibre fraction below "
                        "preform.analysis.rtm.MIN_VF at the braid's fringe) and pieces apart from the braided part")
    return paths, said


def _remove_earlier(out_dir) -> None:
    """Removes ``preform.inp`` and ``layup.csv`` from ``<out_dir>/fe`` (a symlinked ``fe`` is
    left alone, as is anything else in it)."""
    folder = Path(out_dir) / FE_DIR
    if folder.is_dir() and not folder.is_symlink():
        for name in ("preform.inp", "layup.csv"):
            (folder / name).unlink(missing_ok=True)
