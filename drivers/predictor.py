"""Where each SMR will be at the next pose, so the tracker finds it without searching.

Nominal model at first (with the cell's rough base); from the first pose's readings on, the base
corrected by the rigid motion that best maps the predicted SMRs onto the measured ones (its
rotation held near the survey's where a few close SMRs cannot fix it); after a few poses, base
and SMR positions registered to the readings so far; once the data can identify it, the full
geometric model. At a pose, the targets not yet measured are also shifted by the offset seen on
those already measured there: the flange's pose error is common to all its SMRs.
"""

from __future__ import annotations

import numpy as np

from robocal.solver.calibrate import calibrate
from robocal.solver.identifiability import NotIdentifiable
from robocal.solver.identify import register
from robocal.solver.kinematics import Layout, predict
from robocal.solver.problem import Problem
from robocal.solver.rigid import rigid_correction
from robocal.solver.robot import Robot

# Base and SMR positions together (15 parameters) fitted to fewer poses extrapolate badly to
# the next; until then the base alone is fitted (a rigid motion, six)
MIN_REGISTER_POSES = 5
MIN_CALIBRATE_POSES = 7
REFIT_EVERY = 5
# Before MIN_REGISTER_POSES poses: how far off the nominal SMR centres may be (fixture
# drawings, the arm's own errors; per axis) and the base guess's rotation (a quick survey)
NOMINAL_SIGMA_MM = 1.0
SURVEY_ROT_SIGMA_DEG = 0.5
# How far off a prediction may be at each stage (mm), where that is known: the largest error seen
# over thirty simulated cells' first twenty poses was 14 mm registered and 0.1 mm calibrated (a
# rigid fit to two poses may still be 30 mm off); a search further out only costs time, the
# target is out of sight
REACH_MM = {"nominal": np.inf, "rigid": np.inf, "registered": 25.0, "calibrated": 1.0, "given": 1.0}


class SmrPredictor:
    """Predicted SMR centres (tracker frame, mm) for joint positions (rad)."""

    def __init__(self, robot: Robot, targets, names, base_guess=None, *, refit: bool = True):
        """refit=False keeps the given geometry (a calibrated model's): poses clustered in a
        small volume, as a verification's are, would only spoil it."""
        self.robot, self.names = robot, tuple(names)
        self.targets = np.asarray(targets, dtype=float)
        base = np.eye(4) if base_guess is None else np.asarray(base_guess, dtype=float)
        self.layout = Layout(robot, base, self.names)
        self.x = self.layout.initial(self.targets)
        self.stage = "nominal" if refit else "given"
        self.refit = refit
        self._fitted_at = 0

    @property
    def reach_mm(self) -> float:
        """How far off the SMR may be from its prediction at this stage."""
        return REACH_MM[self.stage]

    def predict(self, q) -> np.ndarray:
        """(K, 3) predicted centres at one pose."""
        return predict(self.layout, self.x, np.atleast_2d(q))[0]

    def correct(self, predicted: np.ndarray, measured: dict) -> np.ndarray:
        """Shift predictions by the mean offset of the targets already measured at this pose."""
        offsets = [measured[n] - predicted[k] for k, n in enumerate(self.names) if n in measured]
        return predicted + np.mean(offsets, axis=0) if offsets else predicted

    def update(self, q, meas) -> str:
        """Refit from all readings so far (q (m, n) rad, meas (m, K, 3) NaN where missing)."""
        m = int(np.sum(np.any(np.all(np.isfinite(meas), axis=-1), axis=1)))
        if not self.refit or m - self._fitted_at < (
            1 if m < 2 * MIN_CALIBRATE_POSES else REFIT_EVERY
        ):
            return self.stage
        if m < MIN_REGISTER_POSES:
            return self._rigid(q, meas)
        self._fitted_at = m
        if m >= MIN_CALIBRATE_POSES and len(self.names) * m * 3 > 2 * self.layout.n_params:
            try:
                base = self.layout.base(self.x)
                problem = Problem(self.robot, self.targets, self.names, q, meas, base)
                cal = calibrate(problem, "ls-sum")
                self.layout, self.x, self.stage = cal.layout, cal.x, "calibrated"
                return self.stage
            except (NotIdentifiable, np.linalg.LinAlgError):
                pass
        prob, x = register(
            self.robot,
            self.targets,
            self.names,
            q,
            meas,
            None
            if self.stage in ("nominal", "rigid") and self._base_is_identity()
            else self.layout.base(self.x),
        )
        self.layout, self.x, self.stage = prob.layout, x, "registered"
        return self.stage

    def _rigid(self, q, meas) -> str:
        """Correct the base guess by the rigid motion from predicted to measured SMRs."""
        pred = predict(self.layout, self.x, np.atleast_2d(q))
        ok = np.all(np.isfinite(meas), axis=-1)
        T = rigid_correction(pred[ok], meas[ok], NOMINAL_SIGMA_MM, np.deg2rad(SURVEY_ROT_SIGMA_DEG))
        self._fitted_at = int(np.sum(np.any(ok, axis=1)))
        self.layout = Layout(self.robot, T @ self.layout.base(self.x), self.names)
        self.x = self.layout.initial(self.targets)
        self.stage = "rigid"
        return self.stage

    def _base_is_identity(self) -> bool:
        return bool(np.allclose(self.layout.base(self.x), np.eye(4)))
