"""Levenberg-Marquardt on the normal equations, for tall problems with tens of parameters.

Our Jacobians have tens of columns and up to 10^5 rows: forming J'J (one BLAS call) and solving
a tens-by-tens system beats a QR of J per iteration, and is accurate here because the columns are
scaled to unit norm (the scaled condition numbers are in the tens to thousands).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class LMResult:
    """Solution, final cost (sum of squares), iterations, residual evaluations, why it stopped."""

    x: np.ndarray
    cost: float
    iterations: int
    nfev: int
    message: str


def levenberg_marquardt(fun, x0, residual=None, max_iter=100, ftol=1e-10, xtol=1e-12) -> LMResult:
    """Minimise ||r(x)||^2 given fun(x) -> (r (M,), Jt (P, M)), the transposed Jacobian.

    residual(x) -> r, if given, evaluates a trial step without its Jacobian.
    """
    residual = residual or (lambda z: fun(z)[0])
    x = np.array(x0, dtype=float)
    r, Jt = fun(x)
    cost = float(r @ r)
    nfev, lam, message = 1, 1e-3, "iteration limit reached"
    it = 0
    for it in range(1, max_iter + 1):
        A = Jt @ Jt.T
        g = Jt @ r
        d = np.sqrt(np.diag(A))
        d[d == 0] = 1.0
        As = A / np.outer(d, d)
        gs = g / d
        while True:
            try:
                step = -np.linalg.solve(As + lam * np.eye(len(d)), gs) / d
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            predicted = -(2.0 * g @ step + step @ A @ step)  # decrease of the linear model
            if predicted <= ftol * cost:
                # nothing left to gain at this damping: at the minimum, up to rounding
                return LMResult(x, cost, it, nfev, "converged")
            xn = x + step
            rn = residual(xn)
            nfev += 1
            cn = float(rn @ rn)
            if cn < cost:
                break
            lam *= 10.0
            if lam > 1e16:
                return LMResult(x, cost, it, nfev, "no further decrease")
        small_f = (cost - cn) <= ftol * cost or predicted <= ftol * cost
        small_x = np.linalg.norm(step * d) <= xtol * (np.linalg.norm(x * d) + xtol)
        rho = (cost - cn) / predicted if predicted > 0 else 0.0
        lam = lam * 0.3 if rho > 0.75 else lam * 2.0 if rho < 0.25 else lam
        lam = max(lam, 1e-12)
        x, cost = xn, cn
        if small_f or small_x:
            message = "converged"
            break
        r, Jt = fun(x)
        nfev += 1
    return LMResult(x, cost, it, nfev, message)
