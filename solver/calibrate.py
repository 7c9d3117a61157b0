"""One entry point for every identification method: register, check identifiability, fit."""

from __future__ import annotations

import difflib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from . import identifiability as ident
from . import identify
from .finite import finite
from .identify import (
    SumOfSquares,
    fit_targets,
    pose_fit,
    pose_residuals,
    pose_weight,
    register,
    start_fit,
)
from .kinematics import Layout, predict_with_jacobian
from .lm import LMResult
from .minimax import MinimaxResult, minimax
from .prior import Prior
from .problem import Problem
from .robot import Robot
from .stop import Stop

if TYPE_CHECKING:
    from .noise import NoiseFloor
    from .screen import Outlier, Screening

# Fit residuals (RMS a reading) past this multiple of the noise floor set the level at which
# the parameters are judged identified instead of the floor.
RESIDUAL_OVER_FLOOR = 2.0


class Result(dict):
    """A dict whose keys read as attributes, like scipy's OptimizeResult (without importing
    scipy.optimize: a third of a second at every command's start)."""

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError as e:
            raise AttributeError(name) from e

    def __setattr__(self, name: str, value: Any) -> None:
        self[name] = value

    def __delattr__(self, name: str) -> None:
        del self[name]

    def __dir__(self):
        return list(self.keys())

    def __repr__(self) -> str:
        width = max(map(len, self.keys()), default=0) + 1
        return "\n".join(f"{k.rjust(width)}: {v!r}" for k, v in sorted(self.items()))


# A dict with attribute access rather than a dataclass: every method adds figures of its own
# (minimax its SQP and QP effort and multipliers, ls-pose its weight), which this carries as
# attributes without a field per method, lists (`keys()`) and prints with the common ones, and
# reads as scipy's results do.
class Calibration(Result):
    """A fitted model and how it was obtained, one type for every method.

    Common to all: method, layout, x, cost (the method's objective at x, mm^2, the prior's term
    left out), success, status (0 converged, 1 iteration limit, 2 stopped without converging),
    message, nit, fixed, shrunk (name -> identifiability.Shrunk), prior (solver.prior.Prior,
    None for nominal), condition (of the identified parameters), F (per target, mm^2), seconds.
    The method's own figures are further attributes: structural_condition, layout_condition
    (the identified parameters' condition number on rich poses, identifiability), lm (the
    least-squares stage) and prior_cost (the prior's term, mm^2: the objective is cost plus
    it) for every fit; start (ls-sum, ls-single, minimax); pose_weight_mm_per_rad (ls-pose);
    worst_target, worst_F, qp, qp_iterations, qp_converged, history, lam, mu, constraints,
    sqp_seconds, ls_sum_F (minimax).
    """

    F: np.ndarray  # typed for checkers, since the dict's items are untyped to them

    @property
    def iterations(self) -> int:
        return self.nit

    # set by whoever screened the readings first (server.calibration.workflow.run_method)
    @property
    def screening(self) -> Screening | None:
        """The gross-outlier screening the fit's readings went through; None: not screened."""
        return self.get("screening")

    @screening.setter
    def screening(self, value: Screening | None) -> None:
        self["screening"] = value

    @property
    def outliers(self) -> list[Outlier] | None:
        """The readings the screening excluded, as report rows; None: not screened."""
        return self.get("outliers")

    @outliers.setter
    def outliers(self, value: list[Outlier] | None) -> None:
        self["outliers"] = value

    # set with the screening (server.calibration.workflow.run_method): the verdict reuses it
    @property
    def noise_floor(self) -> NoiseFloor | None:
        """The tracker's noise floor the fit held its parameters against, and its source; None:
        the fit was given none (it held them against the default tracker spec's)."""
        return self.get("noise_floor")

    @noise_floor.setter
    def noise_floor(self, value: NoiseFloor | None) -> None:
        self["noise_floor"] = value

    @property
    def layout_condition(self) -> float | None:
        """The identified parameters' condition number on rich random poses: the least the
        robot and SMR layout allow, whatever the poses; None for the nominal model."""
        return self.get("layout_condition")

    @property
    def shrunk(self) -> dict[str, ident.Shrunk]:
        """The parameters shrunk toward nominal, with their share from the data and why."""
        return self.get("shrunk") or {}

    @property
    def prior(self) -> Prior | None:
        """The geometry's prior the fit was made with; None for the nominal model."""
        return self.get("prior")

    @property
    def qp(self) -> str | None:
        """minimax's QP subsolver; None for the other methods."""
        return self.get("qp")

    @property
    def history(self) -> list | None:
        """minimax's SQP iterations; None for the other methods."""
        return self.get("history")

    @property
    def robot(self) -> Robot:
        return self.layout.robot.with_params(self.x[: self.layout.n_geo])

    @property
    def base(self) -> np.ndarray:
        return self.layout.base(self.x)

    @property
    def targets(self) -> np.ndarray:
        return self.layout.targets(self.x)


class MethodDataError(ValueError):
    """A method the data's targets cannot serve (ls-pose on fewer than three, ls-single on one
    not measured): the data's fault, not the method name's."""


def parse_method(method: str, target_names) -> tuple[str, list[int]]:
    """Method name and the targets it fits: `ls-single:B` fits B only; MethodDataError when
    the targets cannot serve it."""
    name, _, arg = method.partition(":")
    if name not in METHODS:
        shown = ("minimax", "ls-sum", "ls-single", "ls-pose")
        close = difflib.get_close_matches(name, shown, n=1)
        raise ValueError(
            f"unknown method {name!r}; "
            + (f"did you mean {close[0]!r}? " if close else "")
            + "choose from minimax, ls-sum, ls-single:TARGET, ls-pose"
        )
    if name == "ls-single":
        arg = arg or target_names[0]
        if arg not in target_names:
            raise MethodDataError(
                f"method {method!r}: no target {arg!r} in the data ({', '.join(target_names)})"
            )
        return name, [list(target_names).index(arg)]
    if arg:
        raise ValueError(f"method {name!r} takes no ':' argument")
    if name == "ls-pose" and len(target_names) < 3:
        raise MethodDataError(
            f"ls-pose needs at least three SMRs (a pose from each pose's readings); the data "
            f"has {len(target_names)} ({', '.join(target_names)}): use minimax or ls-sum"
        )
    return name, list(range(len(target_names)))


@dataclass
class Stopped:
    """Why a method without a solver of its own stopped."""

    status: Stop
    message: str
    iterations: int


@dataclass
class Fitted:
    """What one method's own steps leave for the common ending."""

    prob: identify.Problem  # the registered problem x is of
    x: np.ndarray
    F: np.ndarray  # (K,) mm^2 per target at x
    cost: float  # the method's objective at x, mm^2
    stop: LMResult | MinimaxResult | Stopped  # the last solver's status, message, iterations
    fixed: dict  # parameter name -> why it is held
    condition: float
    own: dict = field(default_factory=dict)  # the method's own figures
    rebase: bool = True  # the base folded into the layout's reference (nominal keeps its own)
    shrunk: dict = field(default_factory=dict)  # parameter name -> ident.Shrunk
    prior: Prior | None = None


def _nominal(problem: Problem, rows: list[int], **_) -> Fitted:
    """Condition 0: the nominal arm with its base and SMRs registered, nothing of it fitted."""
    p = problem
    prob, x0 = register(p.robot, p.targets, p.target_names, p.q, p.meas, p.base_guess)
    F = prob.sum_squares(x0)
    stop = Stopped(Stop.CONVERGED, "nominal model registered: nothing fitted", 0)
    return Fitted(prob, x0, F, float(F.sum()), stop, {}, float("nan"), rebase=False)


def _structural(problem: Problem, rows: list[int], weight=None):
    """Which parameters the model can identify on the fitted targets (wherever the base is)."""
    lay = Layout(problem.robot, np.eye(4), problem.target_names)
    x0 = lay.initial(problem.targets)
    candidates = np.ones(lay.n_params, dtype=bool)
    ts = lay.target_slice.start
    for k in range(len(problem.target_names)):
        if k not in rows:
            candidates[ts + 3 * k : ts + 3 * k + 3] = False
    return lay, ident.structural(lay, x0, candidates, rows=rows, pose_weight=weight)


def _layout_condition(problem: Problem, rows: list[int], data: ident.DataCheck, weight=None):
    """The condition number data's identified parameters have on rich poses (the layout's)."""
    lay = Layout(problem.robot, np.eye(4), problem.target_names)
    x0 = lay.initial(problem.targets)
    return ident.layout_condition(lay, x0, data.identified, rows, weight)


def _lm_figures(res) -> dict:
    """The least-squares stage's effort, as every fitting method reports it."""
    return {
        "iterations": res.iterations,
        "evaluations": res.nfev,
        "jacobians": res.njev,
        "message": res.message,
    }


def _ls_pose(problem: Problem, rows: list[int], **_) -> Fitted:
    """Condition 6: least squares on the pose (position and orientation) each reading set gives."""
    p = problem
    if len(p.target_names) < 3:
        raise ValueError("ls-pose needs at least three targets")
    lay = Layout(p.robot, np.eye(4), p.target_names)
    weight = pose_weight(lay.targets(lay.initial(p.targets)))
    _, st = _structural(p, rows, weight)
    prob, x0 = register(p.robot, p.targets, p.target_names, p.q, p.meas, p.base_guess, False)
    lay = prob.layout
    full = np.all(prob.mask, axis=1)
    pred, J, _ = predict_with_jacobian(lay, x0, p.q[full])
    Jd = pose_residuals(pred, pred, J, weight)[1].reshape(-1, lay.n_params)
    A = ident.gram(Jd, st.free)
    floor = p.noise_floor_mm or ident.DEFAULT_NOISE_FLOOR_MM
    data = ident.check_data(A, st.free, lay, Jd.shape[0], int(full.sum()), floor)
    prior = geometry_prior(lay, data.free, floor)
    x, res = pose_fit(prob, x0, data.free, weight, prior=prior)
    # residuals well above the noise pin the parameters less: judged and weighed again there
    scatter = float(np.sqrt(3.0 * (res.cost - prior.cost(x)) / max(1, Jd.shape[0])))
    if scatter > RESIDUAL_OVER_FLOOR * floor:
        again = ident.check_data(A, st.free, lay, Jd.shape[0], int(full.sum()), scatter)
        if again.least_share < ident.PRIOR_NEGLIGIBLE or not np.array_equal(again.free, data.free):
            prior = geometry_prior(lay, again.free, scatter)
            x, res = pose_fit(prob, x0, again.free, weight, prior=prior)
        data = again
    x = fit_targets(prob, x, range(len(p.target_names)))
    own = {
        "structural_condition": st.condition,
        "layout_condition": _layout_condition(p, rows, data, weight),
        "pose_weight_mm_per_rad": weight,
        "lm": _lm_figures(res),
    }
    F = prob.sum_squares(x)
    fixed = {**st.fixed, **data.held}
    own["prior_cost"] = prior.cost(x)
    cost = float(res.cost) - own["prior_cost"]
    return Fitted(prob, x, F, cost, res, fixed, data.condition, own, True, data.shrunk, prior)


def geometry_prior(layout: Layout, free, noise_mm: float) -> Prior:
    """The prior on the free geometric parameters' change from nominal, weighed at noise_mm
    (3-D RMS a reading, so noise_mm / sqrt(3) a coordinate)."""
    nominal = np.zeros(layout.n_params)
    nominal[: layout.n_geo] = layout.robot.param_vector()
    return Prior.of(layout, nominal, free, noise_mm / np.sqrt(3.0), ident.PRIOR_MM, ident.PRIOR_DEG)


@dataclass
class _LeastSquares:
    """The point least-squares stage ls-sum, ls-single and minimax share."""

    fit: SumOfSquares
    x: np.ndarray
    res: LMResult
    data: ident.DataCheck
    fixed: dict
    own: dict
    shrunk: dict
    prior: Prior


def _least_squares(problem: Problem, rows: list[int]) -> _LeastSquares:
    """ls-sum on the targets in rows, its held parameters judged at the fit's own scatter."""
    p = problem

    def start(free):
        return start_fit(p.robot, p.targets, p.target_names, p.q, p.meas, free, rows, p.base_guess)

    lay, st = _structural(p, rows)
    fit, first = start(st.free)
    prob = fit.prob
    A, n_rows = first.A, 3 * int(fit.mask.sum())
    floor = p.noise_floor_mm or ident.DEFAULT_NOISE_FLOOR_MM
    data = ident.check_data(A, st.free, lay, n_rows, prob.q.shape[0], floor)
    if data.held:  # the start's normal equations were of the structurally free columns
        fit, first = start(data.free)
    fit.prior = prior = geometry_prior(prob.layout, data.free, floor)
    x, res = fit.fit(first)
    del first  # its twists, as large as a Jacobian, would sit beside minimax's own
    # Residuals well above the tracker's noise (the arm's repeatability, unmodelled effects)
    # pin the parameters less than the noise alone would: judged, and the prior weighed,
    # again at their level.
    F = finite(prob.sum_squares(x)[rows], "the fit's residuals")
    scatter = float(np.sqrt(F.sum() / max(1, fit.mask.sum())))
    if scatter > RESIDUAL_OVER_FLOOR * floor:
        again = ident.check_data(A, st.free, lay, n_rows, prob.q.shape[0], scatter)
        refit = not np.array_equal(again.free, data.free)
        if refit:
            fit, first = start(again.free)
        elif again.least_share < ident.PRIOR_NEGLIGIBLE:  # from the fit so far
            fit.x0, first, refit = x, fit.points(x), True
        data = again
        if refit:
            fit.prior = prior = geometry_prior(prob.layout, data.free, scatter)
            x, res = fit.fit(first)
            del first
    own = {
        "structural_condition": st.condition,
        "layout_condition": _layout_condition(p, rows, data),
        "start": fit.start,
        "lm": _lm_figures(res),
    }
    return _LeastSquares(fit, x, res, data, {**st.fixed, **data.held}, own, data.shrunk, prior)


def _ls_sum(problem: Problem, rows: list[int], **_) -> Fitted:
    """Condition 4: least squares summed over every target."""
    ls = _least_squares(problem, rows)
    prob, x, res = ls.fit.prob, ls.x, ls.res
    # the fit's last residuals, when it kept them, are those of x over every target
    F = ls.fit.per_target(res.r) if res.r is not None else prob.sum_squares(x)
    own = {**ls.own, "prior_cost": ls.prior.cost(x)}
    return Fitted(
        prob, x, F, float(F[rows].sum()), res, ls.fixed, ls.data.condition, own, True, ls.shrunk,
        ls.prior,
    )  # fmt: skip


def _ls_single(problem: Problem, rows: list[int], **_) -> Fitted:
    """Conditions 1-3: least squares on one target, the others' positions fitted after."""
    ls = _least_squares(problem, rows)
    prob, res = ls.fit.prob, ls.res
    others = [k for k in range(len(problem.target_names)) if k not in rows]
    x = fit_targets(prob, ls.x, others)
    F = prob.sum_squares(x)
    own = {**ls.own, "prior_cost": ls.prior.cost(x)}
    return Fitted(
        prob, x, F, float(F[rows].sum()), res, ls.fixed, ls.data.condition, own, True, ls.shrunk,
        ls.prior,
    )  # fmt: skip


def _minimax(problem: Problem, rows: list[int], qp="primal-dual", epsilon=None) -> Fitted:
    """Condition 5, the paper's: the worst target's sum of squares minimised from ls-sum's fit."""
    ls = _least_squares(problem, rows)
    fit, prob, res = ls.fit, ls.fit.prob, ls.res
    # the fit's last residuals, when it kept them, are those of x over every target
    start_F = fit.per_target(res.r) if res.r is not None else prob.sum_squares(ls.x)
    mm = minimax(prob, ls.x, ls.data.free, rows=rows, qp=qp, epsilon=epsilon, prior=ls.prior)
    # its F_i of the last step are those of every target when it fitted every target
    if sorted(rows) == list(range(len(problem.target_names))):
        F = np.empty(len(problem.target_names))
        F[rows] = mm.F
    else:
        F = prob.sum_squares(mm.x)
    worst = rows[int(np.argmax(F[rows]))]
    own = {
        **ls.own,
        "ls_sum_F": start_F.tolist(),
        "history": mm.history,
        "qp": qp,
        "qp_iterations": mm.qp_iterations,
        "qp_converged": mm.qp_unconverged == 0,
        "lam": mm.lam.tolist(),
        "mu": mm.mu.tolist(),
        "constraints": mm.constraints.tolist(),
        "sqp_seconds": mm.seconds,
        "worst_target": problem.target_names[worst],
        "worst_F": float(F[worst]),
    }
    own["prior_cost"] = mm.prior_cost
    return Fitted(
        prob, mm.x, F, float(F[worst]), mm, ls.fixed, ls.data.condition, own, True, ls.shrunk,
        ls.prior,
    )  # fmt: skip


# Each method's own steps; the method's parsing, the rebasing and the result are common.
FITS: dict[str, Callable[..., Fitted]] = {
    "minimax": _minimax,
    "ls-sum": _ls_sum,
    "ls-single": _ls_single,
    "ls-pose": _ls_pose,
    "nominal": _nominal,
}
METHODS = tuple(FITS)


def calibrate(problem: Problem, method="minimax", *, qp="primal-dual", epsilon=None) -> Calibration:
    """Fit geometry, base frame and SMR positions to the problem's readings with the method.

    qp and epsilon are minimax's QP subsolver and stopping tolerance. The problem's
    noise_floor_mm (the tracker's noise, 3-D RMS a reading) is what parameters the data moves
    too little are held against (default: the default tracker spec's).
    """
    t0 = time.perf_counter()
    name, rows = parse_method(method, list(problem.target_names))
    out = FITS[name](problem, rows, qp=qp, epsilon=epsilon)
    prob, x = out.prob.rebased(out.x) if out.rebase else (out.prob, out.x)
    status, message, nit = out.stop.status, out.stop.message, out.stop.iterations
    return Calibration(
        method=method,
        layout=prob.layout,
        x=x,
        cost=out.cost,
        success=status == 0,
        status=int(status),
        message=message,
        nit=nit,
        fixed=out.fixed,
        shrunk=out.shrunk,
        prior=out.prior,
        condition=out.condition,
        F=out.F,
        seconds=time.perf_counter() - t0,
        **out.own,
    )
