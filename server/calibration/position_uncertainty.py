"""A calibration's position uncertainty: kept in model.json (the identified parameters'
covariance in mm and degrees, an extended model's coefficients' too, and the joint scatter that
stands for what the model leaves unexplained), and read back as U at any joints
(solver/position_uncertainty.py)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from robocal.server.formats.model_json import ModelFile
from robocal.solver import position_uncertainty as pu
from robocal.solver.effects import Inputs
from robocal.solver.uncertainty import ParameterErrors

# The mean traces the joint scatter is fitted to are taken over at most this many of the fit's
# poses, evenly spread (a mean: 4,096 poses give it to about a percent, at any campaign's size).
MEAN_POSES = 4096
METHOD = (
    "U holds the position's error with 95 % probability: the parameters' pose-clustered "
    "covariance (an extended model's coefficients included) propagated to the position, and "
    "what the model leaves unexplained as a joint error of `joint_scatter_deg` RMS (fitted to "
    "the held-out error beyond the tracker's noise); a reading adds the tracker's own error"
)


def position_block(
    spread: Callable[[np.ndarray], pu.Spread],
    poses: int,
    errors: ParameterErrors,
    holdout_rms_mm,
    noise_mm,
) -> dict | None:
    """model.json's `uncertainty.position` block of a fit on `poses` poses, spread(rows) its
    spread at those of its poses; None when its held-out error or noise floor is unknown."""
    if holdout_rms_mm is None or noise_mm is None or not np.isfinite(holdout_rms_mm):
        return None
    rows = np.unique(np.linspace(0, poses - 1, min(poses, MEAN_POSES)).astype(int))
    par, lever = pu.mean_traces(spread(rows))
    scatter = pu.joint_scatter_rad(par, lever, holdout_rms_mm, noise_mm)
    free = np.flatnonzero(errors.column >= 0)
    order = free[np.argsort(errors.column[free])]
    scale = np.where(errors.degrees[order], np.degrees(1.0), 1.0)
    return {
        "coverage": pu.COVERAGE,
        "joint_scatter_deg": float(np.degrees(scatter)),
        "parameters": [errors.names[i] for i in order],
        # the named parameters' block (a fit's covariance may have columns of its own besides)
        "covariance": (
            errors.cov[np.ix_(errors.column[order], errors.column[order])] * np.outer(scale, scale)
        ).tolist(),
        "method": METHOD,
    }


def geometric_block(layout, x, q, errors: ParameterErrors, holdout_rms_mm, noise_mm):
    """position_block of a geometric calibration at joints q (its poses)."""
    q = np.asarray(q)
    return position_block(
        lambda rows: pu.spread_at(layout, x, q[rows], errors.cov, errors.column),
        len(q),
        errors,
        holdout_rms_mm,
        noise_mm,
    )


def extended_block(model: ModelFile, inputs: Inputs, errors: ParameterErrors, holdout, noise):
    """position_block of an extended model (a diagnosis's) fitted at these inputs, errors over
    its layout's parameters and its coefficients (solver.fit_errors.extended_errors)."""
    return position_block(
        lambda rows: model_spread(model, inputs.subset(rows), errors.cov, errors.column),
        len(inputs.q),
        errors,
        holdout,
        noise,
    )


def model_spread(model: ModelFile, inputs: Inputs, cov, column) -> pu.Spread:
    """The spread of the model's SMR positions at these inputs, cov over the parameters at
    `column` (the layout's names, then an extended model's coefficients); the extensions'
    bases taken on the nominal arm, as the model file predicts."""
    from robocal.solver.effects import prepare
    from robocal.solver.kinematics import Layout

    lay, x = model.layout()
    if not model.extensions:
        return pu.spread_at(lay, x, inputs.q, cov, column)
    blay = Layout(model.nominal or model.robot, np.eye(4), lay.target_names)
    bx = blay.initial(np.zeros((len(lay.target_names), 3)))
    bases = [prepare(e, blay, bx, inputs) for e in model.extensions]
    return pu.extended_spread_at(lay, x, model.extensions, bases, inputs, cov, column)


def model_uncertainty(
    model: ModelFile, q_rad, instrument_mm=0.0, time_s=None, temp_c=None
) -> pu.PositionUncertainty | None:
    """U of the model's SMR positions (m, K) at joints q (m, n) rad and, where its extensions
    need them, each reading's time_s and temp_c (m, K); a reading's own error (3-D RMS, mm) on
    top. None for a model without a position block (written before it), or with an extension
    whose time or temperature is not given (missing_inputs says which)."""
    from robocal.solver.fit_errors import coef_names

    block = model.uncertainty.position if model.uncertainty else None
    if not block or missing_inputs(model, time_s, temp_c):
        return None
    lay, _ = model.layout()
    names = list(lay.names()) + coef_names(model.extensions)
    where = {n: i for i, n in enumerate(block["parameters"])}
    column = np.array([where.get(n, -1) for n in names])
    if len(where) != int(np.count_nonzero(column >= 0)):
        return None  # another model's parameters: nothing to say
    degrees = np.zeros(len(where), dtype=bool)
    angle = np.r_[_angles(lay), np.zeros(len(names) - lay.n_params, dtype=bool)]
    for n, i in where.items():
        degrees[i] = angle[names.index(n)]
    scale = np.where(degrees, np.radians(1.0), 1.0)
    cov = np.asarray(block["covariance"], dtype=float) * np.outer(scale, scale)
    at = model_spread(model, Inputs(np.atleast_2d(q_rad), time_s, temp_c), cov, column)
    scatter = np.radians(float(block["joint_scatter_deg"]))
    return pu.position_uncertainty(at, scatter, instrument_mm, float(block["coverage"]))


def missing_inputs(model: ModelFile, time_s=None, temp_c=None) -> list[str]:
    """The model's extensions (label and column, "thermal_drift on temp_c") whose prediction needs
    a pose's time or temperature that is not given, or not at every reading."""
    given = {"time_s": time_s, "temp_c": temp_c}
    out = []
    for e in model.extensions:
        need = e.kind.needs(e)
        if need and (given[need] is None or not np.all(np.isfinite(given[need]))):
            out.append(f"{e.label()} on {need}")
    return out


def _angles(layout):
    from robocal.solver.fit_errors import angles

    return angles(layout)
