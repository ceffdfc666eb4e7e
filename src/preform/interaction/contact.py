"""One yarn-yarn crossing: position, internal tensions, stick/slip (paper §2.2; DESIGN.md §3.3).

A warp ``X`` and a weft ``O`` cross at ``C``. Their lower points ``A_X``, ``A_O`` (next crossings or
fell points towards the mandrel, already offset by the yarn thickness, paper eq. 16) are fixed; the
external forces ``F_X^ext``, ``F_O^ext`` come from the supply side (tension times the unit vector from
``C`` towards the supply). :func:`solve_crossing` returns ``C``, the internal tensions along ``C->A_X``
and ``C->A_O``, the Eulerian angles and the stick/slip state.

Conventions (the full derivation is in ``preform._kernels.contact``):

* ``theta_X``: angle at ``A_X`` between ``e1 = A_O - A_X`` and ``A_X->C``; ``theta_O``: angle at
  ``A_O`` between ``-e1`` and ``A_O->C``. ``C`` lies in the plane through ``A_X``, ``A_O`` that holds
  ``F_X^ext + F_O^ext``, where the two rays meet. Sticking keeps both angles exactly.
* ``psi_X``, ``slip_X`` are the warp's own friction state, in the warp's Eulerian frame (eqs. 5-7):
  ``psi_X = |f_X^int - f_X^ext| cos(d/2) - mu (f_X^int + f_X^ext) sin(d/2)``, ``d`` the warp's deflection
  at ``C``; ``slip_X`` means the warp's material slides through ``C`` (its tension jump is on the
  bound). The warp's slip is resolved by moving ``theta_O`` (``C`` slides along the warp line, which
  keeps the warp deflection and gives a closed form): this is the paper's case 1, "weft slipping over
  the warp", which the paper evaluates in the warp frame. Likewise ``slip_O`` moves ``theta_X``.
* ``slide_X = sign(f_X^int - f_X^ext)`` while slipping: +1 the warp slides towards ``A_X`` (the
  mandrel side carries the higher tension), -1 towards its supply, 0 while sticking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PreformError
from .._kernels import contact as K

#: status code -> meaning
STATUS_MESSAGES = {
    K.CROSSING_OK: "ok",
    K.CROSSING_DEGENERATE: "A_X equals A_O or an external force is zero",
    K.CROSSING_PARALLEL: "F_X_ext + F_O_ext is parallel to A_O - A_X: no plane for the crossing",
    K.CROSSING_NO_INTERSECTION: "the two yarn rays do not meet in front of A_X A_O",
    K.CROSSING_NEGATIVE_TENSION: "a yarn segment would be in compression",
    K.CROSSING_NO_SLIP_SOLUTION: "no configuration puts both yarns on their friction bound",
}


class ContactInputError(PreformError, ValueError):
    """An argument of a contact solver has the wrong shape, is not finite or is out of range."""


@dataclass(frozen=True)
class CrossingSolution:
    """Result of :func:`solve_crossing` (SI units, the frame of the inputs).

    C : (3,) float64, m. f_X_int, f_O_int : N, tensions of the segments C->A_X, C->A_O.
    u_X_int, u_O_int : (3,) unit vectors C->A_X, C->A_O. theta_X, theta_O : rad.
    slip_X, slip_O : 0 stick, 1 slip. slide_X, slide_O : -1, 0, +1 (module docstring).
    psi_X, psi_O : N, friction functions at the solution (<= 0, ~0 when slipping).
    status : kernel status code (``STATUS_MESSAGES``); other fields are zero unless ``ok``.
    iterations : residual evaluations of the both-slip solve (0 otherwise).
    """

    C: np.ndarray
    f_X_int: float
    f_O_int: float
    u_X_int: np.ndarray
    u_O_int: np.ndarray
    theta_X: float
    theta_O: float
    slip_X: int
    slip_O: int
    slide_X: int
    slide_O: int
    psi_X: float
    psi_O: float
    status: int
    iterations: int

    @property
    def ok(self) -> bool:
        return self.status == K.CROSSING_OK

    @property
    def message(self) -> str:
        return STATUS_MESSAGES[self.status]

    @property
    def F_X_int(self) -> np.ndarray:
        """Internal warp force f_X^int u_X^int, (3,) N."""
        return self.f_X_int * self.u_X_int

    @property
    def F_O_int(self) -> np.ndarray:
        """Internal weft force f_O^int u_O^int, (3,) N."""
        return self.f_O_int * self.u_O_int

    @classmethod
    def from_row(cls, row: np.ndarray, status: int) -> "CrossingSolution":
        """Unpack one kernel output row (``_kernels.contact.OUT_*`` layout)."""
        row = np.array(row, dtype=np.float64)
        for v in (row[K.OUT_C:K.OUT_C + 3], row[K.OUT_U_X:K.OUT_U_X + 3], row[K.OUT_U_O:K.OUT_U_O + 3]):
            v.flags.writeable = False
        return cls(
            C=row[K.OUT_C:K.OUT_C + 3], f_X_int=float(row[K.OUT_F_X]), f_O_int=float(row[K.OUT_F_O]),
            u_X_int=row[K.OUT_U_X:K.OUT_U_X + 3], u_O_int=row[K.OUT_U_O:K.OUT_U_O + 3],
            theta_X=float(row[K.OUT_THETA_X]), theta_O=float(row[K.OUT_THETA_O]),
            slip_X=int(row[K.OUT_SLIP_X]), slip_O=int(row[K.OUT_SLIP_O]),
            slide_X=int(row[K.OUT_SLIDE_X]), slide_O=int(row[K.OUT_SLIDE_O]),
            psi_X=float(row[K.OUT_PSI_X]), psi_O=float(row[K.OUT_PSI_O]),
            status=int(status), iterations=int(row[K.OUT_ITERATIONS]))


def as_vector(name: str, value) -> np.ndarray:
    """``value`` as a finite (3,) float64 array, or ContactInputError naming ``name``."""
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ContactInputError(f"{name} = {value!r}: expected 3 finite numbers")
    return v


def as_friction(name: str, value) -> float:
    """``value`` as a finite float >= 0, or ContactInputError naming ``name``."""
    mu = float(value)
    if not (np.isfinite(mu) and mu >= 0.0):
        raise ContactInputError(f"{name} = {value!r}: expected a finite friction coefficient >= 0")
    return mu


def _theta_pair(theta_prev) -> tuple[float, float]:
    if theta_prev is None:
        return np.nan, np.nan
    tx, to = (float(t) for t in np.asarray(theta_prev, dtype=np.float64).reshape(2))
    if not (0.0 < tx and 0.0 < to and tx + to < np.pi):
        raise ContactInputError(f"theta_prev = {theta_prev!r}: expected (theta_X, theta_O) in rad, "
                                "both > 0 with theta_X + theta_O < pi")
    return tx, to


def solve_crossing(A_X, A_O, F_X_ext, F_O_ext, theta_prev=None, mu=0.0) -> CrossingSolution:
    """Solve one crossing (paper Fig. 6: stick predictor, cases 1-3 corrector).

    A_X, A_O : (3,) float64, m, lower points of warp and weft (any Cartesian frame).
    F_X_ext, F_O_ext : (3,) float64, N, external forces (tension times unit vector to the supply).
    theta_prev : (theta_X, theta_O) rad, the angles carried from the previous step (a new crossing:
        :func:`crossing_angles` of its creation geometry); None starts from the frictionless
        equilibrium. mu : yarn-yarn friction coefficient mu_y >= 0.
    Returns a :class:`CrossingSolution`; check ``.ok`` (no exception for a configuration without
    equilibrium, only for malformed arguments).
    """
    a_x, a_o = as_vector("A_X", A_X), as_vector("A_O", A_O)
    f_x, f_o = as_vector("F_X_ext", F_X_ext), as_vector("F_O_ext", F_O_ext)
    tx, to = _theta_pair(theta_prev)
    out = np.zeros(K.OUT_SIZE)
    status = K.solve_crossing(a_x[0], a_x[1], a_x[2], a_o[0], a_o[1], a_o[2], f_x[0], f_x[1], f_x[2],
                              f_o[0], f_o[1], f_o[2], tx, to, as_friction("mu", mu), out)
    return CrossingSolution.from_row(out, status)


def crossing_angles(A_X, A_O, C) -> tuple[float, float]:
    """Eulerian angles (theta_X, theta_O), rad, of the triangle A_X, A_O, C ((3,) each, m)."""
    a_x, a_o, c = as_vector("A_X", A_X), as_vector("A_O", A_O), as_vector("C", C)
    return K.crossing_angles(a_x[0], a_x[1], a_x[2], a_o[0], a_o[1], a_o[2], c[0], c[1], c[2])


def psi(f_int, f_ext, u_int, u_ext, mu):
    """Friction function of a yarn at a contact, N (paper eq. 5, tension form; vectorised).

    f_int, f_ext : (...) N, tensions of the two segments; u_int, u_ext : (..., 3) unit vectors from
    the contact along them. ``Psi = |f_int - f_ext| cos(d/2) - mu (f_int + f_ext) sin(d/2)`` with
    ``cos d = -u_int . u_ext``. Sticking: Psi <= 0; slipping: Psi = 0.
    """
    d = np.sum(np.asarray(u_int, float) * np.asarray(u_ext, float), axis=-1)
    c = np.sqrt(np.maximum(0.5 * (1.0 - d), 0.0))
    s = np.sqrt(np.maximum(0.5 * (1.0 + d), 0.0))
    f_int, f_ext = np.asarray(f_int, float), np.asarray(f_ext, float)
    return np.abs(f_int - f_ext) * c - mu * (f_int + f_ext) * s


def psi_frame(F_int, F_ext, mu):
    """Friction function from the force vectors in the Eulerian frame (paper eqs. 5-7), N.

    F_int, F_ext : (..., 3) N, the two segment forces on the contact. ``n = -(u_int + u_ext)/|.|``,
    ``F = F_int + F_ext``, ``F^n = F . n``, ``F^t = |F - F^n n|``, ``Psi = F^t - mu |F^n|``. Equal to
    :func:`psi` except for a straight yarn, where ``n`` is undefined (use :func:`psi` there).
    """
    F_int, F_ext = np.asarray(F_int, float), np.asarray(F_ext, float)
    u_i = F_int / np.linalg.norm(F_int, axis=-1, keepdims=True)
    u_e = F_ext / np.linalg.norm(F_ext, axis=-1, keepdims=True)
    n = -(u_i + u_e)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    F = F_int + F_ext
    fn = np.sum(F * n, axis=-1)
    ft = np.linalg.norm(F - fn[..., None] * n, axis=-1)
    return ft - mu * np.abs(fn)


def cone_ratio(delta, mu):
    """Bounds (low, high) of f_int / f_ext for a sticking yarn with deflection delta (rad).

    ``|f_int - f_ext| <= mu (f_int + f_ext) tan(delta/2)``: ratio within
    ``(1 - m) / (1 + m)`` and ``(1 + m) / (1 - m)``, ``m = mu tan(delta/2)``; high is inf when m >= 1.
    """
    m = mu * np.tan(0.5 * np.asarray(delta, float))
    with np.errstate(divide="ignore"):
        high = np.where(m < 1.0, (1.0 + m) / np.where(m < 1.0, 1.0 - m, 1.0), np.inf)
    return (1.0 - m) / (1.0 + m), high
