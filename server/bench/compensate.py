"""Compensation benchmark: targets solved per second, all at once, next to the same damped least
squares solved one target at a time by scipy with the same analytic Jacobian and tolerance.

Both sides solve the same well-determined problem (three SMRs a target: nine equations in six
joints) from the same starts, and their answers are scored by the same measure: the model's RMS
miss over the target's SMRs at the joints returned (solver/compensate.py's error_mm). Every
figure is the median of interleaved rounds with its spread and the machine's load average.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from .timing import interleaved, load, paired, spread

SEED = 31
EFFECT = "joint_compliance:2=1.0"
SMRS = 3
EPS = float(np.finfo(float).eps)


def _setup():
    """A diagnosed model of a simulated cell with compliance, and that cell."""
    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.effects import make_effects
    from robocal.server.calibration import workflow
    from robocal.server.compensate.compensation import solver_model

    from ..formats.cell_json import default_cell

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=SEED)
    vc.effects.extend(make_effects([EFFECT], vc, SEED))
    _, model = workflow.diagnose(cell, vc.campaign(100, seed=SEED), screen=False)
    return solver_model(model), vc


def miss_mm(model, q, desired, mask) -> np.ndarray:
    """Per target: the model's RMS miss (mm) over its SMRs in mask at joints q (the measure
    solver/compensate.py reports as error_mm)."""
    r = np.where(mask[..., None], model.predict(q) - desired, 0.0)
    return np.sqrt(np.sum(r * r, axis=(1, 2)) / np.maximum(mask.sum(axis=1), 1))


def peer(model, desired, mask, q0, method: str) -> np.ndarray:
    """scipy least_squares on each target by itself with the model's analytic joint Jacobian
    (the one our solver steps with), stopping on the step as ours does (STEP_TOL_RAD); trf
    within the joint limits, lm without them."""
    from scipy.optimize import least_squares

    from robocal.solver.compensate import STEP_TOL_RAD

    lo, hi = model.layout.robot.lower, model.layout.robot.upper
    out = np.empty_like(q0)
    last: dict = {}  # one walk of the chain gives both: the Jacobian of the residual just taken

    def at(q):
        if last.get("q") is None or not np.array_equal(last["q"], q):
            p, J = model.evaluate(q[None])
            last.update(q=q.copy(), p=p[0], J=J[0])
        return last["p"], last["J"]

    for i in range(len(q0)):
        want, keep = desired[i], mask[i]

        def fun(q, want=want, keep=keep):
            return (at(q)[0] - want)[keep].ravel()

        def jac(q, keep=keep):
            return at(q)[1][keep].reshape(-1, len(q))

        # xtol is relative to |q| (about a radian): the same step as ours; ftol and gtol at
        # rounding so that the step decides, as in ours
        bounded = method == "trf"
        out[i] = least_squares(
            fun,
            np.clip(q0[i], lo, hi) if bounded else q0[i],
            jac=jac,
            method=method,
            bounds=(lo, hi) if bounded else (-np.inf, np.inf),
            xtol=STEP_TOL_RAD,
            ftol=EPS,
            gtol=EPS,
        ).x
    return out


def _rounds(n: int) -> int:
    return 9 if n <= 100 else 3


def _size(model, vc, n: int, rounds: int, peers: bool) -> dict:
    """Ours and the peers on n targets of SMRS SMRs each, started at the program's joints
    rounded to 0.1 deg."""
    from robocal.solver.compensate import compensate

    q_want = vc.sample_poses(n, np.random.default_rng([SEED, n]))
    desired = vc.true_points(q_want)
    q0 = np.deg2rad(np.round(np.degrees(q_want), 1))
    mask = np.zeros(desired.shape[:2], dtype=bool)
    mask[:, :SMRS] = True
    fns: dict[str, Callable[[], Any]] = {"ours": partial(compensate, model, desired, mask, q0)}
    if peers:
        fns["peer_trf"] = partial(peer, model, desired, mask, q0, "trf")
        fns["peer_lm"] = partial(peer, model, desired, mask, q0, "lm")
    compensate(model, desired, mask, q0)  # untimed warm-up, and of the peers on a few targets
    if peers:
        for method in ("trf", "lm"):
            peer(model, desired[:5], mask[:5], q0[:5], method)
    before = load()
    times, res = interleaved(fns, rounds)
    ours = res["ours"]
    t = {k: spread(v) for k, v in times.items()}
    row: dict = {
        "targets": n,
        "smrs_per_target": SMRS,
        "rounds": len(times["ours"]),
        "load_average": {"before": before, "after": load()},
        "timings": t,
        "targets_per_second": n / t["ours"]["median_s"],
        "iterations": ours.iterations,
        "converged": int(ours.converged.sum()),
    }
    errs = {"ours": miss_mm(model, ours.q, desired, mask)}
    if peers:
        lo, hi = model.layout.robot.lower, model.layout.robot.upper
        for k in ("peer_trf", "peer_lm"):
            errs[k] = miss_mm(model, res[k], desired, mask)
            row[k] = {
                "targets_per_second": n / t[k]["median_s"],
                "max_joint_difference_from_ours_deg": float(
                    np.degrees(np.abs(res[k] - ours.q)).max()
                ),
                "outside_limits": int(np.sum(np.any((res[k] < lo) | (res[k] > hi), axis=1))),
            }
        best = min(("peer_trf", "peer_lm"), key=lambda k: t[k]["median_s"])
        row["headline"] = {"peer": best, "speedup": paired(times, [best], ["ours"])}
    row["miss_mm"] = {
        k: {"median": float(np.median(e)), "max": float(e.max())} for k, e in errs.items()
    }
    head = row.get("headline")
    print(
        f"[bench] compensate {n} targets: ours {row['targets_per_second']:.0f}/s"
        + (
            f", {head['peer']} {row[head['peer']]['targets_per_second']:.0f}/s, "
            f"speed-up {head['speedup']['median']:.1f}x"
            if head
            else ""
        ),
        file=sys.stderr,
        flush=True,
    )
    return row


def _from_configuration(model, vc, rounds: int) -> dict:
    """100 targets solved from their ABB configuration alone (no starting joints)."""
    from robocal.solver.compensate import compensate
    from robocal.solver.configuration import confdata

    q_want = vc.sample_poses(100, np.random.default_rng([SEED, 1]))
    desired = vc.true_points(q_want)
    cf = confdata(model.nominal, q_want)
    mask = np.ones(desired.shape[:2], dtype=bool)
    times, res = interleaved({"ours": partial(compensate, model, desired, mask, cf=cf)}, rounds)
    r = res["ours"]
    return {
        "targets": 100,
        "smrs_per_target": desired.shape[1],
        "timings": {"ours": spread(times["ours"])},
        "targets_per_second": 100 / spread(times["ours"])["median_s"],
        "worst_miss_mm": float(miss_mm(model, r.q, desired, mask).max()),
        "configuration_kept": int(np.all(confdata(model.nominal, r.q) == cf, axis=1).sum()),
        "max_joint_change_deg": float(np.degrees(np.abs(r.q - q_want)).max()),
    }


def run_compensate_bench(sizes=(100, 1000), reference_max: int = 1000, rounds=None) -> dict:
    """Throughput of ours and of the per-target peers (up to reference_max targets) at each size,
    in interleaved rounds; then 100 targets from their configuration alone."""
    model, vc = _setup()
    start = load()
    rows = [_size(model, vc, n, rounds or _rounds(n), n <= reference_max) for n in sizes]
    return {
        "benchmark": "compensate",
        "model": "irb2600 diagnosed from 100 simulated poses with " + EFFECT,
        "load_average": {"start": start, "end": load()},
        "peers": "scipy.optimize.least_squares on each target by itself, jac= the model's "
        "analytic joint Jacobian (the one ours steps with), xtol = ours' step tolerance "
        "(STEP_TOL_RAD), ftol = gtol = machine epsilon; trf within the joint limits, lm without",
        "error_measure": "per target, the model's RMS miss over its SMRs at the joints returned, "
        "the same function on both sides",
        "timing": "interleaved rounds after an untimed warm-up; medians with quartiles and "
        "extremes; speed-ups the median of per-round ratios",
        "with_starting_guess": rows,
        "from_configuration": _from_configuration(model, vc, rounds or 5),
    }
