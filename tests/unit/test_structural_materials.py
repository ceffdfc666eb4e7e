"""Ply constants from Chamis's micromechanics against its limits and measured plies, and the
``[material]`` section's validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from preform.config import config_from_dict
from preform.errors import ConfigError
from preform.materials import GPA, PRESETS, FibreMatrix
from preform.structural.micromechanics import chamis

BASE = {"mandrel": {"stl": "c.stl"}, "machine": {"carriers": 16, "spool_radius": 0.3, "angular_speed": 10.0},
        "yarn": {"width": 4e-3, "thickness": 2.5e-4}, "process": {"take_up_speed": 0.01, "initial_position": 0.1, "braid_length": 0.2}}


def config(tmp_path, material):
    (tmp_path / "c.stl").write_text("solid c\nendsolid c\n")
    return config_from_dict({**BASE, "material": material}, tmp_path)


def test_chamis_reduces_to_the_matrix_and_the_fibre_at_the_ends():
    fm = PRESETS["AS4/3501-6"][0]
    c = chamis(fm, np.array([0.0, 1.0]))
    np.testing.assert_allclose([c.E1[0], c.E2[0], c.G12[0], c.G23[0], c.nu12[0]],
                               [fm.matrix_E, fm.matrix_E, fm.matrix_G, fm.matrix_G, fm.matrix_nu], rtol=1e-14)
    np.testing.assert_allclose([c.E1[1], c.E2[1], c.G12[1], c.G23[1], c.nu12[1], c.nu23[1]],
                               [fm.fibre_E1, fm.fibre_E2, fm.fibre_G12, fm.fibre_G23, fm.fibre_nu12,
                                fm.fibre_nu23], rtol=1e-14)


def test_chamis_transverse_moduli_are_the_square_array_strip_in_series():
    """E22, G12 and G23 worked by hand: in a square array of fibres a strip across the ply
    through a fibre crosses it over sqrt(kf) of the cell and matrix over the rest, in series."""
    fm = FibreMatrix(fibre_E1=200 * GPA, fibre_E2=20 * GPA, fibre_G12=20 * GPA, fibre_nu12=0.2,
                     fibre_G23=8 * GPA, matrix_E=4 * GPA, matrix_nu=0.25)
    kf = 0.49
    s = math.sqrt(kf)
    Gm = 4.0 / (2 * 1.25)
    c = chamis(fm, kf)
    assert float(c.E2) / GPA == pytest.approx(1.0 / (s / 20.0 + (1 - s) / 4.0), rel=1e-13)
    assert float(c.G12) / GPA == pytest.approx(1.0 / (s / 20.0 + (1 - s) / Gm), rel=1e-13)
    assert float(c.G23) / GPA == pytest.approx(1.0 / (s / 8.0 + (1 - s) / Gm), rel=1e-13)
    assert float(c.E1) / GPA == pytest.approx(0.49 * 200 + 0.51 * 4, rel=1e-13)


# World-Wide Failure Exercise laminae (Soden, Hinton & Kaddour 1998, Table 2): measured ply
# constants at the fibre fraction given there, for the presets' constituents
WWFE = {"AS4/3501-6": (0.60, 126.0, 11.0, 6.6, 0.28),
        "T300/914C": (0.60, 138.0, 11.0, 5.5, 0.28),
        "E-glass/LY556": (0.62, 53.48, 17.7, 5.83, 0.278)}


@pytest.mark.parametrize("name", sorted(WWFE))
def test_chamis_falls_within_the_scatter_of_measured_plies(name):
    vf, E1, E2, G12, nu12 = WWFE[name]
    c = chamis(PRESETS[name][0], vf)
    # the rule of mixtures over-reads E1 by the fibres' waviness and misalignment (5-10 %, up to
    # 8.5 % here); the series rules under-read E2 and G12 of carbon plies by 10-25 % and over-read
    # glass's E2 (Soden et al.'s own comparison: micromechanics within 25 %); nu12 within 10 %
    assert float(c.E1) / GPA == pytest.approx(E1, rel=0.10)
    assert float(c.E2) / GPA == pytest.approx(E2, rel=0.25)
    assert float(c.G12) / GPA == pytest.approx(G12, rel=0.25)
    assert float(c.nu12) == pytest.approx(nu12, rel=0.10)


def test_chamis_refuses_fractions_outside_0_1():
    with pytest.raises(ValueError, match="fibre volume fractions"):
        chamis(PRESETS["AS4/3501-6"][0], [0.5, 1.2])


def test_material_preset_and_overrides(tmp_path):
    cfg = config(tmp_path, {"preset": "AS4/3501-6", "matrix_E": 3.5e9})
    assert cfg.material.preset == "AS4/3501-6"
    assert cfg.material.constituents.matrix_E == 3.5e9
    assert cfg.material.constituents.fibre_E1 == PRESETS["AS4/3501-6"][0].fibre_E1
    full = {k: getattr(PRESETS["T300/914C"][0], k) for k in
            ("fibre_E1", "fibre_E2", "fibre_G12", "fibre_nu12", "fibre_G23", "matrix_E", "matrix_nu")}
    assert config(tmp_path, full).material.constituents == PRESETS["T300/914C"][0]


@pytest.mark.parametrize("material, names", [
    ({"preset": "AS4/3502"}, ["[material] preset", "AS4/3501-6"]),
    ({"fibre_E1": 230e9}, ["fibre_E2", "matrix_nu", "missing", "preset"]),
    ({"preset": "AS4/3501-6", "fibre_E1": 230.0}, ["[material] fibre_E1 = 230.0", "GPa"]),
    ({"preset": "AS4/3501-6", "matrix_nu": 0.6}, ["[material] matrix_nu = 0.6", "Poisson"]),
    ({"preset": "AS4/3501-6", "fibre_G23": 3e9}, ["[material] fibre_G23", "E2 / 4"]),
    ({"preset": "AS4/3501-6", "matrix_E": "4 GPa"}, ["[material] matrix_E", "not a string"]),
    ({"preset": "AS4/3501-6", "fibre_modulus": 1e9}, ["[material] fibre_modulus", "unknown key"]),
])
def test_material_errors_name_the_key(tmp_path, material, names):
    with pytest.raises(ConfigError) as err:
        config(tmp_path, material)
    for name in names:
        assert name in str(err.value)


def test_material_is_optional_and_echoed(tmp_path):
    from preform.config import dump_config

    (tmp_path / "c.stl").write_text("solid c\nendsolid c\n")
    assert config_from_dict(BASE, tmp_path).material is None
    echo = dump_config(config(tmp_path, {"preset": "E-glass/LY556"}))
    assert echo["material"]["preset"] == "E-glass/LY556" and echo["material"]["fibre_E1"] == 80e9
