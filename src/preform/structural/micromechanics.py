"""A unidirectional ply's engineering constants from its fibre, matrix and fibre volume fraction.

Chamis's simplified micromechanics equations (C. C. Chamis, "Simplified composite micromechanics
equations for hygral, thermal and mechanical properties", SAMPE Quarterly 15(3), 1984, 14-23;
NASA TM-83320), with ``k_f`` the fibre volume fraction and ``k_m = 1 - k_f``:

* ``E11 = k_f E_f11 + k_m E_m`` (rule of mixtures);
* ``E22 = E_m / (1 - sqrt(k_f) (1 - E_m / E_f22))``;
* ``G12 = G_m / (1 - sqrt(k_f) (1 - G_m / G_f12))``;
* ``G23 = G_m / (1 - sqrt(k_f) (1 - G_m / G_f23))``;
* ``nu12 = k_f nu_f12 + k_m nu_m``;  ``nu23 = E22 / (2 G23) - 1`` (transversely isotropic ply).

The square roots come from a square array of fibres: a strip across the ply meets fibre over a
width ``sqrt(k_f)`` of it, the rest is matrix in series. No fitted parameter is needed (unlike
Halpin-Tsai's ``xi``); against measured plies ``E22`` and ``G12`` fall within some 10-25 %,
``E11`` and ``nu12`` within 10 % (``tests/unit/test_structural_materials.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..materials import FibreMatrix


@dataclass(frozen=True)
class PlyConstants:
    """Engineering constants of a unidirectional ply (Pa; arrays of the fibre fractions' shape).
    Axis 1 along the fibres, 2 across them in the ply's plane, 3 through its thickness; the ply
    is transversely isotropic (``E3 = E2``, ``G13 = G12``, ``nu13 = nu12``)."""

    E1: np.ndarray
    E2: np.ndarray
    G12: np.ndarray
    nu12: np.ndarray
    G23: np.ndarray
    nu23: np.ndarray


def chamis(fm: FibreMatrix, vf) -> PlyConstants:
    """The ply constants at fibre volume fractions ``vf`` (any shape, each in [0, 1])."""
    kf = np.asarray(vf, dtype=float)
    if np.any(~np.isfinite(kf)) or np.any(kf < 0) or np.any(kf > 1):
        raise ValueError(f"fibre volume fractions must lie in [0, 1], got {kf.min()!r} to {kf.max()!r}")
    km, root = 1.0 - kf, np.sqrt(kf)
    Em, Gm = fm.matrix_E, fm.matrix_G
    E2 = Em / (1.0 - root * (1.0 - Em / fm.fibre_E2))
    G23 = Gm / (1.0 - root * (1.0 - Gm / fm.fibre_G23))
    return PlyConstants(E1=kf * fm.fibre_E1 + km * Em, E2=E2,
                        G12=Gm / (1.0 - root * (1.0 - Gm / fm.fibre_G12)),
                        nu12=kf * fm.fibre_nu12 + km * fm.matrix_nu, G23=G23, nu23=E2 / (2.0 * G23) - 1.0)
