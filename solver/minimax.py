"""The paper's robust calibration (Algorithm 1): min_x max_i F_i(x) s.t. distance invariance, by SQP."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from .identify import Problem
from .kinematics import predict_with_jacobian
from .qp import SOLVERS


@dataclass
class MinimaxResult:
    """Outcome of the SQP: parameters, per-iteration max F_i, multipliers and effort."""

    x: np.ndarray
    F: np.ndarray
    history: list[float]
    iterations: int
    qp_iterations: int
    seconds: float
    lam: np.ndarray
    mu: np.ndarray
    converged: bool
    message: str
    constraints: np.ndarray = field(default_factory=lambda: np.zeros(0))


def measured_distances(meas: np.ndarray):
    """Target pairs, the mean measured distance of each (eq. 8) and its standard error."""
    pairs, mean, sem = [], [], []
    for i, j in combinations(range(meas.shape[1]), 2):
        d = np.linalg.norm(meas[:, i] - meas[:, j], axis=-1)
        d = d[np.isfinite(d)]
        if len(d) >= 2:
            pairs.append((i, j))
            mean.append(d.mean())
            sem.append(d.std(ddof=1) / np.sqrt(len(d)))
    return pairs, np.array(mean), np.array(sem)


def default_epsilon(sem: np.ndarray) -> float:
    """Threshold of eq. (8)-(9) in mm^2: three standard errors of the mean distance, at least 1 um."""
    tol = max(3.0 * float(np.max(sem, initial=0.0)), 1e-3)
    return tol * tol


class _Objective:
    """F_i, their gradients and the distance constraints on the free parameters, scaled."""

    def __init__(self, prob: Problem, x0, free, rows, epsilon):
        self.prob, self.x0 = prob, np.array(x0, float)
        self.idx = np.flatnonzero(free)
        self.rows = list(rows)
        self.pairs, self.dbar, sem = measured_distances(prob.meas[:, self.rows])
        self.pairs = [(self.rows[i], self.rows[j]) for i, j in self.pairs]
        self.eps = default_epsilon(sem) if epsilon is None else float(epsilon)
        _, J, _ = predict_with_jacobian(prob.layout, self.x0, prob.q)
        Jf = J[prob.mask][..., self.idx].reshape(-1, len(self.idx))
        self.scale = np.linalg.norm(Jf, axis=0)
        self.scale[self.scale == 0] = 1.0

    def x(self, z):
        x = self.x0.copy()
        x[self.idx] += z / self.scale
        return x

    def __call__(self, z, jac=True):
        x = self.x(z)
        prob = self.prob
        ts = prob.layout.target_slice.start
        if jac:
            p, J, _ = predict_with_jacobian(prob.layout, x, prob.q)
            J = J[..., self.idx] / self.scale
        else:
            from .kinematics import predict
            p = predict(prob.layout, x, prob.q)
        r = p - prob.meas
        F = np.array([np.sum(r[prob.mask[:, k], k] ** 2) for k in self.rows])
        c = np.zeros(len(self.pairs))
        A = np.zeros((len(self.pairs), len(self.idx)))
        pos = {j: n for n, j in enumerate(self.idx)}
        for n, ((i, j), dbar) in enumerate(zip(self.pairs, self.dbar)):
            ti, tj = x[ts + 3 * i : ts + 3 * i + 3], x[ts + 3 * j : ts + 3 * j + 3]
            dist = np.linalg.norm(ti - tj)
            rt = dist - dbar
            c[n] = rt * rt - self.eps
            u = (ti - tj) / dist  # eq. (29): d||ti - tj|| / d ti
            for sign, k in ((1.0, i), (-1.0, j)):
                for a in range(3):
                    col = pos.get(ts + 3 * k + a)
                    if col is not None:
                        A[n, col] += 2.0 * rt * sign * u[a] / self.scale[col]  # eq. (28)
        if not jac:
            return F, c
        g = np.array([2.0 * J[prob.mask[:, k], k].reshape(-1, len(self.idx)).T
                      @ r[prob.mask[:, k], k].ravel() for k in self.rows])  # eq. (26)
        JtJ = [J[prob.mask[:, k], k].reshape(-1, len(self.idx)) for k in self.rows]
        return F, c, g, A, JtJ


def _merit(F, c, rho):
    return float(np.max(F) + rho * np.sum(np.maximum(c, 0.0)))


def minimax(prob: Problem, x0, free, rows=None, qp="primal-dual", epsilon=None,
            max_iter=100, tol=1e-10) -> MinimaxResult:
    """SQP on the epigraph form (eq. 16-18) from x0 (the ls-sum solution, eq. 32).

    The Hessian starts at the Gauss-Newton Hessian of the Lagrangian with equal SMR weights
    and is then updated by damped BFGS; each step is accepted by a backtracking line search on
    max_i F_i plus a penalty on the distance constraints.
    """
    t0 = time.perf_counter()
    rows = list(range(prob.meas.shape[1])) if rows is None else list(rows)
    obj = _Objective(prob, x0, free, rows, epsilon)
    solve = SOLVERS[qp]
    n = len(obj.idx)
    z = np.zeros(n)
    F, c, g, A, Js = obj(z)
    K = len(rows)
    H = sum(2.0 / K * Jk.T @ Jk for Jk in Js) + 1e-12 * np.eye(n)
    lam, mu = np.full(K, 1.0 / K), np.zeros(len(c))
    history = [float(np.max(F))]
    qp_iters, converged, message = 0, False, "iteration limit reached"
    rho = 1.0
    it = 0
    for it in range(1, max_iter + 1):
        phi = float(np.max(F))
        sol = solve(H, g, F, phi, A, c)
        qp_iters += sol.iterations
        rho = max(rho, 2.0 * float(np.max(sol.mu, initial=0.0)) + 1.0)
        merit = _merit(F, c, rho)
        predicted = sol.dphi - rho * float(np.sum(np.maximum(c, 0.0)))
        if -predicted <= tol * max(phi, 1e-300):
            converged, message = True, "predicted decrease below tolerance"
            lam, mu = sol.lam, sol.mu
            break
        alpha = 1.0
        while True:
            Fn, cn = obj(z + alpha * sol.dx, jac=False)
            if _merit(Fn, cn, rho) <= merit + 1e-4 * alpha * predicted or alpha < 1e-6:
                break
            alpha *= 0.5
        if alpha < 1e-6:
            message = "line search failed: no descent along the QP step"
            break
        s = alpha * sol.dx
        z = z + s
        grad_old = sol.lam @ g + sol.mu @ A
        F, c, g, A, Js = obj(z)
        lam, mu = sol.lam, sol.mu
        y = lam @ g + mu @ A - grad_old
        Hs = H @ s
        sHs = float(s @ Hs)
        sy = float(s @ y)
        if sy < 0.2 * sHs:  # Powell's damping keeps H positive definite
            theta = 0.8 * sHs / (sHs - sy)
            y = theta * y + (1.0 - theta) * Hs
            sy = float(s @ y)
        if sHs > 0 and sy > 0:
            H = H + np.outer(y, y) / sy - np.outer(Hs, Hs) / sHs
        history.append(float(np.max(F)))
    return MinimaxResult(obj.x(z), F, history, it, qp_iters, time.perf_counter() - t0,
                         lam, mu, converged, message, c)
