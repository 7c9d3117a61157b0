"""A Gaussian prior on the geometry's deviation from nominal: what shrinks weakly seen parameters.

A machined arm's link lengths and twists, and its joints' zero offsets, differ from the drawing
by about PRIOR_MM and PRIOR_DEG (identifiability). Taken as a Gaussian prior of that standard
deviation on each geometric parameter's change, the fit minimises r'r + sum_j w_j (x_j - c_j)^2
with w_j = s^2 / sigma_j^2 (s: the residual's standard deviation a coordinate, sigma_j the
prior's): the maximum a posteriori estimate. A parameter the data pins far better than sigma_j
is unaffected (its information outweighs w_j); one the data barely sees stays near nominal
instead of wandering by its standard error. Base and SMR positions carry no prior (a base is
anywhere, a nest drawing a few mm off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kinematics import Layout
from .lm import Normal, from_jacobian


@dataclass(frozen=True)
class Prior:
    """Per entry of the layout's parameter vector: the prior's weight w (mm^2 per unit^2 of the
    entry, 0 where no prior), its standard deviation sigma (entry units) and its centre."""

    weight: np.ndarray  # (P,)
    sigma: np.ndarray  # (P,)
    center: np.ndarray  # (P,)
    noise_mm: float  # s: the residual's standard deviation a coordinate it was weighed at

    @staticmethod
    def of(layout: Layout, x_nominal, free, noise_mm: float, mm: float, deg: float) -> Prior:
        """The prior on the free geometric entries of layout, weighed at noise_mm a coordinate."""
        P = layout.n_params
        angle = np.zeros(P, dtype=bool)
        angle[[op.param for op in layout.ops() if op.kind == "r"]] = True
        sigma = np.where(angle, np.deg2rad(deg), mm)
        on = np.zeros(P, dtype=bool)
        on[: layout.n_geo] = True
        on &= np.asarray(free, dtype=bool)
        weight = np.where(on, noise_mm**2 / sigma**2, 0.0)
        return Prior(weight, sigma, np.array(x_nominal, dtype=float), float(noise_mm))

    def cost(self, x) -> float:
        """sum_j w_j (x_j - c_j)^2, mm^2."""
        d = np.asarray(x) - self.center
        return float(np.sum(self.weight * d * d))

    def rows(self, x, idx) -> np.ndarray:
        """The prior's residual rows sqrt(w_j) (x_j - c_j) over the entries idx."""
        return np.sqrt(self.weight[idx]) * (np.asarray(x)[idx] - self.center[idx])

    def residual(self, r: np.ndarray, x, idx) -> np.ndarray:
        """A fit's residuals r with the prior's rows over the entries idx after them."""
        return np.concatenate([r, self.rows(x, idx)])

    def normal(self, ne: Normal, x, idx) -> Normal:
        """The normal equations ne of a fit's readings at x, whose first len(idx) unknowns are
        the entries idx (any after them, an extension's coefficients, have no prior), with the
        prior's rows added after the readings' (as `residual` places them)."""
        k = len(idx)
        root, rp = np.sqrt(self.weight[idx]), self.rows(x, idx)
        A, g = ne.A.copy(), ne.g.copy()
        A[:k, :k] += np.diag(self.weight[idx])
        g[:k] += root * rp
        jt = ne.jt

        def jt_all(res: np.ndarray) -> np.ndarray:
            n = len(res) - k
            out = np.array(jt(res[:n]), dtype=float)
            out[:k] += root * res[n:]
            return out

        return Normal(ne.cost + float(rp @ rp), A, g, jt_all)

    def fit(self, fun, x, idx, residual=None) -> dict:
        """levenberg_marquardt's normal and residual of fun(z) -> (r, Jt) (the readings', over
        unknowns z whose first len(idx) are the entries idx of x, any after them without a prior;
        residual(z) -> r the readings' alone, default fun's) with the prior's rows after them."""
        normal = from_jacobian(fun)
        residual = residual or (lambda z: fun(z)[0])

        def full(z):
            xx = np.array(x, dtype=float)
            xx[idx] = z[: len(idx)]
            return xx

        return {
            "normal": lambda z: self.normal(normal(z), full(z), idx),
            "residual": lambda z: self.residual(residual(z), full(z), idx),
        }

    def information(self, idx) -> np.ndarray:
        """diag(w) over the entries idx: what the prior adds to J'J."""
        return np.diag(self.weight[idx])

    def terms(self, column: np.ndarray, n: int, factor: float = 1.0) -> PriorTerms:
        """What the prior adds to a fit's sandwich over n columns (column: each entry's, -1 where
        none), its estimating equations G'r + factor w (x - c) = 0."""
        on = (column >= 0) & (self.weight > 0)
        cols, w = column[on], factor * self.weight[on]
        A, meat = np.zeros((n, n)), np.zeros((n, n))
        A[cols, cols] = w
        # the score factor w (x - c) with x drawn from the prior: variance (factor w sigma)^2
        meat[cols, cols] = (w * self.sigma[on]) ** 2
        return PriorTerms(A, meat, meat / self.noise_mm**2)


@dataclass(frozen=True)
class PriorTerms:
    """A prior's part of a fit's covariance: J'J's (information), the scores' covariance
    (meat), and that over the residual's variance (as G'G enters the residuals' covariance)."""

    information: np.ndarray
    meat: np.ndarray
    residual: np.ndarray


def data_share(A: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Per parameter of J'J A (and prior weights `weight` on its columns), the share of its
    estimate that comes from the data, 1 - posterior variance / prior variance (1 without a
    prior; 1 - 1 / (1 + information / w) for one parameter alone)."""
    n = len(weight)
    d = np.sqrt(np.diag(A) + weight)
    d[d == 0] = 1.0
    post = np.linalg.pinv((A + np.diag(weight)) / np.outer(d, d)) / np.outer(d, d)
    share = np.ones(n)
    on = weight > 0
    share[on] = 1.0 - np.diag(post)[on] * weight[on]
    return np.clip(share, 0.0, 1.0)
