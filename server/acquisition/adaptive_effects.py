"""The effects an adaptive campaign's fit includes: named by the solver's diagnosis at checkpoints,
refitted with the geometry at each step, their columns part of the choice of the next poses.

Only effects whose basis reads a pose's joints alone are planned for (a periodic or scale error,
compliance under gravity): a candidate's columns are then known before it is measured, as the
next poses' choice needs. The others the diagnosis may name (backlash, which hangs on the tour's
order; thermal drift and a base shift, on the time) are reported but left out of the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.solver import adaptive
from robocal.solver.effects import Extension, Inputs, prepare
from robocal.solver.extended import extension_rows, fit_extended, predict_extended
from robocal.solver.identify import Problem
from robocal.solver.kinematics import Layout

PLANNABLE = ("joint_periodic", "joint_scale", "joint_compliance")
# A checkpoint diagnoses the data again once the poses grew by this factor since the last one:
# a diagnosis costs seconds, and an effect's evidence grows with the poses, not with each batch.
REDIAGNOSE = 1.3


@dataclass(frozen=True)
class Named:
    """What a checkpoint's diagnosis named: every effect, and those the fit includes."""

    labels: tuple[str, ...]  # every effect named (false alarms on a clean cell counted here)
    included: tuple[Extension, ...]  # the plannable ones, in the adaptive fit from now on


def diagnose(cell, meas) -> Named:
    """The solver's diagnosis of the campaign so far (no outlier screening, as the fit has none)."""
    from robocal.server.calibration import workflow

    d, _ = workflow.diagnose(cell, meas, screen=False)
    keep = tuple(Extension(**{**e.__dict__}) for e in d.extensions if e.name in PLANNABLE)
    return Named(tuple(e.label() for e in d.extensions), keep)


@dataclass(frozen=True)
class ExtendedFit:
    """The geometry's identified parameters and the effects' coefficients fitted together."""

    layout: Layout
    x: np.ndarray
    extensions: tuple[Extension, ...]
    identified: np.ndarray  # the geometry's fitted parameters (indices into x)
    train_rows: np.ndarray  # (m, 3K, P) per pose, a missing reading's rows zero
    residual_rows: np.ndarray  # (m, 3K) prediction - reading, a missing reading's zero
    fit_rms_mm: float  # 3-D RMS a reading

    def predict(self, q) -> np.ndarray:
        """SMR centres (m, K, 3) at joints q (rad)."""
        return predict_extended(self.layout, self.x, list(self.extensions), Inputs(np.asarray(q)))

    def rows(self, q) -> np.ndarray:
        """Per-pose rows (m, 3K, P) at joints q: what the next poses are chosen by."""
        return _rows(self.layout, self.x, self.extensions, q, self.identified)


def extended_fit(cal, meas, column, exts) -> ExtendedFit:
    """Refit the geometric calibration `cal` (its identified parameters, `column` >= 0) with the
    effects exts on the campaign's readings meas."""
    q = np.asarray(meas.q, dtype=float)
    prob = Problem(cal.layout, q, np.asarray(meas.xyz, dtype=float))
    free = np.asarray(column) >= 0
    # under the calibration's prior, as it was fitted: its shrunk columns would wander without
    x, ee, _ = fit_extended(
        prob, Inputs(q), cal.x, free, [_fresh(e) for e in exts], prior=cal.prior
    )
    idx = np.flatnonzero(free)
    train = _rows(cal.layout, x, ee, q, idx, prob.mask)
    pred = predict_extended(cal.layout, x, ee, Inputs(q))
    res = np.where(prob.mask[..., None], pred - prob.meas, 0.0)
    fit_rms = float(np.sqrt(np.sum(res**2) / max(1, int(prob.mask.sum()))))
    return ExtendedFit(cal.layout, x, tuple(ee), idx, train, res.reshape(len(q), -1), fit_rms)


def _fresh(e: Extension) -> Extension:
    """The extension with its coefficients to be fitted again from zero."""
    return Extension(**{**e.__dict__, "coef": np.zeros(0)})


def _rows(layout, x, exts, q, idx, mask=None) -> np.ndarray:
    """Per-pose rows (m, 3K, P) over x[idx] and every extension's coefficients."""
    q = np.asarray(q, dtype=float)
    m, K = len(q), len(layout.target_names)
    mask = np.ones((m, K), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    inputs = Inputs(q)
    bases = [prepare(e, layout, x, inputs) for e in exts]
    _, Jt = extension_rows(layout, x, list(exts), bases, inputs, mask, idx)
    full = np.zeros((m, K, 3, Jt.shape[0]))
    full[mask] = np.moveaxis(Jt, 0, -1)
    return adaptive.rows_of(full)


def from_steps(extensions) -> tuple[Extension, ...]:
    """The effects a step kept (model.json's form, Step.extensions), to be fitted again."""
    from robocal.server.formats.model_doc import ExtensionDoc

    return tuple(_fresh(ExtensionDoc.model_validate(e).extension) for e in extensions)


def fit_campaign(cell, meas, exts=()):
    """The adaptive campaign's model of a campaign's readings: the fast geometric fit, with the
    effects exts when given; what it predicts at joints q (rad) is `.predict(q)` (m, K, 3)."""
    from robocal.server.acquisition.adaptive_plan import METHOD
    from robocal.server.calibration import workflow
    from robocal.solver.fit_errors import calibration_figures

    cal = workflow.run_method(cell, meas, METHOD, screening=False)
    if not exts:
        return _Geometric(cal.layout, cal.x)
    errors, _ = calibration_figures(cal, meas.q, meas.xyz)
    return extended_fit(cal, meas, errors.column, exts)


@dataclass(frozen=True)
class _Geometric:
    layout: Layout
    x: np.ndarray

    def predict(self, q) -> np.ndarray:
        from robocal.solver.kinematics import predict

        return predict(self.layout, self.x, np.asarray(q))
