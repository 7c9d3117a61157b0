"""Where each SMR will be at the next pose, so the tracker finds it without searching.

Nominal model at first (with the cell's rough base); from the first pose's readings on, the most
probable base and SMR positions given the readings, the survey (the base's translation and
rotation about its origin each this far off) and the fixture drawing (each SMR this far off): a
few close poses cannot tell a turned base from SMRs off their drawing, and the priors share the
misfit between them as their uncertainties say; after a few poses, base and SMR positions
registered to the readings so far without priors; once the data can identify it, the full
geometric model. At a pose, the targets not yet measured are also shifted by the offset seen on
those already measured there: the flange's pose error is common to all its SMRs.
"""

from __future__ import annotations

import numpy as np

from robocal.solver.calibrate import calibrate
from robocal.solver.identifiability import NotIdentifiable
from robocal.solver.identify import register
from robocal.solver.kinematics import Layout, predict, predict_with_jacobian
from robocal.solver.problem import Problem
from robocal.solver.robot import Robot

# Base and SMR positions together (15 parameters) fitted to fewer poses extrapolate badly to
# the next; until then the base alone is fitted (a rigid motion, six)
MIN_REGISTER_POSES = 5
MIN_CALIBRATE_POSES = 7
REFIT_EVERY = 5
# Before MIN_REGISTER_POSES poses, the priors (standard deviations): how far off the nominal SMR
# centres may be (the fixture drawing; per axis) and the base guess's rotation (a quick survey)
NOMINAL_SIGMA_MM = 1.0
SURVEY_ROT_SIGMA_DEG = 0.5
SURVEY_MM = 10.0  # the base's translation, per axis
# a reading's misfit the base and SMRs cannot explain: the nominal arm's own position error (an
# uncalibrated arm's absolute accuracy is a few millimetres), per axis
ARM_SIGMA_MM = 3.0
MAP_STEPS = 4  # Gauss-Newton steps: the model is nearly linear in base and SMRs here
# Before registration a search reaches this many standard deviations of the prediction's error
# (a normal error's chance beyond 5 sigma in 3-D is below 1e-4)
REACH_SIGMAS = 5.0
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
        # the survey's base and the drawing's SMRs; the last fit of them, with its covariance
        self._prior: tuple[Layout, np.ndarray] | None = None
        self._fit: tuple[Layout, np.ndarray, np.ndarray] | None = None

    def reach_mm(self, q) -> float:
        """How far off the SMRs may be from their predictions at joints q: before the SMRs are
        registered, REACH_SIGMAS standard deviations of the prediction's error, from the
        posterior of base and SMRs (the survey's and the drawing's before any reading) and the
        arm's own error; after, what each stage has been seen to need."""
        if self.stage not in ("nominal", "rigid") or not self.refit:
            return REACH_MM[self.stage]
        layout, x, cov = self._posterior()
        J = predict_with_jacobian(layout, x, np.atleast_2d(q))[1][0][:, :, _free(layout)]
        spread = np.einsum("kip,pq,kjq->kij", J, cov, J)  # (K, 3, 3) mm^2
        worst = float(np.linalg.eigvalsh(spread)[:, -1].max())
        return REACH_SIGMAS * float(np.sqrt(worst + ARM_SIGMA_MM**2))

    def _posterior(self) -> tuple[Layout, np.ndarray, np.ndarray]:
        """The last fit's layout, vector and covariance of base and SMRs; the priors' alone
        before any reading."""
        if self._fit is not None:
            return self._fit
        return self.layout, self.x, np.diag(_prior_sigma(len(self.names)) ** 2)

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
        """Base and SMR positions, most probable given the readings so far and their priors
        (the survey's base, the drawing's SMRs): Gauss-Newton on the readings and the priors
        together, from the prior each time; its covariance says how far off a prediction may
        be."""
        if self._prior is None:
            self._prior = (self.layout, self.x.copy())
        layout, x0 = self._prior
        free, sigma = _free(layout), _prior_sigma(len(self.names))
        q = np.atleast_2d(q)
        ok = np.all(np.isfinite(meas), axis=-1)
        x = x0.copy()
        for _ in range(MAP_STEPS):
            p, J, _ = predict_with_jacobian(layout, x, q)
            A = np.vstack(
                [J[ok][:, :, free].reshape(-1, len(free)) / ARM_SIGMA_MM, np.diag(1.0 / sigma)]
            )
            b = np.concatenate([(meas[ok] - p[ok]).ravel() / ARM_SIGMA_MM, (x0 - x)[free] / sigma])
            x[free] += np.linalg.lstsq(A, b, rcond=None)[0]
        self._fit = (layout, x.copy(), np.linalg.inv(A.T @ A))
        self._fitted_at = int(np.sum(np.any(ok, axis=1)))
        self.layout, self.x = layout.rebased(x)
        self.stage = "rigid"
        return self.stage

    def _base_is_identity(self) -> bool:
        return bool(np.allclose(self.layout.base(self.x), np.eye(4)))


def _free(layout: Layout) -> np.ndarray:
    """The entries of x for base and SMR positions."""
    return np.r_[
        np.arange(layout.n_params)[layout.base_slice],
        np.arange(layout.n_params)[layout.target_slice],
    ]


def _prior_sigma(smrs: int) -> np.ndarray:
    """Standard deviations of base (translation mm, rotation rad) and SMRs (mm) before any
    reading: the survey's and the fixture drawing's."""
    return np.r_[
        np.full(3, SURVEY_MM),
        np.full(3, np.deg2rad(SURVEY_ROT_SIGMA_DEG)),
        np.full(3 * smrs, NOMINAL_SIGMA_MM),
    ]
