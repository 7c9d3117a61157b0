"""Base registration and the least-squares identification methods (the paper's conditions 0-4 and 6)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .finite import finite, require_inputs
from .kinematics import Layout, predict, predict_rows
from .lm import Normal, damped_step, levenberg_marquardt, scaled
from .normal import PointNormal
from .prior import Prior
from .rigid import kabsch
from .robot import Robot


@dataclass
class Problem:
    """Joint readings and measured SMR centres to fit, with the layout of the unknowns."""

    layout: Layout
    q: np.ndarray  # (m, n) rad
    meas: np.ndarray  # (m, K, 3) mm, NaN where missing
    mask: np.ndarray = field(init=False)

    def __post_init__(self):
        self.mask = np.all(np.isfinite(self.meas), axis=-1)

    def residuals(self, x) -> np.ndarray:
        """pred - meas, (m, K, 3), NaN where missing."""
        return predict(self.layout, x, self.q) - self.meas

    def sum_squares(self, x) -> np.ndarray:
        """F_i of eq. (6) per target."""
        r = self.residuals(x)
        return np.nansum(r * r, axis=(0, 2))

    def rebased(self, x) -> tuple[Problem, np.ndarray]:
        lay, y = self.layout.rebased(x)
        return Problem(lay, self.q, self.meas), y


# The closed-form start needs no more poses than this (spread evenly over the campaign).
REGISTER_POSES = 32
# a base guess that fits the readings worse than the data's own registration by more than this
# (RMS, the nominal arm's millimetres of error and the guess's few) is not used
GUESS_SLACK_MM = 25.0
# On large campaigns the fits' first step is taken on about this many poses: it only has to
# land near the minimum, where the Jacobian of all the data is then taken once.
START_POSES = 64
# A first step is only taken on a subset of the poses that identifies the free parameters this well.
START_CONDITION = 1e6


def spread(m: int, n: int) -> slice:
    """At most n of m poses, evenly spread over the campaign."""
    return slice(None, None, -(-m // n))


def start_poses(m: int) -> slice | None:
    """The poses a fit's first step is taken on, or None where a subset of m would save little."""
    return spread(m, START_POSES) if m > 2 * START_POSES else None


def register(robot: Robot, targets: np.ndarray, names, q, meas, base_guess=None, refine=True):
    """A problem and its start vector with the base found from the data (no user guess needed).

    The nominal prediction in the base frame is registered onto the measurements by a
    closed-form point-set fit; then, if refine, base and SMR positions are fitted with the
    nominal joints (the paper's condition 0). The fitting methods skip that: they start from
    the closed-form base and fit base and SMRs with everything else.
    """
    targets = np.asarray(targets, dtype=float)
    require_inputs(q, meas, targets, base_guess)
    base_guess = trusted_guess(robot, targets, names, q, meas, base_guess)
    if base_guess is None:
        base_guess = _registered(robot, targets, names, q, meas)[0]
    prob = Problem(Layout(robot, np.asarray(base_guess, float), tuple(names)), q, meas)
    x0 = prob.layout.initial(targets)
    if not refine:
        return prob, x0
    free = np.zeros(prob.layout.n_params, dtype=bool)
    free[prob.layout.base_slice] = True
    free[prob.layout.target_slice] = True
    x, _ = least_squares_fit(prob, x0, free)
    return prob.rebased(x)


def _registered(robot: Robot, targets, names, q, meas):
    """The base registering the nominal arm onto the readings (closed form, REGISTER_POSES spread
    poses), the nominal points there in the base frame (N, 3) and the readings (N, 3)."""
    lay0 = Layout(robot, np.eye(4), tuple(names))
    some = spread(len(q), REGISTER_POSES)
    nominal = predict(lay0, lay0.initial(np.asarray(targets, float)), np.asarray(q)[some])
    ok = np.all(np.isfinite(meas[some]), axis=-1)
    return kabsch(nominal[ok], meas[some][ok]), nominal[ok], meas[some][ok]


def trusted_guess(robot: Robot, targets, names, q, meas, base_guess):
    """The user's base guess, or None where the data's registration fits the readings better by
    more than GUESS_SLACK_MM RMS: a guess in metres or turned the wrong way starts the fit so far
    off that it ends in a mirrored arm (links flipped by 180 degrees, a2 +1225 mm)."""
    if base_guess is None:
        return None
    base, nominal, measured = _registered(robot, targets, names, q, meas)

    def rms(T):
        T = np.asarray(T, float)
        e = nominal @ T[:3, :3].T + T[:3, 3] - measured
        return float(np.sqrt(np.mean(np.sum(e * e, axis=-1))))

    return None if rms(base_guess) > rms(base) + GUESS_SLACK_MM else base_guess


# Moves under which the point Jacobian of a metre-sized arm changes by about 1e-4 of itself.
NEAR_RAD, NEAR_MM = 1e-4, 0.1


def selected(mask: np.ndarray, rows=None) -> np.ndarray:
    """The readings of mask (m, K) on the targets in rows (default all)."""
    if rows is None:
        return mask
    sel = np.zeros(mask.shape[1], dtype=bool)
    sel[list(rows)] = True
    return mask & sel[None, :]


class SumOfSquares:
    """ls-sum on the selected targets (eq. 6 summed) over the free entries of x."""

    def __init__(self, prob: Problem, x0, free, rows=None, points: PointNormal | None = None):
        self.prob = prob
        self.mask = selected(prob.mask, rows)
        self.idx = np.flatnonzero(free)
        self.x0 = np.array(x0, dtype=float)
        self.points = points or PointNormal(prob.layout, prob.q, self.mask, prob.meas, self.idx)
        self.start: dict = {}  # the poses of a first step on a subset, and whether it was taken
        kinds = {op.param: op.kind for op in prob.layout.ops()}
        self.angle = np.array([kinds.get(int(i)) == "r" for i in self.idx], dtype=bool)
        # the geometry's prior (solver.prior): its rows follow the readings' in the residuals
        self.prior: Prior | None = None

    def near(self, za, zb) -> bool:
        """The Jacobian at za stands for the one at zb: it changes by ~1e-4 of itself in between."""
        dz = np.abs(np.asarray(zb) - np.asarray(za))
        return (
            dz[self.angle].max(initial=0.0) <= NEAR_RAD
            and dz[~self.angle].max(initial=0.0) <= NEAR_MM
        )

    def full(self, z) -> np.ndarray:
        x = self.x0.copy()
        x[self.idx] = z
        return x

    def normal(self, z=None) -> Normal:
        """J'J, J'r and the cost at z (default: the start), the prior's terms added."""
        x = self.x0 if z is None else self.full(z)
        return self.with_prior(self.points(x), x)

    def with_prior(self, ne: Normal, x) -> Normal:
        """The normal equations ne of the readings at x with the prior's rows added."""
        return ne if self.prior is None else self.prior.normal(ne, x, self.idx)

    def residual(self, z) -> np.ndarray:
        """The readings' residuals at z, then the prior's rows."""
        x = self.full(z)
        r = self.points.residual(x)
        return r if self.prior is None else self.prior.residual(r, x, self.idx)

    def per_target(self, r: np.ndarray) -> np.ndarray:
        """F_i of eq. (6) per target from residuals (predict - meas)[mask] flattened (rows past
        the readings', the prior's, left out)."""
        k = np.nonzero(self.mask)[1]
        r = r[: 3 * len(k)]
        return np.bincount(k, np.sum(r.reshape(-1, 3) ** 2, axis=1), minlength=self.mask.shape[1])

    def step_from(self, ne: Normal) -> bool:
        """Move the start by the Gauss-Newton step of ne, the normal equations of a subset of
        the poses there, if they identify the free parameters well; whether it moved."""
        As, gs, d = scaled(ne.A, ne.g)
        w = np.linalg.eigvalsh(finite(As, "the normal matrix"))
        if w[0] <= w[-1] / START_CONDITION**2:
            return False
        self.x0[self.idx] += damped_step(As, gs, d)
        return True

    def fit(self, first: Normal | None = None, max_iter=100):
        """Levenberg-Marquardt from the start; returns (x, LMResult).

        first: the readings' normal equations at the start (the prior's terms are added here).
        Without first, a large campaign's first step is taken on START_POSES spread poses.
        """
        sub = start_poses(len(self.mask))
        if first is None and sub is not None:
            prob = self.prob
            subset = PointNormal(prob.layout, prob.q[sub], self.mask[sub], prob.meas[sub], self.idx)
            ne = self.with_prior(subset(self.x0), self.x0)
            self.start = {"poses": len(subset.q), "stepped": self.step_from(ne)}
        res = levenberg_marquardt(
            None,
            self.x0[self.idx],
            normal=self.normal,
            first=None if first is None else self.with_prior(first, self.x0),
            residual=self.residual,
            max_iter=max_iter,
            near=self.near,
        )
        return self.full(res.x), res


def start_fit(robot: Robot, targets, names, q, meas, free, rows=None, base_guess=None):
    """ls-sum on the selected targets started from the data alone: (SumOfSquares, normal equations at its start).

    One pass down the chain yields both the closed-form base (unless base_guess is given) and
    the normal equations at the nominal model. Up to 2 x START_POSES poses, that pass covers the
    campaign and the fit starts there. On larger campaigns it covers START_POSES spread poses,
    the fit starts after their Gauss-Newton step, and the normal equations of all the data are
    taken once, there.
    """
    q, meas = np.asarray(q, dtype=float), np.asarray(meas, dtype=float)
    base_guess = trusted_guess(robot, targets, names, q, meas, base_guess)
    lay = Layout(
        robot, np.eye(4) if base_guess is None else np.asarray(base_guess, float), tuple(names)
    )
    x0 = lay.initial(targets)
    mask = selected(np.all(np.isfinite(meas), axis=-1), rows)
    sub = start_poses(len(q))
    some = sub or slice(None)
    points = PointNormal(lay, q[some], mask[some], meas[some], np.flatnonzero(free))
    if base_guess is None:
        points, ne = points.register(x0)
    else:
        ne = points(x0)
    prob = Problem(points.layout, q, meas)
    if sub is None:
        return SumOfSquares(prob, x0, free, rows, points=points), ne
    fit = SumOfSquares(prob, x0, free, rows)
    fit.start = {"poses": len(points.q), "stepped": fit.step_from(ne)}
    return fit, fit.normal()


def least_squares_fit(prob: Problem, x0, free, rows=None, max_iter=100):
    """Levenberg-Marquardt on the point residuals of the selected targets; returns (x, LMResult)."""
    return SumOfSquares(prob, x0, free, rows).fit(max_iter=max_iter)


def fit_targets(prob: Problem, x, which) -> np.ndarray:
    """SMR positions in the flange frame for the given targets with geometry and base held (linear LS)."""
    from .kinematics import flange_frames

    R, o = flange_frames(prob.layout, x, prob.q)
    x = np.array(x, dtype=float)
    ts = prob.layout.target_slice.start
    for k in which:
        ok = prob.mask[:, k]
        # meas = R t + o  =>  t = mean of R^T (meas - o): R is orthonormal, so this is the LS solution
        t = np.einsum("mji,mj->mi", R[ok], prob.meas[ok, k] - o[ok]).mean(axis=0)
        x[ts + 3 * k : ts + 3 * k + 3] = t
    return x


def pose_weight(targets: np.ndarray) -> float:
    """mm per rad for the ls-pose orientation residual: the RMS radius of the SMR ring.

    An orientation error of w rad then weighs as much as the SMR displacement it causes.
    """
    c = targets - targets.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(c * c, axis=1))))


def pose_residuals(pred, meas, J, weight):
    """Per pose: centroid error and weight x the small rotation best aligning the SMR errors.

    For errors e_k = pred_k - meas_k at lever arms d_k from the measured centroid, the rotation
    w solving min sum ||e_k - mean(e) - w x d_k||^2 is M^-1 sum d_k x (e_k - mean(e)). With the
    lever arms taken from the measurement, w is exactly linear in the errors, so its Jacobian is
    the same map applied to the point Jacobians.
    """
    d = meas - meas.mean(axis=1, keepdims=True)
    e = pred - meas
    ebar = e.mean(axis=1)
    dd = np.einsum("mki,mki->m", d, d)
    M = dd[:, None, None] * np.eye(3) - np.einsum("mki,mkj->mij", d, d)
    Minv = np.linalg.inv(finite(M, "the pose fit's normal matrix"))
    w = np.einsum("mij,mj->mi", Minv, np.cross(d, e - ebar[:, None, :]).sum(axis=1))
    Jbar = J.mean(axis=1)
    # d x J for each parameter column: cross along axis -2 of (m, K, 3, P)
    dJ = np.cross(d[..., None], (J - Jbar[:, None]), axisa=-2, axisb=-2, axisc=-2).sum(axis=1)
    Jw = np.einsum("mij,mjp->mip", Minv, dJ)
    r = np.concatenate([ebar, weight * w], axis=1)
    Jr = np.concatenate([Jbar, weight * Jw], axis=1)
    return r, Jr


def pose_fit(prob: Problem, x0, free, weight, max_iter=100, prior: Prior | None = None):
    """Least squares on position and orientation of the frame spanned by the SMRs (condition 6),
    the prior's rows (solver.prior) after the poses'."""
    full_poses = np.all(prob.mask, axis=1)
    if prob.meas.shape[1] < 3 or full_poses.sum() == 0:
        raise ValueError("ls-pose needs poses with at least three targets measured")
    q, meas = prob.q[full_poses], prob.meas[full_poses]
    m, K = meas.shape[:2]
    mask = np.ones((m, K), dtype=bool)
    idx = np.flatnonzero(free)
    x = np.array(x0, dtype=float)

    def fun(z):
        xx = x.copy()
        xx[idx] = z
        p, Jt = predict_rows(prob.layout, xx, q, mask, idx)
        J = Jt.reshape(len(idx), m, K, 3).transpose(1, 2, 3, 0)
        r, Jr = pose_residuals(p.reshape(m, K, 3), meas, J, weight)
        return r.ravel(), Jr.reshape(-1, len(idx)).T

    if prior is None:
        res = levenberg_marquardt(fun, x[idx], max_iter=max_iter)
    else:
        res = levenberg_marquardt(None, x[idx], max_iter=max_iter, **prior.fit(fun, x, idx))
    x[idx] = res.x
    return x, res
