"""The braiding machine: carriers, horn-gear pattern, supply points, guide ring (docs/theory.md §1).

Machine frame (docs/architecture.md §2): ``z`` is the machine axis, the spool plane is ``z = 0``. A group has
``n = carriers / 2`` carriers. Yarns ``0 .. n-1`` are warp (group 0), turning clockwise seen from
``+z`` (azimuth decreasing); yarns ``n .. 2n-1`` are weft (group 1), counter-clockwise. Warp ``k``
starts at azimuth ``2 pi k / n``, weft ``j`` half a pitch further, at ``2 pi (j + 1/2) / n``, so no
two carriers coincide at ``t = 0``.

Passes. Warp ``i`` and weft ``j`` pass when their azimuths coincide mod ``2 pi``, which happens at
``t = (pi / omega) (k - (j - i + 1/2) / n)`` for every integer ``k``, at azimuth
``phi = pi (p + 1/2) / n`` with the *pass location* ``p = (i + j - n k) mod 2n``. So there are
``2n`` fixed pass locations, ``pi / n`` apart; a warp yarn meets them in decreasing order of ``p``
(one every ``pi / (n omega)`` s), a weft yarn in increasing order.

Pattern ``m/m`` (m = 1 diamond, 2 regular, 3 hercules). Over/under is set by where the tracks of the
horn gears put the two carriers, so it is a property of the pass location: the warp goes over at
location ``p`` when ``(p // m) % 2 == 0`` (blocks of ``m`` locations, alternating). Walking along a
yarn visits consecutive locations, so every yarn goes over ``m`` crossings then under ``m``. That
holds around the whole circle only if ``2n`` is a multiple of ``2m``.

Runnable carrier counts (:func:`carrier_count_problem`): ``carriers`` even, ``n = carriers / 2``
divisible by ``m`` (i.e. an even number ``carriers / m`` of horn gears, sides alternating) and
``n >= 2 m`` (at least one full over-and-under block per group).

When ``n / m`` is even the over/under of a warp-weft pair is the same at each of its meetings and
equals ``((i + j) // m) % 2 == 0``. When ``n / m`` is odd (e.g. 36 carriers, regular) successive
meetings of the same pair alternate, so :meth:`Machine.warp_over` then needs the pass time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

#: crossings over (and under) in a row, per pattern name
PATTERN_M = {"diamond": 1, "regular": 2, "hercules": 3}

WARP = 0
WEFT = 1


def carrier_count_problem(carriers: int, pattern: str) -> str | None:
    """What is wrong with running ``carriers`` carriers in ``pattern``; None when runnable.

    Rule: even, ``n = carriers / 2`` divisible by ``m`` and ``n >= 2 m`` (module docstring).
    """
    m = PATTERN_M[pattern]
    step = 2 * m  # carriers must be a multiple of 2 m
    least = 4 * m  # n >= 2 m
    ok = carriers % step == 0 and carriers >= least
    if ok:
        return None
    return (f'expected an even number of carriers, a multiple of {step} and at least {least}, for '
            f'pattern "{pattern}" ({m}/{m}: n = carriers/2 per group must be divisible by {m} and '
            f"at least {2 * m})")


class Passes(NamedTuple):
    """Warp-weft carrier passes, sorted by time.

    time : (k,) float64, s. warp : (k,) int64, yarn index 0..n-1. weft : (k,) int64, weft index
    0..n-1 within its group (its yarn index is ``n + weft``). location : (k,) int64, pass location
    ``p`` in 0..2n-1 (azimuth ``pi (p + 1/2) / n``). warp_over : (k,) bool, from the pattern.
    """

    time: np.ndarray
    warp: np.ndarray
    weft: np.ndarray
    location: np.ndarray
    warp_over: np.ndarray


@dataclass(frozen=True, eq=False)
class Machine:
    """Carrier kinematics of a biaxial braiding machine (module docstring for conventions).

    n_per_group : carriers per group. omega : rad/s. spool_radius : m. m : pattern repeat (1, 2, 3).
    group : (2n,) int8, 0 warp / 1 weft. phase0 : (2n,) float64, rad, azimuths at t = 0.
    ring_radius, ring_offset : m, or None without a guide ring.
    """

    n_per_group: int
    omega: float
    spool_radius: float
    m: int
    group: np.ndarray
    phase0: np.ndarray
    ring_radius: float | None = None
    ring_offset: float | None = None

    @classmethod
    def from_config(cls, machine_cfg) -> "Machine":
        """Build from a :class:`preform.config.MachineConfig` (angular_speed already in rad/s).
        ``omega`` is the fastest speed of an angular-speed table: the reference speed of the
        carriers' clock (``stepping.Clock``), which the step control bounds the turn by."""
        n = machine_cfg.carriers // 2
        k = np.arange(n, dtype=float)
        ring = machine_cfg.guide_ring
        return cls(
            n_per_group=n,
            omega=float(max(speed for _, speed in machine_cfg.angular_speeds)),
            spool_radius=float(machine_cfg.spool_radius),
            m=PATTERN_M[machine_cfg.pattern],
            group=np.repeat(np.array([WARP, WEFT], dtype=np.int8), n),
            phase0=np.concatenate([2.0 * np.pi * k / n, 2.0 * np.pi * (k + 0.5) / n]),
            ring_radius=None if ring is None else float(ring.radius),
            ring_offset=None if ring is None else float(ring.offset),
        )

    @property
    def n_yarns(self) -> int:
        return 2 * self.n_per_group

    @property
    def has_ring(self) -> bool:
        return self.ring_radius is not None

    @property
    def supply_radius(self) -> float:
        """Radius (m) of the kinematic supply point: guide ring if any, else spool (docs/theory.md §3)."""
        return self.ring_radius if self.has_ring else self.spool_radius

    @property
    def supply_z(self) -> float:
        """Axial position (m, machine frame) of the supply plane: ring offset if any, else 0."""
        return self.ring_offset if self.has_ring else 0.0

    def direction(self) -> np.ndarray:
        """(2n,) float64: -1 for warp (clockwise seen from +z), +1 for weft."""
        return np.where(self.group == WARP, -1.0, 1.0)

    def azimuths(self, t: float) -> np.ndarray:
        """(2n,) float64, rad: carrier azimuths at time ``t`` (s); not wrapped to [0, 2 pi)."""
        return self.phase0 + self.direction() * self.omega * t

    def _circle(self, t: float, radius: float, z: float) -> np.ndarray:
        phi = self.azimuths(t)
        return np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, z)], axis=1)

    def supply_points(self, t: float) -> np.ndarray:
        """(2n, 3) float64, m, machine frame: ring point at each carrier's azimuth, or the spool."""
        return self._circle(t, self.supply_radius, self.supply_z)

    def spool_points(self, t: float) -> np.ndarray:
        """(2n, 3) float64, m, machine frame: carrier positions on the spool circle (z = 0)."""
        return self._circle(t, self.spool_radius, 0.0)

    def pass_period(self) -> float:
        """Time (s) between two consecutive passes along one yarn: pi / (n omega)."""
        return np.pi / (self.n_per_group * self.omega)

    def pass_times(self, t0: float, t1: float) -> Passes:
        """Every warp-weft pass with ``t0 <= time < t1`` (s), sorted by time then warp index."""
        n, w = self.n_per_group, np.pi / self.omega
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        i, j = i.ravel(), j.ravel()
        c = (j - i + 0.5) / n  # pass times of the pair: w (k - c)
        k_lo = np.ceil(t0 / w + c).astype(np.int64)
        k_hi = np.ceil(t1 / w + c).astype(np.int64)  # exclusive
        count = np.maximum(k_hi - k_lo, 0)
        pair = np.repeat(np.arange(n * n), count)
        k = np.repeat(k_lo, count) + _ranges(count)
        time = w * (k - c[pair])
        i, j = i[pair], j[pair]
        location = (i + j - n * k) % (2 * n)
        order = np.lexsort((i, time))
        passes = Passes(time, i, j, location, self.warp_over_at(location))
        return Passes(*(a[order] for a in passes))

    def warp_over_at(self, location) -> np.ndarray:
        """bool (array): the warp goes over at pass location ``p`` (module docstring)."""
        return (np.asarray(location) // self.m) % 2 == 0

    def pair_pattern_fixed(self) -> bool:
        """True when each warp-weft pair has the same over/under at every meeting (n / m even)."""
        return (self.n_per_group // self.m) % 2 == 0

    def warp_over(self, i, j, t=None):
        """Does warp ``i`` go over weft ``j`` (0..n-1 each) at their pass at time ``t`` (s)?

        With ``n / m`` even the answer does not depend on the meeting and ``t`` may be omitted:
        ``((i + j) // m) % 2 == 0``. Otherwise ``t`` must be a pass time of the pair (ValueError
        if it is not, or if it is missing). Broadcasts over arrays.
        """
        i, j = np.asarray(i), np.asarray(j)
        if t is None:
            if not self.pair_pattern_fixed():
                raise ValueError(f"with n/m = {self.n_per_group}/{self.m} odd, over/under changes "
                                 "between meetings of a pair: give the pass time t")
            return self.warp_over_at(i + j)
        phi = self.phase0[i] - self.omega * np.asarray(t)
        p_real = phi * self.n_per_group / np.pi - 0.5
        p = np.rint(p_real).astype(np.int64)
        gap = self.phase0[self.n_per_group + j] + self.omega * np.asarray(t) - phi
        if np.any(np.abs(np.angle(np.exp(1j * gap))) > 1e-6):
            raise ValueError("t is not a pass time of warp i and weft j")
        return self.warp_over_at(p % (2 * self.n_per_group))


def _ranges(count: np.ndarray) -> np.ndarray:
    """Concatenation of arange(c) for c in count: (sum(count),) int64."""
    total = int(count.sum())
    starts = np.repeat(np.cumsum(count) - count, count)
    return np.arange(total, dtype=np.int64) - starts
