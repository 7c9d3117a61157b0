"""The extended models' coverage suite (tests/solver/test_position_uncertainty.py runs it): a
geometric model with effects, as `robocal diagnose` fits them, calibrated on a simulated cell
with effects (the model's own effect; with the arm's scatter too; or with a weaker effect the
model does not have), its U from the geometry's and the extension's coefficients' covariance
propagated through its Jacobian columns, against the true error at independent positions."""

from __future__ import annotations

from functools import cache

import numpy as np

from robocal.drivers.cell import VirtualCell
from robocal.drivers.effects import make_effects
from robocal.solver import guard
from robocal.solver import identifiability as ident
from robocal.solver import position_uncertainty as pu
from robocal.solver.effects import Inputs, prepare
from robocal.solver.extended import fit_extended, predict_extended
from robocal.solver.fit_errors import extended_fit_rows
from robocal.solver.identify import register
from robocal.solver.uncertainty import errors_from_rows
from robocal.solver.vocabulary import candidates
from tests.solver.coverage_suite import TARGETS, TEST_POSES

# (effect the model has: name, 0-based joint, harmonic; the simulator's spec of it)
MODELLED = (
    ("joint_compliance", 1, None, "joint_compliance:2=0.3"),
    ("joint_periodic", 2, 1, "joint_periodic:3=0.01"),
    ("joint_compliance", 2, None, "joint_compliance:3=0.3"),
)
UNMODELLED = "joint_periodic:2=0.004"  # the "extra" kind: an effect the model does not have
POSES = 50
KINDS = ("effect", "scatter", "extra")


def _extension(layout, x0, inputs, name, joint, harmonic):
    """The vocabulary's extension of this effect, as the diagnosis would name it."""
    return next(
        e
        for e in candidates(layout, x0, inputs)
        if e.name == name and e.joint == joint and harmonic in (None, e.harmonic)
    )


@cache
def _fitted(robot, seed: int, kind: str):
    """An extended model fitted on POSES poses, its errors and joint scatter, the TEST_POSES
    independent poses with its extensions' bases there, and the true error at their SMRs, mm
    (kept: the too-small check scales the very fits the coverage check judged)."""
    name, joint, harmonic, spec = MODELLED[seed % len(MODELLED)]
    vc = VirtualCell.random(robot, TARGETS, seed=seed)
    vc.effects = make_effects([spec] + ([UNMODELLED] if kind == "extra" else []), vc, seed)
    scatter = 0.003 if kind == "scatter" else 0.0
    train = vc.campaign(POSES, seed, arm_scatter_deg=scatter)
    nominal = np.array([TARGETS[t] for t in train.target_names])
    prob, x0 = register(robot, nominal, train.target_names, train.q, train.xyz)
    lay = prob.layout
    free = ident.structural(lay, x0, np.ones(lay.n_params, dtype=bool)).free
    inputs = Inputs(train.q)
    ext = _extension(lay, x0, inputs, name, joint, harmonic)
    x, exts, _ = fit_extended(prob, inputs, x0, free, [ext])
    rows, names, column, degrees = extended_fit_rows(prob, inputs, x0, free, x, exts)
    errors = errors_from_rows(rows, names, column, degrees)
    holdout = guard.leave_one_pose_out(rows).rms()
    bases = [prepare(e, lay, x0, inputs) for e in exts]
    trained = pu.extended_spread_at(lay, x, exts, bases, inputs, errors.cov, errors.column)
    s = pu.joint_scatter_rad(*pu.mean_traces(trained), holdout, vc.last_campaign["noise_floor_mm"])
    rng = np.random.default_rng([7, seed])
    q = vc.sample_poses(TEST_POSES, rng)
    truth = vc.true_points(q, pose_dq=np.deg2rad(scatter) * rng.normal(size=q.shape))
    test = Inputs(q)
    at_test = [prepare(e, lay, x0, test) for e in exts]
    err = np.linalg.norm(predict_extended(lay, x, exts, test, at_test) - truth, axis=-1)
    return lay, x, exts, at_test, test, errors, s, err


def case(robot, seed: int, kind: str, shrink: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(true error, U) at the SMRs of TEST_POSES independent poses, mm, of an extended model
    fitted on POSES poses; its covariance and scatter multiplied by `shrink`."""
    lay, x, exts, at_test, test, errors, s, err = _fitted(robot, seed, kind)
    at = pu.extended_spread_at(lay, x, exts, at_test, test, errors.cov * shrink, errors.column)
    return err, pu.position_uncertainty(at, s * np.sqrt(shrink)).expanded_mm
