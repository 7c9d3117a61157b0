"""Levenberg-Marquardt on the normal equations, for tall problems with tens of parameters.

Our Jacobians have tens of columns and up to 10^5 rows: working with J'J and J'r (tens by tens)
beats a QR of J per iteration, and is accurate here because the columns are scaled to unit norm
(the scaled condition numbers are in the tens to thousands).

Calibration problems are nearly linear (errors of a millimetre on a metre-sized arm), so after a
step whose linear model predicted the decrease well, the same Jacobian serves once more: the next
step costs one residual evaluation instead of a new Jacobian (a chord step), for as long as the
steps keep decreasing the cost as predicted. Convergence is only declared on a fresh Jacobian, so
the end point is a true stationary point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

# A step whose actual decrease is within this fraction of the predicted one keeps its Jacobian.
REUSE_RHO = 0.9
# A Jacobian taken where the cost was within this fraction of the current one certifies a minimum.
NEAR = 1e-2


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


def levenberg_marquardt(fun, x0, residual=None, max_iter=100, ftol=1e-8, xtol=1e-12,
                        normal=None, first: Normal | None = None) -> LMResult:
    """Minimise ||r(x)||^2.

    Either fun(x) -> (r, Jt) or normal(x) -> Normal; residual(x) -> r evaluates a trial step
    without derivatives (required with normal). first: the normal equations at x0, if known.
    ftol: stop when the next step would lower the cost by less than this fraction (scipy's
    least_squares default).
    """
    if normal is None:
        normal = from_jacobian(fun)
        residual = residual or (lambda z: fun(z)[0])
    x = np.array(x0, dtype=float)
    ne = first or normal(x)
    cost = ne.cost
    at_jacobian, chords = cost, 0  # cost where the Jacobian in use was taken; steps reusing it
    nfev = njev = 1
    lam, message, it, r = 1e-3, "iteration limit reached", 0, None

    def refresh():
        nonlocal ne, at_jacobian, chords, nfev, njev
        ne, at_jacobian, chords = normal(x), cost, 0
        nfev, njev = nfev + 1, njev + 1

    for it in range(1, max_iter + 1):
        A, g = ne.A, ne.g
        d = np.sqrt(np.diag(A))
        d[d == 0] = 1.0
        As, gs = A / np.outer(d, d), g / d
        while True:
            try:
                step = -np.linalg.solve(As + lam * np.eye(len(d)), gs) / d
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            predicted = -(2.0 * g @ step + step @ A @ step)  # decrease of the linear model
            if predicted <= ftol * cost:
                # nothing left to gain at this damping: a minimum, if this Jacobian is that of x
                # or was taken so near that it differs from it by rounding only
                if chords == 0 or at_jacobian - cost <= NEAR * at_jacobian:
                    return LMResult(x, cost, it, nfev, "converged", njev, r)
                break
            rn = residual(x + step)
            nfev += 1
            cn = float(rn @ rn)
            if cn < cost or chords:
                break
            lam *= 10.0
            if lam > 1e16:
                return LMResult(x, cost, it, nfev, "no further decrease", njev, r)
        if chords and (predicted <= ftol * cost or cn >= cost):
            refresh()  # the reused Jacobian is spent
            continue
        small_f = (cost - cn) <= ftol * cost
        small_x = np.linalg.norm(step * d) <= xtol * (np.linalg.norm(x * d) + xtol)
        rho = (cost - cn) / predicted if predicted > 0 else 0.0
        lam = lam * 0.3 if rho > 0.75 else lam * 2.0 if rho < 0.25 else lam
        lam = max(lam, 1e-12)
        x, cost, r = x + step, cn, rn
        if chords == 0 and (small_f or small_x):
            message = "converged"
            break
        # Reuse the Jacobian while its linear model predicts the decrease; after a large move
        # (far from the minimum, where it bends) only once.
        if abs(1.0 - rho) < 1.0 - REUSE_RHO and (chords == 0 or cost >= 0.5 * at_jacobian):
            ne, chords = Normal(cn, A, ne.jt(rn), ne.jt), chords + 1
        else:
            refresh()
    return LMResult(x, cost, it, nfev, message, njev, r)
