"""The residual rows each identification method solves, and so the standard errors of its fit."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .calibrate import Calibration, parse_method
from .effects import Extension, Inputs, prepare
from .extended import extension_rows as extended_rows
from .guard import Holdout
from .identify import Problem, pose_fit, pose_residuals
from .kinematics import Layout, predict_rows
from .normal import PointNormal
from .postfit import BLOCK_ENTRIES, Blocks, Sums, poses_per_block, post_fit
from .prior import Prior, PriorTerms
from .uncertainty import (
    CLUSTERED,
    ParameterErrors,
    Rows,
    StageSums,
    errors_from_rows,
    propagate,
)

if TYPE_CHECKING:
    from .diagnosis_report import Report


def angles(layout: Layout) -> np.ndarray:
    """Which entries of the layout's parameter vector are angles (rad inside, degrees outside)."""
    out = np.zeros(layout.n_params, dtype=bool)
    out[[op.param for op in layout.ops() if op.kind == "r"]] = True
    return out


def point_rows(layout: Layout, x, q, meas, mask, cols, estimated, weight=None, stage=0) -> Rows:
    """Rows of the point residuals (predict - meas) of the readings in mask over parameters cols.

    estimated (len(cols),) bool: the parameters this stage fits (the others are held in it);
    weight (K,): per SMR, the weight of its readings in the equations of the arm's entries (an
    SMR's own position is fitted from its readings alone, whatever their weight).
    """
    p, Jt = predict_rows(layout, x, q, mask, cols)
    J = Jt.reshape(len(cols), -1).T
    pose, k = np.nonzero(mask)
    # least squares over every column (ls-sum, nominal): the weights are the Jacobian itself
    plain = weight is None and bool(np.all(estimated))
    G = J if plain else J * np.asarray(estimated, dtype=float)[None, :]
    if weight is not None:
        arm = np.asarray(cols) < layout.target_slice.start
        G[:, arm] *= np.repeat(np.asarray(weight, dtype=float)[k], 3)[:, None]
    return Rows(J, G, (p - meas[mask]).ravel(), np.repeat(pose, 3), np.full(len(J), stage))


def _in(cols, which) -> np.ndarray:
    return np.isin(cols, np.asarray(list(which), dtype=int))


def calibration_errors(cal: Calibration, q, meas) -> ParameterErrors:
    """Standard errors of a calibration's identified parameters (every method of `calibrate`)."""
    return calibration_figures(cal, q, meas)[0]


def calibration_figures(cal: Calibration, q, meas) -> tuple[ParameterErrors, Holdout]:
    """A calibration's standard errors and leave-one-pose-out residuals, its rows taken a block
    of poses at a time (solver.postfit): memory bounded whatever the campaign's size."""
    blocks, column = calibration_blocks(cal, q, meas)
    post = post_fit(
        blocks,
        lambda rows: point_errors(cal, rows),
        known=plain_sums(cal, q, meas, column),
        prior=prior_terms(cal, column),
    )
    names = cal.layout.names()
    errors = ParameterErrors(
        tuple(names),
        np.asarray(column, dtype=int),
        post.clustered,
        angles(cal.layout),
        CLUSTERED,
        post.poses,
        post.plain,
    )
    return errors, post.holdout


# An SMR minimax leaves inactive (multiplier 0) still holds what the criterion leaves flat: the SQP
# starts from ls-sum's fit of every SMR and steps along the active SMRs' F, so a direction that
# moves only an inactive SMR keeps ls-sum's estimate (a planar arm: base z against every SMR's z
# but the one held, that SMR inactive; with weight 0 its standard error was 956 mm, the
# leave-one-pose-out RMS 0.49 mm where ls-sum's is 0.019, and the model "not deployable"). Along
# such a direction the sandwich does not depend on this weight; elsewhere it moves it by ~0.1%.
INACTIVE_WEIGHT = 1e-3

# Entries (8 bytes each) of a block of plain_sums' twists.
TWIST_BLOCK_ENTRIES = 4 * BLOCK_ENTRIES


def plain_sums(cal: Calibration, q, meas, column) -> Sums | None:
    """The post-fit's first pass (postfit.Sums) of a calibration whose rows are plain least
    squares (ls-sum, nominal, ls-single on the only SMR): J'J and r'r assembled from the
    flange's twists (solver.normal), no row formed, a block of poses at a time; None for the
    others (weighted or staged rows, whose first pass takes the rows). column: as
    calibration_blocks gives it."""
    lay, x = cal.layout, np.asarray(cal.x, dtype=float)
    name, fitted = parse_method(cal.method, list(lay.target_names))
    if name in ("minimax", "ls-pose") or len(fitted) < len(lay.target_names):
        return None
    column = np.asarray(column, dtype=int)
    cols = np.flatnonzero(column >= 0)[np.argsort(column[column >= 0])]
    q, meas = np.asarray(q, dtype=float), np.asarray(meas, dtype=float)
    mask = np.all(np.isfinite(meas), axis=-1)
    if not mask.any():
        raise ValueError("no residual rows")
    # a block's twists (len(cols) + 1, 6, poses) take four of the rows' blocks (16 MiB): fewer
    # walks down the chain; still small beside the fit's own (all poses' at once)
    step = max(1, TWIST_BLOCK_ENTRIES // (6 * (len(cols) + 1)))
    A, rr = np.zeros((len(cols), len(cols))), 0.0
    for lo in range(0, len(q), step):
        at = slice(lo, lo + step)
        normal = PointNormal(lay, q[at], mask[at], meas[at], cols)(x)
        A += normal.A
        rr += normal.cost
    return Sums(A, A, {0: StageSums(rr, 3 * int(mask.sum()), A.copy(), np.diag(A) > 0)})


def prior_terms(cal: Calibration, column: np.ndarray) -> PriorTerms | None:
    """The calibration's prior in its covariance: minimax's estimating equations carry it over
    the number of SMRs fitted (solver.minimax._Objective), least squares' whole."""
    prior = cal.prior
    if prior is None:
        return None
    name, rows = parse_method(cal.method, list(cal.layout.target_names))
    factor = 1.0 / len(rows) if name == "minimax" else 1.0
    return prior.terms(column, int(column.max()) + 1, factor)


def point_errors(cal: Calibration, rows: Rows) -> np.ndarray:
    """Which of calibration_rows' rows are point errors (ls-pose's first stage is not)."""
    if parse_method(cal.method, list(cal.layout.target_names))[0] == "ls-pose":
        return rows.stage == 1
    return np.ones(len(rows.r), dtype=bool)


def calibration_rows(cal: Calibration, q, meas) -> tuple[Rows, np.ndarray]:
    """A calibration's residual rows, all at once, and each parameter's column in them (-1 where
    held fixed); see calibration_blocks."""
    blocks, column = calibration_blocks(cal, q, meas, len(q))
    return Rows.stack(list(blocks())), column


def calibration_blocks(cal: Calibration, q, meas, block=None) -> tuple[Blocks, np.ndarray]:
    """A calibration's residual rows, `block` poses at a time (default: a block of
    postfit.BLOCK_ENTRIES Jacobian entries), and each parameter's column in them (-1 where held
    fixed).

    ls-sum and nominal are least squares over every reading; minimax's optimum is a least-squares
    stationary point weighted per SMR by its multipliers (the distance constraints are left
    out); ls-single and ls-pose are two stages, the second fitting SMR positions with the arm
    held, and both stages enter one stacked sandwich.
    """
    lay, x = cal.layout, np.asarray(cal.x, dtype=float)
    q, meas = np.asarray(q, dtype=float), np.asarray(meas, dtype=float)
    names = lay.names()
    name, rows = parse_method(cal.method, list(lay.target_names))
    mask = np.all(np.isfinite(meas), axis=-1)
    ts = lay.target_slice.start
    smr = lambda ks: [ts + 3 * k + a for k in ks for a in range(3)]  # noqa: E731
    others = [k for k in range(len(lay.target_names)) if k not in rows]
    if name == "nominal":
        registered = np.r_[np.arange(lay.base_slice.start, lay.base_slice.stop), smr(rows)]
        free = registered[independent(registration_normal(cal, q, meas, mask, registered))]
    else:
        free = np.array(
            [i for i, n in enumerate(names) if n not in cal.fixed and i not in smr(others)],
            dtype=int,
        )
    column = np.full(len(names), -1)
    K = mask.shape[1]
    if name == "ls-pose":
        stages = _PoseStages(cal, q, meas, mask, free)
        cols = stages.cols
        column[cols[len(free) :]] = np.arange(len(free), len(cols))  # the SMRs of the second stage
        column[free[free < ts]] = np.flatnonzero(free < ts)
        rows_of, per_pose = stages.rows, 9 * K
    else:
        cols = np.r_[free, smr(others)].astype(int)
        weight = minimax_weights(cal.lam) if name == "minimax" else None
        sel = np.zeros(K, dtype=bool)
        sel[rows] = True

        def rows_of(lo: int, hi: int) -> Rows:
            qb, mb, at = q[lo:hi], meas[lo:hi], mask[lo:hi]
            parts = [point_rows(lay, x, qb, mb, at & sel, cols, _in(cols, free), weight)]
            if others:
                parts.append(
                    point_rows(lay, x, qb, mb, at & ~sel, cols, _in(cols, smr(others)), stage=1)
                )
            return _shifted(Rows.stack(parts), lo)

        column[cols] = np.arange(len(cols))
        per_pose = 3 * K
    step = block or poses_per_block(per_pose, len(cols))
    m = len(q)

    def blocks():
        for lo in range(0, m, step):
            yield rows_of(lo, min(m, lo + step))

    return blocks, column


# A column whose part outside the span of the columns kept before it is below this share of its
# norm (squared, on the Jacobi-scaled normal matrix) is redundant with them: rounding, not data.
REDUNDANT = 1e-10


def registration_normal(cal: Calibration, q, meas, mask, cols) -> np.ndarray:
    """J'J of the nominal model's registration (base and SMRs, columns cols) on the readings."""
    step = max(1, TWIST_BLOCK_ENTRIES // (6 * (len(cols) + 1)))
    A = np.zeros((len(cols), len(cols)))
    x = np.asarray(cal.x, dtype=float)
    for lo in range(0, len(q), step):
        at = slice(lo, lo + step)
        A += PointNormal(cal.layout, q[at], mask[at], meas[at], cols)(x).A
    return A


def independent(A: np.ndarray) -> np.ndarray:
    """Which columns of the normal matrix A to keep, in their order, each adding a direction the
    ones kept before it lack (a pivoted Cholesky on the Jacobi-scaled A). The nominal model's
    registration frees base and SMRs together, which the readings need not all move: one SMR on
    a SCARA (every axis vertical) gives base z and the SMR's z one column; the first is kept,
    the rest held, as a calibration holds what the data cannot move."""
    d = np.sqrt(np.clip(np.diag(A), 0.0, None))
    keep = d > 0
    S = A / np.outer(np.where(keep, d, 1.0), np.where(keep, d, 1.0))
    kept: list[int] = []
    for j in np.flatnonzero(keep):
        if kept:
            K = S[np.ix_(kept, kept)]
            left = S[j, j] - S[j, kept] @ np.linalg.solve(K, S[kept, j])
        else:
            left = S[j, j]
        if left > REDUNDANT:
            kept.append(int(j))
    out = np.zeros(len(A), dtype=bool)
    out[kept] = True
    return out


def minimax_weights(lam) -> np.ndarray:
    """Per SMR, the weight of its readings in minimax's estimating equations of the arm: its
    multiplier, an inactive SMR's (0) raised to INACTIVE_WEIGHT of the largest."""
    lam = np.asarray(lam, dtype=float)
    return np.maximum(lam, INACTIVE_WEIGHT * lam.max())


def _shifted(rows: Rows, lo: int) -> Rows:
    """Rows of a block of poses starting at pose lo, their pose indices made the campaign's."""
    rows.pose = rows.pose + lo
    return rows


class _PoseStages:
    """ls-pose's two stages: pose residuals over `free` (on poses with every SMR), then every SMR
    position from its readings with the arm held. The first stage's SMR entries are its own
    (refitted here, since the second stage replaced them in the calibration)."""

    def __init__(self, cal: Calibration, q, meas, mask, free):
        lay = cal.layout
        self.cal, self.q, self.meas, self.mask, self.free = cal, q, meas, mask, free
        self.weight = cal.pose_weight_mm_per_rad
        prob = Problem(lay, q, meas)
        free_ = np.isin(np.arange(lay.n_params), free)
        self.x1, _ = pose_fit(prob, cal.x, free_, self.weight, prior=cal.prior)
        self.tcols = np.arange(lay.target_slice.start, lay.target_slice.stop)
        self.cols = np.r_[free, self.tcols]

    def rows(self, lo: int, hi: int) -> Rows:
        """Both stages' rows of poses lo to hi."""
        lay, free, cols = self.cal.layout, self.free, self.cols
        q, meas, mask = self.q[lo:hi], self.meas[lo:hi], self.mask[lo:hi]
        full = np.all(mask, axis=1)
        m, K = int(full.sum()), mask.shape[1]
        n1 = len(free)
        parts = []
        if m:
            p, Jt = predict_rows(lay, self.x1, q[full], np.ones((m, K), dtype=bool), free)
            J = Jt.reshape(n1, m, K, 3).transpose(1, 2, 3, 0)
            r, Jr = pose_residuals(p.reshape(m, K, 3), meas[full], J, self.weight)
            J1 = np.zeros((r.size, len(cols)))
            J1[:, :n1] = Jr.reshape(-1, n1)
            pose = np.repeat(np.flatnonzero(full), 6)
            parts.append(Rows(J1, J1.copy(), r.ravel(), pose, np.zeros(r.size, int)))
        # the second stage sees the arm's free entries and its own SMR columns, not stage one's
        ts = lay.target_slice.start
        arm = np.r_[free[free < ts], self.tcols]
        second = point_rows(lay, self.cal.x, q, meas, mask, arm, _in(arm, self.tcols), stage=1)
        J2 = np.zeros((len(second.r), len(cols)))
        G2 = np.zeros_like(J2)
        at = np.r_[np.flatnonzero(free < ts), np.arange(n1, len(cols))]
        J2[:, at], G2[:, at] = second.J, second.G
        parts.append(Rows(J2, G2, second.r, second.pose, second.stage))
        return _shifted(Rows.stack(parts), lo)


def coef_names(exts) -> list[str]:
    """Names of the extensions' coefficients, in the order fit_extended stacks them."""
    return [f"{e.label()}[{i}]" for e in exts for i in range(e.n_params)]


def extended_errors(
    prob: Problem, inputs: Inputs, x0, free, x, exts: list[Extension], prior: Prior | None = None
) -> ParameterErrors:
    """Standard errors of the extended model fitted on every pose (geometry, base, SMRs and each
    extension's coefficients), with the bases evaluated at x0 as fit_extended holds them; with
    the geometry's prior it was fitted under, the posterior's (its terms in the sandwich, as a
    calibration's: prior_terms)."""
    rows, names, column, degrees = extended_fit_rows(prob, inputs, x0, free, x, exts)
    if prior is None:
        return errors_from_rows(rows, names, column, degrees)
    terms = prior.terms(column[: prob.layout.n_params], rows.J.shape[1])
    post = post_fit(lambda: [rows], prior=terms)
    return ParameterErrors(
        tuple(names), column, post.clustered, degrees, CLUSTERED, post.poses, post.plain
    )


def extended_fit_rows(prob: Problem, inputs: Inputs, x0, free, x, exts: list[Extension]):
    """The extended fit's residual rows, the names of its parameters (the layout's, then every
    coefficient), each one's column in the rows (-1 where held) and which are angles."""
    lay = prob.layout
    mask = prob.mask
    idx = np.flatnonzero(free)
    bases = [prepare(e, lay, x0, inputs) for e in exts]
    p, Jt = extended_rows(lay, np.asarray(x, dtype=float), exts, bases, inputs, mask, idx)
    J = Jt.reshape(Jt.shape[0], -1).T
    rows = Rows(
        J,
        J,
        (p - prob.meas[mask]).ravel(),
        np.repeat(np.nonzero(mask)[0], 3),
        np.zeros(len(J), int),
    )
    names = list(lay.names()) + coef_names(exts)
    n_coef = len(names) - lay.n_params
    column = np.r_[np.full(lay.n_params, -1), np.arange(len(idx), len(idx) + n_coef)]
    column[idx] = np.arange(len(idx))
    return rows, names, column, np.r_[angles(lay), np.zeros(n_coef, bool)]


def coef_covariance(errors: ParameterErrors, exts, i: int) -> np.ndarray:
    """Covariance of extension i's coefficients."""
    return errors.block(coef_names(exts[i : i + 1]))


def effect_uncertainty(errors: ParameterErrors, exts, i: int, basis, parameters) -> dict:
    """Standard errors of extension i's parameters as parameters(ext, basis) states them (edge
    units), propagated from its coefficients' covariance."""
    ext = exts[i]

    def values(c):
        e = copy.copy(ext)
        e.coef = c
        return parameters(e, basis)

    return propagate(values, ext.coef, coef_covariance(errors, exts, i))


@dataclass
class ExtendedErrors:
    """The extended model's standard errors: every parameter, and each extension's in edge units."""

    parameters: ParameterErrors
    effects: list[dict]  # per extension (in the model's order): parameter -> standard error
    coefficients: list[list[float]]  # per extension, its coefficients' standard errors


def diagnosis_errors(diag, x, exts, report: Report, params: list, hedged=None) -> ExtendedErrors:
    """Standard errors of a diagnosis's final model; each report effect gets its `uncertainty`.

    params: per extension, its parameters as the report states them (matched to the report's
    effects by value, whatever order the report lists them in). hedged (solver.hedge.Hedged):
    the final model is half way between geometry and the extended fit; its errors are that
    model's (hedge.half_way_errors), and each effect's `whole_effect` gets the whole fit's.
    """
    from .diagnosis_report import parameters
    from .effects import joint_basis

    if hedged is None:
        errors = extended_errors(diag.prob, diag.inputs, diag.x0, diag.free, x, exts, diag.prior)
    else:
        errors = hedged.errors(diag)
        # the whole coefficients' covariance: four times the halved ones' (c = 2 x c/2)
        whole = copy.copy(errors)
        whole.cov = 4.0 * errors.cov
    lay = diag.prob.layout
    effects = []
    for i, (ext, p) in enumerate(zip(exts, params)):
        basis = joint_basis(ext, lay, diag.x0, diag.inputs) if ext.is_joint else None
        u = effect_uncertainty(errors, exts, i, basis, parameters)
        effects.append(u)
        e = next((e for e in report.effects if e.parameters == p and e.uncertainty is None), None)
        if e is not None:
            e.uncertainty = u
            if hedged is not None and e.whole_effect is not None:
                full = hedged.whole[1]
                e.whole_effect.uncertainty = effect_uncertainty(whole, full, i, basis, parameters)
    coefs = [
        np.sqrt(np.clip(np.diag(coef_covariance(errors, exts, i)), 0.0, None)).tolist()
        for i in range(len(exts))
    ]
    return ExtendedErrors(errors, effects, coefs)
