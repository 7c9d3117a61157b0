"""A calibration's position uncertainty: kept in model.json (the identified parameters'
covariance in mm and degrees, and the joint scatter that stands for what the model leaves
unexplained), and read back as U at any joints (solver/position_uncertainty.py)."""

from __future__ import annotations

import numpy as np

from robocal.server.formats.model_json import ModelFile
from robocal.solver import position_uncertainty as pu
from robocal.solver.uncertainty import ParameterErrors

# The mean traces the joint scatter is fitted to are taken over at most this many of the fit's
# poses, evenly spread (a mean: 4,096 poses give it to about a percent, at any campaign's size).
MEAN_POSES = 4096
METHOD = (
    "U holds the position's error with 95 % probability: the parameters' pose-clustered "
    "covariance propagated to the position, and what the model leaves unexplained as a joint "
    "error of `joint_scatter_deg` RMS (fitted to the held-out error beyond the tracker's noise); "
    "a reading adds the tracker's own error"
)


def position_block(layout, x, q, errors: ParameterErrors, holdout_rms_mm, noise_mm) -> dict | None:
    """model.json's `uncertainty.position` block of a fit at joints q (its poses), None when
    its held-out error or noise floor is unknown."""
    if holdout_rms_mm is None or noise_mm is None or not np.isfinite(holdout_rms_mm):
        return None
    q = np.asarray(q)[np.unique(np.linspace(0, len(q) - 1, min(len(q), MEAN_POSES)).astype(int))]
    par, lever = pu.mean_traces(pu.spread_at(layout, x, q, errors.cov, errors.column))
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


def model_uncertainty(model: ModelFile, q_rad, instrument_mm=0.0) -> pu.PositionUncertainty | None:
    """U of the model's SMR positions (m, K) at joints q (m, n) rad, a reading's own error
    (3-D RMS, mm) on top; None for a model without a position block (written before it, or an
    extended model whose coefficients' covariance it does not keep)."""
    block = model.uncertainty.position if model.uncertainty else None
    if not block or model.extensions:
        return None
    lay, x = model.layout()
    names = list(lay.names())
    where = {n: i for i, n in enumerate(block["parameters"])}
    column = np.array([where.get(n, -1) for n in names])
    if len(where) != int(np.count_nonzero(column >= 0)):
        return None  # another model's parameters: nothing to say
    degrees = np.zeros(len(where), dtype=bool)
    angle = np.asarray(_angles(lay))
    for n, i in where.items():
        degrees[i] = angle[names.index(n)]
    scale = np.where(degrees, np.radians(1.0), 1.0)
    cov = np.asarray(block["covariance"], dtype=float) * np.outer(scale, scale)
    at = pu.spread_at(lay, x, np.atleast_2d(q_rad), cov, column)
    scatter = np.radians(float(block["joint_scatter_deg"]))
    return pu.position_uncertainty(at, scatter, instrument_mm, float(block["coverage"]))


def _angles(layout):
    from robocal.solver.fit_errors import angles

    return angles(layout)
