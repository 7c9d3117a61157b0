"""When a base shift happened: the time whose rigid shift best explains a fit's residuals.

Every gap between two consecutive readings is a candidate (a shift may fall between the SMRs of
one pose). For each, the gain of the six shift columns, made orthogonal to the geometric
Jacobian (under the geometry's prior, solver.prior, when the fit has one), is b' G^-1 b; all the
Gram sums are suffix sums over readings in time order, so the whole scan costs about one
Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import Inputs
from .extended import predict_extended
from .finite import finite
from .kinematics import Layout, predict_rows
from .prior import Prior
from .selection import EDGE_POSES
from .tall import tall_qr

GAP_BLOCK = 4096  # gaps between readings whose base-shift gains are solved at once


def shift_time(
    layout: Layout, x, ee, sub: Inputs, meas, free, centroid, prior: Prior | None = None
) -> float:
    """The time of a base shift that best explains the residuals of the model (x, extensions ee)
    on readings meas (m, K, 3) at inputs sub (linearised); free: the geometry's fitted entries."""
    assert sub.time_s is not None  # a base shift is only scanned for with timed readings
    mask = np.all(np.isfinite(meas), axis=-1) & np.isfinite(sub.time_s)
    r = predict_extended(layout, x, ee, sub)[mask] - meas[mask]  # (N, 3)
    idx = np.flatnonzero(free)
    _, Jt = predict_rows(layout, x, sub.q, mask, idx)  # (P, N, 3)
    J, rp = finite(Jt.reshape(len(idx), -1).T, "an effect's Jacobian"), np.zeros(0)
    if prior is not None:  # geometry absorbs the residual under its prior's rows
        J, rp = np.vstack([J, np.diag(np.sqrt(prior.weight[idx]))]), prior.rows(x, idx)
    Q, _ = tall_qr(J)
    Qp, Q = Q[len(Q) - len(rp) :], Q[: len(Q) - len(rp)].reshape(-1, 3, Q.shape[1])  # (N, 3, P)
    t = sub.time_s[mask]
    order = np.argsort(t, kind="stable")
    t, r, Q = t[order], r[order], Q[order]
    v = meas[mask][order] - centroid
    Z = np.zeros((len(t), 3, 6))  # per reading: translation and rotation columns
    Z[:, [0, 1, 2], [0, 1, 2]] = 1.0
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        Z[:, :, 3 + a] = np.cross(e, v)
    suffix = lambda a: np.cumsum(a[::-1], axis=0)[::-1]  # noqa: E731
    ZZ = suffix(np.einsum("nci,ncj->nij", Z, Z))
    QZ = suffix(np.einsum("ncp,nci->npi", Q, Z))
    Zr = suffix(np.einsum("nci,nc->ni", Z, r))
    Qr = np.einsum("ncp,nc->p", Q, r) + Qp.T @ rp
    lo = EDGE_POSES * meas.shape[1]
    gaps = np.arange(max(lo, 1), len(t) - lo)
    gaps = gaps[t[gaps] != t[gaps - 1]]
    blocks = np.array_split(gaps, 1 + len(gaps) // GAP_BLOCK)
    gain = np.concatenate([[]] + [shift_gains(ZZ[n], QZ[n], Zr[n], Qr) for n in blocks])
    gain = np.nan_to_num(gain, nan=-np.inf)  # as the comparison in time order skipped them
    if not len(gain) or not gain.max() > -1.0:
        return float(np.median(t))
    n = gaps[int(np.argmax(gain))]  # the first of equal gains, as a scan in time order keeps
    return 0.5 * float(t[n - 1] + t[n])


def shift_gains(ZZ, QZ, Zr, Qr) -> np.ndarray:
    """Per gap, the gain b' G^-1 b of a base shift after it (shift_time), for a block of
    gaps at once; a gap whose normal matrix is singular gains nothing (-inf)."""
    QZt = np.swapaxes(QZ, 1, 2)
    G = ZZ - QZt @ QZ
    b = Zr - QZt @ Qr
    G = G + 1e-12 * np.trace(G, axis1=1, axis2=2)[:, None, None] * np.eye(6)
    finite(G, "a time shift's normal matrix")
    finite(b, "a time shift's gradient")
    solvable = np.ones(len(G), bool)
    try:
        x = np.linalg.solve(G, b[..., None])[..., 0]
    except np.linalg.LinAlgError:  # a singular gap in the block: the others one by one
        x = np.zeros_like(b)
        for i in range(len(G)):
            try:
                x[i] = np.linalg.solve(G[i], b[i])
            except np.linalg.LinAlgError:
                solvable[i] = False
    return np.where(solvable, np.sum(b * x, axis=1), -np.inf)


# A base shift in the last poses of a campaign: too few poses after it for the selection's split
# (EDGE_POSES on either side), so said apart. Its tail poses each miss by more than LATE_RATIO x
# the other poses' typical reading error and by more than LATE_BEYOND x the worst other pose,
# and one rigid motion of them all leaves no more than LATE_LEFT x that error; two readings at
# least (one is an outlier as well as a shift).
LATE_RATIO = 5.0
LATE_BEYOND = 2.0
LATE_LEFT = 3.0
# 3-D residuals' RMS over their median norm squared (chi-square of 3: mean 3, median 2.366): the
# typical error robust to the outliers and the tail themselves
CHI2_3_MEAN_OVER_MEDIAN = 3.0 / 2.365974


@dataclass(frozen=True)
class LateShift:
    """The last poses of a campaign in time order, moved together: which, by how much (mm)."""

    poses: np.ndarray  # (k,) pose indices, in time order
    shift_mm: np.ndarray  # (3,) their mean residual (prediction - reading), tracker frame
    miss_mm: float  # the shift's length
    rest_mm: float  # the other poses' typical reading error (3-D RMS)
    left_mm: float  # what one rigid motion of the tail leaves (3-D RMS a reading)


def late_shift(resid: np.ndarray, order: np.ndarray, points: np.ndarray) -> LateShift | None:
    """The last poses (fewer than EDGE_POSES, time order `order`) whose readings all miss by a
    common rigid motion, far beyond every other pose's miss; None when there is none.

    resid (m, K, 3): a model's residuals (prediction - reading, NaN where missing); points
    (m, K, 3): the readings, about which the tail's rotation is fitted.
    """
    r = np.asarray(resid, dtype=float)
    seen = np.all(np.isfinite(r), axis=-1)  # (m, K)
    m = len(r)
    if m < 2 * EDGE_POSES:
        return None
    order = np.asarray(order)[seen[np.asarray(order)].any(axis=1)]
    miss = np.full(m, np.nan)  # each pose's mean miss over its SMRs
    mean = np.zeros((m, 3))
    for p in order:
        mean[p] = r[p][seen[p]].mean(axis=0)
        miss[p] = float(np.linalg.norm(mean[p]))
    found = None
    for k in range(1, EDGE_POSES):
        tail, rest = order[-k:], order[:-k]
        e2 = np.sum(r[rest][seen[rest]] ** 2, axis=-1)
        typical = float(np.sqrt(np.median(e2) * CHI2_3_MEAN_OVER_MEDIAN)) if e2.size else 0.0
        worst = float(np.nanmax(miss[rest]))
        if not (typical > 0 and miss[tail].min() > max(LATE_RATIO * typical, LATE_BEYOND * worst)):
            continue
        if seen[tail].sum() < 2:  # one reading: an outlier as well, no common motion to check
            continue
        shift = mean[tail].mean(axis=0)
        left = rigid_left(r[tail][seen[tail]], np.asarray(points)[tail][seen[tail]])
        if left <= LATE_LEFT * typical:
            found = LateShift(tail, shift, float(np.linalg.norm(shift)), typical, left)
    return found


def rigid_left(r: np.ndarray, points: np.ndarray) -> float:
    """3-D RMS of residuals r (n, 3) after the rigid motion (a translation, and a small rotation
    about the points' centroid where three points or more fix one) that best explains them."""
    v = points - points.mean(axis=0)
    Z = np.zeros((len(r), 3, 6))
    Z[:, [0, 1, 2], [0, 1, 2]] = 1.0
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        Z[:, :, 3 + a] = np.cross(e, v)
    Z = Z.reshape(-1, 6) if len(r) >= 3 else Z.reshape(-1, 6)[:, :3]
    y = r.reshape(-1)
    fit = Z @ np.linalg.lstsq(Z, y, rcond=None)[0]
    return float(np.sqrt(np.sum((y - fit) ** 2) / len(r)))
