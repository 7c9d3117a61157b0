"""Levenberg-Marquardt on the normal equations, for tall problems with tens of parameters.

Our Jacobians have tens of columns and up to 10^5 rows: working with J'J and J'r (tens by tens)
beats a QR of J per iteration, and is accurate here because the columns are scaled to unit norm
(the scaled condition numbers are in the tens to thousands).

Calibration problems are nearly linear (errors of a millimetre on a metre-sized arm), so after a
step whose linear model predicted the decrease well, the same Jacobian serves once more: the next
step costs one residual evaluation instead of a new Jacobian (a chord step), for as long as the
steps keep decreasing the cost as predicted. A first step that removes most of the cost is
evaluated with its Jacobian at once, since the point it reaches needs one. Convergence is only
declared on a Jacobian taken at the answer or so near it that they differ by rounding (the caller
can say what near means for its parameters), so the end point is a true stationary point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .finite import finite
from .stop import Stop

# A step whose actual decrease is within this fraction of the predicted one keeps its Jacobian.
REUSE_RHO = 0.9
# A Jacobian taken where the cost was within this fraction of the current one certifies a minimum.
NEAR = 1e-2
# A step predicted to remove more than this fraction of the cost lands where the Jacobian differs.
FAR = 0.5


@dataclass
class LMResult:
    """Solution, final cost (sum of squares), iterations, evaluations, why it stopped."""

    x: np.ndarray
    cost: float
    iterations: int
    nfev: int
    message: str
    njev: int = 0
    r: np.ndarray | None = None  # the residuals at x, when the last evaluation there gave them
    status: Stop = Stop.ITERATION_LIMIT


@dataclass
class Normal:
    """At one x: cost r'r, A = J'J, g = J'r, and jt: r' -> J'r' with this x's Jacobian."""

    cost: float
    A: np.ndarray
    g: np.ndarray
    jt: Callable[[np.ndarray], np.ndarray]


def from_jacobian(fun):
    """Normal equations from fun(x) -> (r (M,), Jt (P, M)), the transposed Jacobian."""

    def normal(x) -> Normal:
        r, Jt = fun(x)
        return Normal(float(r @ r), Jt @ Jt.T, Jt @ r, lambda res: Jt @ res)

    return normal


# The damping Levenberg-Marquardt starts with, relative to the Jacobi-scaled J'J.
LAMBDA0 = 1e-5


def scaled(A: np.ndarray, g: np.ndarray):
    """J'J and J'r with the columns of J scaled to unit norm: (As, gs, column norms)."""
    d = np.sqrt(np.diag(A))
    d[d == 0] = 1.0
    return A / np.outer(d, d), g / d, d


def damped_step(As: np.ndarray, gs: np.ndarray, d: np.ndarray, lam: float = LAMBDA0) -> np.ndarray:
    """The Levenberg-Marquardt step -(A + lam diag(A))^-1 g from scaled(A, g)."""
    return (
        -np.linalg.solve(
            finite(As + lam * np.eye(len(d)), "the normal equations"), finite(gs, "the gradient")
        )
        / d
    )


def near_by_cost(cost_at_jacobian: float, cost: float) -> bool:
    """Default test that a Jacobian taken where the cost was cost_at_jacobian still holds now."""
    return cost_at_jacobian - cost <= NEAR * cost_at_jacobian


def levenberg_marquardt(
    fun,
    x0,
    residual=None,
    max_iter=100,
    ftol=1e-8,
    xtol=1e-12,
    normal=None,
    first: Normal | None = None,
    near=None,
) -> LMResult:
    """Minimise ||r(x)||^2.

    Either fun(x) -> (r, Jt) or normal(x) -> Normal; residual(x) -> r evaluates a trial step
    without derivatives (required with normal). first: the normal equations at x0, if known.
    ftol: stop when the next step would lower the cost by less than this fraction (scipy's
    least_squares default). near(x_at_jacobian, x) -> True when the Jacobian taken at the first
    point is, to rounding, that of the second (default: the cost has changed by under 1%).
    """
    if normal is None:
        normal = from_jacobian(fun)
        residual = residual or (lambda z: fun(z)[0])
    x = np.array(x0, dtype=float)
    ne = first or normal(x)
    cost = ne.cost
    at = (x, cost)  # where the Jacobian in use was taken, and the cost there
    chords = 0  # steps taken on it since
    nfev = njev = 1
    lam, message, it, r = LAMBDA0, "iteration limit reached", 0, None
    stop = Stop.ITERATION_LIMIT

    def holds() -> bool:
        return chords == 0 or (near(at[0], x) if near else near_by_cost(at[1], cost))

    for it in range(1, max_iter + 1):
        A, g = ne.A, ne.g
        As, gs, d = scaled(A, g)
        while True:
            fresh_ne = None
            try:
                step = damped_step(As, gs, d, lam)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            predicted = -(2.0 * g @ step + step @ A @ step)  # decrease of the linear model
            if predicted <= ftol * cost:
                break
            if chords == 0 and predicted > FAR * cost:
                # far from the minimum the next point needs its own Jacobian: take it as the trial
                fresh_ne = normal(x + step)
                rn, cn = None, fresh_ne.cost
                nfev, njev = nfev + 1, njev + 1
            else:
                rn = residual(x + step)
                nfev += 1
                cn = float(rn @ rn)
            if cn < cost or chords:
                break
            lam *= 10.0
            if lam > 1e16:
                return LMResult(x, cost, it, nfev, "no further decrease", njev, r, Stop.OTHER)
        if predicted <= ftol * cost or cn >= cost:
            # nothing left to gain on this Jacobian: a minimum if it holds here, else take a fresh one
            if predicted <= ftol * cost and holds():
                return LMResult(x, cost, it, nfev, "converged", njev, r, Stop.CONVERGED)
            ne, at, chords = normal(x), (x, cost), 0
            nfev, njev = nfev + 1, njev + 1
            continue
        small_f = (cost - cn) <= ftol * cost
        small_x = np.linalg.norm(step * d) <= xtol * (np.linalg.norm(x * d) + xtol)
        rho = (cost - cn) / predicted if predicted > 0 else 0.0
        lam = lam * (0.1 if rho > 0.9 else 0.3 if rho > 0.75 else 2.0 if rho < 0.25 else 1.0)
        lam = max(lam, 1e-12)
        x, cost, r = x + step, cn, rn
        if fresh_ne is not None:
            ne, at, chords = fresh_ne, (x, cost), 0
            continue
        chords += 1
        if (small_f or small_x) and holds():
            message, stop = "converged", Stop.CONVERGED
            break
        if abs(1.0 - rho) < 1.0 - REUSE_RHO:
            # the linear model was right: another step on this Jacobian, at the new residual
            assert rn is not None, "only a step with a fresh Jacobian has no residual, and it left"
            ne = Normal(cn, A, ne.jt(rn), ne.jt)
        else:
            ne, at, chords = normal(x), (x, cost), 0
            nfev, njev = nfev + 1, njev + 1
    return LMResult(x, cost, it, nfev, message, njev, r, stop)
