"""The yarn on the guide ring: Capstan along the yarn, Amontons across it (paper §2.3; docs/theory.md §4).

Machine frame: the ring has radius ``r_ring`` about the z axis in the plane ``z = z_ring``; its point
``R(theta_r) = (r cos theta_r, r sin theta_r, z_ring)``. The yarn runs straight from the fixed point
``A`` (last crossing or fell point) over ``R`` to the supply point ``B``, where the spool tension
``f_ext`` acts.

* Capstan (eq. 9): ``f_int = f_ext exp(capstan_sign mu_r eta)``, ``eta`` the yarn's deflection at
  ``R`` (``cos eta = -u_int . u_ext``, unit vectors ``R->A``, ``R->B``), the sign from the direction
  the yarn's material slides along the ring: ``+1`` towards the mandrel (drawn from the spool: the
  mandrel side carries the higher tension), ``-1`` towards the spool (eq. 9 as the paper writes
  it, ``f_ext = f_int exp(mu_r eta)``; the default of :func:`solve_ring`), ``0`` stick along the
  ring: ``f_int = f_hold`` within the cone ``exp(-mu_r eta) <= f_int / f_ext <= exp(mu_r eta)``.
  ``interaction/model.py`` takes the sign from the material flow over the ring.
* While the yarn slides along the ring by ``s_long`` in the step, along and across are one
  Coulomb cone (``_kernels/ring.py``): no stick across the ring, the transverse friction
  ``mu_r r |dtheta| / |(s_long, r dtheta)|``.
* Transverse stick/slip (eqs. 11-13): ``F_r = f_int u_int + f_ext u_ext``, ``F^t = F_r . t_r`` with
  ``t_r = (-sin theta_r, cos theta_r, 0)``, ``|F^n| = |F_r - F^t t_r|``; ``Psi_r = |F^t| - mu_r |F^n|``.
  Stick keeps ``theta_r``; slip moves ``R`` in the direction of ``F^t`` to the nearest ``Psi_r = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._kernels import ring as ring_kernels
from .contact import ContactInputError, as_friction, as_vector
from .settings import RingSettings

STATUS_MESSAGES = {
    ring_kernels.RING_OK: "ok",
    ring_kernels.RING_DEGENERATE: "A or B lies on the ring point, or the tension or radius is not "
                                  "positive",
    ring_kernels.RING_NO_ROOT: "no ring point within half a turn holds the yarn inside the friction "
                               "cone",
}


@dataclass(frozen=True)
class RingSolution:
    """Result of :func:`solve_ring` (machine frame, SI units).

    R : (3,) m, ring point. theta_r : rad. f_int : N, tension of the segment R->A; f_ext : N, spool
    tension (input). eta : rad, Capstan (deflection) angle. psi_r : N. slip : 0 stick, 1 slip
    (transverse). slide : -1, 0, +1, the sense theta_r moved in. u_int, u_ext : (3,) unit vectors
    R->A, R->B. F_r : (3,) N, F_r = f_int u_int + f_ext u_ext. status : kernel status
    (``STATUS_MESSAGES``); other fields are zero unless ``ok``.
    """

    R: np.ndarray
    theta_r: float
    f_int: float
    f_ext: float
    eta: float
    psi_r: float
    slip: int
    slide: int
    u_int: np.ndarray
    u_ext: np.ndarray
    F_r: np.ndarray
    status: int
    iterations: int

    @property
    def ok(self) -> bool:
        return self.status == ring_kernels.RING_OK

    @property
    def message(self) -> str:
        return STATUS_MESSAGES[self.status]

    @property
    def F_int(self) -> np.ndarray:
        """Force of the segment R->A on the ring point, f_int u_int, (3,) N."""
        return self.f_int * self.u_int

    @classmethod
    def from_row(cls, row, status, f_ext) -> "RingSolution":
        """Unpack one kernel output row (``_kernels.ring.RING_OUT_*`` layout)."""
        rk = ring_kernels
        row = np.array(row, dtype=np.float64)
        vec = {}
        for name, k in (("R", rk.RING_OUT_R), ("u_int", rk.RING_OUT_U_INT),
                        ("u_ext", rk.RING_OUT_U_EXT), ("F_r", rk.RING_OUT_F_R)):
            vec[name] = row[k:k + 3]
            vec[name].flags.writeable = False
        return cls(theta_r=float(row[rk.RING_OUT_THETA]), f_int=float(row[rk.RING_OUT_F_INT]),
                   f_ext=float(f_ext), eta=float(row[rk.RING_OUT_ETA]),
                   psi_r=float(row[rk.RING_OUT_PSI]), slip=int(row[rk.RING_OUT_SLIP]),
                   slide=int(row[rk.RING_OUT_SLIDE]), status=int(status),
                   iterations=int(row[rk.RING_OUT_ITERATIONS]), **vec)


def _positive(name, value) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0.0):
        raise ContactInputError(f"{name} = {value!r}: expected a finite number > 0")
    return v


def solve_ring(A, B, f_ext, r_ring, z_ring, theta_prev, mu_r, *, capstan_sign=-1, f_hold=None,
               s_long=0.0, settings: RingSettings | None = None) -> RingSolution:
    """Solve the yarn-ring contact (paper Fig. A.17: stick predictor, transverse slip corrector).

    A, B : (3,) float64, m, machine frame: fixed point and supply point. f_ext : N, spool tension.
    r_ring : m, ring radius; z_ring : m, ring plane. theta_prev : rad, the ring angle carried from the
    previous step. mu_r : yarn-ring friction >= 0. capstan_sign : -1 (paper eq. 9), +1 or 0 with
    f_hold (N, the tension held below the ring while the yarn sticks along it; module docstring);
    a fraction of +-1 where the slide along the ring is part of one across it. s_long : m, the
    yarn's slide along the ring in the step (0: Amontons across the ring with mu_r; else one
    Coulomb cone with that slide, ``_kernels.ring.transverse_friction``). settings: the root solve's tolerances (default ``RingSettings()``). Returns a
    :class:`RingSolution`; check ``.ok``.
    """
    a, b = as_vector("A", A), as_vector("B", B)
    f = _positive("f_ext", f_ext)
    r = _positive("r_ring", r_ring)
    z = float(z_ring)
    th = float(theta_prev)
    if not (np.isfinite(z) and np.isfinite(th)):
        raise ContactInputError(f"z_ring = {z_ring!r}, theta_prev = {theta_prev!r}: expected finite numbers")
    if not (np.isfinite(capstan_sign) and -1 <= capstan_sign <= 1):
        raise ContactInputError(f"capstan_sign = {capstan_sign!r}: expected a number in [-1, +1]")
    if not (np.isfinite(s_long) and s_long >= 0.0):
        raise ContactInputError(f"s_long = {s_long!r}: expected a finite number >= 0 (m)")
    if capstan_sign == 0 and f_hold is None:
        raise ContactInputError("capstan_sign = 0 (stick along the ring) needs f_hold, the tension "
                                "held below the ring (N)")
    hold = f if f_hold is None else _positive("f_hold", f_hold)
    out = np.zeros(ring_kernels.RING_OUT_SIZE)
    s = RingSettings() if settings is None else settings
    status = ring_kernels.solve_ring(a[0], a[1], a[2], b[0], b[1], b[2], f, r, z, th,
                                     as_friction("mu_r", mu_r), float(capstan_sign), hold,
                                     float(s_long), *ring_arguments(s), out)
    return RingSolution.from_row(out, status, f)


def ring_arguments(s: RingSettings) -> tuple:
    """The ring kernels' settings arguments (psi_rel_tol .. root_rel_tol), in their order."""
    return (float(s.psi_rel_tol), float(s.march_step), int(s.march_max), int(s.root_max_iter),
            float(s.root_rel_tol))


def ring_point(theta_r, r_ring, z_ring) -> np.ndarray:
    """R(theta_r) = (r cos, r sin, z_ring), (..., 3) float64, m."""
    th = np.asarray(theta_r, dtype=np.float64)
    return np.stack([r_ring * np.cos(th), r_ring * np.sin(th), np.full_like(th, z_ring)], axis=-1)
