"""An adaptive campaign's planner: a D-optimal seed set, then after each batch a fast ls-sum fit,
the accuracy it predicts over the working volume (solver/adaptive.py) and the next poses.

The working volume is the candidates themselves: valid random poses drawn uniformly within the
arm's limits (drivers/planning.plan_poses), so a mean over them is a mean over the volume the
campaign could measure. Each batch is ordered into a short tour from the arm's last pose.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from robocal.drivers import planning
from robocal.server.acquisition import adaptive_effects as effects
from robocal.server.formats.cell_json import Cell
from robocal.server.formats.model_json import extension_to_json
from robocal.solver import adaptive
from robocal.solver import observability as obs
from robocal.solver.effects import Extension
from robocal.solver.kinematics import predict, predict_with_jacobian
from robocal.solver.measurements import Measurements

METHOD = "ls-sum"  # the fast fit each step refits with; the final calibration is the user's


@dataclass(frozen=True)
class AdaptiveOptions:
    """The campaign's target accuracy (held-out 3-D RMS a reading, mm) and its limits."""

    target_mm: float
    max_poses: int = 80
    candidates: int = 400  # valid random poses the next ones are chosen from (the volume)
    seed_poses: int = 0  # the D-optimal seed set; 0: twice the parameters over a pose's rows
    batch: int = 0  # poses chosen per step; 0: half the parameters over a pose's rows

    def __post_init__(self):
        if not self.target_mm > 0:
            raise ValueError(f"target_accuracy_mm: must be positive, not {self.target_mm}")
        if self.max_poses < 2:
            raise ValueError(f"max_poses: at least 2, not {self.max_poses}")
        if self.candidates < self.max_poses:
            raise ValueError(
                f"candidates: {self.candidates} is fewer than max_poses {self.max_poses}"
            )


@dataclass(frozen=True)
class Step:
    """One refit of the campaign: its poses, the predicted accuracy, and the rule's verdict."""

    poses: int
    predicted_mm: float
    floor_mm: float
    parameters_mm: float
    holdout_mm: float
    expected_holdout_mm: float
    kappa: float
    stop: bool
    reason: str
    message: str
    campaign_s: float | None = None  # the campaign clock when its poses were measured
    # the effects the fit included (labels), and what this step's diagnosis named (None: none ran)
    effects: tuple[str, ...] = ()
    named: tuple[str, ...] | None = None
    extensions: tuple[dict, ...] = ()  # the included effects as model.json has them

    def to_json(self) -> dict:
        """The step as the campaign's settings (`adaptive_steps`) and its event keep it."""
        return {k: _plain(v) for k, v in asdict(self).items()}

    @classmethod
    def from_json(cls, d: dict) -> Step:
        """A stored step (to_json's form) again: None a non-finite float, a list a tuple."""
        kw = {f.name: _typed(f.name, d[f.name]) for f in fields(cls) if f.name in d}
        return cls(**kw)


# the float fields to_json writes None for when not finite (campaign_s is None when unknown)
_FLOATS = frozenset(f.name for f in fields(Step) if f.type == "float")


def _typed(name: str, v):
    """A stored step's value as Step has it."""
    if v is None and name in _FLOATS:
        return float("nan")
    return tuple(v) if isinstance(v, list) else v


@dataclass(frozen=True)
class AdaptiveSummary:
    """An adaptive campaign's run: its steps so far and, once it stopped, why."""

    target_accuracy_mm: float
    steps: tuple[Step, ...]
    stopped: str | None  # the stop's reason (target, floor, maximum); None: not stopped
    message: str | None  # the last step's words; None: no step yet
    predicted_mm: float | None  # the last step's prediction; None: no step yet

    def to_json(self) -> dict:
        """The summary as the service stores and answers it (acquire's run summary)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        return {**out, "steps": [s.to_json() for s in self.steps]}


class AdaptivePlanner:
    """Chooses an adaptive campaign's poses among candidates (m, n) rad planned on the nominal
    arm at the base guess; `taken` are the candidates measured or planned so far."""

    def __init__(self, cell: Cell, base, candidates_rad, opts: AdaptiveOptions):
        self.cell, self.opts = cell, opts
        self.base = np.asarray(base, dtype=float)
        self.candidates = np.asarray(candidates_rad, dtype=float)
        self.taken: list[int] = []
        # the effects the fit includes (adaptive_effects.py), and the poses last diagnosed at
        self.effects: tuple[Extension, ...] = ()
        self.diagnosed_at = 0
        self._fitted: tuple[Extension, ...] = ()  # the last fit's effects, coefficients fitted
        J = planning.candidate_jacobians(
            cell.robot, self.base, cell.targets, self.candidates
        )  # nominal: for the seed
        self._nominal = J
        rows = J.rows_per_pose
        self.seed_poses = opts.seed_poses or int(np.ceil(2 * J.n_params / rows))
        self.batch = opts.batch or max(1, int(np.ceil(J.n_params / (2 * rows))))
        self.seed_poses = min(self.seed_poses, opts.max_poses)

    def seed(self) -> np.ndarray:
        """The D-optimal seed set's candidate indices (what the nominal arm makes observable)."""
        chosen = obs.select_poses(obs.unit_columns(self._nominal), self.seed_poses, "D")
        self.taken.extend(int(i) for i in chosen)
        return chosen

    def step(self, meas: Measurements, campaign_s: float | None = None):
        """Refit on the poses measured so far; (Step, next candidate indices or None to stop)."""
        pred, n = self.predict(meas)
        decision = adaptive.decide(pred, self.opts.target_mm, n, self.opts.max_poses)
        named = None
        grown = n >= effects.REDIAGNOSE * self.diagnosed_at
        if pred.supported and (
            (not decision.stop and grown) or (decision.stop and n > self.diagnosed_at)
        ):
            # a checkpoint (the target not reached and the poses grown since the last, or about
            # to stop): the solver's diagnosis says what else the residuals show, and the fit
            # includes it from now on (or drops what it no longer names). Before a stop at the
            # target too: a few poses' geometric fit absorbs part of an effect it lacks, and its
            # residuals then under-state the error on new poses (a hidden periodic error, 16-18
            # poses: predicted 27-36 % under what independent poses measured)
            found = effects.diagnose(self.cell, _seen(meas))
            self.diagnosed_at, named = n, found.labels
            if _labels(found.included) != _labels(self.effects):
                self.effects = found.included
                pred, n = self.predict(meas)
                decision = adaptive.decide(pred, self.opts.target_mm, n, self.opts.max_poses)
        step = Step(
            n,
            pred.rms_mm,
            pred.floor_mm,
            pred.parameters_mm,
            pred.holdout_mm,
            pred.expected_holdout_mm,
            pred.kappa,
            decision.stop,
            decision.reason,
            decision.message,
            campaign_s,
            _labels(self.effects),
            named,
            tuple(extension_to_json(e) for e in self._fitted),
        )
        if decision.stop:
            return step, None
        k = min(self.batch, self.opts.max_poses - n, len(self.candidates) - len(self.taken))
        if k <= 0:
            return step, None
        chosen = adaptive.choose_next(self._J_train, self._J_cand, self._W, k, self.taken)
        self.taken.extend(int(i) for i in chosen)
        return step, chosen

    def predict(self, meas: Measurements) -> tuple[adaptive.Prediction, int]:
        """The fit's prediction over the volume, and the poses it was fitted on."""
        from robocal.server.calibration import workflow
        from robocal.server.calibration.validation import tracker_spec
        from robocal.solver.fit_errors import calibration_figures
        from robocal.solver.noise import from_spec

        meas = _seen(meas)
        seen = np.isfinite(meas.xyz).all(axis=-1)
        cal = workflow.run_method(self.cell, meas, METHOD, screening=False)
        errors, holdout = calibration_figures(cal, meas.q, meas.xyz)
        # the tracker's noise by its spec at the readings' ranges and the volume's: the data's
        # own estimate (SMR distances) is too rough at a seed set's few poses (18 poses of 3
        # SMRs: 15 % over), and what the data show beyond the spec comes from the residuals
        spec = tracker_spec(self.cell)
        noise_mm = from_spec(meas.xyz, spec).mm
        volume_noise = from_spec(predict(cal.layout, cal.x, self.candidates), spec).mm
        column = errors.column
        readings = int(seen.sum())
        self._fitted = ()
        if self.effects:  # the geometry and the named effects fitted together
            fit = effects.extended_fit(cal, meas, column, self.effects)
            self._fitted = fit.extensions
            self._J_train = fit.train_rows
            self._J_cand = fit.rows(self.candidates)
            C = adaptive.normal_inverse(self._J_train)
            holdout_mm = adaptive.holdout_rms(self._J_train, C, fit.residual_rows, readings)
            fit_rms = fit.fit_rms_mm
        else:
            self._J_train = adaptive.rows_of(_identified(cal, meas.q, column), seen)
            self._J_cand = adaptive.rows_of(_identified(cal, self.candidates, column))
            res = predict(cal.layout, cal.x, meas.q) - meas.xyz
            fit_rms = float(np.sqrt(np.mean(np.sum(res[seen] ** 2, axis=-1))))
            holdout_mm = float(holdout.rms())
        K = len(self.cell.targets)
        self._W = adaptive.volume_weight(self._J_cand, len(self.candidates) * K)
        pred = adaptive.predict(
            self._J_train, readings, self._W, noise_mm, holdout_mm, fit_rms, volume_noise
        )
        return pred, int(len(meas.q))


def _plain(v):
    """A step's value as JSON keeps it: a non-finite float None, a tuple a list."""
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return list(v) if isinstance(v, tuple) else v


def _seen(meas: Measurements) -> Measurements:
    """The campaign's poses with at least one reading."""
    keep = np.isfinite(meas.xyz).all(axis=-1).any(axis=1)
    return meas if keep.all() else meas.subset(np.flatnonzero(keep))


def _labels(exts) -> tuple[str, ...]:
    return tuple(e.label() for e in exts)


def _identified(cal, q, column) -> np.ndarray:
    """d(point)/d(identified parameter) (m, K, 3, P) at joints q, columns as the covariance's."""
    _, J, _ = predict_with_jacobian(cal.layout, cal.x, q)
    free = np.flatnonzero(column >= 0)
    out = np.zeros(J.shape[:-1] + (int(column.max()) + 1,))
    out[..., column[free]] = J[..., free]
    return out


def plan_candidates(cell: Cell, base, n: int, rng) -> np.ndarray:
    """n valid random poses (n, joints) rad on the nominal arm at the base guess: the volume."""
    return planning.plan_poses(cell.robot, base, cell.targets, n, rng)


def ordered(q, start) -> np.ndarray:
    """q (m, n) rad in a short tour from `start` (the arm's last pose)."""
    return q[planning.order_poses(q, start)]
