"""``fe/preform.inp`` and ``fe/layup.csv`` of ideal helical braids on a cylinder, read back by a
reader of the keyword cards written from their descriptions (CalculiX manual, *NODE, *ELEMENT,
*NSET/*ELSET, *MATERIAL/*ELASTIC, *ORIENTATION, *SHELL SECTION): the plies against the braid's
known angles, thicknesses and fibre fractions, one layer and two."""

from __future__ import annotations

import csv
import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from preform.analysis import rtm
from preform.analysis.fields import map_to_surface, stack_layers
from preform.materials import PRESETS
from preform.io import fe_files
from preform.io.fe_files import curved_midpoint
from preform.structural.layup import BinSettings, structural_layup
from preform.structural.micromechanics import chamis
from support.field_standins import R, cylinder, helices, make_result

TEX, RHO, CAVITY, N_GROUP = 800.0, 1780.0, 1.0e-3, 24
FM = PRESETS["AS4/3501-6"][0]


def write_structural(result, fields, folder, layer_results=(), settings=None):
    """The structural files of a run as the pipeline makes them: its layup (the analysis,
    ``layup.structural_layup``) written by ``io.fe_files.write_structural``; (paths, what the summary
    says)."""
    layup, reason = structural_layup(result, fields, layer_results, settings or BinSettings())
    paths, said = fe_files.write_structural(layup, folder)
    return paths, (said if layup is not None else {"written": False, "reason": reason})


def read_deck(path):
    """cards: list of (keyword line, data lines), in file order; ``**`` lines are comments."""
    cards = []
    for line in path.read_text().splitlines():
        if line.startswith("**") or not line.strip():
            continue
        if line.startswith("*"):
            cards.append((line, []))
        else:
            cards[-1][1].append(line)
    return cards


def params(keyword):
    parts = [p.strip() for p in keyword.split(",")]
    return parts[0].upper(), {p.split("=")[0].upper(): (p.split("=")[1] if "=" in p else True) for p in parts[1:]}


def parse(path):
    out = NS(nodes={}, elements={}, nsets={}, elsets={}, materials={}, orientations={}, sections={})
    for keyword, data in read_deck(path):
        name, p = params(keyword)
        rows = [[v.strip() for v in line.split(",")] for line in data]
        if name == "*NODE":
            out.nodes.update({int(r[0]): np.array([float(v) for v in r[1:4]]) for r in rows})
            out.nsets[p["NSET"]] = [int(r[0]) for r in rows]
        elif name == "*ELEMENT":
            assert p["TYPE"] == "S6"
            out.elements.update({int(r[0]): [int(v) for v in r[1:7]] for r in rows})
            out.elsets[p["ELSET"]] = [int(r[0]) for r in rows]
        elif name in ("*NSET", "*ELSET"):
            ids = [int(v) for r in rows for v in r if v]
            (out.nsets if name == "*NSET" else out.elsets)[p.get("NSET", p.get("ELSET"))] = ids
        elif name == "*MATERIAL":
            current = p["NAME"]
        elif name == "*ELASTIC":
            assert p["TYPE"] == "ENGINEERING CONSTANTS"
            out.materials[current] = [float(v) for r in rows for v in r if v]
        elif name == "*ORIENTATION":
            out.orientations[p["NAME"]] = np.array([float(v) for v in rows[0]])
        elif name == "*SHELL SECTION":
            assert "COMPOSITE" in p and float(p["OFFSET"]) == -0.5
            out.sections[p["ELSET"]] = [(float(r[0]), r[2], r[3], r[4]) for r in rows]
    return out


def braided(alphas, folder, settings=None, axial=(0, 4e-3, 2.5e-4, None)):
    """write_structural of ideal helices at each braid angle in ``alphas`` (deg), one layer per
    angle on one field mesh, with ``axial`` yarns (count, width, thickness, tex) in the first;
    (fields, summary, parsed deck, layup rows)."""
    first = make_result(cylinder(), helices(math.radians(alphas[0]), N_GROUP))
    first.config.axial = lambda: axial
    base = map_to_surface(first, edge_length=0.012)
    mesh = (base.vertices, base.faces, base.source_faces, base.edge_length_m)
    config = NS(yarn=NS(linear_density_tex=TEX, fibre_density=RHO, fibre_radius=3.5e-6, has_material=True),
                rtm=NS(cavity_thickness=CAVITY, permeability="gebart", packing="hexagonal"),
                axial=lambda: axial, material=NS(constituents=FM), source=None)
    layers = [base] + [map_to_surface(make_result(cylinder(), helices(math.radians(a), N_GROUP)), mesh=mesh)
                       for a in alphas[1:]]
    tangents = np.tile([0.0, 0.0, 1.0], (len(base.faces), 1))
    if len(layers) == 1:
        fields = base
        fields.cell_data.update(rtm.rtm_fields(fields, config, tangents))
    else:
        fields = stack_layers(layers)
        fields.cell_data.update(rtm.stacked_rtm_fields(layers, [config] * len(layers), tangents, CAVITY))
    result = make_result(cylinder(), None)
    result.config = config
    more = [NS(config=config) for _ in alphas[1:]]
    paths, said = write_structural(result, fields, folder, more, settings)
    rows = list(csv.DictReader((folder / "fe" / "layup.csv").open()))
    return fields, said, parse(folder / "fe" / "preform.inp"), rows


@pytest.fixture(scope="module")
def one_layer(tmp_path_factory):
    return braided([30.0], tmp_path_factory.mktemp("deck1"))


def test_the_deck_reads_back_complete_and_consistent(one_layer):
    fields, said, deck, rows = one_layer
    assert said["written"] and said["elements"] == len(deck.elements) == len(rows)
    assert said["nodes"] == len(deck.nodes) and sorted(deck.nodes) == list(range(1, len(deck.nodes) + 1))
    assert sorted(deck.elsets["BRAIDED"]) == sorted(deck.elements)
    assert sorted(deck.nsets["BRAIDED"]) == sorted(deck.nodes)
    groups = [g for g in deck.elsets if g.startswith("G")]
    assert len(groups) == said["groups"]
    assert sorted(e for g in groups for e in deck.elsets[g]) == sorted(deck.elements)
    for e in deck.elements:
        plies = deck.sections[f"E{e}"]
        assert deck.elsets[f"E{e}"] == [e] and [p[3] for p in plies] == ["L1WARP", "L1WEFT"]
        for t, material, orientation, _ in plies:
            assert t > 0 and material in deck.materials and orientation in deck.orientations
    for name, values in deck.materials.items():   # the deck's constants are Chamis's at its Vf
        c = chamis(FM, int(name[2:]) / 1000.0)
        np.testing.assert_allclose(values, [c.E1, c.E2, c.E2, c.nu12, c.nu12, c.nu23, c.G12, c.G12, c.G23],
                                   rtol=1e-9)
    assert all(np.isfinite(float(v)) for r in rows for k, v in r.items() if k.endswith(("_Pa", "_m", "_deg")))


def test_plies_follow_the_helices(one_layer):
    """Warp and weft at +-30 deg from the axis about the outward normal (the local 2-axis is
    normal x axis; the helpers' warp winds clockwise seen from +z, along it), in the element's
    plane, each half the cavity, at the face's Vf."""
    fields, said, deck, rows = one_layer
    err = said["binning_error"]
    steps = BinSettings()
    assert err["angle_deg"] <= steps.angle_step_deg / 2 + 1e-12
    assert err["vf"] <= steps.vf_step / 2 + 1e-12
    assert err["thickness_rel"] <= steps.thickness_step / 2 + 1e-9
    for row in rows:
        e = int(row["element"])
        corners = np.array([deck.nodes[n] for n in deck.elements[e][:3]])
        n = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        n /= np.linalg.norm(n)
        centroid = corners.mean(axis=0)
        if abs(n[2]) > 0.5:
            continue   # a face of the end cap the pooling spread yarn onto: no braid angle there
        assert np.dot(n, [centroid[0], centroid[1], 0.0]) > 0          # outward
        axis = np.array([0.0, 0.0, 1.0]) - n[2] * n
        axis /= np.linalg.norm(axis)
        for k, family in ((1, "warp"), (2, "weft")):
            a_b = deck.orientations[f"O{e}_{k}"]
            a = a_b[:3]
            # in the element's plane and unit, to the deck's 10 significant digits
            assert abs(np.dot(a, n)) < 1e-8 and abs(np.linalg.norm(a) - 1) < 1e-8
            turned = math.degrees(math.atan2(np.dot(np.cross(axis, a), n), np.dot(axis, a)))
            assert turned == pytest.approx(float(row[f"ply{k}_angle_deg"]), abs=1e-6)
            expected = 30.0 if family == "warp" else -30.0
            # the pooled direction is within 0.5 deg of the helix (test_fields), binned on top
            assert turned == pytest.approx(expected, abs=0.5 + err["angle_deg"])
            face = int(row["face"])
            assert float(row[f"ply{k}_thickness_m"]) == pytest.approx(
                0.5 * CAVITY, rel=0.05)   # warp and weft fibre equal to the pooling's few %
        t = float(row["ply1_thickness_m"]) + float(row["ply2_thickness_m"])
        assert t == pytest.approx(CAVITY, rel=err["thickness_rel"] + 1e-9)
        vf = fields.cell_data["fibre_volume_fraction"][face]
        assert vf == pytest.approx(float(deck.sections[f"E{e}"][0][1][2:]) / 1000, abs=err["vf"] + 1e-9)


def test_tip_and_end_are_the_two_boundary_loops(one_layer):
    fields, said, deck, rows = one_layer
    assert said["boundary_loops"] == 2 and said["tip_nodes"] == len(deck.nsets["TIP"])
    z_tip = [deck.nodes[n][2] for n in deck.nsets["TIP"]]
    z_end = [deck.nodes[n][2] for n in deck.nsets["END"]]
    assert max(z_tip) < min(z_end)
    on_boundary = set(deck.nsets["TIP"]) | set(deck.nsets["END"])
    counts = {}
    for nodes in deck.elements.values():
        for a, b, m in ((0, 1, 3), (1, 2, 4), (2, 0, 5)):
            key = (min(nodes[a], nodes[b]), max(nodes[a], nodes[b]), nodes[m])
            counts[key] = counts.get(key, 0) + 1
    free = {n for key, c in counts.items() if c == 1 for n in key}
    assert free == on_boundary


def test_mid_edge_nodes_follow_the_cylinder():
    """On a circle the Hermite middle is O(h^4 / r^3) off the arc, the chord's h^2 / (8 r)."""
    errors = []
    for h in (0.02, 0.01, 0.005):
        phi = h / (2 * R)
        p0 = np.array([[R * math.cos(-phi), R * math.sin(-phi), 0.0]])
        p1 = np.array([[R * math.cos(phi), R * math.sin(phi), 0.1]])
        n0, n1 = p0 * [1, 1, 0] / R, p1 * [1, 1, 0] / R
        m = curved_midpoint(p0, p1, n0, n1)[0]
        errors.append(abs(math.hypot(m[0], m[1]) - R))
        assert errors[-1] < 0.05 * h * h / (8 * R)
    # fourth order: halving h divides the error by 16 (here 15.7 and 15.9)
    assert errors[0] / errors[1] == pytest.approx(16, rel=0.05) and errors[1] / errors[2] == pytest.approx(16, rel=0.05)
    crease = curved_midpoint(np.zeros((1, 3)), np.array([[1.0, 0, 0]]), np.array([[0, 0, 1.0]]),
                             np.array([[1.0, 0, 0]]))
    np.testing.assert_allclose(crease, [[0.5, 0, 0]])


def test_two_layers_are_four_plies_from_the_mandrel_out(tmp_path):
    fields, said, deck, rows = braided([30.0, 60.0], tmp_path)
    assert said["plies"] == ["L1WARP", "L1WEFT", "L2WARP", "L2WEFT"]
    inner = [r for r in rows if abs(float(r["z_m"]) - 0.1) < 0.05]
    assert inner
    for r in inner:
        angles = [float(r[f"ply{k}_angle_deg"]) for k in range(1, 5)]
        np.testing.assert_allclose(angles, [30, -30, 60, -60], atol=0.5 + said["binning_error"]["angle_deg"])
        assert [r[f"ply{k}_layer"] for k in range(1, 5)] == ["1", "1", "2", "2"]
        t = [float(r[f"ply{k}_thickness_m"]) for k in range(1, 5)]
        # each layer fills its share of the cavity in proportion to its own thickness, which
        # goes as 1 / cos(alpha) (the same yarns, more length per area at 60 deg)
        share = (1 / math.cos(math.radians(60))) / (1 / math.cos(math.radians(30)))
        assert (t[2] + t[3]) / (t[0] + t[1]) == pytest.approx(share, rel=0.05)
        assert sum(t) == pytest.approx(CAVITY, rel=2 * said["binning_error"]["thickness_rel"] + 1e-9)


def test_without_material_nothing_is_written_and_the_summary_says_why(tmp_path, one_layer):
    fields = one_layer[0]
    (tmp_path / "fe").mkdir()
    (tmp_path / "fe" / "preform.inp").write_text("an earlier run's deck")
    result = make_result(cylinder(), None)
    result.config = NS(material=None, yarn=NS(has_material=True), source=None)
    paths, said = write_structural(result, fields, tmp_path)
    assert paths == [] and not said["written"] and "[material]" in said["reason"]
    assert not (tmp_path / "fe" / "preform.inp").exists()
    result.config = NS(material=NS(constituents=FM), yarn=NS(has_material=False), source=None)
    paths, said = write_structural(result, fields, tmp_path)
    assert not said["written"] and "linear_density_tex" in said["reason"]


def test_axial_yarns_are_a_third_ply_along_the_axis(tmp_path):
    """Triaxial: 16 axial yarns of the braid's tex. Per face, fibre volume per area goes as the
    yarn length per area: 2 x 24 helices / (2 pi R cos 30) against 16 / (2 pi R) axial."""
    fields, said, deck, rows = braided([30.0], tmp_path, axial=(16, 3e-3, 3e-4, None))
    assert said["plies"] == ["L1WARP", "L1WEFT", "L1AXIAL"]
    share = 16 / (16 + 2 * N_GROUP / math.cos(math.radians(30)))
    inner = [r for r in rows if 0.05 < float(r["z_m"]) < 0.15]
    assert inner
    for r in inner:
        assert float(r["ply3_angle_deg"]) == pytest.approx(0.0, abs=said["binning_error"]["angle_deg"] + 1e-9)
        t = [float(r[f"ply{k}_thickness_m"]) for k in (1, 2, 3)]
        # 5 %: the pooled helix lengths' few % (test_rtm_fields' triaxial areal weight: 3 %)
        assert t[2] / sum(t) == pytest.approx(share, rel=0.05)
        assert r["ply3_family"] == "axial"
