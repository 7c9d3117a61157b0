"""Compensation benchmark: targets solved per second, all at once, next to scipy one by one."""

from __future__ import annotations

import time

import numpy as np

SEED = 31
EFFECT = "joint_compliance:2=1.0"


def _setup():
    """A diagnosed model of a simulated cell with compliance, and that cell."""
    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.effects import make_effects

    from .. import workflow
    from ..compensation import solver_model
    from ..formats.cell_json import default_cell

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=SEED)
    vc.effects.extend(make_effects([EFFECT], vc, SEED))
    _, model = workflow.diagnose(cell, vc.campaign(100, seed=SEED), screen=False)
    return solver_model(model), vc


def _reference(model, desired, mask, q0):
    """scipy.optimize.least_squares (trust region, bounded) on each target by itself."""
    from scipy.optimize import least_squares

    lo, hi = model.layout.robot.lower, model.layout.robot.upper
    out = np.empty_like(q0)
    for i in range(len(q0)):
        want, keep = desired[i : i + 1], mask[i : i + 1]

        def fun(q, want=want, keep=keep):
            return (model.predict(q[None]) - want)[keep].ravel()

        out[i] = least_squares(fun, np.clip(q0[i], lo, hi), bounds=(lo, hi), xtol=1e-10).x
    return out


def run_compensate_bench(sizes=(100, 1000), reference_max: int = 30) -> dict:
    """Throughput for 1 and 3 SMRs a target at each size, starting from the program's joints
    (rounded to 0.1 deg), and scipy's one target at a time on up to reference_max of them."""
    from robocal.solver.compensate import compensate
    from robocal.solver.configuration import confdata

    model, vc = _setup()
    rows = []
    for n in sizes:
        q_want = vc.sample_poses(n, np.random.default_rng([SEED, n]))
        desired = vc.true_points(q_want)
        q0 = np.deg2rad(np.round(np.degrees(q_want), 1))
        for smrs in (1, 3):
            mask = np.zeros(desired.shape[:2], dtype=bool)
            mask[:, :smrs] = True
            t0 = time.perf_counter()
            res = compensate(model, desired, mask, q0)
            dt = time.perf_counter() - t0
            row = {
                "targets": n,
                "smrs_per_target": smrs,
                "seconds": round(dt, 4),
                "targets_per_second": round(n / dt, 1),
                "iterations": res.iterations,
                "worst_predicted_error_mm": float(res.error_mm.max()),
            }
            k = min(n, reference_max)
            if k:
                t0 = time.perf_counter()
                ref = _reference(model, desired[:k], mask[:k], q0[:k])
                rdt = time.perf_counter() - t0
                ref_err = model.predict(ref) - desired[:k]
                row["reference"] = {
                    "solver": "scipy.optimize.least_squares, one target at a time",
                    "targets": k,
                    "targets_per_second": round(k / rdt, 1),
                    "worst_predicted_error_mm": float(
                        np.sqrt(np.max(np.sum(np.where(mask[:k, :, None], ref_err, 0) ** 2, -1)))
                    ),
                }
                row["speedup"] = round(row["targets_per_second"] / (k / rdt), 1)
            rows.append(row)
    q_want = vc.sample_poses(100, np.random.default_rng([SEED, 1]))
    desired = vc.true_points(q_want)
    cf = confdata(model.nominal, q_want)
    t0 = time.perf_counter()
    res = compensate(model, desired, np.ones(desired.shape[:2], dtype=bool), cf=cf)
    dt = time.perf_counter() - t0
    return {
        "model": "irb2600 diagnosed from 100 simulated poses with " + EFFECT,
        "with_starting_guess": rows,
        "from_configuration": {
            "targets": 100,
            "smrs_per_target": 3,
            "targets_per_second": round(100 / dt, 1),
            "worst_predicted_error_mm": float(res.error_mm.max()),
            "configuration_kept": int(np.all(confdata(model.nominal, res.q) == cf, axis=1).sum()),
            "max_joint_change_deg": float(np.degrees(np.abs(res.q - q_want)).max()),
        },
    }
