"""RTMsim's few property sets carry the K1 field: the binning error, the ids, the cavity warning."""

from __future__ import annotations

import itertools
import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from preform.analysis import rtm
from preform.io import rtm_files
from preform.io.rtm_files import SETS_COLUMNS


def write_rtm(fields, out_dir, cavity_thickness=None):
    """The RTM solver files as a run makes them: the cells' properties and sets
    (``analysis.rtm.solver_properties``) written by ``io.rtm_files.write_rtm``; (paths, what the
    summary says)."""
    config = SimpleNamespace(yarn=SimpleNamespace(has_material=True),
                             rtm=SimpleNamespace(cavity_thickness=cavity_thickness))
    properties, reason = rtm.solver_properties(config, fields)
    assert properties is not None, reason
    return rtm_files.write_rtm(properties, out_dir), properties.said()


def rms_log(values, weights, index, centres_log):
    """The area-weighted root mean square of ln(K / K_set): the obvious sum."""
    dev = np.log(values) - centres_log[index]
    return math.sqrt(float(np.sum(weights * dev * dev) / np.sum(weights)))


def equal_width_binning(values, n):
    """The obvious reference: n equal widths of ln K, each set at its members' area-weighted
    mean of ln K. Returns (index, centres_log)."""
    logs = np.log(values)
    edges = np.linspace(logs.min(), logs.max(), n + 1)
    index = np.clip(np.searchsorted(edges, logs, side="right") - 1, 0, n - 1)
    centres = np.array([logs[index == k].mean() if np.any(index == k) else 0.0 for k in range(n)])
    return index, centres


def test_a_uniform_spread_of_log_k_is_cut_into_equal_widths():
    # ln K uniform over [a, b]: the best n sets are n equal widths, each a uniform spread of width
    # w = (b - a) / n about its mean, whose rms deviation is w / sqrt(12) (closed form)
    n, lo, hi = 4, math.log(1e-12), math.log(1e-9)
    values = np.exp(np.linspace(lo, hi, 4001))
    binning = rtm.bin_cells(values, n)
    expected = (hi - lo) / n / math.sqrt(12.0)
    # 1e-3: 4001 points stand for the continuum; the discrete rms differs by O(1 / points per set)
    assert math.log(binning.rms_factor) == pytest.approx(expected, rel=1e-3)
    np.testing.assert_array_equal(np.bincount(binning.index), [1000, 1000, 1000, 1001])


@pytest.fixture(scope="module")
def skewed():
    """A field like a braid's: most faces in a narrow band of K1, a tail of edge faces up to 700
    times higher, random face areas."""
    rng = np.random.default_rng(11)
    bulk = np.exp(rng.normal(math.log(2.5e-12), 0.12, 1900))
    tail = np.exp(rng.uniform(math.log(5e-12), math.log(1.7e-9), 100))
    values = np.concatenate([bulk, tail])
    return values, rng.uniform(0.5, 1.5, len(values))


@pytest.mark.parametrize("n", [2, 3, 4])
def test_the_binning_error_is_below_its_bound_and_the_equal_widths(skewed, n):
    values, area = skewed
    binning = rtm.bin_cells(values, n, weights=area)
    ours = math.log(binning.rms_factor)
    assert ours == pytest.approx(rms_log(values, area, binning.index, np.log(binning.values)), rel=1e-12)
    # bound: from the equal-width start every Lloyd step lowers the error; equal widths leave no
    # face further than half a width from its bin's middle, and a set's mean of ln K is closer in
    # mean square than the middle: rms <= ln(K_max / K_min) / (2 n)
    spread = math.log(values.max() / values.min())
    assert ours <= spread / (2 * n)
    reference = rms_log(values, area, *equal_width_binning(values, n))
    assert ours <= reference + 1e-12
    assert np.all(np.abs(np.log(values / binning.values[binning.index])) <= math.log(binning.max_factor) + 1e-12)


def test_the_binning_is_the_best_three_sets_of_a_small_sample():
    # every partition of 40 sorted values into 3 runs (an optimal 1-D partition is contiguous)
    rng = np.random.default_rng(5)
    values = np.sort(np.exp(np.concatenate([rng.normal(-27, 0.1, 30), rng.uniform(-26, -22, 10)])))
    area = rng.uniform(0.5, 1.5, len(values))
    logs = np.log(values)
    best = math.inf
    for i, j in itertools.combinations(range(1, len(values)), 2):
        index = np.repeat([0, 1, 2], [i, j - i, len(values) - j])
        centres = np.array([np.sum(area[index == k] * logs[index == k]) / np.sum(area[index == k])
                            for k in range(3)])
        best = min(best, rms_log(values, area, index, centres))
    ours = math.log(rtm.bin_cells(values, 3, weights=area).rms_factor)
    assert best <= ours + 1e-12
    # Lloyd's iteration finds a local optimum; on this sample, from two starts, the global one
    assert ours == pytest.approx(best, rel=1e-9)


def fields_of(k1, vf, thickness, valid):
    """SurfaceFields-like arrays on an icosphere's faces (the write_rtm inputs)."""
    m = trimesh.creation.icosphere(subdivisions=4, radius=0.2)
    nf = len(m.faces)
    assert nf >= len(k1)
    take = lambda a, fill: np.concatenate([a, np.full(nf - len(a), fill)])  # noqa: E731
    direction = np.tile([1.0, 0.0, 0.0], (nf, 1))
    cd = {"rtm_valid": take(valid.astype(np.uint8), 0).astype(np.uint8),
          "permeability_k1_m2": take(k1, 0.0), "permeability_k2_m2": take(0.3 * k1, 0.0),
          "permeability_direction": direction, "fibre_volume_fraction": take(vf, 0.0),
          "porosity": 1.0 - take(vf, 0.0), "thickness_m": take(thickness, 0.0)}
    return SimpleNamespace(vertices=np.asarray(m.vertices), faces=np.asarray(m.faces), cell_data=cd)


def parse_bdf(text):
    """CTRIA3 element -> property id, SET1 id -> members: fixed 8-column fields, '+' continues."""
    pids, sets, lines, i = {}, {}, text.splitlines(), 0
    while i < len(lines):
        line = lines[i]
        if line[:8].strip() == "CTRIA3":
            pids[int(line[8:16])] = int(line[16:24])
        elif line[:8].strip() == "SET1":
            fields = [line[k:k + 8] for k in range(8, 72, 8)]
            while line[72:80].strip() == "+":
                i += 1
                line = lines[i]
                fields += [line[k:k + 8] for k in range(8, 72, 8)]
            ids = [int(v) for v in fields if v.strip()]
            sets[ids[0]] = ids[1:]
        i += 1
    return pids, sets


def test_the_bdf_ids_the_sets_csv_and_the_summary_agree(tmp_path, skewed):
    values, _ = skewed
    n_preform = 1500
    k1 = values[-n_preform:]                 # 1400 of the band, the 100 of the tail
    fields = fields_of(k1, np.full(n_preform, 0.5), np.full(n_preform, 3e-4), np.ones(n_preform, bool))
    written, said = write_rtm(fields, tmp_path, cavity_thickness=2e-4)
    bdf = next(p for p in written if p.name == "rtmsim.bdf")
    text = bdf.read_text()
    pids, sets = parse_bdf(text)
    table = np.genfromtxt(bdf.with_name("rtmsim_sets.csv"), delimiter=",", names=True)
    assert tuple(table.dtype.names) == SETS_COLUMNS
    assert sorted(sets) == [int(p) for p in table["pid"]] == sorted(set(pids.values()))
    for pid, members in sets.items():
        assert all(pids[e] == pid for e in members)
        row = table[table["pid"] == pid][0]
        assert int(row["faces"]) == len(members)
    assert said["sets"] == len(sets) == 4                 # 3 preform sets + the resin channel
    assert said["faces_per_set"] == [int(n) for n in table["faces"]]
    # the channel (no preform) is the last set, at the cavity's Hele-Shaw h^2 / 12
    channel = [e for e in pids if e > n_preform]
    assert {pids[e] for e in channel} == {4}
    assert table["permeability_k1_m2"][-1] == pytest.approx(2e-4 ** 2 / 12, rel=1e-15)
    # every preform face's K1 within the reported largest factor of its set's
    k_set = table["permeability_k1_m2"][[pids[e] - 1 for e in range(1, n_preform + 1)]]
    assert np.all(np.abs(np.log(k1 / k_set)) <= math.log(said["k1_binning"]["max_factor"]) + 1e-12)
    assert said["k1_binning"]["sets_k1_m2"] == pytest.approx(list(table["permeability_k1_m2"][:3]), rel=1e-15)
    assert "property id is the id of the SET1" in text.splitlines()[0]
    assert said["compression"] == pytest.approx(1.5, rel=1e-12)     # 0.3 mm braided into 0.2 mm


@pytest.mark.parametrize("cavity, warns", [(9e-5, True), (2e-4, False)])
def test_a_cavity_that_packs_the_fibres_too_tight_is_warned_about(tmp_path, cavity, warns):
    # 0.2 kg/m^2 of glass (2560 kg/m^3) is 78 um of fibre: a 90 um cavity packs it to V_f 0.87,
    # beyond the pi / 4 where fibres touch; a 0.2 mm cavity to 0.39
    n = 500
    vf = rtm.fibre_volume_fraction(np.full(n, 0.2), 2560.0, cavity)
    k1 = rtm.gebart(vf, 6.5e-6, "hexagonal")[0]
    fields = fields_of(k1, vf, np.full(n, 3.5e-4), np.ones(n, bool))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, said = write_rtm(fields, tmp_path, cavity_thickness=cavity)
    texts = [str(w.message) for w in caught if "cavity_thickness" in str(w.message)]
    assert said["fibre_volume_fraction"]["max"] == pytest.approx(0.2 / 2560.0 / cavity, rel=1e-12)
    if warns:
        assert len(texts) == 1
        assert f"cavity_thickness = {cavity:g} m" in texts[0] and "0.785" in texts[0]
        assert "3.9 times" in texts[0]                     # 0.35 mm into 90 um
    else:
        assert texts == []
