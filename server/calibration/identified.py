"""The identified parameters of a calibration as model.json's `identified` block (and the API's
parameter table): per joint the change of theta, d, a, alpha, beta from nominal, the base and SMR
frames, each with its standard error, the parameters held fixed and why, the condition number
and the strongest correlations."""

from __future__ import annotations

import numpy as np

from robocal.server.exports.params import Entry, base_entries, entries
from robocal.server.formats.blocks import (
    Correlation,
    FixedParameter,
    Identified,
    ParameterRow,
    ShrunkParameter,
)
from robocal.server.formats.model_json import ModelFile
from robocal.solver.guard import strongest_correlations
from robocal.solver.identifiability import PRIOR_DEG, PRIOR_MM, Shrunk
from robocal.solver.kinematics import BASE_NAMES, rot, translation
from robocal.solver.prior import Prior
from robocal.solver.uncertainty import ParameterErrors, propagate

CORRELATIONS = 5  # the strongest |r| listed


def base_standard_errors(base: np.ndarray, errors: ParameterErrors) -> dict[str, float]:
    """Standard errors of base_entries' x, y, z (mm, tracker frame) and rz, ry, rx (deg),
    propagated from the fit's base entries (small motions of the calibrated base)."""
    names = list(BASE_NAMES)
    if any(errors.column[errors.names.index(n)] < 0 for n in names):
        return {}

    def values(c):
        moved = base @ translation(*c[:3]) @ rot(2, c[3]) @ rot(1, c[4]) @ rot(0, c[5])
        return {f"{n}_deg" if u == "deg" else n: v for n, u, v in base_entries(moved)}

    se = propagate(values, np.zeros(6), errors.block(names))
    out: dict[str, float] = {}
    for n in names:
        v = se.get(n, se.get(f"{n}_deg"))
        if v is not None:
            out[n] = v
    return out


def _status(name: str, fixed, shrunk) -> str:
    if name in fixed:
        return "held fixed"
    return "shrunk toward nominal" if name in shrunk else "identified"


def _change(d: float, unit: str) -> float:
    """A change from nominal; an angle's the short way round: a base hung upside down (rx 180
    deg nominal) identified at 179.9998 deg changed by -0.0002 deg, not +359.9998."""
    return (d + 180.0) % 360.0 - 180.0 if unit == "deg" else d


def _row(
    e: Entry, fixed, nominal: float | None, standard_error: float | None, shrunk=()
) -> ParameterRow:
    """One table row of a params entry: where it sits (joint, base, SMR) and its change."""
    where: dict[str, int | str]
    if e.joint is not None:
        group, kind, where = "joint", e.name.rstrip("0123456789"), {"joint": e.joint}
    elif e.name in BASE_NAMES:
        group, kind, where = "base", e.name[len("base_") :], {}
    else:
        target, kind = e.name.rsplit("_", 1)
        group, where = "smr", {"target": target}
    return ParameterRow(
        parameter=e.name,
        group=group,
        kind=kind,
        **where,
        unit=e.unit,
        nominal=nominal,
        calibrated=e.calibrated,
        change=None if nominal is None else _change(e.calibrated - nominal, e.unit),
        standard_error=standard_error,
        status=_status(e.name, fixed, shrunk),
    )


def _block(
    model: ModelFile, rows, fixed, condition, estimator, correlations, shrunk=None, prior=None
) -> Identified:
    return Identified(
        convention=model.robot.convention,
        units="mm; degrees for theta, alpha, beta, rz, ry, rx",
        frames="joints in the robot's convention; base x, y, z and Rz Ry Rx in the tracker "
        "frame (base = Trans(x, y, z) Rz(rz) Ry(ry) Rx(rx)); SMRs in the flange frame, their "
        "change the offset from the cell's nominal position",
        estimator=estimator,
        rows=rows,
        fixed=[FixedParameter(parameter=n, why=why) for n, why in fixed.items()],
        shrunk=[
            ShrunkParameter(parameter=n, data_share=round(s.share, 6), why=s.why)
            for n, s in (shrunk or {}).items()
        ],
        prior=prior,
        condition_number=condition,
        correlations=correlations,
    )


def identified_block(
    model: ModelFile,
    errors: ParameterErrors,
    *,
    fixed: dict[str, str],
    condition: float,
    nominal_targets: dict | None = None,
    nominal_base: np.ndarray | None = None,
    shrunk: dict[str, Shrunk] | None = None,
    prior: Prior | None = None,
) -> Identified:
    """model.json's `identified` block: one row per parameter (edge units), the held-fixed
    parameters with why, the shrunk ones with their data share and why, the prior, the
    condition number (of the identified ones) and the strongest correlations (between
    identified parameters; the base's are of its small motions along and about its axes)."""
    base_se = base_standard_errors(model.base, errors)
    nominal = {}
    if nominal_base is not None:
        nominal.update({n: v for n, _, v in base_entries(np.asarray(nominal_base, dtype=float))})
    for t, xyz in (nominal_targets or {}).items():
        nominal.update({f"{t}_{c}": float(v) for c, v in zip("xyz", xyz)})
    rows = [
        _row(
            e,
            fixed,
            e.nominal if e.nominal is not None else nominal.get(e.name),
            base_se.get(e.name) if e.name in BASE_NAMES else e.standard_error,
            shrunk or {},
        )
        for e in entries(model)
    ]
    # the named parameters' columns (ls-pose's covariance has its first stage's SMRs besides)
    named = [(int(c), n) for n, c in zip(errors.names, errors.column) if c >= 0]
    cols = [c for c, _ in named]
    top = strongest_correlations(errors.cov[np.ix_(cols, cols)], CORRELATIONS)
    pairs = [Correlation(a=named[i][1], b=named[j][1], r=round(r, 6)) for i, j, r in top]
    return _block(model, rows, fixed, condition, errors.estimator, pairs, shrunk, prior_text(prior))


def prior_text(prior: Prior | None) -> str | None:
    """The prior a fit was made with, in a sentence."""
    if prior is None or not np.any(prior.weight > 0):
        return None
    return (
        f"Gaussian on each geometric parameter's change from nominal: {PRIOR_MM:g} mm, "
        f"{PRIOR_DEG:g} deg (standard deviation), weighed at the residual's "
        f"{prior.noise_mm * np.sqrt(3.0):.4g} mm RMS a reading"
    )


def parameters_of(model: ModelFile) -> Identified:
    """A model file's identified block; rebuilt from its parameters and standard errors (no
    correlations, no base standard errors) for a model without one (a diagnosis's, or older)."""
    if model.identified is not None:
        return model.identified
    fixed = (model.fit.fixed_parameters if model.fit else None) or {}
    rows = [
        _row(e, fixed, e.nominal, None if e.name in BASE_NAMES else e.standard_error)
        for e in entries(model)
    ]
    estimator = model.uncertainty.estimator if model.uncertainty else None
    condition = model.fit.condition_number if model.fit else None
    return _block(model, rows, fixed, condition, estimator or "none", [])


def arm_parameters(model: ModelFile) -> list[dict]:
    """The arm's own identified parameters (joints; not the cell's base or SMRs) with their
    standard errors, as a calibration job keeps them for the fleet view."""
    return [
        r.model_dump(include={"parameter", "unit", "calibrated", "standard_error"})
        for r in parameters_of(model).rows
        if r.group == "joint" and r.status == "identified" and r.standard_error is not None
    ]
