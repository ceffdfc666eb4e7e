"""A verdict on every run: the plausibility checks a process engineer makes.

A run can finish ``done`` and still be nonsense: a pose that leaves the braiding zone misaligned
makes the yarns bridge and catch at every step, the convergence length collapse to almost
nothing, and the braid angle jump from step to step. :func:`assess` reads the history and the
deposited yarns (and the surface fields, when given) and returns ``{"verdict": "ok" | "suspect",
"reasons": [...]}``; each reason names what was seen, the figure and the threshold.
``summary.json`` carries it under ``quality``; the CLI prints it (``--strict`` makes ``suspect``
an error).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..result import FLAG_BRIDGE, FLAG_CATCH, FLAG_SLIP
from .interlacing import INTERLACING, InterlacingSettings


@dataclass(frozen=True)
class QualitySettings:
    """Thresholds of the plausibility checks."""

    #: bridged or caught points above this share of the deposited yarn: on a convex mandrel
    #: there are none; a concave stretch here and there gives well under 1 %
    max_flag_share: float = 0.01
    #: the first part of the run (fraction of the braided length) is its start-up transient
    transient: float = 0.1
    #: a yarn's convergence length below this fraction of the run's median: the fell point has
    #: caught up with the supply side, which a straight yarn from a carrier cannot do
    min_convergence_ratio: float = 0.5
    #: braid-angle change between consecutive steps (deg) beyond which the laid angle jumps: a
    #: converged step moves it by hundredths of a degree
    max_angle_jump_deg: float = 5.0
    #: faces covered beyond the braided length by more than this (m) past the furthest fell point
    field_reach_margin: float = 0.02
    #: uncovered faces inside the braided region above this share of its faces
    max_hole_share: float = 0.005
    #: a snapshot's crossing out of balance by more than this fraction of the snapshot's largest
    #: tension (its tensions along the written segments plus ``external_force_N``)
    max_snapshot_imbalance: float = 1e-3
    #: a snapshot's crossing outside the friction cone by more than this fraction of its larger
    #: tension (Psi): its friction bounds did not settle
    max_snapshot_psi: float = 1e-3
    #: history.csv's residual (a step's balance, or the lag of its friction bounds relative to
    #: the tensions): above ``residual_high`` on more than ``residual_high_share`` of the steps,
    #: or above ``residual_max`` on any, the steps were not converged in the paper's sense
    #: (case A's steps stay below 9.4e-3 at friction 0.25)
    residual_high: float = 1e-2
    residual_high_share: float = 0.01
    residual_max: float = 0.1
    #: a step that moves the fell front (the braided length) by more than this many times the
    #: take-up advance of the step: the fell points follow the mandrel at the take-up speed
    #: give or take the transient's change of the convergence length, which is slow (measured:
    #: case A up to 1.6x), not in jumps
    max_fell_jump: float = 5.0
    #: warp-weft crossings of the laid yarns below this fraction of the pattern's
    #: (``preform.analysis.interlacing``): an interlaced braid gives 1 to within one crossing per pair
    #: (case A 16 carriers: 0.985; the kinematic S-tube 0.988); warp and weft in bands that do
    #: not meet give 0
    min_interlacing: float = 0.5
    #: the interlacing is judged only where the pattern gives at least this many crossings per
    #: warp-weft pair over the band (fewer: a short run, where one crossing more or less is
    #: a large share)
    min_pattern_per_pair: float = 0.5
    #: slip-tendency flags (|kappa_g| > mu |kappa_n|) above this share of the deposited points:
    #: a geodesic helix on a cylinder has none, so a few per cent mark a bend or a section
    #: change; beyond a tenth of the braid the laid pattern as simulated is not where the yarns
    #: would stay
    max_slip_share: float = 0.1
    #: m, a snapshot's crossing further than this many yarn widths from where the re-balance
    #: of its step's own problem puts it: the written state is far from a converged one
    #: (measured: behind a ring, converged, at most 1.2 mm; not converged, up to 28 mm; case A
    #: 16 carriers, friction 0.25, 0.3 m: up to 1 mm at 8 of 11 snapshots, 14 and 35 mm at two)
    max_snapshot_shift_widths: float = 5.0


QUALITY = QualitySettings()


def _share(flags, bit) -> float:
    return float(np.count_nonzero(flags & bit)) / max(len(flags), 1)


def history_reasons(history, settings: QualitySettings = QUALITY) -> list[str]:
    """Reasons to doubt a run from its ``history`` columns (arrays of one row per step)."""
    reasons = []
    L = np.asarray(history["braided_length_m"], dtype=float)
    if len(L) < 3:
        return reasons
    settled = L >= L[0] + settings.transient * (L[-1] - L[0])
    settled[:2] = False   # the first rows are the tie and its first step
    if not np.any(settled):
        return reasons
    H_mean = np.asarray(history["convergence_length_mean_m"], dtype=float)[settled]
    H_min = np.asarray(history["convergence_length_min_m"], dtype=float)[settled]
    median = float(np.median(H_mean))
    if np.min(H_min) <= 0.0:
        reasons.append(f"a fell point went behind the supply plane (convergence length "
                       f"{np.min(H_min):.4g} m): the yarns cannot be laid there")
    elif median > 0 and np.min(H_min) < settings.min_convergence_ratio * median:
        reasons.append(f"convergence length down to {np.min(H_min):.4g} m, below "
                       f"{settings.min_convergence_ratio:g} x the run's median {median:.4g} m")
    for group in ("warp", "weft"):
        angle = np.asarray(history[f"braid_angle_{group}_deg"], dtype=float)
        jumps = np.abs(np.diff(angle))[settled[1:]]
        if len(jumps) and np.max(jumps) > settings.max_angle_jump_deg:
            n = int(np.count_nonzero(jumps > settings.max_angle_jump_deg))
            reasons.append(f"{group} braid angle jumps by up to {np.max(jumps):.1f} deg between steps "
                           f"({n} steps above {settings.max_angle_jump_deg:g} deg)")
    return reasons


def residual_reasons(history, settings: QualitySettings = QUALITY) -> list[str]:
    """Reasons to doubt the convergence of a run's steps from history.csv's ``residual``."""
    res = np.asarray(history.get("residual", ()), dtype=float)[1:]   # row 0: the tie
    if not len(res):
        return []
    reasons = []
    bad = ~np.isfinite(res)
    high = np.count_nonzero(bad | (res > settings.residual_high))
    if high > settings.residual_high_share * len(res):
        reasons.append(f"{high} of {len(res)} steps ({high / len(res):.1%}) have a residual above "
                       f"{settings.residual_high:g} (history.csv; at most "
                       f"{settings.residual_high_share:.0%} may): the steps are not converged")
    top = int(np.count_nonzero(bad | (res > settings.residual_max)))
    if top:
        worst = float(np.max(np.where(bad, np.inf, res)))
        reasons.append(f"{top} steps have a residual above {settings.residual_max:g}, up to "
                       f"{worst:.3g} (history.csv): their friction bounds or balance were not "
                       "those of a solution")
    return reasons


def fell_jump_reasons(history, take_up_speed, settings: QualitySettings = QUALITY) -> list[str]:
    """Reasons to doubt a run whose fell front jumps: a step moving the braided length by more
    than ``max_fell_jump`` times the take-up advance ``v dt`` (``take_up_speed``: the config's
    table of (braided length m, speed m/s))."""
    L = np.asarray(history["braided_length_m"], dtype=float)
    t = np.asarray(history["time_s"], dtype=float)
    if len(L) < 3:
        return []
    table = np.asarray(take_up_speed, dtype=float).reshape(-1, 2)
    v = np.interp(L[:-1], table[:, 0], table[:, 1])
    advance = v * np.diff(t)
    jump = np.abs(np.diff(L)) / np.maximum(advance, 1e-300)
    n = int(np.count_nonzero(jump > settings.max_fell_jump))
    if not n:
        return []
    k = int(np.argmax(jump))
    return [f"the fell front jumps: {n} steps move the braided length by more than "
            f"{settings.max_fell_jump:g}x the take-up advance, up to {abs(L[k + 1] - L[k]) * 1e3:.3g} mm "
            f"in one step ({jump[k]:.3g}x, at t = {t[k + 1]:.4g} s)"]


def run_interlacing(result, settings: InterlacingSettings = INTERLACING):
    """``preform.interlacing.interlacing`` of a run's laid yarns (None without yarns or a
    centerline)."""
    from .interlacing import interlacing

    if result.centerline is None or not len(result.yarns.points):
        return None
    return interlacing(result.yarns, result.centerline, settings=settings)


def interlacing_reasons(il, settings: QualitySettings = QUALITY) -> list[str]:
    """Reasons to doubt a run whose warp and weft separate: ``il`` its interlacing
    (:func:`run_interlacing`, or None)."""
    if il is None or il.pattern < settings.min_pattern_per_pair * il.pairs:
        return []
    if il.ratio < settings.min_interlacing:
        return [f"warp and weft separate: {il.measured} warp-weft crossings between "
                f"{il.s_start:.3g} and {il.s_end:.3g} m of centerline against {il.pattern:.0f} "
                f"that the braid pattern gives there ({il.ratio:.2f}, below "
                f"{settings.min_interlacing:g}; {il.measured_per_m2:.3g} against "
                f"{il.pattern_per_m2:.3g} per m^2): the yarns lie in bands, not interlaced"]
    return []


def slip_reasons(flags, settings: QualitySettings = QUALITY) -> list[str]:
    """A share of slip-tendency flags above ``max_slip_share``."""
    share = _share(np.asarray(flags, dtype=np.int64), FLAG_SLIP)
    if share <= settings.max_slip_share:
        return []
    return [f"{share:.0%} of the deposited yarn points have a slip tendency (|kappa_g| > mu "
            f"|kappa_n|; above {settings.max_slip_share:.0%}): the models keep deposited yarn "
            "where it was laid, so the laid pattern there is not where the yarns would stay"]


def yarn_reasons(flags, settings: QualitySettings = QUALITY) -> list[str]:
    """Reasons to doubt a run from the flags of its deposited yarn points (``YarnPaths.flags``)."""
    flags = np.asarray(flags, dtype=np.int64)
    reasons = []
    for bit, what in ((FLAG_BRIDGE, "bridged"), (FLAG_CATCH, "caught")):
        share = _share(flags, bit)
        if share > settings.max_flag_share:
            reasons.append(f"{share:.1%} of the deposited yarn points are {what} (above "
                           f"{settings.max_flag_share:.0%}): the yarns do not follow the mandrel; "
                           "check the pose ([process] pose_lead, eccentricity)")
    return reasons


def field_reasons(face_s, covered, braided_end, braided_start=0.0, smoothing=0.0,
                  settings: QualitySettings = QUALITY, front_start=None) -> list[str]:
    """Reasons to doubt the surface fields.

    face_s : (f,) float64, m, centerline arc length of each field face's centroid
    covered : (f,) bool, faces some yarn crosses
    braided_end : float, m, arc length of the furthest fell point at the end of the run
    braided_start : float, m, arc length where the braid starts (the tie points)
    smoothing : float, m, how far the fields' pooling spreads coverage (added to the margins)
    front_start : float, m, arc length of the least advanced fell point (default braided_end):
        between it and braided_end the fell front is ragged, so faces there may carry no yarn yet
    """
    face_s = np.asarray(face_s, dtype=float)
    covered = np.asarray(covered, dtype=bool)
    margin = settings.field_reach_margin + smoothing
    reasons = []
    beyond = covered & (face_s > braided_end + margin)
    if np.any(beyond):
        reasons.append(f"{np.count_nonzero(beyond)} faces are covered up to {face_s[beyond].max():.4g} m "
                       f"of centerline, beyond the braided length {braided_end:.4g} m")
    hole_end = braided_end if front_start is None else front_start
    inside = (face_s > braided_start + margin) & (face_s < hole_end - margin)
    holes = inside & ~covered
    if np.any(inside) and np.count_nonzero(holes) > settings.max_hole_share * np.count_nonzero(inside):
        reasons.append(f"{np.count_nonzero(holes)} faces inside the braided region "
                       f"({braided_start:.3g}-{hole_end:.3g} m) carry no yarn")
    return reasons


def verdict(reasons) -> dict:
    """``{"verdict": "ok" | "suspect", "reasons": reasons}``."""
    reasons = list(reasons)
    return {"verdict": "suspect" if reasons else "ok", "reasons": reasons}


def surface_reasons(result, fields, settings: QualitySettings = QUALITY) -> list[str]:
    """:func:`field_reasons` of a run's surface fields (faces located on its centerline)."""
    if fields is None or result.centerline is None or result.fell_s is None or not len(result.fell_s):
        return []
    V, F = np.asarray(fields.vertices), np.asarray(fields.faces)
    s, _ = result.centerline.project(V[F].mean(axis=1))
    cd = fields.cell_data
    covered = (np.asarray(cd["reached_warp"]) > 0) | (np.asarray(cd["reached_weft"]) > 0)
    fell = np.asarray(result.fell_s)
    return field_reasons(s, covered, float(fell[-1].max()), float(fell[0].min()),
                         2.0 * float(fields.pool_radius_m), settings, front_start=float(fell[-1].min()))


def snapshot_checks(snap, mu, kinds=None) -> tuple[float, float]:
    """(largest imbalance / the snapshot's largest tension, largest Psi / tension) of a
    convergence-zone snapshot, from its own arrays as a reader of ``convergence.pvd`` sees them.

    At a crossing point i of a yarn (``contact_id >= 0``, not the yarn's first or last point) the
    segments below and above pull with tensions f_lo, f_hi along the unit vectors u_lo, u_hi to
    the neighbouring points; the crossing's two points (one per yarn, the same contact id) and
    their ``external_force_N`` must sum to zero. The friction law: with cos(beta) =
    u_lo . u_hi, ``Psi = |f_lo - f_hi| sqrt((1 - cos beta) / 2) - mu (f_lo + f_hi) sqrt((1 + cos
    beta) / 2) <= 0``. (0, 0) for a snapshot without crossings (the kinematic zone).

    mu: the yarn-yarn friction, or with ``kinds`` (n_yarns,) every yarn's type, the (nt, nt)
    table of every pair of types (``Config.pair_friction``): each crossing its pair's."""
    P = np.asarray(snap.points, dtype=float)
    off = np.asarray(snap.offsets, dtype=np.int64)
    cid = np.asarray(snap.contact_id, dtype=np.int64)
    ten = np.asarray(snap.tension_N, dtype=float)
    yarn = np.repeat(np.arange(len(off) - 1), np.diff(off))
    j = np.arange(len(P))
    inner = (cid >= 0) & (j > off[yarn]) & (j < off[yarn + 1] - 1)
    j, k = j[inner], yarn[inner]
    if not len(j) or not len(ten):
        return 0.0, 0.0
    lo, hi = P[j - 1] - P[j], P[j + 1] - P[j]
    u_lo = lo / np.linalg.norm(lo, axis=1)[:, None]
    u_hi = hi / np.linalg.norm(hi, axis=1)[:, None]
    f_lo, f_hi = ten[j - k - 1], ten[j - k]
    force = f_lo[:, None] * u_lo + f_hi[:, None] * u_hi + snap.external_forces()[j]
    ids, at = np.unique(cid[j], return_inverse=True)
    net = np.zeros((len(ids), 3))
    np.add.at(net, at, force)
    if kinds is not None:     # a crossing's pair: the types of the two yarns of its contact id
        kinds = np.asarray(kinds)
        lo_type = np.full(len(ids), np.iinfo(np.int64).max)
        hi_type = np.full(len(ids), -1)
        np.minimum.at(lo_type, at, kinds[k])
        np.maximum.at(hi_type, at, kinds[k])
        mu = np.asarray(mu, dtype=float)[lo_type, hi_type][at]
    imbalance = np.linalg.norm(net, axis=1) / float(np.max(ten))
    cb = np.clip(np.einsum("ij,ij->i", u_lo, u_hi), -1.0, 1.0)
    psi = (np.abs(f_lo - f_hi) * np.sqrt((1.0 - cb) / 2.0)
           - mu * (f_lo + f_hi) * np.sqrt((1.0 + cb) / 2.0)) / np.maximum(f_lo, f_hi)
    return float(imbalance.max()), float(psi.max())


def snapshot_reasons(snapshots, mu, settings: QualitySettings = QUALITY,
                     width: float | None = None, kinds=None) -> list[str]:
    """Reasons to doubt the written convergence-zone snapshots, one a kind (the worst snapshot
    and how many): crossings out of balance beyond ``max_snapshot_imbalance``
    (:func:`snapshot_checks`), a slack segment, and, where a re-balance checked the snapshot
    (``Snapshot.rebalanced``): the re-balanced copy outside the friction cone
    (``max_snapshot_psi``), the re-balance failing, or the written crossings further than
    ``max_snapshot_shift_widths`` yarn widths (``width``, m) from the re-balanced ones. A
    snapshot without a re-balanced copy is checked for the friction cone itself. mu, kinds: as
    :func:`snapshot_checks`."""
    found = {"imbalance": [], "psi": [], "slack": [], "failed": [], "shift": []}
    for snap in snapshots:
        imbalance, psi = snapshot_checks(snap, mu, kinds)
        if snap.rebalanced is not None:
            psi = snapshot_checks(snap.rebalanced, mu, kinds)[1]
        ten = np.asarray(snap.tension_N, dtype=float)
        shift = float(snap.rebalance_shift_m)
        t = snap.time_s
        if imbalance > settings.max_snapshot_imbalance:
            found["imbalance"].append((imbalance, t))
        if psi > settings.max_snapshot_psi:
            found["psi"].append((psi, t))
        if len(ten) and float(ten.min()) <= 0.0:
            found["slack"].append((-float(ten.min()), t))
        if snap.rebalance_error:
            found["failed"].append((0.0, t, snap.rebalance_error))
        if width is not None and np.isfinite(shift) and shift > settings.max_snapshot_shift_widths * width:
            found["shift"].append((shift, t))
    n = len(snapshots)
    reasons = []

    def worst(kind):
        items = found[kind]
        return len(items), max(items, key=lambda x: x[0])

    if found["imbalance"]:
        k, (v, t) = worst("imbalance")
        reasons.append(f"{k} of {n} convergence-zone snapshots have crossings out of balance, by up "
                       f"to {v:.2g} of their largest tension at t = {t:.4g} s (above "
                       f"{settings.max_snapshot_imbalance:g}; convergence.pvd)")
    if found["psi"]:
        k, (v, t) = worst("psi")
        reasons.append(f"{k} of {n} convergence-zone snapshots have crossings outside the friction "
                       f"cone, by up to {v:.2g} of their tension at t = {t:.4g} s (above "
                       f"{settings.max_snapshot_psi:g}): their friction bounds did not settle "
                       f"(convergence.pvd)")
    if found["slack"]:
        k, (v, t) = worst("slack")
        reasons.append(f"{k} of {n} convergence-zone snapshots have a slack yarn (a segment at "
                       f"{-v:.3g} N at t = {t:.4g} s; convergence.pvd)")
    if found["failed"]:
        k = len(found["failed"])
        _, t, why = found["failed"][0]
        reasons.append(f"{k} of {n} convergence-zone snapshots could not be checked: their "
                       f"re-balance found no balanced state (first at t = {t:.4g} s: {why})")
    if found["shift"]:
        k, (v, t) = worst("shift")
        reasons.append(f"{k} of {n} convergence-zone snapshots (the run's own states) have "
                       f"crossings more than {settings.max_snapshot_shift_widths:g} yarn widths "
                       f"from where their step's own problem puts them balanced (its fell and "
                       f"ring points held, its friction bounds converged), up to "
                       f"{v * 1e3:.3g} mm at t = {t:.4g} s: those steps had not converged "
                       f"(history.csv's residual)")
    return reasons


def assess(result, settings: QualitySettings = QUALITY, interlacing=False) -> dict:
    """The verdict on a Result from its status, history, laid yarns and convergence-zone
    snapshots (see module docstring). ``interlacing``: the run's :func:`run_interlacing` where
    the caller has it (False: computed here)."""
    reasons = []
    if result.status != "done":
        reasons.append(f"the run did not finish: status {result.status}"
                       + (f" ({result.message})" if result.message else ""))
    if result.steps:
        reasons += history_reasons(result.history, settings)
        reasons += residual_reasons(result.history, settings)
        if result.config is not None:
            reasons += fell_jump_reasons(result.history, result.config.process.take_up_speed,
                                         settings)
    reasons += yarn_reasons(result.yarns.flags, settings)
    reasons += slip_reasons(result.yarns.flags, settings)
    reasons += interlacing_reasons(run_interlacing(result) if interlacing is False else interlacing,
                                   settings)
    if result.snapshots and result.config is not None:
        cfg = result.config
        if getattr(cfg, "is_mixed", False):   # every crossing's pair friction
            reasons += snapshot_reasons(result.snapshots, cfg.pair_friction()[0], settings,
                                        width=float(cfg.yarn.width), kinds=cfg.carrier_types())
        else:
            reasons += snapshot_reasons(result.snapshots, float(cfg.yarn.friction), settings,
                                        width=float(cfg.yarn.width))
    return verdict(reasons)
