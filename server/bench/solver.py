"""Solver benchmark: our ls-sum and minimax against the strongest fair peers on the same problems.

The peers get what ours has: the analytic Jacobian (scipy least_squares, lm and trf, for ls-sum;
SLSQP with analytic gradients on the epigraph form for minimax), the same tolerances, the same
registered problem, start and free parameters. Every figure is the median of interleaved repeats
(each round runs every side once, in a rotating order), with its quartiles and extremes and the
machine's load average. Finite-difference scipy, the former reference, stays as a secondary line.
"""

from __future__ import annotations

import os
import platform
import sys
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import scipy
from scipy.optimize import least_squares, minimize

from robocal.solver.calibrate import calibrate
from robocal.solver.identifiability import structural
from robocal.solver.identify import least_squares_fit, register
from robocal.solver.kinematics import predict, predict_rows
from robocal.solver.minimax import default_epsilon, measured_distances, minimax
from robocal.solver.problem import Problem

from .timing import interleaved, load, paired, spread

SEED = 0
# speedup_min: ours against the strongest fair peer (median of paired rounds), at every size
GOALS = {"ls_sum_100_poses_ms_max": 20, "minimax_100_poses_ms_max": 100, "speedup_min": 1.0}
OURS = {
    "ls_sum": ("ls-sum", "primal-dual"),
    "minimax": ("minimax", "primal-dual"),
    "minimax_exact": ("minimax", "exact"),
}
# ours' LM: stop once a step would lower the cost by less than FTOL of it, or move x by less
# than XTOL of it (solver/lm.py); the peers are given the same
FTOL, XTOL = 1e-8, 1e-12
MINIMAX_TOL = 1e-10  # ours: predicted decrease relative to max F_i; SLSQP: ftol on max F_i / phi0
FD_ROUNDS = 3  # finite-difference rounds (seconds each at 1,000 poses): a secondary figure


def _log(msg: str) -> None:
    """Progress line on stderr (stdout carries the JSON)."""
    print(f"[bench] {msg}", file=sys.stderr, flush=True)


def _rounds(m: int) -> int:
    """Interleaved rounds for m poses (fewer if the size's time budget runs out first)."""
    return 41 if m <= 100 else 15 if m <= 1000 else 7


def _campaign(cell, m: int, seed: int):
    """A simulated campaign of m poses on the virtual cell (fixed seed)."""
    from robocal.drivers.cell import TrackerSpec, VirtualCell

    vc = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec.of(cell.tracker)
    )
    return vc.campaign(m, seed=seed)


def _violation(targets: np.ndarray, meas: np.ndarray) -> float:
    """Largest violation (mm^2, 0 if feasible) of the distance-invariance constraints by SMR positions."""
    pairs, dbar, sem = measured_distances(meas)
    eps = default_epsilon(sem)
    c = [(np.linalg.norm(targets[i] - targets[j]) - d) ** 2 - eps for (i, j), d in zip(pairs, dbar)]
    return float(max(0.0, *c)) if c else 0.0


def _setup(robot, targets, names, q, xyz):
    """Registered problem, start and free parameters as calibrate() finds them for ls-sum and minimax."""
    prob, x0 = register(robot, targets, names, q, xyz, refine=False)
    lay = prob.layout
    st = structural(lay, x0, np.ones(lay.n_params, dtype=bool))
    return prob, x0, st.free


class _Model:
    """The model's point residuals over the free parameters, and their analytic Jacobian, as a
    peer would be handed them (calls counted)."""

    def __init__(self, prob, x0, free):
        self.prob, self.x0, self.idx = prob, np.array(x0, float), np.flatnonzero(free)
        self.meas = prob.meas[prob.mask]
        self.calls = self.jacobians = 0

    def x(self, z) -> np.ndarray:
        x = self.x0.copy()
        x[self.idx] = z
        return x

    def residuals(self, z) -> np.ndarray:
        """(pred - meas) of the measured readings, flattened (3N,)."""
        self.calls += 1
        return (
            predict(self.prob.layout, self.x(z), self.prob.q)[self.prob.mask] - self.meas
        ).ravel()

    def jacobian(self, z) -> np.ndarray:
        """d residuals / d z, (3N, free), from the kinematics' analytic derivatives."""
        self.jacobians += 1
        prob = self.prob
        _, Jt = predict_rows(prob.layout, self.x(z), prob.q, prob.mask, self.idx)
        return Jt.reshape(len(self.idx), -1).T


def _ls_figures(prob, x, **more) -> dict:
    """The same measure for every side: F_i of eq. (6) at x and their sum."""
    F = prob.sum_squares(x)
    return {"objective": float(F.sum()), "F": F.tolist(), **more}


def _peer_ls(prob, x0, free, method: str, jac="analytic", ftol=FTOL, xtol=XTOL):
    """ls-sum by scipy least_squares (lm or trf) from x0 over the free parameters: (x, figures)."""
    model = _Model(prob, x0, free)
    res = least_squares(
        model.residuals,
        model.x0[model.idx],
        jac=model.jacobian if jac == "analytic" else jac,
        method=method,
        x_scale="jac",
        ftol=ftol,
        xtol=xtol,
    )
    x = model.x(res.x)
    return x, _ls_figures(
        prob,
        x,
        nfev=int(res.nfev),
        njev=int(res.njev or 0),
        model_evaluations=model.calls,
        status=int(res.status),
        message=res.message,
    )


class _Epigraph:
    """min w s.t. F_i / phi0 <= w and the distance invariance, over v = (z, w) where
    x = x_ls + z * sqrt(phi0) / |J column| on the free entries: every variable moves the SMRs
    alike and the objective starts at 1, so SLSQP's ftol is relative, as ours' tolerance."""

    def __init__(self, prob, x_ls, free):
        self.prob, self.model = prob, _Model(prob, x_ls, free)
        idx = self.model.idx
        scale = np.linalg.norm(self.model.jacobian(x_ls[idx]), axis=0)
        scale[scale == 0] = 1.0
        self.pairs, self.dbar, sem = measured_distances(prob.meas)
        self.eps = default_epsilon(sem)
        self.phi0 = float(prob.sum_squares(x_ls).max())
        self.step = np.sqrt(self.phi0) / scale
        self.z0 = x_ls[idx]
        self.K = prob.meas.shape[1]
        self.target = np.nonzero(prob.mask)[1]
        self.onehot = (np.arange(self.K)[:, None] == self.target[None, :]).astype(float)
        self.ts = prob.layout.target_slice.start
        self.col = {int(j): n for n, j in enumerate(idx)}

    def x(self, v) -> np.ndarray:
        return self.model.x(self.z0 + v[:-1] * self.step)

    def _distances(self, x):
        t = x[self.ts :].reshape(self.K, 3)
        c = np.empty(len(self.pairs))
        G = np.zeros((len(self.pairs), len(self.step)))
        for n, ((i, j), d) in enumerate(zip(self.pairs, self.dbar)):
            dv = t[i] - t[j]
            dist = np.linalg.norm(dv)
            c[n] = (dist - d) ** 2
            for sign, k in ((1.0, i), (-1.0, j)):
                for a in range(3):
                    col = self.col.get(self.ts + 3 * k + a)
                    if col is not None:
                        G[n, col] += sign * 2.0 * (dist - d) * dv[a] / dist
        return c, G

    def constraints(self, v) -> np.ndarray:
        x = self.x(v)
        r = self.model.residuals(self.z0 + v[:-1] * self.step).reshape(-1, 3)
        F = np.bincount(self.target, np.sum(r * r, axis=1), minlength=self.K)
        return np.concatenate(
            [v[-1] - F / self.phi0, (self.eps - self._distances(x)[0]) / self.phi0]
        )

    def jacobian(self, v) -> np.ndarray:
        """Of the constraints: -dF_i/dv / phi0 and 1 for w; -d(distance terms)/dv / phi0."""
        x = self.x(v)
        prob, model = self.prob, self.model
        model.jacobians += 1
        p, Jt = predict_rows(prob.layout, x, prob.q, prob.mask, model.idx)  # one walk: both
        r = p - model.meas  # (N, 3)
        per_reading = 2.0 * np.einsum("pnc,nc->np", Jt, r)  # d(|r_n|^2)/dx, (N, P)
        dF = self.onehot @ per_reading  # summed per SMR, (K, P)
        dc = self._distances(x)[1]
        out = np.zeros((self.K + len(self.pairs), len(v)))
        out[: self.K, :-1] = -dF * self.step / self.phi0
        out[: self.K, -1] = 1.0
        out[self.K :, :-1] = -dc * self.step / self.phi0
        return out


def _peer_minimax(prob, x_ls, free, analytic=True, ftol=MINIMAX_TOL):
    """minimax by SLSQP on the epigraph form from the ls-sum solution x_ls: (x, figures)."""
    ep = _Epigraph(prob, x_ls, free)
    v0 = np.zeros(len(ep.step) + 1)
    v0[-1] = 1.0
    con = {"type": "ineq", "fun": ep.constraints}
    if analytic:
        con["jac"] = ep.jacobian
    res = minimize(
        lambda v: v[-1],
        v0,
        jac=(lambda v: np.eye(len(v))[-1]) if analytic else None,
        method="SLSQP",
        options={"maxiter": 1000, "ftol": ftol},
        constraints=[con],
    )
    x = ep.x(res.x)
    F = prob.sum_squares(x)
    return x, {
        "objective": float(F.max()),
        "F": F.tolist(),
        "nit": int(res.nit),
        "nfev": int(res.nfev),
        "njev": int(res.njev),
        "model_evaluations": ep.model.calls,
        "success": bool(res.success),
        "message": res.message,
        "max_constraint_violation_mm2": _violation(prob.layout.targets(x), prob.meas),
    }


def _ours_calibrate(cal, xyz) -> dict:
    """Figures of one calibrate() run."""
    r = {
        "calibrate_seconds": cal.seconds,
        "F": cal.F.tolist(),
        "free_parameters": int(len(cal.x) - len(cal.fixed)),
        "iterations": cal.nit,
    }
    if cal.method == "ls-sum":
        r["objective"] = float(cal.F.sum())
    else:
        r.update(
            objective=float(cal.F.max()),
            sqp_seconds=cal.sqp_seconds,
            qp_iterations=cal.qp_iterations,
            converged=cal.success,
            message=cal.message,
            max_constraint_violation_mm2=_violation(cal.targets, xyz),
        )
    return r


def _rel(value: float, best: float) -> float:
    """How far above the best objective reached (relative; 0 at the best)."""
    return (value - best) / best


def _size(cell, meas, names, targets, m: int, rounds: int, peers: bool, fd: bool) -> dict:
    """Every side on one campaign of m poses, in interleaved rounds."""
    args = (cell.robot, targets, meas.target_names, meas.q, meas.xyz)
    prob, x0, free = _setup(*args)
    problem = Problem(*args)
    fns: dict[str, Callable[[], Any]] = {
        "ours_ls_sum": partial(calibrate, problem, "ls-sum"),
        "ours_minimax": partial(calibrate, problem, "minimax"),
        "ours_minimax_exact": partial(calibrate, problem, "minimax", qp="exact"),
    }
    x_ls, _ = least_squares_fit(prob, x0, free)
    if peers:
        fns.update(
            setup=partial(_setup, *args),
            ours_ls_solve=partial(least_squares_fit, prob, x0, free),
            ours_minimax_sqp=partial(minimax, prob, x_ls, free, tol=MINIMAX_TOL),
            peer_ls_lm=partial(_peer_ls, prob, x0, free, "lm"),
            peer_ls_trf=partial(_peer_ls, prob, x0, free, "trf"),
            peer_minimax_slsqp=partial(_peer_minimax, prob, x_ls, free),
        )
    for fn in fns.values():  # untimed warm-up: a first run is slower
        fn()
    limits = {}
    if fd:
        fns.update(
            fd_ls_trf=partial(_peer_ls, prob, x0, free, "trf", jac="2-point"),
            fd_minimax_slsqp=partial(_peer_minimax, prob, x_ls, free, analytic=False),
        )
        limits = {"fd_ls_trf": FD_ROUNDS, "fd_minimax_slsqp": FD_ROUNDS}
    load_before = load()
    times, res = interleaved(fns, rounds, limits=limits)
    entry: dict = {
        "poses": int(m),
        "readings": meas.n_readings,
        "free_parameters": int(free.sum()),
        "rounds": len(times["ours_ls_sum"]),
        "load_average": {"before": load_before, "after": load()},
        "timings": {k: spread(v) for k, v in times.items()},
        "ours": {},
    }
    for key in OURS:
        r = _ours_calibrate(res[f"ours_{key}"], meas.xyz)
        r["seconds"] = entry["timings"][f"ours_{key}"]["median_s"]
        entry["ours"][key] = r
        _log(
            f"  ours {key}: {r['seconds'] * 1000:.1f} ms median, objective {r['objective']:.6g} mm^2"
        )
    entry["ours_seconds_per_pose"] = {k: v["seconds"] / m for k, v in entry["ours"].items()}
    if not peers:
        return entry
    x_solve, lm = res["ours_ls_solve"]
    mm = res["ours_minimax_sqp"]
    entry["stages"] = {
        "ls_solve": _ls_figures(
            prob, x_solve, iterations=lm.iterations, nfev=lm.nfev, njev=lm.njev
        ),
        "minimax_sqp": {
            "objective": float(prob.sum_squares(mm.x).max()),
            "F": prob.sum_squares(mm.x).tolist(),
            "iterations": mm.iterations,
            "converged": mm.converged,
            "max_constraint_violation_mm2": _violation(prob.layout.targets(mm.x), prob.meas),
        },
    }
    entry["peers"] = {
        "ls_lm": res["peer_ls_lm"][1],
        "ls_trf": res["peer_ls_trf"][1],
        "minimax_slsqp": res["peer_minimax_slsqp"][1],
    }
    med = entry["timings"]
    ls_peer = min(("peer_ls_lm", "peer_ls_trf"), key=lambda k: med[k]["median_s"])
    entry["headline"] = {
        "ls_sum": {
            "peer": ls_peer,
            "ours": "ours_ls_solve",
            "speedup": paired(times, [ls_peer], ["ours_ls_solve"]),
        },
        "minimax": {
            "peer": "peer_minimax_slsqp",
            "ours": "ours_minimax_sqp",
            "speedup": paired(times, ["peer_minimax_slsqp"], ["ours_minimax_sqp"]),
        },
    }
    mm_chain = ["setup", ls_peer, "peer_minimax_slsqp"]
    entry["end_to_end"] = {
        "ls_sum": paired(times, ["setup", ls_peer], ["ours_ls_sum"]),
        "minimax": paired(times, mm_chain, ["ours_minimax"]),
        "minimax_exact": paired(times, mm_chain, ["ours_minimax_exact"]),
    }
    entry["precision"] = _precision(prob, x_ls, free, entry)
    if fd:
        entry["finite_difference"] = {
            "ls_trf": res["fd_ls_trf"][1],
            "minimax_slsqp": res["fd_minimax_slsqp"][1],
            "speedup_end_to_end": {
                "ls_sum": paired(times, ["setup", "fd_ls_trf"], ["ours_ls_sum"]),
                "minimax": paired(
                    times, ["setup", "fd_ls_trf", "fd_minimax_slsqp"], ["ours_minimax"]
                ),
            },
        }
    h = entry["headline"]
    _log(
        f"  speedup over the fair peers (median of rounds): ls-sum {h['ls_sum']['speedup']['median']:.2f}x "
        f"({ls_peer}), minimax {h['minimax']['speedup']['median']:.2f}x (SLSQP)"
    )
    return entry


def _precision(prob, x_ls, free, entry: dict) -> dict:
    """Each side's objective relative to the best any reached, tight runs included (untimed):
    scipy lm at ftol = xtol = gtol = 1e-15 for ls-sum; ours and SLSQP at 1e-14 for minimax."""
    _, tight = _peer_ls(prob, x_ls, free, "lm", ftol=1e-15, xtol=1e-15)
    ls = {
        "ours_solve": entry["stages"]["ls_solve"]["objective"],
        "ours_calibrate": entry["ours"]["ls_sum"]["objective"],
        "peer_lm": entry["peers"]["ls_lm"]["objective"],
        "peer_trf": entry["peers"]["ls_trf"]["objective"],
    }
    ls_best = min(tight["objective"], *ls.values())
    tight_mm = minimax(prob, x_ls, free, tol=1e-14)
    _, tight_slsqp = _peer_minimax(prob, x_ls, free, ftol=1e-14)
    mm = {
        "ours_sqp": entry["stages"]["minimax_sqp"]["objective"],
        "ours_calibrate": entry["ours"]["minimax"]["objective"],
        "ours_calibrate_exact": entry["ours"]["minimax_exact"]["objective"],
        "peer_slsqp": entry["peers"]["minimax_slsqp"]["objective"],
    }
    mm_best = min(float(prob.sum_squares(tight_mm.x).max()), tight_slsqp["objective"], *mm.values())
    return {
        "ls_sum": {
            "best_objective": ls_best,
            "relative_excess": {k: _rel(v, ls_best) for k, v in ls.items()},
        },
        "minimax": {
            "best_objective": mm_best,
            "relative_excess": {k: _rel(v, mm_best) for k, v in mm.items()},
        },
        "note": "calibrate() may hold parameters the data moves too little, so its objective "
        "can sit above the stage's on the structurally free set",
    }


def _machine() -> dict:
    """What the figures were measured on."""
    return {
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
    }


def _goals(sizes: dict) -> dict:
    """The targets, the achieved figures and whether each is met (None: not measured).

    speedup_min is judged on the headline ratios (the solve stages against the strongest fair
    peer, median of paired rounds) of ls-sum and minimax at every size with peers.
    """
    at100 = sizes.get("100", {}).get("ours")
    heads = [s["headline"] for s in sizes.values() if "headline" in s]
    achieved = {
        "ls_sum_100_poses_ms": at100["ls_sum"]["seconds"] * 1000 if at100 else None,
        "minimax_100_poses_ms": at100["minimax"]["seconds"] * 1000 if at100 else None,
        "speedup_min": min(
            (h[k]["speedup"]["median"] for h in heads for k in ("ls_sum", "minimax")), default=None
        ),
    }
    ls_ms, mm_ms, speedup = (
        achieved[k] for k in ("ls_sum_100_poses_ms", "minimax_100_poses_ms", "speedup_min")
    )
    met = {
        "ls_sum_100_poses_ms_max": None
        if ls_ms is None
        else ls_ms <= GOALS["ls_sum_100_poses_ms_max"],
        "minimax_100_poses_ms_max": None
        if mm_ms is None
        else mm_ms <= GOALS["minimax_100_poses_ms_max"],
        "speedup_min": None if speedup is None else speedup >= GOALS["speedup_min"],
    }
    return {"targets": dict(GOALS), "achieved": achieved, "met": met}


def run_solver_bench(
    sizes=(100, 1000, 10000),
    reference=True,
    reference_max=10000,
    seed=SEED,
    repeats=None,
    scale_poses=50_000,
    fd_max=1000,
) -> dict:
    """Time our solvers and the fair peers (analytic derivatives) on virtual-cell campaigns of each
    size, in interleaved rounds; finite-difference scipy up to fd_max poses as a secondary line;
    then ls-sum, minimax and the meas.csv reader at scale_poses (time and peak memory).

    reference: run the peers at all (up to reference_max poses); repeats: rounds per size.
    """
    from ..formats.cell_json import default_cell

    cell = default_cell()
    names = tuple(cell.targets)
    targets = cell.target_positions(names)
    load_start = load()
    results = {}
    for m in sizes:
        meas = _campaign(cell, int(m), seed)
        _log(f"{m} poses x {len(names)} SMRs ({meas.n_readings} readings)")
        peers = reference and m <= reference_max
        results[str(m)] = _size(
            cell, meas, names, targets, int(m), repeats or _rounds(m), peers, peers and m <= fd_max
        )
    scale = None
    if scale_poses:
        from .scale import run_scale

        _log(f"{scale_poses} poses: time and peak memory of ls-sum and minimax, meas.csv read")
        scale = run_scale(cell, _campaign(cell, int(scale_poses), seed))
    return {
        "benchmark": "solver",
        "machine": _machine(),
        "load_average": {"start": load_start, "end": load()},
        "cell": {
            "robot": cell.robot.name,
            "targets": {k: v.tolist() for k, v in zip(names, targets)},
            "seed": seed,
        },
        "reference": {
            "ls_sum": "scipy.optimize.least_squares, method 'lm' and 'trf', x_scale='jac', the "
            f"analytic Jacobian (kinematics.predict_rows), ftol={FTOL:g} and xtol={XTOL:g} as "
            "ours; the faster of the two is the headline's peer",
            "minimax": "scipy.optimize.minimize(method='SLSQP') on the epigraph form with "
            f"analytic gradients, ftol={MINIMAX_TOL:g} on max F_i relative to the start (ours: "
            "tol on the predicted decrease relative to max F_i), from the same ls-sum solution",
            "headline": "solve stages on the same registered problem, start and free "
            "parameters: ours_ls_solve (identify.least_squares_fit) and ours_minimax_sqp "
            "(minimax.minimax) against the peers; end_to_end: calibrate() against the peers "
            "plus the set-up (register + structural)",
            "finite_difference": f"least_squares trf with jac='2-point' and SLSQP without "
            f"derivatives, up to {fd_max} poses, {FD_ROUNDS} rounds: secondary",
            "timing": "interleaved rounds, every side once a round in a rotating order after one "
            "untimed warm-up; medians with quartiles and extremes; speed-ups are the median of "
            "the per-round ratios",
            "precision": "every side's objective (sum F_i; max F_i) relative to the best any "
            "reached, tight untimed runs included",
        },
        "sizes": results,
        "scale": scale,
        **_goals(results),
    }
