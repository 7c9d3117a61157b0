"""The residual rows each identification method solves, and so the standard errors of its fit."""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .calibrate import Calibration, parse_method
from .effects import Extension, Inputs, prepare
from .extended import extension_rows as extended_rows
from .identify import Problem, pose_fit, pose_residuals
from .kinematics import Layout, predict_rows
from .uncertainty import ParameterErrors, Rows, errors_from_rows, propagate


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
    G = J * np.asarray(estimated, dtype=float)[None, :]
    if weight is not None:
        arm = np.asarray(cols) < layout.target_slice.start
        G[:, arm] *= np.repeat(np.asarray(weight, dtype=float)[k], 3)[:, None]
    return Rows(J, G, (p - meas[mask]).ravel(), np.repeat(pose, 3), np.full(len(J), stage))


def _in(cols, which) -> np.ndarray:
    return np.isin(cols, np.asarray(list(which), dtype=int))


def calibration_errors(cal: Calibration, q, meas) -> ParameterErrors:
    """Standard errors of a calibration's identified parameters (every method of `calibrate`)."""
    rows, column = calibration_rows(cal, q, meas)
    return errors_from_rows(rows, cal.layout.names(), column, angles(cal.layout))


def point_errors(cal: Calibration, rows: Rows) -> np.ndarray:
    """Which of calibration_rows' rows are point errors (ls-pose's first stage is not)."""
    if parse_method(cal.method, list(cal.layout.target_names))[0] == "ls-pose":
        return rows.stage == 1
    return np.ones(len(rows.r), dtype=bool)


def calibration_rows(cal: Calibration, q, meas) -> tuple[Rows, np.ndarray]:
    """A calibration's residual rows and each parameter's column in them (-1 where held fixed).

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
        free = np.r_[np.arange(lay.base_slice.start, lay.base_slice.stop), smr(rows)]
    else:
        free = np.array(
            [i for i, n in enumerate(names) if n not in cal.fixed and i not in smr(others)],
            dtype=int,
        )
    column = np.full(len(names), -1)
    if name == "ls-pose":
        parts, cols = _pose_stages(cal, q, meas, mask, free)
        column[cols[len(free) :]] = np.arange(len(free), len(cols))  # the SMRs of the second stage
        column[free[free < ts]] = np.flatnonzero(free < ts)
    else:
        cols = np.r_[free, smr(others)].astype(int)
        weight = np.asarray(cal.lam) if name == "minimax" else None
        sel = np.zeros(mask.shape[1], dtype=bool)
        sel[rows] = True
        parts = [point_rows(lay, x, q, meas, mask & sel, cols, _in(cols, free), weight)]
        if others:
            parts.append(
                point_rows(lay, x, q, meas, mask & ~sel, cols, _in(cols, smr(others)), stage=1)
            )
        column[cols] = np.arange(len(cols))
    return Rows.stack(parts), column


def _pose_stages(cal: Calibration, q, meas, mask, free):
    """ls-pose's two stages: pose residuals over `free` (on poses with every SMR), then every SMR
    position from its readings with the arm held. The first stage's SMR entries are its own
    (refitted here, since the second stage replaced them in the calibration)."""
    lay = cal.layout
    weight = cal.pose_weight_mm_per_rad
    prob = Problem(lay, q, meas)
    x1, _ = pose_fit(prob, cal.x, np.isin(np.arange(lay.n_params), free), weight)
    full = np.all(mask, axis=1)
    m, K = int(full.sum()), mask.shape[1]
    p, Jt = predict_rows(lay, x1, q[full], np.ones((m, K), dtype=bool), free)
    J = Jt.reshape(len(free), m, K, 3).transpose(1, 2, 3, 0)
    r, Jr = pose_residuals(p.reshape(m, K, 3), meas[full], J, weight)
    tcols = np.arange(lay.target_slice.start, lay.target_slice.stop)
    cols = np.r_[free, tcols]
    n1 = len(free)
    J1 = np.zeros((r.size, len(cols)))
    J1[:, :n1] = Jr.reshape(-1, n1)
    first = Rows(
        J1, J1.copy(), r.ravel(), np.repeat(np.flatnonzero(full), 6), np.zeros(r.size, int)
    )
    # the second stage sees the arm's free entries and its own SMR columns, not stage one's SMRs
    arm = np.r_[free[free < lay.target_slice.start], tcols]
    second = point_rows(lay, cal.x, q, meas, mask, arm, _in(arm, tcols), stage=1)
    J2 = np.zeros((len(second.r), len(cols)))
    G2 = np.zeros_like(J2)
    at = np.r_[np.flatnonzero(free < lay.target_slice.start), np.arange(n1, len(cols))]
    J2[:, at], G2[:, at] = second.J, second.G
    return [first, Rows(J2, G2, second.r, second.pose, second.stage)], cols


def coef_names(exts) -> list[str]:
    """Names of the extensions' coefficients, in the order fit_extended stacks them."""
    return [f"{e.label()}[{i}]" for e in exts for i in range(e.n_params)]


def extended_errors(
    prob: Problem, inputs: Inputs, x0, free, x, exts: list[Extension]
) -> ParameterErrors:
    """Standard errors of the extended model fitted on every pose (geometry, base, SMRs and each
    extension's coefficients), with the bases evaluated at x0 as fit_extended holds them."""
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
    return errors_from_rows(rows, names, column, np.r_[angles(lay), np.zeros(n_coef, bool)])


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


def diagnosis_errors(diag, x, exts, report: dict, params: list) -> ExtendedErrors:
    """Standard errors of a diagnosis's final model; each report effect gets its `uncertainty`.

    params: per extension, its parameters as the report states them (matched to the report's
    effects by value, whatever order the report lists them in).
    """
    from .diagnosis_report import parameters
    from .effects import joint_basis

    errors = extended_errors(diag.prob, diag.inputs, diag.x0, diag.free, x, exts)
    lay = diag.prob.layout
    effects = []
    for i, (ext, p) in enumerate(zip(exts, params)):
        basis = joint_basis(ext, lay, diag.x0, diag.inputs) if ext.is_joint else None
        u = effect_uncertainty(errors, exts, i, basis, parameters)
        effects.append(u)
        e = next(
            (e for e in report["effects"] if e.get("parameters") == p and "uncertainty" not in e),
            None,
        )
        if e is not None:
            e["uncertainty"] = u
    coefs = [
        np.sqrt(np.clip(np.diag(coef_covariance(errors, exts, i)), 0.0, None)).tolist()
        for i in range(len(exts))
    ]
    return ExtendedErrors(errors, effects, coefs)
