"""One entry point for every identification method: register, check identifiability, fit."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import identifiability as ident
from .finite import require_inputs
from .identify import fit_targets, pose_fit, pose_residuals, pose_weight, register, start_fit
from .kinematics import Layout, predict_with_jacobian
from .minimax import minimax
from .robot import Robot

METHODS = ("minimax", "ls-sum", "ls-single", "ls-pose", "nominal")


@dataclass
class Calibration:
    """A fitted model and how it was obtained."""

    method: str
    layout: Layout
    x: np.ndarray
    fixed: dict[str, str]
    condition: float
    F: np.ndarray
    seconds: float
    iterations: int
    details: dict = field(default_factory=dict)

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
        raise ValueError(
            f"unknown method {method!r}: choose from minimax, ls-sum, ls-single:T, ls-pose"
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
) -> Calibration:
    """Fit geometry, base frame and SMR positions to measurements with the chosen method.

    q: (m, n) joint readings in rad; meas: (m, K, 3) mm with NaN for missing readings.
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
            method, prob.layout, x0, {}, float("nan"), F, time.perf_counter() - t0, 0
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
    details: dict = {"structural_condition": st.condition}
    if name == "ls-pose":
        prob, x0 = register(robot, targets, target_names, q, meas, base_guess, refine=False)
        lay = prob.layout
        full = np.all(prob.mask, axis=1)
        p, J, _ = predict_with_jacobian(lay, x0, q[full])
        Jd = pose_residuals(p, p, J, weight)[1].reshape(-1, lay.n_params)
        cond = ident.check_data(
            ident.gram(Jd, st.free), st.free, lay.names(), Jd.shape[0], int(full.sum())
        )
        x, res = pose_fit(prob, x0, st.free, weight)
        x = fit_targets(prob, x, range(len(target_names)))
        details["pose_weight_mm_per_rad"] = weight
    else:
        fit, first = start_fit(robot, targets, target_names, q, meas, st.free, rows, base_guess)
        prob = fit.prob
        cond = ident.check_data(
            first.A, st.free, lay.names(), 3 * int(fit.mask.sum()), prob.q.shape[0]
        )
        x, res = fit.fit(first)
        details["start"] = fit.start
        if name == "ls-single":
            x = fit_targets(prob, x, [k for k in range(len(target_names)) if k not in rows])
    iters = res.iterations
    details["lm"] = {
        "iterations": res.iterations,
        "evaluations": res.nfev,
        "jacobians": res.njev,
        "message": res.message,
    }
    if name == "minimax":
        details["ls_sum_F"] = prob.sum_squares(x).tolist()
        mm = minimax(prob, x, st.free, rows=rows, qp=qp, epsilon=epsilon)
        x = mm.x
        iters = mm.iterations
        details.update(
            history=mm.history,
            qp=qp,
            qp_iterations=mm.qp_iterations,
            converged=mm.converged,
            message=mm.message,
            lam=mm.lam.tolist(),
            mu=mm.mu.tolist(),
            constraints=mm.constraints.tolist(),
            sqp_seconds=mm.seconds,
        )
    # ls-sum's last residuals, when the fit kept them, are those of x over every target
    F = fit.per_target(res.r) if name == "ls-sum" and res.r is not None else prob.sum_squares(x)
    prob, x = prob.rebased(x)
    return Calibration(
        method, prob.layout, x, st.fixed, cond, F, time.perf_counter() - t0, iters, details
    )
