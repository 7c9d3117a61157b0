"""The paper's robust calibration (Algorithm 1): min_x max_i F_i(x) s.t. distance invariance, by SQP."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from .identify import Problem
from .kinematics import predict, predict_rows
from .normal import PointNormal
from .prior import Prior
from .qp import SOLVERS
from .stop import Stop


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
    status: Stop
    constraints: np.ndarray = field(default_factory=lambda: np.zeros(0))
    qp_unconverged: int = 0  # SQP iterations whose QP subproblem missed its own optimality test
    prior_cost: float = 0.0  # the prior's term at x, mm^2 (F leaves it out)


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
    """F_i, their gradients and the distance constraints on the free parameters, scaled.

    The scaled variables are z = scale * (x_free - x0_free), scale being the norms of the
    Jacobian columns at x0, so that every variable moves the SMRs alike.

    With a prior (solver.prior), every F_i carries the prior's term divided by the number of
    SMRs K: at equal multipliers 1/K the SQP's stationarity is then ls-sum's with the prior
    (sum_i F_i + prior, over K), and at any multipliers a least-squares stationary point
    weighted by them with the prior's information over K (fit_errors' estimating equations).
    """

    def __init__(self, prob: Problem, x0, free, rows, epsilon, derivatives="twist", prior=None):
        self.prob, self.x0 = prob, np.array(x0, float)
        self.prior: Prior | None = prior
        self.derivatives = derivatives
        self.points: PointNormal | None = None
        self._kept: tuple | None = None  # (z bytes, residuals, J' operator) of the last trial
        self.idx = np.flatnonzero(free)
        self.rows = list(rows)
        sel = np.zeros(prob.meas.shape[1], dtype=bool)
        sel[self.rows] = True
        self.mask = prob.mask & sel[None, :]
        self.meas = prob.meas[self.mask]
        tgt = np.nonzero(self.mask)[1]
        self.onehot = (tgt[:, None] == np.array(self.rows)[None, :]).astype(float)  # (N, K)
        self.pairs, self.dbar, sem = measured_distances(prob.meas[:, self.rows])
        self.pairs = [(self.rows[i], self.rows[j]) for i, j in self.pairs]
        self.eps = default_epsilon(sem) if epsilon is None else float(epsilon)
        self.scale = None
        self.pos = {j: n for n, j in enumerate(self.idx)}

    def prior_term(self, x) -> tuple[float, np.ndarray]:
        """The prior's term each F_i carries (mm^2) and its gradient in x's free entries."""
        if self.prior is None:
            return 0.0, np.zeros(len(self.idx))
        K, pr = len(self.rows), self.prior
        return pr.cost(x) / K, 2.0 * pr.weight[self.idx] * (x[self.idx] - pr.center[self.idx]) / K

    def prior_hessian(self) -> np.ndarray:
        """The prior term's Hessian in the scaled variables (after the first call)."""
        if self.prior is None:
            return np.zeros((len(self.idx), len(self.idx)))
        assert self.scale is not None, "the scale is set by the first call"
        return np.diag(2.0 * self.prior.weight[self.idx] / len(self.rows) / self.scale**2)

    def x(self, z):
        x = self.x0.copy()
        x[self.idx] += z / self.scale
        return x

    def constraints(self, x):
        """c(x) of eq. (9) and its gradient (eq. 28-29) in the scaled variables."""
        ts = self.prob.layout.target_slice.start
        c = np.zeros(len(self.pairs))
        A = np.zeros((len(self.pairs), len(self.idx)))
        for n, ((i, j), dbar) in enumerate(zip(self.pairs, self.dbar)):
            ti, tj = x[ts + 3 * i : ts + 3 * i + 3], x[ts + 3 * j : ts + 3 * j + 3]
            dist = np.linalg.norm(ti - tj)
            rt = dist - dbar
            c[n] = rt * rt - self.eps
            u = (ti - tj) / dist  # d||ti - tj|| / d ti
            for sign, k in ((1.0, i), (-1.0, j)):
                for a in range(3):
                    col = self.pos.get(ts + 3 * k + a)
                    if col is not None:
                        A[n, col] += 2.0 * rt * sign * u[a] / self.scale[col]
        return c, A

    def values(self, z):
        """F_i and c at z (for the line search). On the twist path the walk down the chain that
        gives the residuals also gives the derivatives, kept for the step it accepts."""
        x = self.x(z)
        if self.derivatives == "full":
            r = predict(self.prob.layout, x, self.prob.q)[self.mask] - self.meas
        else:
            self._kept = None  # one set of twists alive at a time
            r, jt, _ = self._points().operator(x)
            self._kept = (z.tobytes(), r, jt)
            r = r.reshape(-1, 3)
        return np.sum(r * r, axis=1) @ self.onehot + self.prior_term(x)[0], self.constraints(x)[0]

    def _points(self) -> PointNormal:
        if self.points is None:
            self.points = PointNormal(
                self.prob.layout, self.prob.q, self.mask, self.prob.meas, self.idx
            )
        return self.points

    def __call__(self, z=None):
        """F_i (K,), c (L,), gradients of F_i (K, n) (eq. 26), of c (L, n), all in the scaled
        variables, and at the first call (z None) the Gauss-Newton Hessian J'J (n, n) of the
        summed squares (None after: BFGS updates the Hessian from there)."""
        first = self.scale is None
        x = self.x0 if first else self.x(z)
        if self.derivatives == "full":
            r, JtJ, grad = self._full(x, first)
        else:
            r, JtJ, grad = self._twist(x, None if first else z)
        if first:  # the norms of the Jacobian's columns at x0
            self.scale = np.sqrt(np.clip(np.diag(JtJ), 0.0, None))
            self.scale[self.scale == 0] = 1.0
            JtJ = JtJ / np.outer(self.scale, self.scale)
        Q, dQ = self.prior_term(x)
        F = np.sum(r * r, axis=1) @ self.onehot + Q
        c, A = self.constraints(x)
        return F, c, (grad + dQ[None, :]) / self.scale[None, :], A, JtJ

    def _twist(self, x, z):
        """Residuals, J'J (at the start, z None) and each SMR's gradient from the twist normal
        equations, as ls-sum assembles them: time and memory grow like ls-sum's, J is never
        formed."""
        JtJ = None
        kept, self._kept = self._kept, None
        if z is not None and kept is not None and kept[0] == z.tobytes():
            _, r, jt = kept  # the line search's last trial, the step taken
        else:
            del kept
            r, jt, ne = self._points().operator(x, normal=z is None)
            JtJ = None if ne is None else ne.A
        return r.reshape(-1, 3), JtJ, 2.0 * jt.per_target(r)[self.rows]

    def _full(self, x, first: bool):
        """The same from the full Jacobian (n x 3N): the reference the twist path must equal."""
        p, Jt = predict_rows(self.prob.layout, x, self.prob.q, self.mask, self.idx)
        Jt = Jt.reshape(len(self.idx), -1)
        r = p - self.meas
        grad = 2.0 * (Jt * r.ravel()).reshape(len(self.idx), -1, 3).sum(axis=2) @ self.onehot
        return r, Jt @ Jt.T if first else None, grad.T


def _merit(F, c, rho):
    return float(np.max(F) + rho * np.sum(np.maximum(c, 0.0)))


def minimax(
    prob: Problem,
    x0,
    free,
    rows=None,
    qp="primal-dual",
    epsilon=None,
    max_iter=100,
    tol=1e-10,
    derivatives="twist",
    prior: Prior | None = None,
) -> MinimaxResult:
    """SQP on the epigraph form (eq. 16-18) from x0 (the ls-sum solution, eq. 32).

    prior: the geometry's prior (solver.prior), its term over K in every F_i (see _Objective);
    the F returned leaves it out, prior_cost is it.

    The Hessian starts at the Gauss-Newton Hessian of the Lagrangian with equal SMR weights
    and is then updated by damped BFGS; each step is accepted by a backtracking line search on
    max_i F_i plus a penalty on the distance constraints. derivatives: "twist" (the twist normal
    equations, no Jacobian) or "full" (the full Jacobian, the reference).
    """
    t0 = time.perf_counter()
    rows = list(range(prob.meas.shape[1])) if rows is None else list(rows)
    obj = _Objective(prob, x0, free, rows, epsilon, derivatives, prior)
    solve = SOLVERS[qp]
    n = len(obj.idx)
    z = np.zeros(n)
    F, c, g, A, JtJ = obj()
    K = len(rows)
    H = (2.0 / K) * JtJ + obj.prior_hessian() + 1e-12 * np.eye(n)
    lam, mu = np.full(K, 1.0 / K), np.zeros(len(c))
    history = [float(np.max(F))]
    qp_iters, qp_missed, converged, message = 0, 0, False, "iteration limit reached"
    stop = Stop.ITERATION_LIMIT
    rho = 1.0
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is reported after the loop)
        phi = float(np.max(F))
        sol = solve(H, g, F, phi, A, c)
        qp_iters += sol.iterations
        if not sol.converged:
            qp_missed, missed = qp_missed + 1, sol.message
        rho = max(rho, 2.0 * float(np.max(sol.mu, initial=0.0)) + 1.0)
        merit = _merit(F, c, rho)
        predicted = sol.dphi - rho * float(np.sum(np.maximum(c, 0.0)))
        if -predicted <= tol * max(phi, 1e-300):
            # a stop on the decrease an unsolved subproblem predicts is no proof of optimality
            converged = sol.converged
            message = (
                "predicted decrease below tolerance"
                if converged
                else "stopped on the decrease of a QP subproblem not solved to tolerance"
            )
            stop = Stop.CONVERGED if converged else Stop.OTHER
            lam, mu = sol.lam, sol.mu
            break
        alpha = 1.0
        while True:
            Fn, cn = obj.values(z + alpha * sol.dx)
            if _merit(Fn, cn, rho) <= merit + 1e-4 * alpha * predicted or alpha < 1e-6:
                break
            alpha *= 0.5
        if alpha < 1e-6:
            message, stop = "line search failed: no descent along the QP step", Stop.OTHER
            break
        s = alpha * sol.dx
        z = z + s
        grad_old = sol.lam @ g + sol.mu @ A
        F, c, g, A, _ = obj(z)
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
    if qp_missed:  # the steps still went through the line search, so x is sound; say so
        message += f"; {qp_missed} QP subproblem(s) not solved to tolerance ({missed})"
    Q = obj.prior_term(obj.x(z))[0]
    return MinimaxResult(
        obj.x(z),
        F - Q,
        history,
        it,
        qp_iters,
        time.perf_counter() - t0,
        lam,
        mu,
        converged,
        message,
        stop,
        c,
        qp_missed,
        Q,
    )
