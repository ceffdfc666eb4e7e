"""Fibre and matrix elastic constants: the ``[material]`` section's values and its named presets.

A yarn's fibre is transversely isotropic about its axis (five constants: ``E1`` along the fibre,
``E2`` across it, ``G12``, ``nu12``, ``G23``); the matrix is isotropic (``E``, ``nu``). SI: Pa.

Presets are the constituent properties of the World-Wide Failure Exercise (Soden, Hinton and
Kaddour 1998, "Lamina properties, lay-up configurations and loading conditions for a range of
fibre-reinforced composite laminates", Composites Science and Technology 58, 1011-1022, Table 1),
a set that is published, widely reused and gives every constant the micromechanics needs.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

GPA = 1e9


@dataclass(frozen=True)
class FibreMatrix:
    """The constituents of one yarn type's composite (Pa; Poisson's ratios dimensionless)."""

    fibre_E1: float
    fibre_E2: float
    fibre_G12: float
    fibre_nu12: float
    fibre_G23: float
    matrix_E: float
    matrix_nu: float

    @property
    def matrix_G(self) -> float:
        """Shear modulus of the isotropic matrix, ``E / (2 (1 + nu))``."""
        return self.matrix_E / (2.0 * (1.0 + self.matrix_nu))

    @property
    def fibre_nu23(self) -> float:
        """The fibre's transverse Poisson's ratio, ``E2 / (2 G23) - 1`` (isotropic in its 2-3 plane)."""
        return self.fibre_E2 / (2.0 * self.fibre_G23) - 1.0


#: the constants' names, in the order of the ``[material]`` keys
CONSTANTS = tuple(f.name for f in fields(FibreMatrix))

#: preset name -> (constituents, where the values come from)
PRESETS = {
    "AS4/3501-6": (FibreMatrix(fibre_E1=225 * GPA, fibre_E2=15 * GPA, fibre_G12=15 * GPA, fibre_nu12=0.2,
                               fibre_G23=7 * GPA, matrix_E=4.2 * GPA, matrix_nu=0.34),
                   "Hercules AS4 carbon fibre in 3501-6 epoxy; Soden et al. 1998, Table 1"),
    "T300/914C": (FibreMatrix(fibre_E1=230 * GPA, fibre_E2=15 * GPA, fibre_G12=15 * GPA, fibre_nu12=0.2,
                              fibre_G23=7 * GPA, matrix_E=4.0 * GPA, matrix_nu=0.35),
                  "Toray T300 carbon fibre in BSL914C epoxy; Soden et al. 1998, Table 1"),
    "E-glass/LY556": (FibreMatrix(fibre_E1=80 * GPA, fibre_E2=80 * GPA, fibre_G12=33.33 * GPA,
                                  fibre_nu12=0.2, fibre_G23=33.33 * GPA, matrix_E=3.35 * GPA,
                                  matrix_nu=0.35),
                      "Gevetex E-glass fibre in LY556/HT907/DY063 epoxy; Soden et al. 1998, Table 1"),
}


def stiffness_problem(fm: FibreMatrix) -> tuple[str, str]:
    """("", "") if the constituents have a positive-definite stiffness, else (the key to blame,
    why): the fibre needs ``|nu23| < 1`` and ``1 - nu23 - 2 nu12^2 E2 / E1 > 0`` (transversely
    isotropic), the matrix ``-1 < nu < 0.5``."""
    nu23 = fm.fibre_nu23
    if not -1.0 < nu23 < 1.0:
        return "fibre_G23", (f"gives the fibre a transverse Poisson's ratio E2 / (2 G23) - 1 = {nu23:.3g}; "
                             "expected G23 > E2 / 4 (|nu23| < 1)")
    if 1.0 - nu23 - 2.0 * fm.fibre_nu12 ** 2 * fm.fibre_E2 / fm.fibre_E1 <= 0.0:
        return "fibre_nu12", "makes the fibre's stiffness indefinite (1 - nu23 - 2 nu12^2 E2 / E1 <= 0)"
    if not -1.0 < fm.matrix_nu < 0.5:
        return "matrix_nu", "expected an isotropic Poisson's ratio between -1 and 0.5"
    return "", ""
