"""The SQP subproblem of eq. (18) in epigraph form, and its two solvers.

    minimise   1/2 dx' H dx + dphi
    subject to g_i' dx - dphi <= phi - F_i     (one row per SMR, eq. 16)
               a_l' dx        <= -c_l          (distance invariance, eq. 9)

`primal_dual` is the paper's primal-dual method (eq. 22-24): the primal block is minimised
exactly for the current multipliers (H is known and positive definite), the dual block moves
along the constraint residual C + G dx and is projected back onto its feasible set (the SMR
multipliers sum to one because dphi is free; the others stay non-negative). A constant step
1/L with Nesterov momentum replaces the paper's diminishing step gamma_p / ||T^p||, which
converges only sub-linearly. `exact` hands the same QP to a maintained interior-point solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .finite import finite


@dataclass
class QPSolution:
    """Step, epigraph change, multipliers of the SMR rows and of the constraint rows, and
    whether the solver met its own optimality test (else dx is its last iterate)."""

    dx: np.ndarray
    dphi: float
    lam: np.ndarray
    mu: np.ndarray
    iterations: int
    converged: bool
    message: str


def project_simplex(v: np.ndarray) -> np.ndarray:
    """Euclidean projection onto {x >= 0, sum x = 1}."""
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - 1.0
    k = np.arange(1, len(v) + 1)
    rho = np.nonzero(u - css / k > 0)[0][-1]
    return np.maximum(v - css[rho] / (rho + 1), 0.0)


def _dphi(dx, g, F, phi):
    return float(np.max(g @ dx + F - phi))


def primal_dual(H, g, F, phi, A, c, tol=1e-10, max_iter=20000) -> QPSolution:
    """Solve the subproblem by dual projected gradient with momentum on exact primal minimisers."""
    K, L = g.shape[0], A.shape[0]
    G = np.vstack([g, A])
    b = np.concatenate([F - phi, c])
    chol = np.linalg.cholesky(finite(H, "the QP's Hessian"))
    W = np.linalg.solve(
        chol, finite(G.T, "the QP's constraints")
    )  # H^-1 = chol^-T chol^-1, so G H^-1 G' = W' W
    Q = W.T @ W
    # Rescaling a constraint row leaves the QP unchanged and evens out the dual's curvature.
    s = np.ones(K + L)
    if L:
        ref = np.mean(np.diag(Q)[:K]) or 1.0
        s[K:] = np.sqrt(ref / np.maximum(np.diag(Q)[K:], 1e-300 * ref))
    Q = Q * s[:, None] * s[None, :]
    b = b * s
    step = 1.0 / max(np.linalg.eigvalsh(finite(Q, "the QP's dual Hessian"))[-1], 1e-300)

    def project(v):
        return np.concatenate([project_simplex(v[:K]), np.maximum(v[K:], 0.0)])

    nu = project(np.full(K + L, 1.0 / K) * (np.arange(K + L) < K))
    y, t = nu.copy(), 1.0
    scale = max(abs(float(b @ nu)), float(nu @ Q @ nu), 1e-300)
    it, converged = 0, False
    for it in range(1, max_iter + 1):
        nu_new = project(y + step * (b - Q @ y))
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        y = nu_new + ((t - 1.0) / t_new) * (nu_new - nu)
        moved = np.max(np.abs(nu_new - nu))
        nu, t = nu_new, t_new
        if it % 10 == 0 or moved == 0.0:
            # duality gap of the primal point recovered from nu, with its constraint violation
            Qnu = Q @ nu
            dual = float(b @ nu - 0.5 * nu @ Qnu)
            lin = b - Qnu  # = C + G dx for dx = -H^-1 G' nu (scaled rows)
            primal = 0.5 * float(nu @ Qnu) + float(np.max(lin[:K]))
            viol = float(np.max(lin[K:], initial=0.0))
            if primal - dual <= tol * scale and viol <= tol * scale:
                converged = True
                break
    dx = -np.linalg.solve(chol.T, finite(W @ (s * nu), "the QP's step"))
    message = "duality gap below tolerance" if converged else "iteration limit reached"
    return QPSolution(dx, _dphi(dx, g, F, phi), nu[:K], s[K:] * nu[K:], it, converged, message)


def exact(H, g, F, phi, A, c) -> QPSolution:
    """Solve the subproblem with the Clarabel interior-point solver (through qpsolvers)."""
    from qpsolvers import Problem, solve_problem
    from scipy.sparse import csc_matrix

    n, K, L = H.shape[0], g.shape[0], A.shape[0]
    P = np.zeros((n + 1, n + 1))
    P[:n, :n] = H
    qv = np.zeros(n + 1)
    qv[n] = 1.0
    Gi = np.vstack([np.hstack([g, -np.ones((K, 1))]), np.hstack([A, np.zeros((L, 1))])])
    hi = np.concatenate([phi - F, -c])
    sol = solve_problem(
        Problem(csc_matrix(P), qv, csc_matrix(Gi), hi),
        solver="clarabel",
        verbose=False,
        tol_gap_abs=1e-12,
        tol_gap_rel=1e-12,
        tol_feas=1e-12,
    )
    if sol.x is None or sol.z is None:
        raise RuntimeError("the QP solver found no solution of the SQP subproblem")
    dx = sol.x[:n]
    z = np.maximum(sol.z, 0.0)
    message = f"clarabel: {(sol.extras or {}).get('status', 'no status')}"
    return QPSolution(dx, _dphi(dx, g, F, phi), z[:K], z[K:], 0, bool(sol.found), message)


SOLVERS = {"primal-dual": primal_dual, "exact": exact}
