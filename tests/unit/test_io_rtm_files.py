"""RTM solver files read back by independent readers written from the formats' descriptions."""

from __future__ import annotations

import h5py
import numpy as np
import trimesh

from preform.io.rtm_files import write_lcmsim_h5, write_rtmsim_bdf
from preform.analysis.rtm import bin_cells


def mesh():
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.37)
    return m.vertices + [1.25, -0.5, 2.0], m.faces


def read_bdf(path):
    """A reader of Nastran bulk data from its card descriptions (fixed columns; not our writer):
    small field = 8 columns per field, large field (GRID*) = 8 + 4 x 16 with a '*' continuation;
    a '+' in columns 73-80 continues a small-field card on the next line."""
    grids, trias, sets = {}, {}, {}
    lines = path.read_text().splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        name = line[:8].strip()
        if name == "GRID*":
            nid = int(line[8:24])
            x, y = float(line[40:56]), float(line[56:72])
            nxt = lines[i + 1]
            assert nxt[:8].strip() == "*"
            grids[nid] = (x, y, float(nxt[8:24]))
            i += 2
            continue
        if name == "CTRIA3":
            f = [line[k:k + 8] for k in range(8, 48, 8)]
            trias[int(f[0])] = (int(f[1]), int(f[2]), int(f[3]), int(f[4]))
        elif name == "SET1":
            fields = [line[k:k + 8] for k in range(8, 72, 8)]
            while line[72:80].strip() == "+":
                i += 1
                line = lines[i]
                fields += [line[k:k + 8] for k in range(8, 72, 8)]
            values = [int(v) for v in fields if v.strip()]
            sets[values[0]] = values[1:]
        i += 1
    return grids, trias, sets


def test_bdf_round_trip_and_binning(tmp_path):
    V, F = mesh()
    k1 = np.exp(np.linspace(np.log(1e-12), np.log(8e-11), len(F)))
    binning = bin_cells(k1, 4)
    index, rep = binning.index, binning.values
    values = [(1e-3, 0.45, r, 0.3, (1.0, 0.0, 0.0)) for r in rep]
    bdf, sets_csv = write_rtmsim_bdf(tmp_path / "rtmsim.bdf", V, F, index, values)
    grids, trias, sets = read_bdf(bdf)
    np.testing.assert_allclose([grids[i + 1] for i in range(len(V))], V, rtol=1e-9, atol=1e-12)
    assert [trias[e + 1][1:] for e in range(len(F))] == [tuple(int(v) + 1 for v in f) for f in F]
    assert sorted(sets) == [1, 2, 3, 4]
    for sid, members in sets.items():
        assert all(trias[e][0] == sid for e in members)
        cells = np.array(members) - 1
        # every cell's K within the reported largest factor of its set's value
        assert np.all(np.abs(np.log(k1[cells] / rep[sid - 1])) <= np.log(binning.max_factor) + 1e-12)
    assert sum(len(m) for m in sets.values()) == len(F)
    table = np.loadtxt(sets_csv, delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 4], rep, rtol=1e-15)
    np.testing.assert_array_equal(table[:, 0], [1, 2, 3, 4])
    np.testing.assert_array_equal(table[:, 1], [len(sets[k]) for k in (1, 2, 3, 4)])


def test_lcmsim_h5_round_trip(tmp_path):
    V, F = mesh()
    n = len(F)
    rng = np.random.default_rng(0)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    props = dict(thickness=rng.uniform(5e-4, 1e-3, n), porosity=rng.uniform(0.4, 0.6, n),
                 k1=rng.uniform(1e-12, 1e-10, n), alpha=rng.uniform(0.2, 1.0, n))
    path = write_lcmsim_h5(tmp_path / "lcmsim.h5", V, F, props["thickness"], props["porosity"],
                           props["k1"], props["alpha"], direction)
    with h5py.File(path, "r") as f:   # h5py reads the layout the format describes
        np.testing.assert_array_equal(f["/mesh/vertices"][...], V)
        np.testing.assert_array_equal(f["/mesh/cells"][...], F)
        np.testing.assert_array_equal(f["/properties/thickness"][...], props["thickness"])
        np.testing.assert_array_equal(f["/properties/porosity"][...], props["porosity"])
        np.testing.assert_array_equal(f["/properties/permeability"][...], props["k1"])
        np.testing.assert_array_equal(f["/properties/alpha"][...], props["alpha"])
        np.testing.assert_array_equal(f["/properties/reference_direction"][...], direction)
