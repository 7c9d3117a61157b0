"""Standard errors of identified parameters, honest when the readings of a pose share an error.

A fit solves estimating equations G'r(theta) = 0 over its residual rows (least squares: G = J,
the identification Jacobian). Linearised, reading errors e move the estimate by -A^-1 G'e with
A = G'J, so its covariance is A^-1 G' Cov(e) G A^-T. The plain estimate takes Cov(e) = s^2 I,
every coordinate of every reading independent. On a real arm the readings of one pose share an
error (repeatability, settling, whatever no model predicts), so the default estimate clusters
by pose: G' Cov(e) G is estimated by the sum over poses of their scores G_p'r_p G_p'r_p', each
pose's residuals first scaled up by what the fit absorbed of them (CR2, Bell and McCaffrey
2002), which makes it unbiased with independent errors as well, however few the poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .finite import finite

CLUSTERED = "pose-clustered sandwich (CR2)"
# eigenvalues of a pose's residual-maker block below this count as absorbed whole by the fit
ABSORBED = 1e-9


def pose_blocks(pose: np.ndarray):
    """The rows of each pose, grouped by their count: (n, (poses, n) row indices) pairs, so that
    poses with as many rows are handled at once (each pose's rows in their order)."""
    order = np.argsort(pose, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(pose[order]) != 0])
    counts = np.diff(np.r_[starts, len(order)])
    for n in np.unique(counts).tolist():
        yield n, order[starts[counts == n][:, None] + np.arange(n)]


@dataclass
class Rows:
    """The residual rows of a fit: Jacobian, estimating weights, residuals, pose and stage of each.

    A stage is one fit of a staged method (ls-single fits the other SMRs afterwards with the arm
    held); the plain estimate gives every stage its own residual scale.
    """

    J: np.ndarray  # (N, P) d r / d theta
    G: np.ndarray  # (N, P) estimating-equation weights: G'r = 0 at the fit
    r: np.ndarray  # (N,)
    pose: np.ndarray  # (N,) int
    stage: np.ndarray  # (N,) int

    @staticmethod
    def stack(parts: list[Rows]) -> Rows:
        if len(parts) == 1:
            return parts[0]
        return Rows(
            *(
                np.concatenate([getattr(p, k) for p in parts])
                for k in ("J", "G", "r", "pose", "stage")
            )
        )


def _bread(rows: Rows) -> np.ndarray:
    """(G'J)^-1, the map from the scores to the parameters."""
    return bread(rows.G.T @ rows.J)


def bread(A: np.ndarray) -> np.ndarray:
    """(G'J)^-1 from the normal matrix A = G'J."""
    return np.linalg.inv(finite(A, "the covariance's bread"))


@dataclass
class StageSums:
    """What the plain estimate needs of one stage's rows: r'r, their count, G'G and which
    columns of G any row uses (a column's sum of squares is positive)."""

    rr: float
    count: int
    GG: np.ndarray
    used: np.ndarray  # (P,) bool

    @staticmethod
    def of(rows: Rows, on: np.ndarray) -> StageSums:
        G, r = rows.G[on], rows.r[on]
        GG = G.T @ G
        return StageSums(float(r @ r), int(on.sum()), GG, np.diag(GG) > 0)

    def add(self, other: StageSums) -> None:
        self.rr += other.rr
        self.count += other.count
        self.GG += other.GG
        self.used |= other.used


def stage_sums(rows: Rows, GG: np.ndarray | None = None) -> dict[int, StageSums]:
    """Each stage's StageSums over these rows (GG: their G'G, if known)."""
    stages = np.unique(rows.stage)
    if len(stages) == 1 and GG is not None:  # the usual case: no copy of G
        sums = StageSums(float(rows.r @ rows.r), len(rows.r), GG.copy(), np.diag(GG) > 0)
        return {int(stages[0]): sums}
    return {int(s): StageSums.of(rows, rows.stage == s) for s in stages}


def plain_from_sums(Ai: np.ndarray, stages: dict[int, StageSums]) -> np.ndarray:
    """The plain covariance from the bread and the stages' sums (see plain)."""
    meat = np.zeros_like(Ai)
    for s in sorted(stages):
        st = stages[s]
        p = int(np.count_nonzero(st.used))
        meat += st.rr / max(st.count - p, 1) * st.GG
    return Ai @ meat @ Ai.T


def plain(rows: Rows) -> np.ndarray:
    """Covariance with every residual row independent, of one variance per stage."""
    return plain_from_sums(_bread(rows), stage_sums(rows))


def clustered(rows: Rows) -> np.ndarray:
    """Covariance with the rows of each pose sharing any error: CR2 sandwich over poses.

    The fitted residuals are r = (I - H) e with H = J A^-1 G'; with independent errors of one
    variance, a pose's residuals have covariance s^2 M_p, M_p the pose's block of
    (I - H)(I - H)'. Scaling them by M_p^-1/2 undoes what the fit absorbed, so small campaigns,
    where each pose weighs much in the fit, are not reported too certain.
    """
    Ai = _bread(rows)
    C = Ai @ (rows.G.T @ rows.G) @ Ai.T
    return Ai @ cr2_meat(rows, Ai, C) @ Ai.T


def cr2_meat(rows: Rows, Ai: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The CR2 meat (sum of the poses' adjusted scores' outer products) of rows holding whole
    poses, given the whole fit's bread Ai and C = Ai G'G Ai': the meat of a fit is the sum of
    this over any split of its rows by pose."""
    meat = np.zeros_like(Ai)
    # poses with as many rows (all readings present) are done at once
    for _n, idx in pose_blocks(rows.pose):
        J, G, r = rows.J[idx], rows.G[idx], rows.r[idx]
        meat += cr2_block_meat(J, G, r, hat_blocks(J, G, Ai), C)
    return meat


def hat_blocks(J: np.ndarray, G: np.ndarray, Ai: np.ndarray) -> np.ndarray:
    """The hat matrix's diagonal blocks J_p Ai G_p' (b, n, n) of poses of n rows each (J, G:
    (b, n, P)): one large product, then the small per-pose ones."""
    P = J.shape[-1]
    return (J.reshape(-1, P) @ Ai).reshape(J.shape) @ G.transpose(0, 2, 1)


def cr2_block_meat(J, G, r, H, C) -> np.ndarray:
    """cr2_meat of poses of n rows each (J, G (b, n, P), r (b, n)) given their hat blocks H."""
    P = J.shape[-1]
    JC = (J.reshape(-1, P) @ C).reshape(J.shape)
    E = finite(H + H.transpose(0, 2, 1) - JC @ J.transpose(0, 2, 1), "the residual blocks")
    score = (inverse_root_times(E, r)[:, None, :] @ G)[:, 0]
    return score.T @ score


# Poses whose residual-maker block is I - E with |E|_F up to this take the binomial series
# (I - E)^-1/2 = sum_k binom(2k, k) (E / 4)^k, whose terms shrink as |E|^k: 27 terms at most
# for a double's precision. Small leverage makes it the usual case (50,000 poses: |E| ~ 1e-3,
# 6 terms), at the cost of matrix-vector products instead of an eigensolver per pose.
SERIES_MAX = 0.25


def inverse_root_times(E: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(I - E)^-1/2 r for each symmetric block E (b, n, n) and vector r (b, n), eigenvalues of
    I - E below ABSORBED taken as absorbed whole (their part of r dropped)."""
    u = np.empty_like(r)
    rho = np.sqrt(np.einsum("bij,bij->b", E, E))
    near = rho <= SERIES_MAX
    if near.any():
        En, t = E[near], r[near]
        top = float(rho[near].max())
        terms = 0 if top == 0 else int(np.ceil(np.log(1e-17) / np.log(top)))
        un = t.copy()
        for k in range(1, terms + 1):
            t = (En @ t[..., None])[..., 0] * ((2 * k - 1) / (2 * k))
            un += t
        u[near] = un
    far = ~near
    if far.any():
        M = np.eye(E.shape[-1]) - E[far]
        w, V = np.linalg.eigh(0.5 * (M + M.transpose(0, 2, 1)))
        inv_root = np.where(w > ABSORBED, 1.0 / np.sqrt(np.clip(w, ABSORBED, None)), 0.0)
        u[far] = np.einsum("bij,bj->bi", V, inv_root * np.einsum("bji,bj->bi", V, r[far]))
    return u


@dataclass
class ParameterErrors:
    """Covariance of a fit's identified parameters and their standard errors in edge units.

    Parameters held fixed (not identifiable) have no column: their standard error is None.
    """

    names: tuple[str, ...]  # every parameter of the model, in its order
    column: np.ndarray  # (len(names),) its column in cov, -1 where held fixed
    cov: np.ndarray  # mm, rad and coefficient units
    degrees: np.ndarray  # (len(names),) bool: an angle, reported in degrees
    estimator: str = CLUSTERED
    poses: int = 0
    plain_cov: np.ndarray | None = None  # the plain estimate, for comparison

    def internal(self, plain_estimate: bool = False) -> np.ndarray:
        """Standard errors (mm, rad, coefficient units) per name, NaN where held fixed."""
        cov = self.plain_cov if plain_estimate else self.cov
        if cov is None:
            raise ValueError("this estimate keeps no plain covariance")
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        return np.where(self.column >= 0, sd[np.maximum(self.column, 0)], np.nan)

    def standard_errors(self, plain_estimate: bool = False) -> dict[str, float | None]:
        """Per parameter name, its standard error in mm or degrees; None where held fixed."""
        sd = self.internal(plain_estimate)
        sd = np.where(self.degrees, np.degrees(sd), sd)
        return {n: (None if not np.isfinite(v) else float(v)) for n, v in zip(self.names, sd)}

    def block(self, names) -> np.ndarray:
        """Covariance of the named parameters (all must be identified)."""
        idx = [int(self.column[self.names.index(n)]) for n in names]
        if min(idx, default=0) < 0:
            raise ValueError("a named parameter is held fixed")
        return self.cov[np.ix_(idx, idx)]


def errors_from_rows(rows: Rows, names, column, degrees) -> ParameterErrors:
    """Both estimates from a fit's rows; the clustered one is the one reported."""
    return ParameterErrors(
        tuple(names),
        np.asarray(column, dtype=int),
        clustered(rows),
        np.asarray(degrees, dtype=bool),
        CLUSTERED,
        int(len(np.unique(rows.pose))),
        plain(rows),
    )


# central differences over these fractions of each coefficient's standard deviation: the first
# small enough to be linear; the larger ones for entries the parameter formulas round so finely
# that the first step does not move them
REL_STEPS = (1e-3, 1e-1, 1.0)


def _numbers(values: dict) -> dict[str, np.ndarray]:
    """The numeric entries of a parameter dict (numbers or lists of numbers) as float arrays."""
    out = {}
    for k, v in values.items():
        items = v if isinstance(v, (list, tuple, np.ndarray)) else [v]
        if len(items) and all(
            isinstance(i, (int, float, np.number)) and not isinstance(i, bool) for i in items
        ):
            out[k] = np.asarray(items, dtype=float)
    return out


def _gradients(values, coef, sd, rel, base: dict) -> dict[str, np.ndarray]:
    """Central-difference gradients (entries, coefficients) of the entries in base, steps rel x sd."""
    grads = {k: np.zeros((len(v), len(coef))) for k, v in base.items()}
    for i in np.flatnonzero(sd > 0):
        step = np.zeros_like(coef)
        step[i] = rel * sd[i]
        up, down = _numbers(values(coef + step)), _numbers(values(coef - step))
        for k, g in grads.items():
            d = up[k] - down[k]
            if k.endswith("_deg"):
                d = (d + 180.0) % 360.0 - 180.0
            g[:, i] = d / (2.0 * step[i])
    return grads


def propagate(values, coef, cov) -> dict:
    """Standard errors of the numeric entries of values(coef) (a dict of numbers or lists of
    numbers) from the covariance of coef, through a central-difference Jacobian.

    Entries that do not move with the coefficients (a harmonic's order, a reference time) are no
    estimates of them and get none; differences of entries in degrees are wrapped, so a phase
    near +-180 degrees does not jump.
    """
    coef = np.asarray(coef, dtype=float)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    orig = values(coef)
    base = _numbers(orig)
    out = {}
    for rel in REL_STEPS:
        todo = {k: v for k, v in base.items() if k not in out}
        for k, g in _gradients(values, coef, sd, rel, todo).items():
            if np.any(g):
                se = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", g, cov, g), 0.0, None))
                out[k] = (
                    se.tolist() if isinstance(orig[k], (list, tuple, np.ndarray)) else float(se[0])
                )
    return {k: out[k] for k in base if k in out}
