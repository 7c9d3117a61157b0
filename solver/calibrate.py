"""One entry point for every identification method: register, check identifiability, fit."""

from __future__ import annotations

import difflib
import time

import numpy as np
from scipy.optimize import OptimizeResult

from . import identifiability as ident
from .finite import finite, require_inputs
from .identify import fit_targets, pose_fit, pose_residuals, pose_weight, register, start_fit
from .kinematics import Layout, predict_with_jacobian
from .minimax import minimax
from .robot import Robot

METHODS = ("minimax", "ls-sum", "ls-single", "ls-pose", "nominal")
# Fit residuals (RMS a reading) past this multiple of the noise floor set the level at which
# the parameters are judged identified instead of the floor.
RESIDUAL_OVER_FLOOR = 2.0


# An OptimizeResult (a dict with attribute access) rather than a dataclass: every method adds
# figures of its own (minimax its SQP and QP effort and multipliers, ls-pose its weight), which
# this carries as attributes without a field per method, lists (`keys()`) and prints with the
# common ones, and reads as scipy's results do.
class Calibration(OptimizeResult):
    """A fitted model and how it was obtained, one type for every method.

    Common to all: method, layout, x, cost (the method's objective at x, mm^2), success, status
    (0 converged, 1 iteration limit, 2 stopped without converging), message, nit, fixed,
    condition, F (per target, mm^2), seconds. The method's own figures are further attributes:
    structural_condition and lm (the least-squares stage) for every fit; start (ls-sum,
    ls-single, minimax); pose_weight_mm_per_rad (ls-pose); worst_target, worst_F, qp,
    qp_iterations, qp_converged, history, lam, mu, constraints, sqp_seconds, ls_sum_F (minimax).
    """

    F: np.ndarray  # typed for checkers, since OptimizeResult's items are untyped to them

    @property
    def iterations(self) -> int:
        return self.nit

    @property
    def robot(self) -> Robot:
        return self.layout.robot.with_params(self.x[: self.layout.n_geo])

    @property
    def base(self) -> np.ndarray:
        return self.layout.base(self.x)

    @property
    def targets(self) -> np.ndarray:
        return self.layout.targets(self.x)


def parse_method(method: str, target_names) -> tuple[str, list[int]]:
    """Method name and the targets it fits: `ls-single:B` fits B only."""
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
            raise ValueError(
                f"method {method!r}: no target {arg!r} in the data ({', '.join(target_names)})"
            )
        return name, [list(target_names).index(arg)]
    if arg:
        raise ValueError(f"method {name!r} takes no ':' argument")
    return name, list(range(len(target_names)))


def calibrate(
    robot: Robot,
    targets,
    target_names,
    q,
    meas,
    method="minimax",
    base_guess=None,
    qp="primal-dual",
    epsilon=None,
    noise_floor_mm=None,
) -> Calibration:
    """Fit geometry, base frame and SMR positions to measurements with the chosen method.

    q: (m, n) joint readings in rad; meas: (m, K, 3) mm with NaN for missing readings;
    noise_floor_mm: the tracker's noise (3-D RMS a reading), against which the parameters the
    data moves too little are held (default: the default tracker spec's).
    """
    t0 = time.perf_counter()
    name, rows = parse_method(method, list(target_names))
    require_inputs(q, meas, targets, base_guess)
    if name == "ls-pose" and len(target_names) < 3:
        raise ValueError("ls-pose needs at least three targets")
    if name == "nominal":
        prob, x0 = register(robot, targets, target_names, q, meas, base_guess)
        F = prob.sum_squares(x0)
        return Calibration(
            method=method,
            layout=prob.layout,
            x=x0,
            cost=float(F.sum()),
            success=True,
            status=0,
            message="nominal model registered: nothing fitted",
            nit=0,
            fixed={},
            condition=float("nan"),
            F=F,
            seconds=time.perf_counter() - t0,
        )
    # which parameters the model can identify does not depend on where the base is
    lay = Layout(robot, np.eye(4), tuple(target_names))
    x0 = lay.initial(targets)
    candidates = np.ones(lay.n_params, dtype=bool)
    ts = lay.target_slice.start
    for k in range(len(target_names)):
        if k not in rows:
            candidates[ts + 3 * k : ts + 3 * k + 3] = False
    weight = pose_weight(lay.targets(x0)) if name == "ls-pose" else None
    st = ident.structural(lay, x0, candidates, rows=rows, pose_weight=weight)
    own: dict = {"structural_condition": st.condition}  # the method's own figures
    if name == "ls-pose":
        prob, x0 = register(robot, targets, target_names, q, meas, base_guess, refine=False)
        lay = prob.layout
        full = np.all(prob.mask, axis=1)
        p, J, _ = predict_with_jacobian(lay, x0, q[full])
        Jd = pose_residuals(p, p, J, weight)[1].reshape(-1, lay.n_params)
        data = ident.check_data(
            ident.gram(Jd, st.free), st.free, lay, Jd.shape[0], int(full.sum()), noise_floor_mm
        )
        x, res = pose_fit(prob, x0, data.free, weight)
        x = fit_targets(prob, x, range(len(target_names)))
        own["pose_weight_mm_per_rad"] = weight
    else:
        fit, first = start_fit(robot, targets, target_names, q, meas, st.free, rows, base_guess)
        prob = fit.prob
        A, n_rows = first.A, 3 * int(fit.mask.sum())
        data = ident.check_data(A, st.free, lay, n_rows, prob.q.shape[0], noise_floor_mm)
        if data.held:  # the start's normal equations were of the structurally free columns
            fit, first = start_fit(
                robot, targets, target_names, q, meas, data.free, rows, base_guess
            )
        x, res = fit.fit(first)
        del first  # its twists, as large as a Jacobian, would sit beside minimax's own
        # Residuals well above the tracker's noise (the arm's repeatability, unmodelled effects)
        # pin the parameters less than the noise alone would: judged again at their level.
        F = finite(prob.sum_squares(x)[rows], "the fit's residuals")
        scatter = float(np.sqrt(F.sum() / max(1, fit.mask.sum())))
        floor = noise_floor_mm or ident.DEFAULT_NOISE_FLOOR_MM
        if scatter > RESIDUAL_OVER_FLOOR * floor:
            again = ident.check_data(A, st.free, lay, n_rows, prob.q.shape[0], scatter)
            if set(again.held) - set(data.held):
                data = again
                fit, first = start_fit(
                    robot, targets, target_names, q, meas, data.free, rows, base_guess
                )
                x, res = fit.fit(first)
                del first
        own["start"] = fit.start
        if name == "ls-single":
            x = fit_targets(prob, x, [k for k in range(len(target_names)) if k not in rows])
    iters, message, status = res.iterations, res.message, res.status
    own["lm"] = {
        "iterations": res.iterations,
        "evaluations": res.nfev,
        "jacobians": res.njev,
        "message": res.message,
    }
    if name == "minimax":
        # the fit's last residuals, when it kept them, are those of x over every target
        start_F = fit.per_target(res.r) if res.r is not None else prob.sum_squares(x)
        own["ls_sum_F"] = start_F.tolist()
        mm = minimax(prob, x, data.free, rows=rows, qp=qp, epsilon=epsilon)
        x = mm.x
        iters, message, status = mm.iterations, mm.message, mm.status
        own.update(
            history=mm.history,
            qp=qp,
            qp_iterations=mm.qp_iterations,
            qp_converged=mm.qp_unconverged == 0,
            lam=mm.lam.tolist(),
            mu=mm.mu.tolist(),
            constraints=mm.constraints.tolist(),
            sqp_seconds=mm.seconds,
        )
    # ls-sum's last residuals, when the fit kept them, are those of x over every target;
    # minimax's F_i of its last step too when it fitted every target
    if name == "ls-sum" and res.r is not None:
        F = fit.per_target(res.r)
    elif name == "minimax" and sorted(rows) == list(range(len(target_names))):
        F = np.empty(len(target_names))
        F[rows] = mm.F
    else:
        F = prob.sum_squares(x)
    if name == "minimax":
        worst = rows[int(np.argmax(F[rows]))]
        cost = float(F[worst])
        own.update(worst_target=list(target_names)[worst], worst_F=cost)
    else:  # least squares: ls-pose its own residuals, the others F summed over their targets
        cost = float(res.cost) if name == "ls-pose" else float(F[rows].sum())
    prob, x = prob.rebased(x)
    return Calibration(
        method=method,
        layout=prob.layout,
        x=x,
        cost=cost,
        success=status == 0,
        status=int(status),
        message=message,
        nit=iters,
        fixed={**st.fixed, **data.held},
        condition=data.condition,
        F=F,
        seconds=time.perf_counter() - t0,
        **own,
    )
